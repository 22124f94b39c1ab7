"""Integration tests of the `sorting_line` node, continued from test_node.py (the helpers they
share are in support/): determinism across node processes and lines, the batch service and topics of several lines,
truncation, and exit on signals. The real binary, real rclpy over DDS, in a loopback-only network
namespace."""

from __future__ import annotations

import contextlib
import math
import os
import signal

import pytest

from support import ros_harness as h
from support.lockstep_trace import compare_with_trace, run_tokens
from support.node_graph import clock_recorder, diagnostics_recorder, topic_types, wait_diagnostics
from support.ros_harness import LINE_TYPES, NS_PER_S, ns_args, show_ns, stamp_ns

# ------------------------------------------------------------------------------------------
# Determinism


@pytest.mark.parametrize("variant,setup", [("basic", "D"), ("advanced", "B")])
def test_two_node_processes_and_the_library_agree(variant, setup, start_node, client_factory, namespace):
    seed = 8
    n_actions = 10 if variant == "basic" else 30
    tokens = [
        "r",
        *[(7 * k + 3) % n_actions for k in range(7)],
        "r",
        4,
        9,
        1,
        "r99",
        *[(5 * k + 1) % n_actions for k in range(6)],
    ]
    clients = []
    # Two node processes, joining the graph one at a time: two started together announce their
    # endpoints to our participant in one burst, and on a busy machine part of it can be lost for
    # good (workarounds/simultaneous_discovery.py; test_node's flood test lost it so).
    for tag in ["a", "b"]:
        ns = namespace(tag)
        node = start_node(*h.SETUP_FLAGS[setup], "--variant", variant, "--seed", str(seed), *ns_args(ns))
        clients.append(client_factory(ns, variant, node_proc=node))
        clients[-1].wait_connected()
    runs = [(c, run_tokens(c, tokens)) for c in clients]
    (a, states_a), (b, states_b) = runs
    for topic in ["state", "input", "belt/occupancy", "sensors/ratio", "events/reset"]:
        assert [h.msg_to_dict(m) for m in a.since_reset(topic)] == [h.msg_to_dict(m) for m in b.since_reset(topic)], (
            topic
        )
    compare_with_trace(states_a, h.run_trace(setup, variant, seed, tokens), f"{a.ns} vs trace")
    assert [e.seed for e in a.since_reset("events/reset")] == [seed, seed, 99]
    assert [e.episode for e in a.since_reset("events/reset")] == [1, 2, 3]
    assert [e.seeded for e in a.since_reset("events/reset")] == [False, False, True]


def test_four_lines_are_independent_and_seeded_seed_plus_k(ros, start_node, client_factory, probe, namespace):
    ns, seed, setup, variant = namespace(), 20, "B", "advanced"
    node = start_node(*h.SETUP_FLAGS[setup], "--variant", variant, "--lines", "4", "--seed", str(seed), *ns_args(ns))
    clock = clock_recorder(ros, probe)
    diag = diagnostics_recorder(ros, probe)
    clients = [client_factory(f"{ns}/line_{k}", variant, node_proc=node) for k in range(4)]
    for c in clients:
        c.wait_connected()
    for k, c in enumerate(clients):
        response = c.reset()
        assert (response.seed, response.episode) == (seed + k, 1)
    # Interleaved: line k takes k + 2 steps, different actions per line.
    plans = [[(3 * k + 5 * i) % 30 for i in range(k + 2)] for k in range(4)]
    results = [[c.by_stamp["state"][c.stamp][0]] for c in clients]
    for i in range(max(map(len, plans))):
        for k, c in enumerate(clients):
            if i < len(plans[k]):
                results[k].append(c.act(plans[k][i]))
    ros.spin_for(0.2)
    for k, c in enumerate(clients):
        trace = h.run_trace(setup, variant, seed + k, ["r", *plans[k]])
        compare_with_trace(results[k], trace, f"{c.ns} vs trace --seed {seed + k}")
        assert len(c.since_reset("state")) == len(plans[k]) + 1, f"{c.ns}: states of other lines leaked in"
        assert all(s.seed == seed + k for s in c.msgs["state"])
    types = topic_types(probe)
    for k in range(4):
        for rel, type_name in LINE_TYPES.items():
            assert types.get(f"{ns}/line_{k}/{rel}") == [type_name], f"{ns}/line_{k}/{rel}"
    assert f"{ns}/state" not in types and f"{ns}/line_4/state" not in types
    # /clock follows the line furthest ahead (line 3: reset at tick 1, then 5 steps).
    final = max(c.stamp for c in clients)
    assert final == 6 * NS_PER_S
    clock.wait_for(lambda m: stamp_ns(m.clock) == final, 3.0, f"clock at {show_ns(final)}")
    values = [stamp_ns(m.clock) for m in clock.msgs]
    assert values == sorted(set(values)) and values[-1] == final
    array = diag.wait_for(
        lambda a: all(
            (v := h.diagnostic_values(a, f"{ns}/line_{k}")) is not None and v["ticks"] == str(len(plans[k]))
            for k in range(4)
        ),
        5.0,
        "statuses of the 4 lines with their tick counts",
    )
    for k in range(4):
        values = h.diagnostic_values(array, f"{ns}/line_{k}")
        assert (values["seed"], values["episodes"], values["commands_rejected"]) == (str(seed + k), "1", "0")


def batch_stamps(batch) -> list[int]:
    """Each line's stamp (ns) of a batch of states or commands."""
    return [s * NS_PER_S + n for s, n in zip(batch.stamp_sec, batch.stamp_nanosec, strict=False)]


def stamp_fields(stamps_ns: list[int]) -> dict[str, list[int]]:
    """A batch message's stamp fields for each line's stamp (ns)."""
    return {"stamp_sec": [t // NS_PER_S for t in stamps_ns], "stamp_nanosec": [t % NS_PER_S for t in stamps_ns]}


def check_refused_resets(reset, stamps: list[int]) -> None:
    """batch/reset requests that are malformed answer success=false naming why, and reset nothing."""
    for request, reason in [
        (([0, 1], [True], [1, 2]), "same length"),
        (([2], [False], [0]), "out of range"),
        (([1, 1], [False, False], [0, 0]), "repeated"),
    ]:
        refused = reset(*request)
        assert not refused.success and reason in refused.message, refused
        assert batch_stamps(refused.states) == stamps


def assert_batches_follow_the_trace(setup: str, variant: str, seed: int, plan: list[list[int]], after: list) -> None:
    """Line k of each batch state in ``after`` is the library's step for line k's actions
    ``plan[k]`` after a reset with seed k + 1 (the node's seed + k)."""
    for k in range(len(plan)):
        trace = h.run_trace(setup, variant, seed + k, [f"r{k + 1}", *plan[k]])
        for entry, batch in zip(trace[2:], after, strict=True):
            want = h.trace_step_view(entry)
            got = {key: getattr(batch, key)[k] for key in want if hasattr(batch, key)}
            assert got == {key: want[key] for key in got}, f"line {k}"


@contextlib.contextmanager
def another_participant():
    """An rclpy node in a context of its own: another DDS participant, as another client's."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        yield rclpy.create_node(f"other_client_{os.getpid()}", context=context)
    finally:
        rclpy.shutdown(context=context)


def test_malformed_batch_requests_are_rejected_counted_and_change_nothing(ros, start_node, probe, namespace):
    """batch/reset and batch/cmd from rclpy: a refused reset answers success=false naming why and
    resets nothing; malformed lists, bad entries, stale and future stamps and another client's
    batch are rejected, counted per reason and line on /diagnostics, and the lines then follow the
    library's trajectory of the valid commands alone."""
    from sorting_line_interfaces.msg import LineCommands, LineStates
    from sorting_line_interfaces.srv import ResetLines

    ns, setup, variant, seed = namespace(), "A", "advanced", 5
    start_node(*h.SETUP_FLAGS[setup], "--variant", variant, "--lines", "2", "--seed", str(seed), *ns_args(ns))
    diag = diagnostics_recorder(ros, probe)
    states = h.TopicRecorder(ros, probe, f"{ns}/batch/state", LineStates)
    commands = probe.create_publisher(LineCommands, f"{ns}/batch/cmd", 10)
    resets = probe.create_client(ResetLines, f"{ns}/batch/reset")
    wait_diagnostics(diag, f"{ns}/line_1", {"episodes": "0"}, timeout=15.0)

    def reset(lines, has_seed, seeds):
        request = ResetLines.Request(lines=lines, has_seed=has_seed, seeds=seeds)
        return ros.call_service(resets, request, f"{ns}/batch/reset")

    first = reset([0, 1], [True, True], [1, 2])
    assert first.success and list(first.states.seed) == [1, 2], first
    stamps = batch_stamps(first.states)
    check_refused_resets(reset, stamps)

    ros.spin_until(lambda: commands.get_subscription_count() > 0, 10.0, f"{ns}/batch/cmd to match")

    def send(stamps_ns, speeds, modes, publisher=commands):
        publisher.publish(LineCommands(**stamp_fields(stamps_ns), speeds=speeds, modes=modes))

    def step(actions):
        """Sends the valid batch for `actions` and returns the batch state of the next tick."""
        speeds, modes = zip(*(h.decode_action(variant, a) for a in actions), strict=False)
        want = [t + NS_PER_S for t in stamps]
        send(stamps, list(speeds), list(modes))
        got = states.wait_for(lambda m: batch_stamps(m) == want, 10.0, f"batch/state at {want}")
        stamps[:] = want
        return got

    send(stamps, [0.5], [1, 1])  # one speed for two lines
    send(stamps, [0.5, 0.5], [1])  # one mode for two lines
    send(stamps, [math.nan, 0.55], [7, 9])  # unknown modes, off-grid speeds
    send([t - NS_PER_S for t in stamps], [0.5, 0.5], [1, 1])  # stale: the reset left that tick
    send([t + NS_PER_S for t in stamps], [0.5, 0.5], [1, 1])  # a tick that does not exist yet
    plan = [[4, 20], [13, 2]]
    after = [step([plan[0][0], plan[1][0]])]  # this client now owns both lines' episodes

    # Another client (its own rclpy context, so another DDS participant) is refused.
    with another_participant() as other:
        other_pub = other.create_publisher(LineCommands, f"{ns}/batch/cmd", 10)
        ros.spin_until(lambda: other_pub.get_subscription_count() > 0, 10.0, "the other client's batch/cmd to match")
        send(stamps, [0.1, 0.1], [0, 0], publisher=other_pub)
        wait_diagnostics(diag, f"{ns}/line_1", {"rejected_not_owner": "2"})
    after.append(step([plan[0][1], plan[1][1]]))

    assert_batches_follow_the_trace(setup, variant, seed, plan, after)
    want = dict(ticks="2", rejected_malformed="5", rejected_unknown_mode="1", rejected_invalid_speed="1")
    want.update(rejected_stale="2", rejected_unknown_tick="2", rejected_not_owner="2")
    wait_diagnostics(diag, f"{ns}/line_0", want)
    wait_diagnostics(diag, f"{ns}/line_1", {**want, "rejected_malformed": "0"})


def test_truncation_then_episode_over_then_reset(ros, start_node, client_factory, probe, namespace):
    ns, setup, variant = namespace(), "A", "basic"
    node = start_node(
        *h.SETUP_FLAGS[setup],
        "--variant",
        variant,
        "--max-steps",
        "5",
        "--seed",
        "1",
        "--tick-period",
        "0.25",
        *ns_args(ns),
    )
    diag = diagnostics_recorder(ros, probe)
    c = client_factory(ns, variant, node_proc=node, tick_period=0.25)
    c.wait_connected()
    response = c.reset(4)
    assert response.stamp.nanosec % 250_000_000 == 0
    actions = [2, 9, 9, 4, 0]
    states = [c.by_stamp["state"][c.stamp][0]] + [c.act(a) for a in actions]
    assert [s.truncated for s in states] == [False] * 5 + [True]
    assert [s.step for s in states] == list(range(6))
    assert all(not s.terminated for s in states)
    # The episode is over: commands for the waiting tick are rejected, no state comes.
    count = len(c.msgs["state"])
    for speed in (0.5, 0.2, 1.0):
        c.send_speed(speed)
    ros.spin_for(0.5)
    assert len(c.msgs["state"]) == count, "a step after truncation"
    wait_diagnostics(
        diag, ns, {"rejected_episode_over": "3", "commands_rejected": "3", "ticks": "5"}, context=c.context
    )
    assert "[episode_over]" in node.log()
    # A reset starts the next episode.
    response = c.reset(6)
    assert (response.seed, response.episode) == (6, 2)
    states += [c.by_stamp["state"][c.stamp][0], c.act(7)]
    assert (states[-1].episode, states[-1].step, states[-1].truncated) == (2, 1, False)
    trace = h.run_trace(setup, variant, 1, ["r4", *actions, "r6", 7], max_steps=5)
    compare_with_trace(states, trace, f"{ns} vs trace")
    stamps = [stamp_ns(s.header.stamp) for s in c.since_reset("state")]
    assert all(b - a == 250_000_000 for a, b in zip(stamps, stamps[1:], strict=False)), stamps


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_exits_zero(sig, start_node, client_factory, namespace):
    ns = namespace()
    node = start_node(*ns_args(ns))
    c = client_factory(ns, "basic", node_proc=node)
    c.wait_connected()
    c.reset(1)
    c.step(0.4)  # proven up and serving
    assert node.stop(sig, timeout=5.0) == 0, node.describe()
    log = node.log()
    assert f"received {sig.name}" in log and "shut down cleanly" in log, log
