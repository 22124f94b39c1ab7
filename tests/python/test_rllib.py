"""Ray RLlib trains on the sorting line: our Gymnasium ids registered with Ray Tune
(sorting_line_gym.training.rllib), envs made by ``gymnasium.make`` inside RLlib's EnvRunners.

- PPO with 2 EnvRunners x 4 envs on this machine, each EnvRunner's envs on the lines of a node of
  its own (``nodes``), trained 4,000 env steps;
- a Ray cluster of a head and a worker in two network namespaces this test makes (tests/python/
  netns_hosts.py), the EnvRunners on the worker (the head offers no CPU), their envs on lines of the
  worker's own line server; the driver and the learner on the head.

Both run in CI: test.sh installs Ray (setup.sh --rllib) in the background next to the Rust tests and
sets SORTING_LINE_RLLIB=1, under which a missing Ray is a failure, not a skip. Without that variable
they run when Ray is installed and skip, saying how to install it, when it is not. About 25 s and
40 s on a quiet 2-core machine (importing Ray, starting it and building the algorithm are most of it).
Ray is kept from talking to anyone: usage statistics off (RAY_USAGE_STATS_ENABLED=0), no dashboard,
and only the addresses of the namespaces (or loopback).
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import secrets
import subprocess
import sys
import tempfile

import pytest

from support import netns_hosts
from support.ray_cluster import RayCluster, ray_env

REQUIRED = os.environ.get("SORTING_LINE_RLLIB") == "1"
INSTALLED = importlib.util.find_spec("ray") is not None
if REQUIRED and not INSTALLED:
    raise ImportError(
        "SORTING_LINE_RLLIB=1 but Ray is not installed in this venv: bash launch_scripts/setup.sh --rllib "
        "(launch_scripts/requirements-rllib.txt)"
    )
pytestmark = pytest.mark.skipif(
    not INSTALLED, reason="Ray RLlib is not installed: bash launch_scripts/setup.sh --rllib (test.sh does this itself)"
)

TRAIN = [sys.executable, "-m", "sorting_line_gym.training.rllib"]


def summary(r: subprocess.CompletedProcess, what: str) -> dict:
    assert r.returncode == 0, f"{what} failed ({r.returncode}):\n{r.stdout[-2000:]}\n{r.stderr[-6000:]}"
    return json.loads(r.stdout.strip().splitlines()[-1])


def check_training(result: dict, timesteps: int, where: str) -> None:
    assert result["env_steps"] >= timesteps, f"{where}: {result['env_steps']} env steps, want {timesteps}: {result}"
    last = result["iterations"][-1]
    assert last["episodes"] and last["episodes"] > 0, f"{where}: no episode completed: {result}"
    assert last["episode_return_mean"] is not None and math.isfinite(last["episode_return_mean"]), result


def test_ppo_with_two_env_runners_each_on_a_node_of_its_own(start_node, namespace):
    nodes = [namespace("runner1"), namespace("runner2")]
    for ns in nodes:
        start_node("--setup", "B", "--lines", "4", "--ros-args", "-r", f"__ns:={ns}")
    r = subprocess.run(
        [
            *TRAIN,
            "--setup",
            "B",
            "--env-runners",
            "2",
            "--envs-per-runner",
            "4",
            "--timesteps",
            "4000",
            "--batch",
            "1000",
            "--nodes",
            *nodes,
        ],
        capture_output=True,
        text=True,
        timeout=400,
        env=ray_env(),
    )
    result = summary(r, "RLlib PPO")
    check_training(result, 4000, "2 EnvRunners x 4 envs")
    placement = sorted(result["env_runners"], key=lambda p: p["worker_index"])
    assert [p["worker_index"] for p in placement] == [1, 2], placement
    for p, ns in zip(placement, nodes, strict=False):
        assert sorted(p["lines"]) == [f"{ns}/line_{k}" for k in range(4)], f"EnvRunner {p['worker_index']}: {p}"
    assert len({p["pid"] for p in placement}) == 2, placement
    # RLlib closes a remote EnvRunner's envs, then ray.kill()s it: its DDS participant is never
    # deleted (deleting it while the other EnvRunner closes its envs hung a CI run in Fast DDS).
    assert all(p["keeps_participant"] for p in placement), placement


@pytest.mark.skipif(netns_hosts.problem() is not None, reason=f"hosts: {netns_hosts.problem()}")
def test_ray_cluster_head_and_worker_in_two_hosts_runs_the_env_runners_on_the_worker(tmp_path):
    # Ray's unix sockets live under its temp dir: keep the path short (a socket path has 107 bytes).
    temp = {host: tempfile.mkdtemp(prefix=f"slray_{host}_") for host in ("head", "worker")}
    with netns_hosts.Hosts(["head", "worker"]) as hosts:
        head_ip, worker_ip = hosts.address("head"), hosts.address("worker")
        gcs = f"{head_ip}:6379"
        # The lines stay on the worker host; the cluster's members prove themselves with a token of
        # this test's own (Ray's token authentication; `ray start --head` requires one).
        env = ray_env(
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32)
        )
        cluster = RayCluster(hosts, env, gcs, tmp_path)
        try:
            head = f"--head --node-ip-address={head_ip} --port=6379 --num-cpus=0 --include-dashboard=false"
            cluster.start(
                "head",
                f"{head} --temp-dir={temp['head']} --disable-usage-stats",
                lambda s: s.returncode == 0,
                "the head did not answer",
            )
            # The driver would wait forever for CPUs: first the worker's 2 CPUs must be in the cluster.
            worker = f"--address={gcs} --node-ip-address={worker_ip} --num-cpus=2 --temp-dir={temp['worker']}"
            cluster.start(
                "worker",
                f"{worker} --disable-usage-stats",
                lambda s: s.returncode == 0 and "/2.0 CPU" in s.stdout,
                "the worker did not join the head",
            )
            flags = "--setup A --env-runners 2 --envs-per-runner 4 --timesteps 4000 --batch 1000"
            driver = hosts.argv("head", [*TRAIN, *flags.split(), "--address", gcs])
            r = subprocess.run(driver, capture_output=True, text=True, timeout=400, env=env)
            result = summary(r, "RLlib PPO on the two-host Ray cluster")
        finally:
            cluster.stop()
    print(json.dumps(result, indent=1))
    check_training(result, 2000, "Ray cluster")
    assert {p["node_ip"] for p in result["env_runners"]} == {worker_ip}, f"EnvRunners not all on the worker: {result}"
    lines = [ns for p in result["env_runners"] for ns in p["lines"]]
    assert len(lines) == 8 and len(set(lines)) == 8, f"8 envs on 8 distinct lines: {lines}"
