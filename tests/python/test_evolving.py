"""The evolving line (upgrades and drifts during a run) against the real node over DDS:
`sorting_line node --evolution FILE`.

- The same seed and commands give the trajectory of `sorting_line trace --evolution FILE`, state
  by state, and `events/evolution` announces exactly the events the trace applies.
- The hardware shows in the graph: no `sensors/ratio` publisher before the sensor upgrade, no
  `cmd/sort_mode` subscription before the machine upgrade; they appear when it applies.
- A sort mode other than 0 before the machine upgrade is refused, counted on /diagnostics, and the
  line keeps its speed command; /diagnostics shows the setup; /parameter_events carries the
  changed parameters.
- A bad schedule fails at start naming the event, the field, the value and the range.
"""

from __future__ import annotations

import json
import subprocess

from support import ros_harness as h
from support.ros_harness import NS_PER_S, stamp_ns
from support.waits import wait_until

# Both schedules run the advanced line (as built, episode 0) with basic hardware: no sort modes, no
# ratio sensor, until their upgrades.
BASIC_HARDWARE_AS_BUILT = """\
events:
  - at: {episode: 0}
    sort_modes: false
    ratio_sensor: false
"""
# Advanced B with the hardware of basic B until the upgrades; tick and episode events of every kind.
SCHEDULE = (
    BASIC_HARDWARE_AS_BUILT
    + """\
  - at: {tick: 4}
    obs_noise: 0.2
    threshold: 0.8
  - at: {tick: 6}
    input_fault: {kind: dropped, ticks: 2}
  - at: {episode: 2}
    ratio_sensor: true
  - at: {tick: 14}
    sort_modes: true
"""
)
UPGRADE_TICK = 14
SEED = 42
# Advanced actions (speed index * 3 + mode), modes other than 0 before the upgrade included.
EPISODE_1 = [17, 5, 20, 26, 8, 11, 29, 14, 2, 22]
EPISODE_2 = [13, 19, 4, 25, 16, 28, 10, 7, 23, 1]
BATCH_STEP = 2  # this step of episode 1 goes through batch/cmd with a mode the machine lacks


def trace(schedule_file, tokens, seed: int = SEED) -> list[dict]:
    argv = [
        str(h.node_binary()),
        "trace",
        "--setup",
        "B",
        "--variant",
        "advanced",
        "--seed",
        str(seed),
        "--evolution",
        str(schedule_file),
        "--actions",
        ",".join(map(str, tokens)),
    ]
    out = subprocess.run(argv, capture_output=True, text=True, timeout=30, check=True).stdout
    return [json.loads(line) for line in out.splitlines()]


def step_view(entry: dict) -> dict:
    view = h.trace_step_view(entry)
    view["observation_category"] = entry["category_reading"]  # the sensor's reading, 3 = unknown
    return view


def evolving_line(tmp_path, start_node, client_factory, ns: str):
    """A lock-step node running advanced B by SCHEDULE in `ns`, and a client of its line that
    publishes cmd/sort_mode (the basic-variant client: it does not wait for the node's, which
    appears only with the machine upgrade). Returns (schedule file, ns, node, client)."""
    schedule = tmp_path / "schedule.yaml"
    schedule.write_text(SCHEDULE)
    node = start_node(
        "--setup",
        "B",
        "--variant",
        "advanced",
        "--seed",
        SEED,
        "--evolution",
        schedule,
        "--ros-args",
        "-r",
        f"__ns:={ns}",
    )
    return schedule, ns, node, client_factory(ns, "basic", node_proc=node, mode_topic=True)


def test_bad_schedule_fails_at_start_naming_the_event(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("events:\n  - at: {tick: 5}\n    obs_noise: 0.1\n  - at: {tick: 500}\n    threshold: 1.2\n")
    code, err = h.run_node_expecting_failure(["--evolution", bad])
    assert code != 0
    assert (
        "parameter evolution_file = " + str(bad) + " (from --evolution): evolution event 1 (at tick 500): "
        "threshold = 1.2 is out of range: allowed 0.0 ..< 1.0"
    ) in err, err
    code, err = h.run_node_expecting_failure(["--ros-args", "-p", f"evolution_file:={tmp_path / 'missing.yaml'}"])
    assert code != 0 and "evolution_file" in err and "cannot read it" in err, err


def step_line(c, batch, action: int, via_batch: bool = False):
    """Answers the tick ``c`` waits at with ``action`` (through batch/cmd, or the line's topics,
    the mode only once the node subscribes it); the next state."""
    from sorting_line_interfaces.msg import LineCommands

    speed, mode = h.decode_action("advanced", action)
    if via_batch:
        t = c.stamp
        batch.publish(
            LineCommands(stamp_sec=[t // NS_PER_S], stamp_nanosec=[t % NS_PER_S], speeds=[speed], modes=[mode])
        )
    else:
        if c.mode_pub.get_subscription_count() >= 1:
            c.send_mode(mode)
        c.send_speed(speed)
    state = c.wait_state(c.stamp + c.period_ns)
    c.stamp += c.period_ns
    return state


def check_states_follow_the_trace(expected: list[dict], states: list) -> None:
    assert len(expected) == len(states)
    for k, (entry, state) in enumerate(zip(expected, states, strict=False)):
        if "reset" in entry:
            assert h.state_reset_view(state) == {
                **h.trace_reset_view(entry),
                "observation_category": entry["category_reading"],
            }, k
        else:
            assert h.state_step_view(state) == step_view(entry), f"record {k}, tick {entry['tick']}"


def check_evolution_events(ros, events: list, expected: list[dict], states: list) -> None:
    """events/evolution: one message per reset, and one per tick with events, the trace's events."""
    ros.spin_until(lambda: len(events) >= 4, 5, "the events/evolution messages")
    applied = [
        (e["reset"]["episode"] if "reset" in e else None, e["tick"], [x["index"] for x in e["evolution"]])
        for e in expected
        if e["evolution"]
    ]
    announced = [(m.episode if m.at_reset else None, m.tick, list(m.event_indices)) for m in events if m.event_indices]
    assert announced == applied, (announced, applied)
    resets = [m for m in events if m.at_reset]
    assert [m.episode for m in resets] == [1, 2] and [m.ratio_sensor for m in resets] == [False, True]
    upgrade = next(m for m in events if list(m.event_indices) == [4])
    assert (upgrade.tick, upgrade.sort_modes, upgrade.ratio_sensor, list(upgrade.changed)) == (
        14,
        True,
        True,
        ["sort_modes"],
    )
    # Announced with the state of the tick the line then waits at (after the step of tick 13).
    arrival = 1 + len(EPISODE_1) + 1 + (UPGRADE_TICK - 1 - len(EPISODE_1))
    assert stamp_ns(upgrade.header.stamp) == stamp_ns(states[arrival].header.stamp)
    assert states[arrival + 1].mode == EPISODE_2[UPGRADE_TICK - len(EPISODE_1)] % 3, "the upgraded step ran its mode"
    fault = next(m for m in events if list(m.event_indices) == [2])
    assert (fault.input_fault, fault.input_fault_ticks, list(fault.values)) == ("dropped", 2, ["dropped 2"])


def check_parameters_moved(ros, probe, ns: str, param_events: list, schedule, context) -> None:
    """/parameter_events: obs_noise and threshold moved at tick 4; the services give the new values."""
    from rcl_interfaces.srv import GetParameters

    def changed(name):
        return [p.value.double_value for m in param_events for p in m.changed_parameters if p.name == name]

    ros.spin_until(lambda: changed("threshold"), 5, "/parameter_events with threshold")
    assert (changed("obs_noise"), changed("threshold")) == ([0.2], [0.8])
    get = probe.create_client(GetParameters, f"{ns}/sorting_line/get_parameters")
    reply = ros.call_service(
        get,
        GetParameters.Request(names=["obs_noise", "threshold", "evolution_file"]),
        "get_parameters",
        context=context,
    )
    assert [v.double_value for v in reply.values[:2]] == [0.2, 0.8]
    assert reply.values[2].string_value == str(schedule)


def check_diagnostics_show_the_evolution(ros, c, node, schedule) -> None:
    """/diagnostics: the refused mode is counted, and the evolution state shown; the node's log says so."""
    want = {
        "rejected_sort_modes_off": "1",
        "sort_modes": "true",
        "ratio_sensor": "true",
        "obs_noise": "0.2",
        "threshold": "0.8",
        "evolution_events_applied": "5",
        "evolution_events_total": "5",
        "evolution_file": str(schedule),
    }

    def diagnosed():
        return c.diagnostics and all(c.diagnostics[-1][1].get(k) == v for k, v in want.items())

    ros.spin_until(
        diagnosed, 5, f"/diagnostics showing {want}", lambda: str(c.diagnostics[-1][1] if c.diagnostics else None)
    )
    assert "rejected sort mode 2" in node.log() and "[sort_modes_off]" in node.log(), node.log_tail()
    assert "sensors/ratio appears" in node.log() and "cmd/sort_mode appears" in node.log(), node.log_tail()


def test_evolving_node_follows_its_schedule_like_trace(tmp_path, start_node, client_factory, probe, namespace, ros):
    from rcl_interfaces.msg import ParameterEvent
    from sorting_line_interfaces.msg import EvolutionEvent, LineCommands, MaterialRatio

    schedule, ns, node, c = evolving_line(tmp_path, start_node, client_factory, namespace("evo"))
    events: list = []
    probe.create_subscription(EvolutionEvent, f"{ns}/events/evolution", events.append, 10)
    ratios: list = []
    ratio_sub = probe.create_subscription(MaterialRatio, f"{ns}/sensors/ratio", ratios.append, 10)
    param_events: list = []
    probe.create_subscription(
        ParameterEvent,
        "/parameter_events",
        lambda m: param_events.append(m) if m.node == f"{ns}/sorting_line" else None,
        100,
    )
    batch = probe.create_publisher(LineCommands, f"{ns}/batch/cmd", 10)
    c.wait_connected()
    ros.spin_until(lambda: batch.get_subscription_count() >= 1, 10, "batch/cmd to match", c.context)
    ros.spin_until(lambda: probe.count_publishers(f"{ns}/events/evolution") >= 1, 10, "events/evolution publisher")

    def hardware():
        return (probe.count_publishers(f"{ns}/sensors/ratio"), probe.count_subscribers(f"{ns}/cmd/sort_mode"))

    def reset(seed=None):
        c.reset(seed=seed)
        return c.wait_state(c.stamp)

    states = [reset(SEED)]
    assert hardware() == (0, 0), "basic hardware at episode 1: no ratio sensor, no sort modes"
    for i, action in enumerate(EPISODE_1):
        states.append(step_line(c, batch, action, via_batch=i == BATCH_STEP))
    assert hardware() == (0, 0)
    states.append(reset())
    # Episode 2 fits the ratio sensor: its publisher appears. The node announces it before the
    # reset's state goes out, but the probe is another participant than the client that got the
    # state, and its discovery thread may run later (it lagged in about 1 run of 10, whatever the
    # node's rustdds patches): so wait a moment for it.
    ros.spin_until(lambda: hardware()[0] == 1, 5, f"the probe to see {ns}/sensors/ratio's publisher")
    ros.spin_until(lambda: ratio_sub.get_publisher_count() >= 1, 10, f"{ns}/sensors/ratio to match", c.context)
    for tick, action in enumerate(EPISODE_2, start=len(EPISODE_1)):
        if tick == UPGRADE_TICK:
            # The machine upgrade is due at this tick: cmd/sort_mode is subscribed before the
            # client has to command the upgraded step.
            ros.spin_until(lambda: hardware()[1] == 1, 5, f"the probe to see {ns}/cmd/sort_mode's subscriber")
            ros.spin_until(lambda: c.mode_pub.get_subscription_count() >= 1, 10, "cmd/sort_mode to match", c.context)
        elif tick < UPGRADE_TICK:
            assert hardware()[1] == 0, f"tick {tick}: {hardware()}"
        states.append(step_line(c, batch, action))

    ros.spin_until(lambda: ratios, 5, f"a message on {ns}/sensors/ratio", c.context)
    episode_2 = stamp_ns(states[len(EPISODE_1) + 1].header.stamp)
    assert all(stamp_ns(m.header.stamp) >= episode_2 for m in ratios), "no ratio readings before the sensor upgrade"

    # The node's trajectory is the library's.
    expected = trace(schedule, [f"r{SEED}", *EPISODE_1, "r", *EPISODE_2])[1:]  # [0] is the line as built (episode 0)
    check_states_follow_the_trace(expected, states)
    check_evolution_events(ros, events, expected, states)
    check_parameters_moved(ros, probe, ns, param_events, schedule, c.context)
    check_diagnostics_show_the_evolution(ros, c, node, schedule)


# --------------------------------------------------------------------------------------------
# Gymnasium: SortingLineEvolving-v0

# Basic hardware until episode 3 (the third reset), then both upgrades; a drift mid-episode 3.
ENV_SCHEDULE = (
    BASIC_HARDWARE_AS_BUILT
    + """\
  - at: {episode: 3}
    sort_modes: true
    ratio_sensor: true
  - at: {tick: 25}
    obs_noise: 0.1
"""
)
ENV_EPISODE_STEPS = 10


def make_env(schedule_file, **kwargs):
    import gymnasium

    import sorting_line_gym  # noqa: F401 - registers the ids

    return gymnasium.make(
        "sorting_line_gym:SortingLineEvolving-v0",
        evolution=str(schedule_file),
        setup="B",
        max_episode_steps=ENV_EPISODE_STEPS,
        **kwargs,
    )


def env_rows_of_the_trace(schedule, tokens: list[str], seed: int) -> list[tuple]:
    """What the env should have returned, from `sorting_line trace`: ("reset", observation) and
    ("step", observation, reward, mode) rows (an unknown ratio category reads 0.5)."""
    expected = []
    for entry in trace(schedule, tokens, seed=seed)[1:]:
        category = entry["category_reading"]
        category = 0.5 if category == 3 else float(category)
        if "reset" in entry:
            expected.append(("reset", [entry["reset"]["observation"]["quantity"], category]))
        else:
            s = entry["step"]
            mode = h.MODES[s["action"]["mode"]]
            expected.append(("step", [s["observation"]["quantity"], category], s["reward"], mode))
    return expected


def test_evolving_env_is_the_trace_with_masks_and_unknown_category(tmp_path):
    import numpy as np

    schedule = tmp_path / "env.yaml"
    schedule.write_text(ENV_SCHEDULE)
    seeds = [7, 8, 9]
    rng = np.random.default_rng(3)
    actions = [rng.integers(0, 30, ENV_EPISODE_STEPS).tolist() for _ in seeds]
    env = make_env(schedule)
    got, tokens = [], []
    try:
        for episode, (seed, acts) in enumerate(zip(seeds, actions, strict=False), start=1):
            obs, info = env.reset(seed=seed)
            tokens.append(f"r{seed}")
            masks = env.unwrapped.action_masks()
            upgraded = episode >= 3
            assert masks.tolist() == [upgraded or a % 3 == 0 for a in range(30)], (episode, masks)
            assert info["settings"]["sort_modes"] == upgraded and info["settings"]["ratio_sensor"] == upgraded
            assert (obs[1] == 0.5) != upgraded, f"episode {episode}: category {obs[1]}"
            if episode == 3:
                assert info["evolution"] == [
                    {
                        "at_reset": True,
                        "episode": 3,
                        "tick": 20,
                        "changed": {"sort_modes": "true", "ratio_sensor": "true"},
                    }
                ]
            got.append(("reset", obs.tolist()))
            for action in acts:
                obs, reward, terminated, truncated, info = env.step(action)
                tokens.append(str(action))
                got.append(("step", obs.tolist(), reward, info["mode"]))
                assert (obs[1] == 0.5) != upgraded
                if info["line_tick"] == 25:
                    assert info["evolution"] == [
                        {"at_reset": False, "episode": 3, "tick": 25, "changed": {"obs_noise": "0.1"}}
                    ], info["evolution"]
                    assert info["settings"]["obs_noise"] == 0.1
            assert truncated and not terminated
    finally:
        env.close()

    expected = env_rows_of_the_trace(schedule, tokens, seeds[0])

    # float32 observations: compare the readings (two decimals) at float32 precision.
    def as32(rows):
        return [tuple(np.float32(v).item() if isinstance(v, float) else v for v in r[1]) for r in rows]

    assert as32(got) == as32(expected)
    assert [r[2:] for r in got] == [r[2:] for r in expected]


def test_maskable_ppo_never_picks_a_masked_action(tmp_path):
    import gymnasium
    from sb3_contrib import MaskablePPO

    schedule = tmp_path / "env.yaml"
    schedule.write_text(ENV_SCHEDULE)
    picks: list[tuple[bool, bool]] = []  # (action allowed, modes on) per step

    class Recorder(gymnasium.Wrapper):
        def action_masks(self):
            return self.env.get_wrapper_attr("action_masks")()

        def step(self, action):
            picks.append((bool(self.action_masks()[int(action)]), bool(self.action_masks().all())))
            return self.env.step(action)

    env = Recorder(make_env(schedule))
    try:
        model = MaskablePPO("MlpPolicy", env, n_steps=40, batch_size=40, n_epochs=1, seed=3, device="cpu")
        model.learn(80)
    finally:
        env.close()
    assert len(picks) >= 80
    assert all(allowed for allowed, _ in picks), [i for i, (ok, _) in enumerate(picks) if not ok]
    before = [modes for _, modes in picks[: 2 * ENV_EPISODE_STEPS]]
    assert not any(before) and all(modes for _, modes in picks[2 * ENV_EPISODE_STEPS :]), "the upgrade at episode 3"


# The first reset: episode 1 of the schedule whatever the handshake meets (a slow or lost first
# exchange). Episode 1 announces a change, so that its number shows; episode 2 upgrades.
FIRST_RESET_SCHEDULE = (
    BASIC_HARDWARE_AS_BUILT
    + """\
  - at: {episode: 1}
    threshold: 0.75
  - at: {episode: 2}
    sort_modes: true
    ratio_sensor: true
"""
)


def check_first_episode_is_the_schedules_first(env, schedule) -> None:
    """Two episodes of ``env``: the first announces episode 1 and has basic hardware, the second
    the upgrade of episode 2; the trajectory is the trace's."""
    import numpy as np

    seeds = [7, 8]
    actions = np.random.default_rng(5).integers(0, 30, (len(seeds), ENV_EPISODE_STEPS)).tolist()
    got, tokens = [], []
    for episode, (seed, acts) in enumerate(zip(seeds, actions, strict=True), start=1):
        obs, info = env.reset(seed=seed)
        tokens.append(f"r{seed}")
        upgraded = episode == 2
        assert [e["episode"] for e in info["evolution"] if e["at_reset"]] == [episode], (episode, info)
        assert env.unwrapped.action_masks().tolist() == [upgraded or a % 3 == 0 for a in range(30)], episode
        assert info["settings"]["threshold"] == 0.75 and info["settings"]["sort_modes"] == upgraded
        got.append(("reset", obs.tolist()))
        for action in acts:
            obs, reward, _, _, info = env.step(action)
            tokens.append(str(action))
            got.append(("step", obs.tolist(), reward, info["mode"]))
    expected = env_rows_of_the_trace(schedule, tokens, seeds[0])
    assert [(r[0], *np.float32(r[1]).tolist(), *r[2:]) for r in got] == [
        (r[0], *np.float32(r[1]).tolist(), *r[2:]) for r in expected
    ]


def test_a_slow_first_reply_is_waited_for_not_a_second_episode(tmp_path, monkeypatch):
    """Handshake attempts far shorter than any reply (as a reply slower than 0.2 s under load):
    the first reset is still the schedule's episode 1, not a repeated reset's episode 2."""
    import sorting_line_gym.ros.bank as bank

    monkeypatch.setattr(bank, "HANDSHAKE_TIMEOUTS", (1e-4, 1e-4, 1e-4, 1e-4, 2.0))
    schedule = tmp_path / "first.yaml"
    schedule.write_text(FIRST_RESET_SCHEDULE)
    env = make_env(schedule)
    try:
        check_first_episode_is_the_schedules_first(env, schedule)
    finally:
        env.close()


def test_a_node_paused_at_the_first_reset_still_starts_episode_1(tmp_path):
    """Every node stopped (SIGSTOP) for 0.7 s once discovered, longer than the fixed lines'
    first two handshake attempts (0.2 + 0.4 s): the env's first episode is episode 1, and no
    node is sent its first reset twice.

    Usually the first node's reply is waited out. Sometimes the pause catches the node before it
    has matched our readers: its step-0 state goes out to nobody, and the bank rightly moves to
    a fresh node (also paused), which has had no reset. Which of the two happened is not what this
    test checks; that a paused node is never reset twice, and that the waiting outlasts the pause
    (else every node would be replaced), is."""
    import collections
    import os
    import signal
    import threading

    schedule = tmp_path / "first.yaml"
    schedule.write_text(FIRST_RESET_SCHEDULE)
    env = make_env(schedule)
    bank = env.unwrapped.bank
    connect, first_exchange = bank._connect, bank._first_exchange
    resumes, first_resets = [], collections.Counter()

    def connect_then_pause(deadline):
        connect(deadline)
        pid = bank.process.process.pid
        os.kill(pid, signal.SIGSTOP)
        resumes.append(threading.Timer(0.7, os.kill, (pid, signal.SIGCONT)))
        resumes[-1].start()

    def counted_first_exchange(seeds, timeout):
        first_resets[bank.namespace] += 1
        return first_exchange(seeds, timeout)

    bank._connect, bank._first_exchange = connect_then_pause, counted_first_exchange
    try:
        check_first_episode_is_the_schedules_first(env, schedule)
    finally:
        for timer in resumes:
            timer.join()
        env.close()
    assert list(first_resets.values()) == [1] * len(resumes), (first_resets, len(resumes))


def test_a_lost_first_exchange_goes_to_a_fresh_node(tmp_path):
    """A first exchange that does not complete in time (here: a step timeout no reply can meet,
    for the first node only) puts the reset to a fresh node, never a second time to the same one."""
    schedule = tmp_path / "first.yaml"
    schedule.write_text(FIRST_RESET_SCHEDULE)
    env = make_env(schedule)
    bank = env.unwrapped.bank
    first_namespace, fresh_node = bank.namespace, bank._fresh_node

    def restore_then_fresh_node():
        bank.step_timeout = 2.0
        fresh_node()

    bank.step_timeout, bank._fresh_node = 1e-4, restore_then_fresh_node
    try:
        check_first_episode_is_the_schedules_first(env, schedule)
        assert env.unwrapped.namespace != first_namespace
    finally:
        env.close()


def test_a_lost_setup_announcement_goes_to_a_fresh_node(tmp_path):
    """The first node's events/evolution never reaches the env (as when its writer has not matched
    our reader yet as it announces the setup of episode 1): the first exchange is not done, so the
    reset goes to a fresh node, whose announcement arrives, instead of a reset that times out."""
    schedule = tmp_path / "first.yaml"
    schedule.write_text(FIRST_RESET_SCHEDULE)
    env = make_env(schedule)
    bank = env.unwrapped.bank
    first_namespace = bank.namespace
    msg_type, keep = bank._watch["events/evolution"]
    bank._watch["events/evolution"] = (msg_type, lambda m: None if bank.namespace == first_namespace else keep(m))
    try:
        check_first_episode_is_the_schedules_first(env, schedule)
        assert env.unwrapped.namespace != first_namespace
    finally:
        env.close()


# --------------------------------------------------------------------------------------------
# Bags: record an evolving run, replay it exactly


def check_a_tampered_event_is_named(out, tmp_path) -> None:
    """A copy of the bag at ``out`` whose announcement of tick 4 says threshold 0.75 replays with
    that difference named (topic, field, recorded and replayed values)."""
    import dataclasses

    from sorting_line_gym.bag import rewrite_bag
    from sorting_line_gym.bag.storage.schema import typestore
    from sorting_line_gym.bag.transport.replay import replay

    store = typestore()

    def edit(m):
        if m.topic.endswith("/events/evolution") and m.plain["tick"] == 4 and not m.plain["at_reset"]:
            return dataclasses.replace(store.deserialize_cdr(m.data, m.msgtype), threshold=0.75)
        return None

    assert rewrite_bag(out, tmp_path / "tampered", edit) == 1
    tampered = replay(tmp_path / "tampered")
    assert not tampered.identical
    assert (
        tampered.difference.topic,
        tampered.difference.field,
        tampered.difference.recorded,
        tampered.difference.replayed,
    ) == ("events/evolution", "threshold", 0.75, 0.8), tampered.report()


def test_a_recorded_evolving_run_replays_exactly(tmp_path, start_node, client_factory, probe, namespace, ros):
    from sorting_line_gym.bag import open_bag
    from sorting_line_gym.bag.transport.replay import replay
    from support.bag_golden import BagProcess, wait_for_command_writers

    schedule, ns, node, c = evolving_line(tmp_path, start_node, client_factory, namespace("bag"))
    c.wait_connected()
    out = tmp_path / "evolving"
    recorder = BagProcess(["record", "--namespace", ns, "-o", out], tmp_path / "record.log")
    wait_for_command_writers(ros, recorder, ns, "advanced", recorder.describe, writers=1)

    def step(action: int):
        speed, mode = h.decode_action("advanced", action)
        c.send_mode(mode)  # before the upgrade only the recorder reads it: the node has no cmd/sort_mode
        c.send_speed(speed)
        c.wait_state(c.stamp + c.period_ns)
        c.stamp += c.period_ns

    c.reset(SEED)
    for action in EPISODE_1:
        step(action)
    c.reset()
    for tick, action in enumerate(EPISODE_2, start=len(EPISODE_1)):
        if tick == UPGRADE_TICK:  # the node's cmd/sort_mode appears: ours must reach it
            ros.spin_until(lambda: c.mode_pub.get_subscription_count() >= 2, 10, "the node's cmd/sort_mode", c.context)
        step(action)
    ros.spin_for(0.3)
    assert recorder.stop() == 0, recorder.describe()

    bag = open_bag(out)
    assert bag.info.node["evolution"] == SCHEDULE and bag.info.node["evolution_file"] == str(schedule)
    evolution = [m.plain for m in bag.on(f"{ns}/events/evolution")]
    assert [(e["at_reset"], e["episode"], e["tick"], e["event_indices"]) for e in evolution] == [
        (True, 1, 0, []),
        (False, 1, 4, [1]),
        (False, 1, 6, [2]),
        (True, 2, 10, [3]),
        (False, 2, 14, [4]),
    ]
    result = replay(out)
    assert result.identical, result.report()
    assert result.comparison.compared["events/evolution"] == 5
    assert result.comparison.compared["state"] == len(c.since_reset("state")) == 2 + len(EPISODE_1) + len(EPISODE_2)
    assert "sensors/ratio" not in result.comparison.compared and any(
        "schedule stored in the bag" in n for n in result.notes
    )

    # The events are compared: a recorded announcement with another threshold is named.
    check_a_tampered_event_is_named(out, tmp_path)


def test_ros2_topic_list_shows_the_upgraded_hardware(ros2_daemon, tmp_path, start_node, client_factory, namespace, ros):
    """The real `ros2 topic list`: no sensors/ratio and no cmd/sort_mode until the upgrade (here at
    the first reset), both after it."""
    schedule = tmp_path / "upgrade-at-1.yaml"
    schedule.write_text(
        "events:\n  - at: {episode: 0}\n    sort_modes: false\n    ratio_sensor: false\n"
        "  - at: {episode: 1}\n    sort_modes: true\n    ratio_sensor: true\n"
    )
    ns = namespace("cli")
    node = start_node(
        "--setup", "B", "--variant", "advanced", "--evolution", schedule, "--ros-args", "-r", f"__ns:={ns}"
    )
    c = client_factory(ns, "basic", node_proc=node)
    c.wait_connected()
    hardware = {f"{ns}/sensors/ratio", f"{ns}/cmd/sort_mode"}

    def listed(want, what: str, timeout: float = 30.0) -> set[str]:
        last: set[str] = set()

        def topics() -> set[str] | None:
            last.clear()
            last.update(ros2_daemon.run("topic", "list", timeout=30).stdout.split())
            return set(last) if want(last) else None

        return wait_until(
            topics,
            timeout,
            f"`ros2 topic list` to show {what}",
            poll=0.5,
            context=lambda: f"listed under {ns}: {sorted(t for t in last if t.startswith(ns))}",
        )

    before = listed(lambda t: f"{ns}/state" in t and f"{ns}/events/evolution" in t, "the line's state and events")
    assert f"{ns}/state" in before and not hardware & before, sorted(t for t in before if t.startswith(ns))
    c.reset(1)
    after = listed(lambda t: hardware <= t, "the upgraded hardware's topics")
    assert hardware <= after, sorted(t for t in after if t.startswith(ns))
