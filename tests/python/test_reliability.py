"""Reliability of the line and the bridge under load, faults and bad input, in CI size
(launch_scripts/reliability.sh runs it in full size).

- soak: 50,000 lock-step line-ticks through the vector env (benches/soak.py at reduced size):
  nothing lost, misaligned or different from `sorting_line trace`, memory bounded; and the soak's
  checker itself catches a skipped, repeated or altered observation (it must be able to fail);
- faults: a node killed under an attached vector env (the step fails within its timeout, naming the
  topic and the ticks; a new node and env recover); bridge processes killed mid-episode (the node
  keeps serving another client, without growing; a spawned node dies with its bridge); a second
  client on a driven line (refused as not_owner, counted, the first client's trajectory untouched;
  a reset takes the line over and the displaced bridge says so); the node restarted under a running
  realtime controller (the controller drives the new node);
- bad input: a seeded random flood of bad commands at the real node (FLOOD_TICKS ticks; each rejection counted per
  reason on /diagnostics, the trajectory equal to the library's), and malformed parameter files and
  `--ros-args` refused at start, naming the problem;
- determinism across paths: the same seeds and actions through the library, the node (1 and 16
  lines), the single-line env and the vector env give identical trajectories.

The full-size runs (1,000,000 ticks, more fuzz cases) are the commands of docs/reliability.md; their figures are
in docs/results/reliability.md.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sorting_line_gym import BridgeError, BridgeTimeout, SortingLineEnv, SortingLineVectorEnv
from sorting_line_gym.bag import open_bag
from sorting_line_gym.bag.storage.schema import stamp_ns
from sorting_line_gym.bag.transport.replay import replay
from support import ros_harness as h
from support.bag_golden import BagProcess, wait_for_command_writers
from support.controller_process import ControllerProcess
from support.node_graph import diagnostics_recorder, wait_diagnostics
from support.ros_harness import ns_args
from support.waits import wait_until

sys.path.insert(0, str(h.ROOT / "benches"))
import soak  # noqa: E402

SOAK_TICKS = 50_000
#: Ticks of the topic-level flood (launch_scripts/reliability.sh runs 200).
FLOOD_TICKS = int(os.environ.get("SORTING_LINE_FLOOD_TICKS", "25"))


pytestmark = pytest.mark.usefixtures("same_binary")  # conftest: the tools start the tests' binary


# --------------------------------------------------------------------------------------------
# Soak


def test_soak_loses_nothing_and_stays_flat():
    r = soak.run_soak(SOAK_TICKS, lines=16, window=10_000, verify_episodes=20, show_progress=False)
    print(soak.report(r))
    assert r.ticks >= SOAK_TICKS
    assert (r.lost, r.misaligned, r.mismatched) == (0, 0, 0), soak.report(r)
    assert r.verified >= r.ticks, "every step must have been compared with the library"
    # Memory: bounded, not a figure (the node's RSS follows the message rate up to a plateau).
    assert r.rss_node_end < 2 * r.rss_node_start + 32, soak.report(r)
    assert r.rss_bridge_end < r.rss_bridge_start + 64, soak.report(r)


def test_soak_checker_catches_lost_misaligned_and_wrong_observations():
    """The soak's checks can fail: a skipped step, a repeated step, a wrong seed, an altered value."""
    setup, variant, seed = "A", "basic", 3
    actions = [4, 5, 6, 7, 8, 1]
    trace = h.run_trace(setup, variant, seed, actions)

    def ledger_from(entries, actions_seen):
        ledger = soak.LineLedger(setup, variant, seed)
        ok = []
        for action, entry in zip(actions_seen, entries, strict=False):
            s = entry["step"]
            ok.append(
                ledger.expect_step(
                    action,
                    seed,
                    s["step"],
                    s["reward"],
                    entry["cumulative_reward"],
                    soak.observation_of(variant, s["observation"]),
                )
            )
        return ledger, ok

    ledger, ok = ledger_from(trace[1:], actions)
    assert all(ok) and ledger.verify() == (len(actions), 0), "the true stream must pass"

    lost = trace[1:3] + trace[4:]  # step 3's observation never arrived
    _, ok = ledger_from(lost, actions[:2] + actions[3:])
    assert not all(ok), "a lost observation must be seen as misaligned"
    repeated = trace[1:3] + trace[2:]
    _, ok = ledger_from(repeated, actions)
    assert not all(ok), "a repeated observation must be seen as misaligned"

    ledger = soak.LineLedger(setup, variant, seed)
    assert not ledger.expect_step(actions[0], seed + 1, 1, 0.0, 0.0, (0.5,)), "another episode's seed"

    altered = [dict(e, step=dict(e["step"])) for e in trace[1:]]
    altered[2]["step"]["reward"] += 1e-9
    ledger, ok = ledger_from(altered, actions)
    assert all(ok) and ledger.verify() == (len(actions), 1), "an altered reward must be a mismatch"


# --------------------------------------------------------------------------------------------
# Faults


def test_node_killed_under_an_attached_vector_env_times_out_then_a_new_node_recovers(start_node, namespace):
    ns = namespace("killed")
    node = start_node("--lines", "4", *h.SETUP_FLAGS["A"], *ns_args(ns))
    env = SortingLineVectorEnv(num_envs=4, setup="A", node="attach", namespace=ns, step_timeout=2.0)
    try:
        env.reset(seed=11)
        for t in range(7):
            env.step(np.full(4, t % 10))
        node.proc.send_signal(signal.SIGKILL)
        node.proc.wait(5)
        node.stopped_by_test = True
        started = time.monotonic()
        with pytest.raises(BridgeTimeout) as excinfo:
            env.step(np.full(4, 3))
        elapsed = time.monotonic() - started
        message = str(excinfo.value)
        assert elapsed < 2.0 + 1.0, f"the failure took {elapsed:.2f} s with step_timeout 2 s"
        assert f"{ns}/batch/state" in message and "step 8" in message, message
    finally:
        env.close()

    # A new node on a new namespace (the dead one's endpoints linger ~50 s) and a new env recover.
    ns2 = namespace("recovered")
    start_node("--lines", "4", *h.SETUP_FLAGS["A"], *ns_args(ns2))
    fresh = SortingLineVectorEnv(num_envs=4, setup="A", node="attach", namespace=ns2)
    try:
        actions = [2, 9, 0, 5]
        want = h.run_trace("A", "basic", 11 + 2, actions)
        obs, _ = fresh.reset(seed=11)
        assert obs[2][0] == np.float32(want[0]["reset"]["observation"]["quantity"])
        for t, a in enumerate(actions, start=1):
            _, rewards, _, _, _ = fresh.step(np.full(4, a))
            assert rewards[2] == want[t]["step"]["reward"], f"step {t}"
    finally:
        fresh.close()


def test_spawned_node_log_is_deleted_after_a_clean_stop_and_kept_after_a_failure():
    env = SortingLineEnv(setup="A", node="spawn")
    env.reset(seed=1)
    log = Path(env.bank.process.log_path)
    assert log.exists()
    env.close()
    assert not log.exists(), f"{log}: the log of a cleanly stopped node was left behind"

    env = SortingLineEnv(setup="A", step_timeout=2.0, node="spawn")
    env.reset(seed=1)
    log = Path(env.bank.process.log_path)
    env.bank.process.process.kill()
    with pytest.raises(BridgeError) as excinfo:
        env.step(3)
    assert str(log) in str(excinfo.value), "the error must name the kept log"
    with pytest.warns(RuntimeWarning, match="log is kept"):
        env.close()
    assert log.exists(), "the log of a failed node must be kept"
    log.unlink()


BRIDGE_SCRIPT = r"""
import sys, time
import numpy as np
from sorting_line_gym import SortingLineEnv
node, ns = sys.argv[1], sys.argv[2]
env = SortingLineEnv(setup="A", node=node, namespace=ns if node == "attach" else None, max_episode_steps=1_000_000)
env.reset(seed=5)
pid = env.bank.process.process.pid if env.bank.process else 0
for t in range(200):
    env.step(t % 10)
print(f"stepping node_pid={pid} log={env.bank.process.log_path if env.bank.process else ''}", flush=True)
while True:
    env.step(3)
"""


def start_bridge(mode: str, ns: str) -> tuple[subprocess.Popen, dict[str, str]]:
    """A bridge process (SortingLineEnv, attach or spawn) that steps forever once it said so."""
    proc = subprocess.Popen(
        [sys.executable, "-c", BRIDGE_SCRIPT, mode, ns],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    line = proc.stdout.readline()
    if not line.startswith("stepping"):
        try:
            rest, _ = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            rest, _ = proc.communicate()
        raise AssertionError(f"the bridge process did not start stepping: {line}{rest}")
    return proc, dict(kv.split("=", 1) for kv in line.split()[1:])


def test_killed_bridges_leave_the_node_serving_without_growth(ros, start_node, client_factory, probe, namespace):
    ns = namespace("served")
    # Long episodes: the bridges step until they are killed.
    node = start_node(*h.SETUP_FLAGS["A"], "--max-steps", "1000000", *ns_args(ns))
    diag = diagnostics_recorder(ros, probe)
    rss = []
    client = client_factory(ns, "basic", node_proc=node)
    client.wait_connected()
    for cycle in range(3):
        bridge, _ = start_bridge("attach", ns)
        bridge.kill()  # SIGKILL, mid-episode: the dead bridge still owns the episode
        bridge.wait(5)
        bridge.stdout.close()
        # Another client resets (which frees the line) and drives it: the node serves it correctly.
        seed, actions = 40 + cycle, [1, 8, 3, 3, 6]
        want = h.run_trace("A", "basic", seed, actions)
        client.reset(seed)
        for t, a in enumerate(actions, start=1):
            state = client.act(a)
            assert state.reward == want[t]["step"]["reward"], f"cycle {cycle}, step {t}"
        rss.append(h.rss_mb(node.pid))
    assert node.running()
    wait_diagnostics_where(diag, ns, lambda v: v["owner"] != "none", 5.0, client.context)
    assert rss[-1] < rss[0] + 8, f"node RSS after each bridge killed: {rss} MB"

    # A bridge that spawned its own node takes the node with it (parent-death signal): no orphan.
    bridge, info = start_bridge("spawn", "")
    node_pid, log = int(info["node_pid"]), Path(info["log"])
    bridge.kill()
    bridge.wait(5)
    bridge.stdout.close()

    def ended() -> bool:
        try:
            return "Z" in Path(f"/proc/{node_pid}/stat").read_text().split()[2]  # a zombie has ended too
        except (FileNotFoundError, ProcessLookupError):  # gone
            return True

    wait_until(ended, 5, f"the node {node_pid} of a killed bridge to end (it is still running)")
    log.unlink(missing_ok=True)  # a SIGKILLed bridge cannot clean up after itself


def test_a_second_client_is_refused_and_a_reset_takes_the_line_over(ros, start_node, client_factory, probe, namespace):
    ns = namespace("shared")
    node = start_node(*h.SETUP_FLAGS["B"], *ns_args(ns))
    diag = diagnostics_recorder(ros, probe)
    first = SortingLineEnv(setup="B", node="attach", namespace=ns, step_timeout=2.0)
    second = client_factory(ns, "basic", node_proc=node)  # another DDS participant: another client
    try:
        second.wait_connected()
        actions = [3, 3, 7, 1, 0, 9, 4]
        want = h.run_trace("B", "basic", 17, actions)
        first.reset(seed=17)
        for a in actions[:3]:
            first.step(a)
        # The second client answers the tick the line waits at: refused, counted, logged.
        stamp = h.stamp_ns(first.bank.links[0].tick.stamp)
        for speed in (0.9, 0.2):
            second.send_speed(speed, stamp)
        got = wait_diagnostics(diag, ns, {"rejected_not_owner": "2"}, context=second.context)
        assert got["ticks"] == "3", got
        for t, a in enumerate(actions[3:], start=4):
            _, reward, _, _, info = first.step(a)
            assert reward == want[t]["step"]["reward"], f"step {t}: the refused commands changed the line"
        assert "[not_owner]" in node.log() and "the episode's owner is" in node.log()

        # A reset by the second client frees the line; it drives it, and the first bridge says so.
        second.reset(23)
        state = second.step(0.5)
        assert state.step == 1
        with pytest.raises(BridgeError, match="another client reset this line"):
            first.step(2)
    finally:
        first.close()


def test_node_restarted_under_a_running_realtime_controller(ros, start_node, probe, namespace, tmp_path):
    ns = namespace("restart")
    args = ["--mode", "realtime", "--rate", "20", *h.SETUP_FLAGS["A"], *ns_args(ns)]
    node = start_node(*args)
    diag = diagnostics_recorder(ros, probe)
    controller = ControllerProcess(tmp_path, "restart", ["--namespace", ns, "--setup", "A", "--agent", "rba"])
    try:
        wait_diagnostics_where(diag, ns, lambda v: int(v["commands_accepted"]) >= 20, 20.0, controller.describe)
        node.proc.send_signal(signal.SIGKILL)
        node.proc.wait(5)
        node.stopped_by_test = True
        # Rows, not stamps: the new node's clock starts again at 0, so its ticks repeat the old one's
        # stamps (all of them, when the controller answers it only from the old node's first stamp on).
        decisions_before = len(controller.decision_rows())
        # Take what the killed node sent before it died: a status left unread in the reader would
        # land after `since` and pass the wait below for the new node (a sleep spun nothing). The
        # writer is gone, so nothing more can come than what is in flight over loopback.
        ros.spin_for(0.5)
        since = len(diag.msgs)  # every status from here on is the new node's
        start_node(*args)
        values = wait_diagnostics_where(
            diag, ns, lambda v: int(v["commands_accepted"]) >= 20, 30.0, controller.describe, since=since
        )
        assert values["owner"] != "none" and values["commands_rejected"] == "0", values
        assert controller.running(), controller.describe()
        assert len(controller.decision_rows()) > decisions_before, controller.describe()
    finally:
        assert controller.stop() == 0, controller.describe()


def wait_diagnostics_where(
    diag: h.TopicRecorder, hardware_id: str, predicate, timeout: float, context, since: int = 0
) -> dict[str, str]:
    """The values of the first status of `hardware_id` (among those recorded from index `since` on)
    that satisfy `predicate`; waits for it (the node publishes at 1 Hz)."""

    def found():
        for array in diag.msgs[since:]:
            values = h.diagnostic_values(array, hardware_id)
            if values is not None and predicate(values):
                return values
        return None

    return diag.session.spin_until(found, timeout, f"/diagnostics: a matching status of {hardware_id}", context)


# --------------------------------------------------------------------------------------------
# Bad input


def test_random_flood_at_the_node_is_counted_per_reason_and_changes_nothing(
    ros, start_node, client_factory, probe, namespace
):
    """A seeded random flood of bad commands on the topics of a real node (advanced line)."""
    variant, setup, seed = "advanced", "D", 31
    ns = namespace("flood")
    node = start_node(
        "--variant", variant, *h.SETUP_FLAGS[setup], "--max-steps", str(max(50, FLOOD_TICKS)), *ns_args(ns)
    )
    diag = diagnostics_recorder(ros, probe)
    line = client_factory(ns, variant, node_proc=node)
    line.wait_connected()
    rng = np.random.default_rng(2024)
    actions = [int(a) for a in rng.integers(0, 30, size=FLOOD_TICKS)]
    want = h.run_trace(setup, variant, seed, actions, max_steps=max(50, FLOOD_TICKS))
    line.reset(seed)
    p = line.period_ns
    expected = {"invalid_speed": 0, "unknown_mode": 0, "stale": 0, "unknown_tick": 0, "duplicate": 0}
    sent = 0
    for t, a in enumerate(actions, start=1):
        now = line.stamp
        speed, mode = h.decode_action(variant, a)
        for _ in range(int(rng.integers(2, 8))):
            kind = rng.integers(0, 5)
            if kind == 0:
                line.send_speed(
                    float(rng.choice([math.nan, math.inf, -math.inf, 0.0, 1.1, 0.55, -0.2, 0.3 + 1e-3])), now
                )
                expected["invalid_speed"] += 1
            elif kind == 1:
                line.send_mode(int(rng.integers(3, 256)), now)
                expected["unknown_mode"] += 1
            elif kind == 2 and now - 3 * p >= 0:
                line.send_speed(speed, now - p * int(rng.integers(1, 4)))  # a tick the line has left
                expected["stale"] += 1
            else:
                line.send_speed(speed, now + int(rng.choice([p, 2 * p, 1, p // 3])))
                expected["unknown_tick"] += 1
            sent += 1
        line.send_mode(mode, now)
        if t % 5 == 0:  # a second mode for a tick that still waits for its speed
            line.send_mode((mode + 1) % 3, now)
            expected["duplicate"] += 1
            sent += 1
            wait_diagnostics_where(
                diag, ns, lambda v, n=expected["duplicate"]: v["rejected_duplicate"] == str(n), 5.0, line.context
            )
        line.send_speed(speed, now)
        state = line.wait_state(now + p)
        line.stamp = now + p
        assert h.state_step_view(state) | {"episode": 0} == h.trace_step_view(want[t]) | {"episode": 0}, f"step {t}"
    total = sum(expected.values())
    got = wait_diagnostics_where(
        diag, ns, lambda v: v["commands_rejected"] == str(total) and v["ticks"] == str(len(actions)), 10.0, line.context
    )
    assert {k: got[f"rejected_{k}"] for k in expected} == {k: str(n) for k, n in expected.items()}
    assert got["commands_accepted"] == str(2 * len(actions)) and got["ticks"] == str(len(actions))
    print(f"topic-level flood: {sent} bad commands, {total} rejections counted: {expected}")


BAD_FILES = {
    "tabs.yaml": ("seed:\t1\n\tlines: 2\n", ["params file", "not valid YAML"]),
    "list.yaml": ("- seed\n- 1\n", ["params file", "must be a mapping"]),
    "scalar.yaml": ("42\n", ["params file", "must be a mapping"]),
    "dup.yaml": ("seed: 1\nseed: 2\n", ["params file", "not valid YAML"]),
    "section.yaml": ("/**:\n  ros__parameters: 3\n", ["params file", "ros__parameters"]),
    "binary.yaml": ("\x00\x01\x02", ["params file"]),
    "nested.yaml": ("/**:\n  ros__parameters:\n    seed: {a: 1}\n", ["seed", "not valid"]),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_malformed_params_file_fails_at_start_naming_the_problem(name, tmp_path):
    text, expected = BAD_FILES[name]
    path = tmp_path / name
    path.write_text(text)
    code, stderr = h.run_node_expecting_failure(["--params-file", str(path)])
    assert code == 2, f"exit code {code}: {stderr}"
    for want in expected + [str(path)]:
        assert want in stderr, f"stderr lacks {want!r}:\n{stderr}"


@pytest.mark.parametrize(
    "ros_args,expected",
    [
        (["--unknown-flag"], "unknown argument '--unknown-flag'"),
        (["-p", "seed:=[1"], "-p seed:=[1 is not valid YAML"),
        (["--params-file"], "--params-file needs a file"),
        (["-r", "no_separator"], "'no_separator' is not of the form"),
        (["-r", ":=x"], "has an empty name"),
    ],
)
def test_bad_ros_args_fail_at_start_naming_the_argument(ros_args, expected):
    code, stderr = h.run_node_expecting_failure(["--ros-args", *ros_args])
    assert code == 2 and expected in stderr, f"exit code {code}; stderr:\n{stderr}"


# --------------------------------------------------------------------------------------------
# Determinism across paths


def run_library(setup, variant, episodes):
    """[(seed, actions)] -> one trajectory: per step (obs..., reward, cumulative reward, step)."""
    tokens = []
    for seed, actions in episodes:
        tokens += [f"r{seed}", *actions]
    entries = h.run_trace(setup, variant, episodes[0][0], tokens)[1:]
    out = []
    for e in entries:
        if "reset" in e:
            out.append(("reset", soak.observation_of(variant, e["reset"]["observation"])))
        else:
            s = e["step"]
            out.append((soak.observation_of(variant, s["observation"]), s["reward"], e["cumulative_reward"], s["step"]))
    return out


def run_node_line(client, variant, episodes):
    out = []
    for seed, actions in episodes:
        r = client.reset(seed)
        out.append(
            ("reset", soak.observation_of(variant, [r.quantity, r.category][: 2 if variant == "advanced" else 1]))
        )
        for a in actions:
            s = client.act(a)
            obs = [s.observation_quantity, s.observation_category][: 2 if variant == "advanced" else 1]
            out.append((soak.observation_of(variant, obs), s.reward, s.cumulative_reward, s.step))
    return out


def run_bag_replay(path, variant):
    """The trajectory a bag holds, once `sorting-line-bag replay` has reproduced every recorded
    message field by field in a fresh lock-step node (else the test fails with the first
    difference)."""
    result = replay(path)
    assert result.identical, result.report()
    out = []
    for message in sorted(open_bag(path).by_relative_topic()["state"], key=lambda m: stamp_ns(m.plain)):
        s = message.plain
        obs = soak.observation_of(
            variant, [s["observation_quantity"], s["observation_category"]][: 2 if variant == "advanced" else 1]
        )
        out.append(("reset", obs) if s["step"] == 0 else (obs, s["reward"], s["cumulative_reward"], s["step"]))
    return out


def run_single_env(variant, setup, episodes):
    env = SortingLineEnv(setup=setup, variant=variant, max_episode_steps=50)
    out = []
    try:
        for seed, actions in episodes:
            obs, _ = env.reset(seed=seed)
            out.append(("reset", soak.observation_of(variant, obs)))
            for a in actions:
                obs, reward, _, _, info = env.step(a)
                out.append((soak.observation_of(variant, obs), reward, info["cumulative_reward"], info["step"]))
    finally:
        env.close()
    return out


def run_vector_env(variant, setup, episodes, lines, k):
    """Line k of a vector env of `lines` lines; every line gets the same actions, line k the seeds."""
    env = SortingLineVectorEnv(num_envs=lines, setup=setup, variant=variant, max_episode_steps=50)
    out = []
    try:
        for seed, actions in episodes:
            seeds = [seed if j == k else seed + 1000 * (j + 1) for j in range(lines)]
            obs, _ = env.reset(seed=seeds)
            out.append(("reset", soak.observation_of(variant, obs[k])))
            for a in actions:
                obs, rewards, _, truncated, infos = env.step(np.full(lines, a))
                o = infos["final_obs"][k] if truncated[k] else obs[k]
                out.append(
                    (soak.observation_of(variant, o), rewards[k], infos["cumulative_reward"][k], infos["step"][k])
                )
    finally:
        env.close()
    return out


@pytest.mark.parametrize("variant,setup", [("basic", "C"), ("advanced", "D")])
def test_library_node_bridge_and_vector_paths_give_identical_trajectories(
    variant, setup, ros, start_node, client_factory, namespace, tmp_path
):
    rng = np.random.default_rng(99)
    n_actions = 30 if variant == "advanced" else 10
    # A whole episode (to its truncation) and part of another, with new seeds.
    episodes = [
        (1234, [int(a) for a in rng.integers(0, n_actions, 50)]),
        (77, [int(a) for a in rng.integers(0, n_actions, 12)]),
    ]
    paths = {"library (sorting_line trace)": run_library(setup, variant, episodes)}

    ns1, ns16 = namespace("one"), namespace("sixteen")
    # The 1-line node's run is recorded into a bag as it happens (sorting-line-bag record, a process
    # of its own), and that bag is replayed into a fresh node below. Only that node runs meanwhile:
    # /clock is global, and a second node's ticks would be in the bag too.
    node1 = start_node("--variant", variant, *h.SETUP_FLAGS[setup], *ns_args(ns1))
    bag = tmp_path / "node_one_line"
    recorder = BagProcess(["record", "--namespace", ns1, "-o", bag], tmp_path / "record.log")
    client = client_factory(ns1, variant, node_proc=node1)
    client.wait_connected()
    wait_for_command_writers(ros, recorder, ns1, variant, recorder.describe, writers=1)
    paths["node, 1 line"] = run_node_line(client, variant, episodes)
    ros.spin_for(0.3)
    assert recorder.stop() == 0, recorder.describe()
    paths["bag (recorded from the 1-line node), replayed identically"] = run_bag_replay(bag, variant)

    node16 = start_node("--variant", variant, "--lines", "16", *h.SETUP_FLAGS[setup], *ns_args(ns16))
    client = client_factory(f"{ns16}/line_9", variant, node_proc=node16)
    client.wait_connected()
    paths["node, 16 lines (line 9)"] = run_node_line(client, variant, episodes)
    paths["bridge, SortingLineEnv"] = run_single_env(variant, setup, episodes)
    paths["bridge, SortingLineVectorEnv (16 lines, line 5)"] = run_vector_env(variant, setup, episodes, 16, 5)

    reference = paths["library (sorting_line trace)"]
    assert len(reference) == sum(len(a) + 1 for _, a in episodes)
    for label, trajectory in paths.items():
        assert len(trajectory) == len(reference), f"{label}: {len(trajectory)} entries, library {len(reference)}"
        for i, (got, want) in enumerate(zip(trajectory, reference, strict=False)):
            assert tuple(got) == tuple(want), f"{label} differs from the library at entry {i}: {got} != {want}"
