"""Integration tests of the `sorting_line` ROS 2 node: the real binary, real rclpy over DDS (Fast DDS
on the Python side, RustDDS in the node), inside a loopback-only network namespace.

Every node gets a namespace of its own (an exited node's endpoints stay visible to rclpy for ~50 s),
and readiness is always proven by a real reply or message, never by a match count alone.
"""

from __future__ import annotations

import math
import time

import pytest

from sorting_line_gym.line.vocabulary import START_CONTENTS
from support import ros_harness as h
from support.line_client import LineClient
from support.lockstep_trace import compare_with_trace
from support.node_graph import clock_recorder, diagnostics_recorder, topic_types, wait_diagnostics
from support.ros_harness import LINE_TYPES, ns_args, show_ns, stamp_ns

REASONS = [
    "invalid_speed",
    "unknown_mode",
    "mode_on_basic_line",
    "stale",
    "duplicate",
    "unknown_tick",
    "episode_over",
    "malformed",
]

# The fixed line contents after a reset (src/sim/line.rs, as the library exports them).
START_BELT = START_CONTENTS["belt"]


PUBLISHED = ["input", "belt/occupancy", "sensors/ratio", "state", "events/reset"]
SUBSCRIBED = ["cmd/speed", "cmd/sort_mode"]


def check_line_endpoints(probe, line_ns: str, variant: str, node_name: str, node_ns: str) -> None:
    """The node publishes/subscribes each topic of the line with the right type (and the basic line
    has no sensors/ratio and no cmd/sort_mode)."""

    def owners(infos):
        return {(i.node_name, i.node_namespace, i.topic_type) for i in infos}

    for rel in PUBLISHED + SUBSCRIBED:
        name = f"{line_ns}/{rel}"
        infos = (
            probe.get_publishers_info_by_topic(name)
            if rel in PUBLISHED
            else probe.get_subscriptions_info_by_topic(name)
        )
        mine = {o for o in owners(infos) if o[:2] == (node_name, node_ns)}
        if variant == "basic" and rel in ("sensors/ratio", "cmd/sort_mode"):
            assert not mine, f"the basic line has {name}: {mine}"
        else:
            assert mine == {(node_name, node_ns, LINE_TYPES[rel])}, f"{name}: {owners(infos)}"


def check_tick_consistency(c: LineClient, stamps: list[int], reset_stamps: set[int]) -> None:
    """Sensor topics agree with `state` for every tick stamp in `stamps` (in order)."""
    previous_input = None
    for stamp in stamps:
        state = c.wait_state(stamp)
        inp = c.wait_message("input", stamp)
        belt = c.wait_message("belt/occupancy", stamp)
        where = f"{c.ns} tick {show_ns(stamp)}"
        assert len(c.by_stamp["state"][stamp]) == 1, f"{where}: more than one state"
        assert inp.quantity == state.observation_quantity, where
        assert (inp.episode, inp.step) == (state.episode, state.step), where
        assert inp.occupancy == (inp.amount_a + inp.amount_b) / 100, where
        assert 0.0 <= inp.quantity <= 1.0, where
        assert (belt.episode, belt.step) == (state.episode, state.step), where
        assert belt.speed == state.speed, where
        assert belt.occupancy == state.occupancy == (belt.amount_a + belt.amount_b) / 100, where
        if stamp in reset_stamps:
            assert (belt.amount_a, belt.amount_b) == START_BELT, f"{where}: belt after reset"
        else:
            assert previous_input is not None
            assert (belt.amount_a, belt.amount_b) == (previous_input.amount_a, previous_input.amount_b), (
                f"{where}: the belt carries the previous tick's input"
            )
        if c.variant == "advanced":
            ratio = c.wait_message("sensors/ratio", stamp)
            assert (ratio.episode, ratio.step) == (state.episode, state.step), where
            assert (ratio.ratio, ratio.category) == h.ratio_rule(inp.amount_a, inp.amount_b), (
                f"{where}: ratio {ratio.ratio} category {ratio.category} for A={inp.amount_a} B={inp.amount_b}"
            )
            assert state.observation_category == ratio.category, where
        previous_input = inp


# ------------------------------------------------------------------------------------------
# Start-up failures (no DDS needed)

BAD_PARAMS_FILES = {
    "threshold.yaml": ("threshold: 1.5\n", ["threshold = 1.5", "params file", "allowed 0.0 ..< 1.0"]),
    "lines.yaml": ("/**:\n  ros__parameters:\n    lines: 100\n", ["lines = 100", "allowed 1 ..= 64"]),
    "variant.yaml": ("variant: fancy\n", ["variant = fancy", "allowed basic or advanced"]),
    "unknown.yaml": ("speed: 3\n", ["unknown parameter 'speed'", "allowed variant"]),
    "broken.yaml": ("a: [unclosed\n", ["is not valid YAML"]),
}


BAD_START = [
    (["--lines", "0"], {}, ["lines = 0", "allowed 1 ..= 64"]),
    (["--threshold", "1.5"], {}, ["threshold = 1.5", "--threshold", "allowed 0.0 ..< 1.0"]),
    (["--obs-noise", "2"], {}, ["obs_noise = 2", "allowed 0.0 ..= 1.0"]),
    (["--max-steps", "0"], {}, ["max_steps = 0", "allowed 1 ..= 1000000"]),
    (["--mode", "realtime", "--rate", "0"], {}, ["rate = 0", "allowed 0.0 <.. 100000.0"]),
    (["--tick-period", "0"], {}, ["tick_period = 0", "allowed 0.000001 ..= 3600.0"]),
    (
        ["--lines", "2", "--seed", "9223372036854775807"],
        {},
        ["seed = 9223372036854775807 (with 2 lines, up to seed + 1)", "allowed 0 ..= 9223372036854775807"],
    ),
    # A ROS integer parameter is an int64: a larger seed would read back negative.
    (["--seed", "9223372036854775808"], {}, ["seed = 9223372036854775808", "allowed 0 ..= 9223372036854775807"]),
    (["--variant", "fancy"], {}, ["'fancy'", "basic", "advanced"]),
    (["--setup", "E"], {}, ["'E'", "allowed A, B, C, D"]),
    (["--ros-args", "-p", "setup:=E"], {}, ["setup = E", "--ros-args -p", "allowed A, B, C or D"]),
    (["--mode", "sometimes"], {}, ["'sometimes'", "lockstep", "realtime"]),
    (["--no-such-flag"], {}, ["--no-such-flag"]),
    (["--params-file", "/nonexistent/p.yaml"], {}, ["cannot read params file /nonexistent/p.yaml"]),
    *[(["--params-file", f"@{name}"], {}, expected) for name, (_, expected) in BAD_PARAMS_FILES.items()],
    (["--ros-args", "--params-file", "@threshold.yaml"], {}, ["threshold = 1.5", "allowed 0.0 ..< 1.0"]),
    (["--ros-args", "--bogus"], {}, ["unknown argument '--bogus'", "allowed -r/--remap"]),
    (["--ros-args", "-p", "seed:=-1"], {}, ["seed = -1", "--ros-args -p", "allowed 0 ..= 9223372036854775807"]),
    (["--ros-args", "-p", "lines:=65"], {}, ["lines = 65", "allowed 1 ..= 64"]),
    (["--ros-args", "-p", "seed"], {}, ["'seed' is not of the form name:=value"]),
    (["--ros-args", "-r", "__ns:=/bad-ns"], {}, ["namespace '/bad-ns' is not valid"]),
    # ROS names allow no repeated underscores (ros2-client refuses them when creating the topics).
    (["--ros-args", "-r", "__ns:=/a__b"], {}, ["namespace '/a__b' is not valid", "allowed"]),
    (["--ros-args", "-r", "__node:=a__b"], {}, ["node name 'a__b' is not valid", "allowed"]),
    (["--ros-args", "-r", "__fancy:=1"], {}, ["unsupported special remap '__fancy'"]),
    ([], {"ROS_DOMAIN_ID": "999"}, ["ROS_DOMAIN_ID = 999", "allowed 0 ..= 232"]),
    ([], {"ROS_DOMAIN_ID": "abc"}, ["ROS_DOMAIN_ID = abc", "allowed 0 ..= 232"]),
]


@pytest.mark.parametrize(
    "args,env,expected",
    BAD_START,
    ids=[" ".join([*(f"{k}={v}" for k, v in env.items()), *args]) for args, env, _ in BAD_START],
)
def test_bad_start_arguments_exit_2_naming_value_and_range(args, env, expected, tmp_path):
    for name, (text, _) in BAD_PARAMS_FILES.items():
        (tmp_path / name).write_text(text)
    args = [str(tmp_path / a[1:]) if a.startswith("@") else a for a in args]
    started = time.monotonic()
    code, stderr = h.run_node_expecting_failure(args, env=env)
    assert code == 2, f"exit code {code} (want 2) for {args} {env}; stderr:\n{stderr}"
    for text in expected:
        assert text in stderr, f"stderr of {args} {env} lacks {text!r}:\n{stderr}"
    assert time.monotonic() - started < 5.0


# ------------------------------------------------------------------------------------------
# Topics, service, clock, diagnostics


def check_line_counters(diag, ns: str, setup: str, variant: str, steps: int, final: int, context) -> None:
    """/diagnostics: the counters of line ``ns`` after one episode of ``steps`` answered ticks
    (seed 11), the last at ``final``."""
    accepted = steps * (2 if variant == "advanced" else 1)
    values = wait_diagnostics(diag, ns, {"ticks": str(steps), "sim_time": show_ns(final)}, context=context)
    want = {
        "episodes": "1",
        "commands_accepted": str(accepted),
        "commands_rejected": "0",
        "seed": "11",
        "episode": "1",
        "step": str(steps),
        "variant": variant,
        "input": "seasonal" if setup in "BD" else "random",
        "mode": "lockstep",
        **{f"rejected_{r}": "0" for r in REASONS},
    }
    assert {k: values.get(k) for k in want} == want
    assert float(values["tick_rate"]) >= 0.0
    status = next(s for a in reversed(diag.msgs) for s in a.status if s.hardware_id == ns)
    assert status.name == f"sorting_line: {ns}"


@pytest.mark.parametrize("variant,setup", [("basic", "D"), ("advanced", "B")])
def test_every_topic_and_the_reset_service(variant, setup, ros, start_node, client_factory, probe, namespace):
    ns = namespace()
    node = start_node(*h.SETUP_FLAGS[setup], "--variant", variant, "--seed", "3", *ns_args(ns))
    clock = clock_recorder(ros, probe)
    diag = diagnostics_recorder(ros, probe)
    c = client_factory(ns, variant, node_proc=node)
    c.wait_connected()

    response = c.reset(11)
    assert response.success and response.seed == 11 and response.episode == 1, response
    assert "11" in response.message
    reset_stamp = c.stamp
    state0 = c.wait_state(reset_stamp)
    assert (state0.seed, state0.episode, state0.step) == (11, 1, 0)
    assert (response.quantity, response.category) == (state0.observation_quantity, state0.observation_category)
    assert state0.reward == 0.0 and not state0.truncated and not state0.terminated
    event = c.wait_message("events/reset", reset_stamp)
    assert (event.seed, event.episode) == (11, 1)

    actions = [5, 27, 3, 14, 29, 0, 8, 22] if variant == "advanced" else [5, 9, 3, 0, 7, 7, 2, 9]
    states = [c.act(a) for a in actions]
    for state, action in zip(states, actions, strict=False):
        speed, mode = h.decode_action(variant, action)
        assert state.speed == speed and state.seed == 11
        assert state.mode == (mode or 0)
    stamps = [reset_stamp + k * c.period_ns for k in range(len(actions) + 1)]
    assert [stamp_ns(s.header.stamp) for s in c.since_reset("state")] == stamps, "one state per tick, in order"

    # The library's reference trajectory for the same seed and actions.
    trace = h.run_trace(setup, variant, 3, ["r11", *actions])
    compare_with_trace([state0, *states], trace, f"{ns} vs trace")
    check_tick_consistency(c, stamps, {reset_stamp})
    assert len(c.since_reset("events/reset")) == 1
    if variant == "basic":
        assert not c.msgs["sensors/ratio"]

    # /clock follows the tick stamps (one tick = tick_period = 1 s here) and never goes back.
    final = stamps[-1]
    clock.wait_for(lambda m: stamp_ns(m.clock) == final, 3.0, f"clock at {show_ns(final)}", c.context)
    values = [stamp_ns(m.clock) for m in clock.msgs]
    assert values == sorted(set(values)), f"/clock not strictly increasing: {values}"
    assert set(stamps[1:]) <= set(values) <= set(stamps), f"/clock {values} vs ticks {stamps}"

    check_line_counters(diag, ns, setup, variant, len(actions), final, c.context)

    # The graph: which endpoints the node itself has, with their types.
    check_line_endpoints(probe, ns, variant, node_name="sorting_line", node_ns=ns)
    types = topic_types(probe)
    assert "rosgraph_msgs/msg/Clock" in types.get("/clock", [])
    assert types.get("/diagnostics") == ["diagnostic_msgs/msg/DiagnosticArray"]
    services = dict(probe.get_service_names_and_types())
    assert services.get(f"{ns}/reset") == ["sorting_line_interfaces/srv/ResetLine"]
    assert ("sorting_line", ns) in probe.get_node_names_and_namespaces()


# ------------------------------------------------------------------------------------------
# Lock-step


@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_lockstep_publishes_exactly_one_state_per_answered_tick(variant, ros, start_node, client_factory, namespace):
    ns = namespace()
    node = start_node("--variant", variant, "--seed", "5", *ns_args(ns))
    c = client_factory(ns, variant, node_proc=node)
    c.wait_connected()
    c.reset(5)

    def count() -> int:
        return len(c.since_reset("state"))

    assert count() == 1
    if variant == "advanced":
        # Only the speed: the tick waits, no state.
        t = c.stamp
        c.send_speed(0.3)
        ros.spin_for(0.5)
        assert count() == 1, f"a state without the sort mode: {c.since_reset('state')[1:]}"
        c.send_mode(1)
        state = c.wait_state(t + c.period_ns)
        assert (state.speed, state.mode, state.step) == (0.3, 1, 1)
        c.stamp += c.period_ns
        ros.spin_for(0.3)
        assert count() == 2
        # The other order: the mode alone does not step either.
        t = c.stamp
        c.send_mode(2)
        ros.spin_for(0.5)
        assert count() == 2
        c.send_speed(0.7)
        state = c.wait_state(t + c.period_ns)
        assert (state.speed, state.mode, state.step) == (0.7, 2, 2)
        c.stamp += c.period_ns
    for k in range(10):
        c.step(0.1 * (k % 10 + 1), k % 3)
    ros.spin_for(0.3)
    states = c.since_reset("state")
    stamps = [stamp_ns(s.header.stamp) for s in states]
    first = stamps[0]
    assert stamps == [first + i * c.period_ns for i in range(len(stamps))], "one state per tick, none repeated"
    assert [s.step for s in states] == list(range(len(states)))


def check_fixed_parameters_of_plant_sorter(ros, probe, context) -> None:
    """/plant/sorter's parameters through the ROS parameter services: their values (the params
    file's, the -p flags', the defaults), and a set request refused with a reason (fixed for the run)."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters

    get = probe.create_client(GetParameters, "/plant/sorter/get_parameters")
    names = "variant max_steps seed threshold mode lines input obs_noise action_penalty tick_period".split()
    reply = ros.call_service(get, GetParameters.Request(names=names), "/plant/sorter/get_parameters", context=context)

    def value(v):
        return {
            ParameterType.PARAMETER_BOOL: v.bool_value,
            ParameterType.PARAMETER_INTEGER: v.integer_value,
            ParameterType.PARAMETER_DOUBLE: v.double_value,
            ParameterType.PARAMETER_STRING: v.string_value,
        }.get(v.type, f"<type {v.type}>")

    got = dict(zip(names, map(value, reply.values), strict=False))
    assert got == {
        "variant": "advanced",
        "max_steps": 30,
        "seed": 3,
        "threshold": 0.75,
        "mode": "lockstep",
        "lines": 1,
        "input": "random",
        "obs_noise": 0.0,
        "action_penalty": 0.0,
        "tick_period": 1.0,
    }
    # Fixed for the run: a set request is refused with a reason.
    set_client = probe.create_client(SetParameters, "/plant/sorter/set_parameters")
    request = SetParameters.Request(
        parameters=[
            Parameter(name="threshold", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=0.9))
        ]
    )
    result = ros.call_service(set_client, request, "/plant/sorter/set_parameters", context=context).results[0]
    assert not result.successful and "fixed" in result.reason, result


def test_started_like_launch_ros(ros, start_node, client_factory, probe, tmp_path):
    params = tmp_path / "f.yaml"
    params.write_text("/**:\n  ros__parameters:\n    variant: advanced\n    max_steps: 30\n")
    node = start_node(
        "--ros-args",
        "-r",
        "__ns:=/plant",
        "-r",
        "__node:=sorter",
        "-p",
        "seed:=3",
        "-p",
        "threshold:=0.75",
        "--params-file",
        str(params),
    )
    c = client_factory("/plant", "advanced", node_proc=node)
    c.wait_connected()
    response = c.reset()  # no seed: the streams of the node's seed carry on
    assert (response.seed, response.episode) == (3, 1), response
    assert c.wait_state(c.stamp).seed == 3

    check_fixed_parameters_of_plant_sorter(ros, probe, c.context)

    # The namespace and the node name.
    assert ("sorter", "/plant") in probe.get_node_names_and_namespaces()
    types = topic_types(probe)
    for rel, type_name in LINE_TYPES.items():
        assert types.get(f"/plant/{rel}") == [type_name], rel
    assert "/state" not in types and "/input" not in types
    assert dict(probe.get_service_names_and_types()).get("/plant/reset") == ["sorting_line_interfaces/srv/ResetLine"]

    # max_steps 30 from the parameter file: the 30th step truncates.
    states = [c.step(0.5, 0) for _ in range(30)]
    assert [s.truncated for s in states] == [False] * 29 + [True]
    assert states[-1].step == 30


def test_a_setup_is_a_preset_that_explicit_values_override(ros, start_node, client_factory, probe, namespace):
    from rcl_interfaces.srv import GetParameters

    ns = namespace()
    node = start_node("--setup", "D", "--obs-noise", "0.1", *ns_args(ns))
    c = client_factory(ns, "basic", node_proc=node)
    c.wait_connected()
    names = ["setup", "input", "obs_noise", "action_penalty", "threshold"]
    get = probe.create_client(GetParameters, f"{ns}/sorting_line/get_parameters")
    reply = ros.call_service(
        get, GetParameters.Request(names=names), f"{ns}/sorting_line/get_parameters", context=c.context
    )
    got = [v.string_value or v.double_value for v in reply.values]
    assert got == ["D", "seasonal", 0.1, 0.5, 0.7], got


# ------------------------------------------------------------------------------------------
# Bad commands


def answer_one_tick_amid_bad_commands(noisy, diag, ns_noisy: str, expected: dict, k: int, speed: float, mode: int):
    """Answers the tick ``noisy`` waits at with (speed, mode), each surrounded by bad commands of
    every kind, counted into ``expected`` by reason; then re-sends them, stale."""
    p = noisy.period_ns
    t = noisy.stamp
    # Per topic, samples arrive in order, so everything before the clean command of a topic is
    # judged while the line still waits at t.
    for bad_mode, stamp in [(7, t), (3, t), (255, t), (mode, t - p), (mode, t + p)]:
        noisy.send_mode(bad_mode, stamp)
    expected["unknown_mode"] += 3
    expected["stale"] += 1
    expected["unknown_tick"] += 1
    noisy.send_mode(mode, t)
    if k == 3:
        # A second sort mode for the same tick is a duplicate only while the tick still waits
        # for its speed: hold the speed back until /diagnostics shows the duplicate counted.
        noisy.send_mode((mode + 1) % 3, t)
        expected["duplicate"] += 1
        wait_diagnostics(diag, ns_noisy, {"rejected_duplicate": "1"}, context=noisy.context)
    for bad_speed, stamp in [
        (math.nan, t),
        (math.inf, t),
        (-math.inf, t),
        (0.55, t),
        (-1.0, t),
        (0.0, t),
        (1.1, t),
        (speed, t - p),
        (speed, t + p),
        (speed, t + p // 2),
        (speed, 0),
    ]:
        noisy.send_speed(bad_speed, stamp)
    expected["invalid_speed"] += 7
    expected["stale"] += 2  # t - p and tick 0 (the line is past both)
    expected["unknown_tick"] += 2
    noisy.send_speed(speed, t)
    noisy.wait_state(t + p)
    noisy.stamp = t + p
    # Re-sending the answered tick's commands: stale now.
    noisy.send_speed(speed, t)
    noisy.send_mode(mode, t)
    expected["stale"] += 2


def test_bad_command_flood_leaves_the_state_stream_identical(ros, start_node, client_factory, probe, namespace):
    variant, setup, seed = "advanced", "B", 21
    ns_clean, ns_noisy = namespace("clean"), namespace("noisy")
    diag = diagnostics_recorder(ros, probe)
    # One node joins the graph at a time: two started together announce their endpoints to our
    # participant in one burst, and on a busy machine part of it was lost for good (the clean
    # line's state writer and cmd/speed reader never matched in 4 of 7 runs at load 15;
    # workarounds/simultaneous_discovery.py).
    node_clean = start_node(*h.SETUP_FLAGS[setup], "--variant", variant, "--seed", str(seed), *ns_args(ns_clean))
    clean = client_factory(ns_clean, variant, node_proc=node_clean)
    clean.wait_connected()
    node_noisy = start_node(*h.SETUP_FLAGS[setup], "--variant", variant, "--seed", str(seed), *ns_args(ns_noisy))
    noisy = client_factory(ns_noisy, variant, node_proc=node_noisy)
    noisy.wait_connected()
    actions = [(0.5, 1), (0.9, 2), (0.1, 0), (0.3, 2), (1.0, 1), (0.6, 0), (0.6, 2), (0.2, 1), (0.8, 0), (0.4, 2)]

    clean.reset(seed)
    for speed, mode in actions:
        clean.step(speed, mode)

    expected = dict.fromkeys(REASONS, 0)
    flood_started = time.monotonic()
    noisy.reset(seed)
    for k, (speed, mode) in enumerate(actions):
        answer_one_tick_amid_bad_commands(noisy, diag, ns_noisy, expected, k, speed, mode)

    for topic in ["state", "input", "belt/occupancy", "sensors/ratio"]:
        assert [h.msg_to_dict(m) for m in noisy.since_reset(topic)] == [
            h.msg_to_dict(m) for m in clean.since_reset(topic)
        ], f"{topic}: the noisy run differs from the clean run"
    assert len(noisy.since_reset("state")) == len(actions) + 1

    total = sum(expected.values())
    want = {
        "ticks": str(len(actions)),
        "commands_accepted": str(2 * len(actions)),
        "commands_rejected": str(total),
        **{f"rejected_{r}": str(n) for r, n in expected.items()},
    }
    got = wait_diagnostics(diag, ns_noisy, {"commands_rejected": str(total)}, context=noisy.context)
    assert {k: got.get(k) for k in want} == want
    got_clean = wait_diagnostics(diag, ns_clean, {"ticks": str(len(actions))}, context=clean.context)
    assert got_clean["commands_rejected"] == "0" and got_clean["commands_accepted"] == str(2 * len(actions))
    assert "rejected" in node_noisy.log() and "[invalid_speed]" in node_noisy.log()
    # Rejections are logged once per reason and 5 s interval, not once per command.
    allowed = 1 + int((time.monotonic() - flood_started) / 5.0)
    assert node_noisy.log().count("[invalid_speed]") <= allowed, node_noisy.log()
