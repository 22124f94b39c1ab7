"""The studies' cells on a Ray cluster (``--ray ADDRESS``, studies/ray_cells.py): a small benchmark
(two baselines and a short A2C cell, native lines) run on a cluster of two hosts in network
namespaces (tests/python/support/netns_hosts.py, the cluster as test_rllib.py starts its own), cut by
SIGTERM after its first cell and run again, against the same command on one machine without Ray.

It checks that the cells ran on both hosts (each record's ``ran_on``), that the cut run kept its
finished cells and the rerun ran only the others, and that the store equals the one-machine store
but for wall times and ``ran_on`` (determinism: the same numbers wherever a cell runs), the model
written under ``--out`` as there. Bad input: an address that does not answer, ``--jobs`` with
``--ray``, a malformed address, and Ray missing.

Like test_rllib.py it runs in CI (test.sh installs Ray, SORTING_LINE_RLLIB=1 makes a missing Ray a
failure) and otherwise skips, saying how to install Ray. Most of its time is Ray's daemons starting (each
`ray status` poll imports Ray) and three benchmark runs importing torch and drawing their reports; its
time under load: docs/results/scaling.md, "Ray RLlib".
"""

from __future__ import annotations

import importlib.util
import json
import re
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from support import netns_hosts
from support.ray_cluster import RayCluster, ray_env

INSTALLED = importlib.util.find_spec("ray") is not None
needs_ray = pytest.mark.skipif(
    not INSTALLED, reason="Ray is not installed: bash launch_scripts/setup.sh --rllib (test.sh does this itself)"
)
BENCHMARK = [sys.executable, "-m", "sorting_line_gym.studies.benchmark"]
#: Two baselines and one short RL cell, on native lines; the held-out episodes as many as a curve needs.
FLAGS = (
    "--backend native --setups A --variants basic --agents random rba-hold a2c --train-seeds 42 "
    "--timesteps 1000 --heldout-episodes 20 --out results"
)
CELLS = {"A_basic_random", "A_basic_rba-hold", "A_basic_a2c_seed42"}
#: What differs between two runs of one cell: its wall times, and where it ran.
VOLATILE = {"wall_s", "steps_per_s", "seconds", "ran_on"}


class Cluster(RayCluster):
    """test_rllib's cluster, whose `ray status` may also be slower than its 60 s under load: then the
    cluster counts as not ready yet (start() asks again until its own deadline)."""

    def status(self) -> subprocess.CompletedProcess:
        try:
            return super().status()
        except subprocess.TimeoutExpired as e:
            return subprocess.CompletedProcess(e.cmd, 124, "", f"`ray status` took over {e.timeout} s")


def cells(results: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted((results / "cells").glob("*.json"))}


def steady(value):
    """A record without what changes from run to run (VOLATILE)."""
    if isinstance(value, dict):
        return {k: steady(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [steady(v) for v in value]
    return value


def run(argv: list[str], cwd: Path, env: dict[str, str], what: str) -> subprocess.CompletedProcess:
    r = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=400, env=env)
    assert r.returncode == 0, f"{what} failed ({r.returncode}):\n{r.stdout[-2000:]}\n{r.stderr[-6000:]}"
    return r


def cut_after_first_cell(argv: list[str], cwd: Path, env: dict[str, str]) -> str:
    """Runs ``argv`` until it reports its first finished cell (a line on stdout), then SIGTERM; its
    output. It must stop with 130 (interrupted, finished cells kept)."""
    log = cwd / "cut.log"
    with open(log, "w") as errors:
        p = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=errors, text=True)
        watchdog = threading.Timer(400, p.kill)  # a run that hangs ends the loop below
        watchdog.start()
        seen = []
        assert p.stdout is not None
        for line in p.stdout:
            seen.append(line)
            if re.search(r"A_basic_\S+: seeds 42\.\.51", line):
                p.send_signal(signal.SIGTERM)
                break
        rest = p.stdout.read()
        code = p.wait(timeout=60)
        watchdog.cancel()
    output = "".join(seen) + rest + log.read_text()
    assert len(seen) and code == 130, f"SIGTERM after the first cell: exit {code}, want 130:\n{output[-6000:]}"
    return output


@needs_ray
@pytest.mark.skipif(netns_hosts.problem() is not None, reason=f"hosts: {netns_hosts.problem()}")
def test_a_benchmark_on_two_hosts_resumes_and_equals_the_one_machine_run(tmp_path):
    local, on_ray = tmp_path / "local", tmp_path / "ray"
    local.mkdir()
    on_ray.mkdir()
    env = ray_env(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    temp = {host: tempfile.mkdtemp(prefix=f"slrc_{host}_") for host in ("head", "worker")}
    try:
        with netns_hosts.Hosts(["head", "worker"]) as hosts:
            head_ip, worker_ip = hosts.address("head"), hosts.address("worker")
            kept, rerun = on_the_cluster(hosts, env, on_ray, temp, tmp_path)
    finally:
        for path in temp.values():
            shutil.rmtree(path, ignore_errors=True)
    # Then, not meanwhile: under load Ray's daemons miss their own start deadlines when starved.
    run([*BENCHMARK, *FLAGS.split()], local, env, "the same benchmark on one machine")
    assert f"{len(kept)} already done, {len(CELLS) - len(kept)} to run" in rerun.stderr, rerun.stderr[-3000:]
    for name, (mtime, data) in kept.items():
        path = on_ray / "results/cells" / f"{name}.json"
        assert (path.stat().st_mtime_ns, path.read_bytes()) == (mtime, data), f"the rerun redid {name}"
    there, here = cells(on_ray / "results"), cells(local / "results")
    assert set(there) == set(here) == CELLS, (sorted(there), sorted(here))
    ran_on = {name: r["ran_on"] for name, r in there.items()}
    assert {where["ip"] for where in ran_on.values()} == {head_ip, worker_ip}, f"not on both hosts: {ran_on}"
    for name in CELLS:
        assert steady(there[name]) == steady(here[name]), f"{name} differs on the cluster:\n{there[name]}\n{here[name]}"
    model = there["A_basic_a2c_seed42"]["training"]["model_path"]
    assert model == "results/models/a2c_A_basic_seed42.zip" and (on_ray / model).is_file(), model


def on_the_cluster(hosts, env: dict[str, str], on_ray: Path, temp: dict[str, str], logs: Path):
    """A head and a worker of one CPU each (two cells at once are on two hosts), the benchmark
    driven from the head, cut after its first cell and run again; (the cut run's cells: their
    mtimes and bytes, the rerun)."""
    head_ip, worker_ip = hosts.address("head"), hosts.address("worker")
    gcs = f"{head_ip}:6379"
    cluster = Cluster(hosts, env, gcs, logs)
    try:
        head = f"--head --node-ip-address={head_ip} --port=6379 --num-cpus=1 --include-dashboard=false"
        # Ready once its raylet is in (its CPU counted): a head whose GCS answers may still time out
        # waiting for its raylet (Ray's fixed 30 s, under load) and exit; start() then starts it again.
        cluster.start(
            "head", f"{head} --temp-dir={temp['head']} --disable-usage-stats",
            lambda s: s.returncode == 0 and "/1.0 CPU" in s.stdout, "the head did not answer",
        )  # fmt: skip
        worker = f"--address={gcs} --node-ip-address={worker_ip} --num-cpus=1 --temp-dir={temp['worker']}"
        cluster.start(
            "worker", f"{worker} --disable-usage-stats", lambda s: s.returncode == 0 and "/2.0 CPU" in s.stdout,
            "the worker did not join the head",
        )  # fmt: skip
        driver = hosts.argv("head", [*BENCHMARK, *FLAGS.split(), "--ray", gcs])
        cut = cut_after_first_cell(driver, on_ray, env)
        saved = sorted((on_ray / "results/cells").glob("*.json"))
        kept = {p.stem: (p.stat().st_mtime_ns, p.read_bytes()) for p in saved}
        assert 1 <= len(kept) < len(CELLS), f"the cut run saved {sorted(kept)}:\n{cut}"
        return kept, run(driver, on_ray, env, "the rerun on the cluster")
    finally:
        cluster.stop()


def benchmark(*flags: str, modules: str = "") -> subprocess.CompletedProcess:
    """``sorting-line-benchmark FLAGS`` (random agent, native lines) with ``modules`` hidden."""
    code = f"import sys; sys.modules.update(dict.fromkeys({modules.split()!r})); " + (
        "from sorting_line_gym.studies.benchmark import main; sys.exit(main(sys.argv[1:]))"
    )
    argv = [sys.executable, "-c", code, "--backend", "native", "--agents", "random", "--setups", "A", *flags]
    return subprocess.run(argv, capture_output=True, text=True, timeout=120)


@needs_ray
def test_an_address_that_does_not_answer_fails_at_once_naming_it(tmp_path):
    start = time.monotonic()
    r = benchmark("--variants", "basic", "--out", str(tmp_path / "r"), "--ray", "127.0.0.1:9")
    assert r.returncode == 2, r.stderr
    assert "--ray 127.0.0.1:9: nothing answers at 127.0.0.1:9" in r.stderr, r.stderr
    assert time.monotonic() - start < 60, "the refusal took over a minute"
    assert not list((tmp_path / "r" / "cells").glob("*.json")), "a cell ran without a cluster"


def test_ray_with_jobs_a_malformed_address_and_no_ray_are_refused_by_name(tmp_path):
    out = ["--variants", "basic", "--out", str(tmp_path / "r")]
    r = benchmark(*out, "--ray", "127.0.0.1:6379", "--jobs", "2")
    assert r.returncode == 2 and "--jobs 2 with --ray is not valid" in r.stderr, r.stderr
    r = benchmark(*out, "--ray", "head.example/6379", modules="ray" if not INSTALLED else "")
    want = "launch_scripts/setup.sh --rllib" if not INSTALLED else "--ray head.example/6379 is not valid: allowed"
    assert r.returncode == 2 and want in r.stderr, r.stderr
    r = benchmark(*out, "--ray", "127.0.0.1:6379", modules="ray")
    assert r.returncode == 2, r.stderr
    assert "--ray needs Ray, which is not installed" in r.stderr and "setup.sh --rllib" in r.stderr, r.stderr
