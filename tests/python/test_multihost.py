"""Lines on several hosts of one DDS domain, driven by one vector env on another host.

The hosts are network namespaces this test makes, each plugged by a veth pair into a Linux bridge,
with addresses that exist only inside them (tests/python/support/netns_hosts.py): h1, h2, h3 each run a
`sorting_line node --lines 16` in a namespace of their own (/h1/plant, ...), and "trainer" runs a
`SortingLineVectorEnv` over all three (``namespace=[...]``, ``node="attach"``). Discovery is set as
users set it: h1, h2 and the trainer under ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET (multicast through
the bridge); h3 under LOCALHOST with ROS_STATIC_PEERS naming the trainer, which names h3 in its own
ROS_STATIC_PEERS.

- line i of the env equals `sorting_line trace` for its seed, across same-step autoresets (the
  resets of the three nodes in flight together); so does line i of the SB3 face
  (``SortingLineSB3VecEnv``) over the same three nodes, across one autoreset;
- h2's cable pulled out of the switch mid-episode: the next step raises within step_timeout, naming
  /h2/plant and the env's lines on it, not the others; an env over h1 and h3 works meanwhile; once
  the cable is back, a new env over all three works;
- h3's node killed (SIGKILL) mid-episode: the same, and an env over a new node on h3 works.
"""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from support import netns_hosts
from support import ros_harness as h
from support.env_trace import assert_obs, assert_step, fixed_actions, trace

LINES = 16  # per node: a batch/reset reply of 16 lines (2.5 KB) is larger than one datagram of a 1500-byte MTU
SETUP, VARIANT = "B", "basic"
EPISODE = 10
STEP_TIMEOUT = 2.0
NODES = ["h1", "h2", "h3"]

# The trainer's side: a vector env over the nodes of `namespaces`, driven phase by phase. It prints
# one JSON object per phase and waits for a line on stdin before the next one.
TRAINER = r'''
import json, sys, time
import numpy as np
from sorting_line_gym import BridgeError
from sorting_line_gym import SortingLineVectorEnv

cfg = json.loads(sys.argv[1])
KEYS = ("accuracy", "purity", "containers", "speed_changes", "occupancy", "cumulative_reward", "speed_index",
        "mode", "step", "seed")


def say(**kw):
    print(json.dumps(kw), flush=True)


def go():
    sys.stdin.readline()


def make(namespaces):
    return SortingLineVectorEnv(num_envs=len(namespaces) * cfg["lines"], setup=cfg["setup"], variant=cfg["variant"],
                                namespace=namespaces, node="attach", max_episode_steps=cfg["episode"],
                                step_timeout=cfg["step_timeout"], startup_timeout=40.0)


def run(env, seed, actions):
    """Resets with `seed`, steps `actions` (one row per step); each line's record."""
    obs, _ = env.reset(seed=seed)
    lines = [{"obs": obs[k].tolist(), "steps": []} for k in range(env.num_envs)]
    for row in actions:
        obs, rewards, _, truncated, info = env.step(np.array(row))
        for k, line in enumerate(lines):
            line["steps"].append(record(obs[k], rewards[k], truncated[k], {key: info[key][k] for key in KEYS},
                                        info["final_obs"][k] if truncated[k] else None))
    return lines


def record(obs, reward, truncated, info, final_obs):
    """One line's step as the test reads it (the same for both faces)."""
    step = {"obs": obs.tolist(), "reward": float(reward), "truncated": bool(truncated),
            "info": {key: np.asarray(value).tolist() for key, value in info.items()}}
    if truncated:
        step["final_obs"] = np.asarray(final_obs).tolist()
    return step


def run_sb3(namespaces, seed, actions):
    """The same through the SB3 face (seeded at construction, autoreset by SB3's convention):
    each line's record in run()'s format, final_obs from terminal_observation."""
    from sorting_line_gym import SortingLineSB3VecEnv

    vec = SortingLineSB3VecEnv(num_envs=len(namespaces) * cfg["lines"], setup=cfg["setup"], variant=cfg["variant"],
                               namespace=namespaces, node="attach", max_episode_steps=cfg["episode"],
                               step_timeout=cfg["step_timeout"], startup_timeout=40.0, seed=seed)
    obs = vec.reset()
    lines = [{"obs": obs[k].tolist(), "steps": []} for k in range(vec.num_envs)]
    for row in actions:
        obs, rewards, dones, infos = vec.step(np.array(row))
        for k, line in enumerate(lines):
            line["steps"].append(record(obs[k], rewards[k], dones[k], {key: infos[k][key] for key in KEYS},
                                        infos[k].get("terminal_observation")))
    vec.close()
    return lines


def failing_step(env, row):
    t0 = time.monotonic()
    try:
        env.step(np.array(row))
    except BridgeError as e:
        return {"error": str(e), "kind": type(e).__name__, "seconds": round(time.monotonic() - t0, 2)}
    return {"error": None, "seconds": round(time.monotonic() - t0, 2)}


ns = cfg["namespaces"]
acts = cfg["actions"]
if cfg["scenario"] == "trajectories":
    env = make(ns)
    say(phase="trajectories", lines=run(env, cfg["seed"], acts))
    env.close()
    say(phase="sb3", lines=run_sb3(ns, cfg["seed"] + 50, acts[:cfg["episode"] + 3]))
else:
    env = make(ns)
    run(env, cfg["seed"], acts[:3])
    say(phase="stepping")
    go()  # h2 unplugged
    say(phase="unplugged", failure=failing_step(env, acts[3]))
    env.close()
    others = make([ns[0], ns[2]])
    say(phase="others", lines=run(others, cfg["seed"] + 100, acts[:5]))
    go()  # h2 plugged back
    env = make(ns)
    say(phase="replugged", lines=run(env, cfg["seed"] + 200, acts[:5]))
    go()  # h3's node killed
    say(phase="killed", failure=failing_step(env, acts[5]))
    env.close()
    env = make([ns[0], ns[1], cfg["new_node"]])
    say(phase="new_node", lines=run(env, cfg["seed"] + 300, acts[:5]))
    env.close()
'''


class Conversation:
    """A process whose stdout lines are JSON objects, read with a timeout."""

    def __init__(self, proc: subprocess.Popen, log: Path):
        self.proc, self.log = proc, log
        self.started = time.monotonic()
        self.lines: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def expect(self, phase: str, timeout: float = 90.0) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self.lines.get(timeout=max(0.1, deadline - time.monotonic()))
            except queue.Empty:
                pytest.fail(f"the trainer did not report phase {phase!r} within {timeout:g} s\n{self.tail()}")
            if line is None:
                self.proc.wait(timeout=10)
                pytest.fail(f"the trainer exited ({self.proc.returncode}) before phase {phase!r}\n{self.tail()}")
            if line.startswith("{"):
                report = json.loads(line)
                print(f"[{time.monotonic() - self.started:5.1f} s] trainer phase {report.get('phase')}", flush=True)
                assert report.get("phase") == phase, f"phase {report.get('phase')!r}, expected {phase!r}\n{self.tail()}"
                return report

    def go(self):
        self.proc.stdin.write("go\n")
        self.proc.stdin.flush()

    def tail(self) -> str:
        return self.log.read_text(errors="replace")[-4000:] if self.log.exists() else ""


def start_node(hosts, tmp_path, host: str, namespace: str, env: dict) -> subprocess.Popen:
    log = open(tmp_path / f"node_{host}_{namespace.strip('/').replace('/', '_')}.log", "wb")
    argv = [
        str(h.node_binary()),
        "node",
        "--setup",
        SETUP,
        "--variant",
        VARIANT,
        "--lines",
        str(LINES),
        "--max-steps",
        str(EPISODE),
        "--ros-args",
        "-r",
        f"__ns:={namespace}",
    ]
    return hosts.popen(host, argv, env=env, stdout=log, stderr=subprocess.STDOUT)


def discovery_env(**values: str) -> dict[str, str]:
    import os

    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY")
    }
    env.update(values, PYTHONUNBUFFERED="1", SORTING_LINE_BIN=str(h.node_binary()))
    return env


def with_resets(line: dict, actions: list[int]) -> list:
    """The trace actions of a recorded line: its actions, with "r<seed>" where the env reset it
    (a truncated step; the seed is the one the next step's info reports)."""
    out = []
    for t, step in enumerate(line["steps"]):
        out.append(actions[t])
        if step["truncated"] and t + 1 < len(line["steps"]):
            out.append(f"r{line['steps'][t + 1]['info']['seed']}")
    return out


def assert_line_matches_trace(line: dict, seed: int, actions: list[int], where: str, float32_rewards=False) -> None:
    """A recorded line against the library's trajectory for its seed and actions, resets included.
    ``float32_rewards``: the rewards were handed over as float32 (SB3's VecEnv), so they must equal
    the library's rounded to float32."""
    want = iter(trace(SETUP, VARIANT, seed, with_resets(line, actions)))
    assert_obs(np.array(line["obs"], dtype=np.float32), VARIANT, next(want)["reset"]["observation"], f"{where} reset")
    for t, step in enumerate(line["steps"]):
        entry = next(want)
        # Same-step autoreset: the episode's last observation is in final_obs, the new one in obs.
        obs = step["final_obs"] if step["truncated"] else step["obs"]
        if step["truncated"] and t + 1 < len(line["steps"]):
            fresh = next(want)
            assert "reset" in fresh, f"{where} step {t + 1}: the library has no reset after it: {fresh}"
            assert_obs(
                np.array(step["obs"], dtype=np.float32),
                VARIANT,
                fresh["reset"]["observation"],
                f"{where} autoreset after step {t + 1}",
            )
        info = dict(step["info"], containers=tuple(step["info"]["containers"]))
        reward = step["reward"]
        if float32_rewards and "step" in entry:
            library = entry["step"]["reward"]
            assert np.float32(reward) == np.float32(library), (
                f"{where} step {t + 1}: reward {reward!r} != library {library!r}"
            )
            reward = library  # compared above, at the precision it was handed over in
        assert_step(VARIANT, np.array(obs, dtype=np.float32), reward, info, entry, f"{where} step {t + 1}")


def check_lines(lines: list[dict], seed: int, actions: list[list[int]], where: str, float32_rewards=False) -> None:
    for k, line in enumerate(lines):
        assert_line_matches_trace(line, seed + k, [row[k] for row in actions], f"{where}, line {k}", float32_rewards)


def start_trainer(hosts, tmp_path, env: dict, cfg: dict) -> Conversation:
    """The trainer script on the trainer host, for the scenario of ``cfg``; its log in tmp_path."""
    script = tmp_path / "trainer.py"
    script.write_text(TRAINER)
    log = tmp_path / f"trainer_{cfg['scenario']}.log"
    proc = hosts.popen(
        "trainer",
        [sys.executable, str(script), json.dumps(cfg)],
        env=env,
        text=True,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=open(log, "w"),
    )
    return Conversation(proc, log)


def stop_with_sigint(p: subprocess.Popen) -> int:
    p.send_signal(signal.SIGINT)
    return p.wait(timeout=10)


def check_faults_and_recovery(trainer, hosts, nodes: dict, node_envs: dict, tmp_path, actions: list) -> None:
    """h2's link down (a step fails naming h2's node and lines, within step_timeout; h1 and h3 go on),
    then back; h3's node killed (the same), then replaced by a new node on h3 that the trainer uses."""
    t = trainer("faults", 600, new_node="/h3/plant2")
    t.expect("stepping")
    hosts.unplug("h2")
    t.go()
    failure = t.expect("unplugged")["failure"]
    first, last = LINES, 2 * LINES - 1
    assert failure["error"], f"a step with h2 unplugged did not fail: {failure}"
    assert failure["kind"] == "BridgeTimeout", failure
    assert "/h2/plant" in failure["error"] and f"lines {first}..{last}" in failure["error"], failure
    assert "/h1/plant" not in failure["error"] and "/h3/plant" not in failure["error"], (
        f"the error names nodes that answered: {failure}"
    )
    # The wait is bounded by step_timeout (plus its own 50 ms slices): a loose bound, as the
    # machine is shared; it tells a bounded wait from a hang.
    assert failure["seconds"] < STEP_TIMEOUT + 3.0, failure
    others = t.expect("others")["lines"]
    check_lines(others, 600 + 100, actions[:5], "h1 + h3 while h2 is unplugged")
    hosts.plug("h2")
    t.go()
    check_lines(t.expect("replugged")["lines"], 600 + 200, actions[:5], "h1 + h2 + h3 after h2 is back")
    nodes["h3"].send_signal(signal.SIGKILL)
    nodes["h3"].wait(timeout=10)
    t.go()
    failure = t.expect("killed")["failure"]
    assert failure["kind"] == "BridgeTimeout" and "/h3/plant" in failure["error"], failure
    assert f"lines {2 * LINES}..{3 * LINES - 1}" in failure["error"], failure
    assert "/h1/plant" not in failure["error"] and "/h2/plant" not in failure["error"], failure
    assert failure["seconds"] < STEP_TIMEOUT + 3.0, failure
    nodes["h3b"] = start_node(hosts, tmp_path, "h3", "/h3/plant2", node_envs["h3"])
    t.go()
    check_lines(t.expect("new_node")["lines"], 600 + 300, actions[:5], "h1 + h2 + a new node on h3")
    assert t.proc.wait(timeout=30) == 0, t.tail()


@pytest.mark.skipif(netns_hosts.problem() is not None, reason=f"hosts: {netns_hosts.problem()}")
def test_one_vector_env_over_three_hosts_faults_and_recovery(tmp_path):
    namespaces = [f"/{host}/plant" for host in NODES]
    n = LINES * len(NODES)
    steps = 2 * EPISODE + 5  # two autoresets of every line, the three nodes' resets in flight together
    actions = [[a for a in fixed_actions(10, n, 1000 + t)] for t in range(steps)]
    with netns_hosts.Hosts([*NODES, "trainer"]) as hosts:
        trainer_addr, h3_addr = hosts.address("trainer"), hosts.address("h3")
        subnet = discovery_env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET")
        node_envs = {
            "h1": subnet,
            "h2": subnet,
            "h3": discovery_env(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_STATIC_PEERS=trainer_addr),
        }
        nodes = {
            host: start_node(hosts, tmp_path, host, ns, node_envs[host])
            for host, ns in zip(NODES, namespaces, strict=False)
        }
        trainer_env = discovery_env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", ROS_STATIC_PEERS=h3_addr)
        base = dict(namespaces=namespaces, lines=LINES, setup=SETUP, variant=VARIANT, episode=EPISODE, actions=actions)

        def trainer(scenario: str, seed: int, **extra) -> Conversation:
            cfg = dict(base, scenario=scenario, step_timeout=STEP_TIMEOUT, seed=seed, **extra)
            return start_trainer(hosts, tmp_path, trainer_env, cfg)

        # 1. Trajectories across the three hosts, through two autoresets.
        t = trainer("trajectories", 500)
        report = t.expect("trajectories")
        check_lines(report["lines"], 500, actions, "3 hosts")
        # The SB3 face over the same three nodes, through one autoreset of every line.
        check_lines(t.expect("sb3")["lines"], 550, actions[: EPISODE + 3], "SB3 face, 3 hosts", float32_rewards=True)
        assert t.proc.wait(timeout=30) == 0, t.tail()

        # 2. Faults: h2's link down, then back; h3's node killed, then replaced.
        check_faults_and_recovery(trainer, hosts, nodes, node_envs, tmp_path, actions)

        codes = {host: stop_with_sigint(p) for host, p in nodes.items() if host != "h3"}  # h3's was killed above
        assert codes == {host: 0 for host in codes}, f"node exit codes after SIGINT: {codes}"


def test_a_list_of_nodes_is_checked_when_the_env_is_made():
    """Nothing starts before the first reset, but a bad list fails at once, saying why."""
    from sorting_line_gym import SortingLineSB3VecEnv, SortingLineVectorEnv

    env = SortingLineVectorEnv(num_envs=8, namespace=["/a/plant", "/b/plant"], node="attach")
    assert len(env._lines.bank) == 8 and env._lines.bank.lines_per_node == 4
    sb3 = SortingLineSB3VecEnv(num_envs=6, namespace=["/a/plant", "/b/plant", "/c/plant"], node="attach")
    assert sb3._lines.bank.namespaces == ["/a/plant", "/b/plant", "/c/plant"] and sb3._lines.bank.lines_per_node == 2
    with pytest.raises(ValueError, match="num_envs = 7 lines cannot be spread evenly over 2 nodes"):
        SortingLineVectorEnv(num_envs=7, namespace=["/a/plant", "/b/plant"], node="attach")
    with pytest.raises(ValueError, match="lists a node twice"):
        SortingLineVectorEnv(num_envs=4, namespace=["/a/plant", "/a/plant"], node="attach")
    with pytest.raises(ValueError, match="node='shared' leases single lines"):
        SortingLineVectorEnv(num_envs=4, namespace=["/a/plant", "/b/plant"], node="shared")
    with pytest.raises(ValueError, match="name at least one node"):
        SortingLineVectorEnv(num_envs=4, namespace=[], node="attach")


BENCH = Path(__file__).resolve().parents[2] / "benches" / "multihost.py"
# Small: 1 and 2 hosts, 100 timed round trips each, and a soak of 3,000 line-ticks over 2 hosts.
SMALL_BENCH = [
    "--hosts",
    "1",
    "2",
    "--rounds",
    "1",
    "--round-trips",
    "100",
    "--soak-ticks",
    "3000",
    "--soak-hosts",
    "2",
]


def assert_bench_output(out: str, node_cpu: str) -> None:
    import re

    assert re.search(rf"^\| 1 \| 16 \| [\d,]+ \| [\d,]+ \| [\d.]+ \| [\d.]+ \| [\d.]+ \| {node_cpu} \|", out, re.M), out
    assert re.search(rf"^\| 2 \| 32 \| [\d,]+ \| [\d,]+ \| [\d.]+ \| [\d.]+ \| [\d.]+ \| {node_cpu} \|", out, re.M), out
    assert re.search(r"^2 hosts / 1 host, p50 round trip: [\d.]+x \(target <= 1.5x\)$", out, re.M), out
    assert re.search(
        r"^soak: [\d,]+ line-ticks over 2 hosts \(32 lines\): lost 0, misaligned 0, values compared with "
        r"the library [1-9][\d,]+, mismatched 0;",
        out,
        re.M,
    ), out


@pytest.mark.skipif(netns_hosts.problem() is not None, reason=f"hosts: {netns_hosts.problem()}")
def test_the_multihost_benchmark_on_hosts_it_makes(tmp_path):
    """benches/multihost.py, which gives docs/results/scaling.md its figures, at a small size over the
    network-namespace hosts it makes itself."""
    r = subprocess.run(
        [sys.executable, str(BENCH), *SMALL_BENCH, "--logs", str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    assert_bench_output(r.stdout, r"[\d.]+")


def test_the_multihost_benchmark_attaches_to_running_nodes(tmp_path):
    """``--attach``: what a user with real machines runs, here over two nodes started in this
    test's namespace (the ROS environment decides where they are; the nodes' CPU is not the
    benchmark's to measure then)."""
    nodes = [
        h.NodeProcess(
            ["--setup", "A", "--lines", "16", "--max-steps", "50", "--ros-args", "-r", f"__ns:=/{n}/plant"],
            tmp_path / f"{n}.log",
        )
        for n in ("m1", "m2")
    ]
    try:
        r = subprocess.run(
            [sys.executable, str(BENCH), "--attach", "/m1/plant", "/m2/plant", *SMALL_BENCH],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:] + "".join(n.describe() for n in nodes)
        assert_bench_output(r.stdout, "n/a")
        too_many = subprocess.run(
            [sys.executable, str(BENCH), "--attach", "/m1/plant", "--hosts", "1", "2"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert too_many.returncode != 0 and "ask for 3 nodes, --attach names 1" in too_many.stderr, too_many.stderr
    finally:
        for n in nodes:
            n.stop()
