"""`sorting-line-bag` (record, replay, play) against the real node and real rclpy over DDS, and the
golden bags of tests/data/bags (recorded with the tool itself, see bag_golden.py).

Runs inside the loopback-only network namespace that launch_scripts/test.sh makes:

    unshare -n bash -c 'ip link set lo up; source launch_scripts/env.sh; export ROS_DOMAIN_ID=142;
                        python -m pytest tests/python/test_bags.py -q'

What is checked:
- replaying each golden bag into a fresh node reproduces every recorded message exactly, also
  when the first node's messages of the bag's first reset are lost (a second, fresh node);
- a copy of a golden bag with one field changed at one tick makes replay name that topic, tick
  and field; a changed command makes it name the first tick the node then publishes differently;
- the golden bags' states are the simulation library's trajectory (`sorting_line trace`);
- the golden bags open with rosbags and with the mcap tools, schemas embedded, type hashes those
  rosidl generated;
- `record` on a live line captures resets (seeded or not), commands (a refused one too) and the
  node's options, and that bag replays exactly;
- `play --lockstep` feeds a golden bag's sensor data to the real `sorting-line-controller`, whose
  commands are the recorded ones; `play --rate` keeps the recorded timing (scaled);
- bad input exits with 2 and says why.
"""

from __future__ import annotations

import dataclasses
import shutil
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from sorting_line_gym.bag import open_bag, rewrite_bag
from sorting_line_gym.bag.storage.schema import stamp_ns as plain_stamp
from sorting_line_gym.bag.storage.schema import typestore
from sorting_line_gym.bag.transport.replay import replay
from support import ros_harness as h
from support.bag_golden import DATA, GOLDEN, MAX_STEPS, BagProcess, wait_for_command_writers
from support.ros_harness import NS_PER_S

pytestmark = pytest.mark.usefixtures("same_binary")  # conftest: the tools start the tests' binary


def relative(bag, rel: str) -> list:
    """The decoded messages of the bag's line topic `rel`, in receive order."""
    return [m.plain for m in bag.by_relative_topic().get(rel, [])]


# --------------------------------------------------------------------------------------------
# The golden bags


@pytest.mark.parametrize("name", list(GOLDEN))
def test_golden_bag_replays_exactly(name, tmp_path):
    tool = BagProcess(["replay", DATA / name], tmp_path / "replay.log")
    code = tool.wait(90)
    out = tool.log()
    assert code == 0, out
    assert "identical" in out and "state 255" in out and "events/reset 5" in out, out


def test_a_first_reset_whose_messages_are_lost_is_replayed_on_a_fresh_node(monkeypatch):
    """The first replay node's states never reach the capture (as when a node has not matched that
    reader yet): its first reset is not proven, so the replay starts again on a fresh node instead
    of resetting the first one twice, and reproduces the bag exactly."""
    from sorting_line_gym.bag.transport import replay as replay_module

    captures: list = []
    keeper = replay_module._Capture._keeper

    def lossy_keeper(self, rel: str):
        if self not in captures:
            captures.append(self)
        keep = keeper(self, rel)
        return (lambda _data, _received: None) if rel == "state" and captures[0] is self else keep

    monkeypatch.setattr(replay_module._Capture, "_keeper", lossy_keeper)
    result = replay(DATA / "basic_d")
    assert result.identical, result.report()
    assert len(captures) == 2, f"{len(captures)} replay nodes"
    fresh = [n for n in result.notes if "fresh node" in n]
    assert len(fresh) == 1 and "state 0 of 1" in fresh[0], result.notes
    assert result.resets == 5, result.report()


def _tampered(tmp_path: Path, name: str, topic: str, tick: int, change) -> Path:
    store = typestore()

    def edit(m):
        if m.topic.endswith("/" + topic) and plain_stamp(m.plain) == tick * NS_PER_S:
            return change(store.deserialize_cdr(m.data, m.msgtype))
        return None

    out = tmp_path / f"{name}_tampered"
    assert rewrite_bag(DATA / name, out, edit) == 1, f"no {topic} at tick {tick} in {name}"
    return out


def test_a_changed_field_is_named_by_topic_tick_and_field(tmp_path):
    bag = _tampered(tmp_path, "advanced_b", "state", 130, lambda s: dataclasses.replace(s, reward=s.reward + 0.25))
    result = replay(bag)
    d = result.difference
    assert d is not None, result.report()
    assert (d.topic, d.tick, d.field) == ("state", 130, "reward"), result.report()
    assert d.replayed == pytest.approx(d.recorded - 0.25)
    assert "state at tick 130" in str(d) and "field reward" in str(d), str(d)


def test_a_changed_command_shows_where_the_node_goes_another_way(tmp_path):
    # Tick 60 is answered with speed 0.7 here (episode 2, step 8): the node's next tick differs.
    bag = _tampered(
        tmp_path,
        "basic_d",
        "cmd/speed",
        60,
        lambda c: dataclasses.replace(c, speed=0.7 if abs(c.speed - 0.7) > 1e-9 else 0.3),
    )
    result = replay(bag)
    d = result.difference
    assert d is not None, result.report()
    assert (d.topic, d.tick, d.field) == ("belt/occupancy", 61, "speed"), result.report()


@pytest.mark.parametrize("name", list(GOLDEN))
def test_golden_states_are_the_library_trajectory(name):
    """No ROS: the trace of the bag's resets and applied actions equals the bag's states."""
    spec, bag = GOLDEN[name], open_bag(DATA / name)
    assert bag.info.node["seed"] == spec["seed"] and bag.info.node["max_steps"] == MAX_STEPS
    states = sorted(relative(bag, "state"), key=plain_stamp)
    events = {plain_stamp(e): e for e in relative(bag, "events/reset")}
    tokens = []
    for s in states:
        e = events.get(plain_stamp(s))
        if e is not None:
            tokens.append(f"r{e['seed']}" if e["seeded"] else "r")
        else:
            tokens.append(s["speed_index"] * 3 + s["mode"] if spec["variant"] == "advanced" else s["speed_index"])
    assert [bool(e["seeded"]) for e in events.values()] == [seed is not None for seed in spec["plan"]]
    trace = h.run_trace(spec["setup"], spec["variant"], spec["seed"], tokens, max_steps=MAX_STEPS)[1:]
    assert len(trace) == len(states) == 255
    for k, (s, entry) in enumerate(zip(states, trace, strict=False)):
        view = SimpleNamespace(**s)
        if "reset" in entry:
            assert h.state_reset_view(view) == h.trace_reset_view(entry), f"{name}: tick {k + 1}"
        else:
            assert h.state_step_view(view) == h.trace_step_view(entry), f"{name}: tick {k + 1}"


@pytest.mark.parametrize("name", list(GOLDEN))
def test_golden_bag_opens_with_rosbags_and_mcap(name):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = DATA / name
    # rosbags with an EMPTY typestore: every type must come from the schemas in the bag.
    with AnyReader([path], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert all(c.msgdef.data for c in reader.connections)
        first = {}
        for connection, _, raw in reader.messages():
            first.setdefault(connection.topic, reader.deserialize(raw, connection.msgtype))
    ns = f"/golden_{name}"
    assert types[f"{ns}/state"] == "sorting_line_interfaces/msg/LineState"
    assert types["/clock"] == "rosgraph_msgs/msg/Clock"
    assert first[f"{ns}/events/reset"].seeded == (GOLDEN[name]["plan"][0] is not None)

    mcap_file = next(path.glob("*.mcap"))
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        schemas = {s.name: s.encoding for s in summary.schemas.values()}
        channels = {c.topic: c.message_encoding for c in summary.channels.values()}
        assert set(schemas.values()) == {"ros2msg"} and "sorting_line_interfaces/msg/LineState" in schemas
        assert set(channels) == set(types) and set(channels.values()) == {"cdr"}
        rewards = [decoded.reward for _, channel, _, decoded in reader.iter_decoded_messages(topics=[f"{ns}/state"])]
    assert rewards == [s["reward"] for s in relative(open_bag(path), "state")]

    # The type hashes in metadata.yaml are those rosidl generated for the interfaces rclpy uses
    # (what `ros2 bag play` checks against a ROS install's types).
    import json

    import yaml

    share = Path(sys.prefix) / "share" / "sorting_line_interfaces" / "msg"  # setup.sh installs it into .venv
    topics = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"][
        "topics_with_message_count"
    ]
    for t in topics:
        meta = t["topic_metadata"]
        if meta["type"].startswith("sorting_line_interfaces/"):
            generated = json.loads((share / (meta["type"].rsplit("/", 1)[1] + ".json")).read_text())
            want = next(x["hash_string"] for x in generated["type_hashes"] if x["type_name"] == meta["type"])
            assert meta["type_description_hash"] == want, meta


# --------------------------------------------------------------------------------------------
# Recording a live line


def test_record_a_live_line_and_replay_it(ros, start_node, client_factory, namespace, tmp_path):
    ns = namespace("rec")
    node = start_node(
        *h.SETUP_FLAGS["C"],
        "--variant",
        "advanced",
        "--seed",
        "3",
        "--max-steps",
        "6",
        "--ros-args",
        "-r",
        f"__ns:={ns}",
    )
    c = client_factory(ns, "advanced", node_proc=node)
    c.wait_connected()
    out = tmp_path / "live"
    recorder = BagProcess(["record", "--namespace", ns, "-o", out], tmp_path / "record.log")
    wait_for_command_writers(ros, recorder, ns, "advanced", recorder.describe, writers=1)
    c.reset(7)
    for action in (5, 27, 14):
        c.act(action)
    c.send_speed(0.55)  # refused by the node (not one of the ten speeds), recorded all the same
    c.act(3)
    c.reset()  # the streams carry on
    for action in (29, 0):
        c.act(action)
    c.reset(7)  # the same seed again: a restart, not a continuation
    c.act(11)
    ros.spin_for(0.3)
    assert recorder.stop() == 0, recorder.describe()

    bag = open_bag(out)
    assert bag.info.namespace == ns
    node_options = {k: bag.info.node[k] for k in ("variant", "input", "obs_noise", "max_steps", "seed", "mode")}
    assert node_options == {
        "variant": "advanced",
        "input": "random",
        "obs_noise": 0.3,
        "max_steps": 6,
        "seed": 3,
        "mode": "lockstep",
    }
    events = relative(bag, "events/reset")
    assert [(e["seed"], e["seeded"]) for e in events] == [(7, True), (7, False), (7, True)]
    assert [m["speed"] for m in relative(bag, "cmd/speed")][3] == 0.55
    assert len(relative(bag, "cmd/speed")) == 8 and len(relative(bag, "cmd/sort_mode")) == 7
    assert len(relative(bag, "state")) >= 10 and len(bag.on("/clock")) >= 10
    result = replay(out)
    assert result.identical, result.report()
    assert result.resets == 3 and result.comparison.compared["state"] == len(c.since_reset("state"))


# --------------------------------------------------------------------------------------------
# Playing a bag to a controller


def test_a_command_writer_counts_once_its_node_says_it_matched_every_reader(namespace, monkeypatch):
    """The recorder's count of a controller's command writers (the one test_record_golden's bag
    lost every command to, under load): a writer counts once its node says on /diagnostics that
    it matched every reader seen here, or once it has been silent for CommandMatches.SILENT."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from sorting_line_interfaces.msg import SpeedCommand

    from sorting_line_gym.bag.transport.rosnode import CommandMatches, ToolNode

    monkeypatch.setattr(CommandMatches, "SILENT", 2.0)
    topic = namespace("cmd") + "/cmd/speed"
    recorder, controller, silent = ToolNode("recorder"), ToolNode("controller"), ToolNode("silent")
    try:
        commands = CommandMatches(recorder.node)
        sub = recorder.node.create_subscription(SpeedCommand, topic, lambda _m: None, 10)
        controller.node.create_publisher(SpeedCommand, topic, 10)
        status = controller.node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        recorder.until(lambda: sub.get_publisher_count() == 1, 20.0, f"the recorder to match the writer of {topic}")

        def say(readers: int) -> None:
            name = controller.node.get_fully_qualified_name()
            value = KeyValue(key="cmd_speed_readers", value=str(readers))
            status.publish(DiagnosticArray(status=[DiagnosticStatus(hardware_id=name, values=[value])]))

        def counted_after_saying(readers: int) -> int:
            say(readers)
            controller.spin_for(0.3)
            recorder.spin_for(0.3)
            return commands.matched(topic, sub.get_publisher_count())

        assert counted_after_saying(0) == 0  # it has matched no reader yet: its commands reach nobody here
        assert counted_after_saying(0) == 0
        assert counted_after_saying(1) == 1  # every reader of the topic: ours
        silent.node.create_publisher(SpeedCommand, topic, 10)  # a writer whose node never says
        recorder.until(lambda: sub.get_publisher_count() == 2, 20.0, "the recorder to match the second writer")
        assert commands.matched(topic, 2) == 1
        recorder.until(lambda: commands.matched(topic, 2) == 2, 10.0, "the silent writer to count")
    finally:
        for tool in (silent, controller, recorder):
            tool.close()


def test_controller_answers_played_sensor_data_as_recorded(ros, probe, namespace, tmp_path):
    from support.controller_process import ControllerProcess, line_recorders

    spec, bag = GOLDEN["advanced_b"], open_bag(DATA / "advanced_b")
    ns = namespace("play")
    rec = line_recorders(probe, ns)
    controller = ControllerProcess(
        tmp_path,
        "play",
        ["--namespace", ns, "--setup", spec["setup"], "--variant", spec["variant"], "--agent", spec["agent"]],
    )
    try:
        ros.spin_until(
            lambda: all(rec[t].sub.get_publisher_count() for t in ("cmd/speed", "cmd/sort_mode")),
            20.0,
            "the controller's command writers",
            controller.describe,
        )
        # Tick by tick, each after the controller's answer, as the lock-step node it was recorded
        # with. (Played by time at the recorded pace, ~250 ticks/s, a controller that stalls for
        # a moment on this shared machine loses readings from its keep-last-10 queues and never
        # answers those ticks: seen at --rate 1, 0.2, and once at 0.1 under a load of 8.)
        player = BagProcess(["play", DATA / "advanced_b", "--namespace", ns, "--lockstep"], tmp_path / "play.log")
        want = {t: {plain_stamp(m): m for m in relative(bag, t)} for t in ("cmd/speed", "cmd/sort_mode")}
        ros.spin_until(
            lambda: all(len(rec[t].items) >= len(want[t]) for t in want),
            30.0,
            f"{len(want['cmd/speed'])} commands of each kind from the controller",
            lambda: (
                f"received {[len(rec[t].items) for t in want]}; no decision for the ticks "
                f"{sorted(s // NS_PER_S for s in set(want['cmd/speed']) - set(controller.decisions()))}"
                f"\n{player.describe()}\n{controller.describe()}"
            ),
        )
        assert player.wait(30) == 0, player.describe()
    finally:
        assert controller.stop() == 0, controller.describe()
    got_speed, got_mode = rec["cmd/speed"].by_stamp(), rec["cmd/sort_mode"].by_stamp()
    assert set(got_speed) == set(want["cmd/speed"]) and set(got_mode) == set(want["cmd/sort_mode"])
    for stamp, m in want["cmd/speed"].items():
        assert got_speed[stamp][1].speed == m["speed"], f"cmd/speed for tick {stamp // NS_PER_S}"
    for stamp, m in want["cmd/sort_mode"].items():
        assert got_mode[stamp][1].mode == m["mode"], f"cmd/sort_mode for tick {stamp // NS_PER_S}"
    assert "played 1280 messages" in player.log() and "no answer" not in player.log(), player.log()


def test_play_keeps_the_recorded_timing(ros, probe, namespace, tmp_path):
    """Played by time (4x faster): every message, in order, spread over a quarter of the recording."""
    from sorting_line_interfaces.msg import MaterialInput

    bag = open_bag(DATA / "basic_d")
    ns = namespace("timing")
    inputs = h.TopicRecorder(ros, probe, f"{ns}/input", MaterialInput, qos=1000)
    player = BagProcess(
        ["play", DATA / "basic_d", "--namespace", ns, "--rate", "4", "--topic", "input", "--topic", "/clock"],
        tmp_path / "play.log",
    )
    ros.spin_until(lambda: not player.running(), 30.0, "play to finish", player.describe)
    assert player.wait(5) == 0, player.describe()
    ros.spin_for(0.2)
    recorded = [m["header"]["stamp"]["sec"] for m in relative(bag, "input")]
    assert [m.header.stamp.sec for m in inputs.msgs] == recorded
    span = (
        bag.on(f"{bag.info.namespace}/input")[-1].log_time - bag.on(f"{bag.info.namespace}/input")[0].log_time
    ) / 1e9
    played = float(player.log().split(" s (recorded over")[0].rsplit(" ", 1)[1])
    assert played >= 0.9 * span / 4, player.log()


# --------------------------------------------------------------------------------------------
# Bad input


def test_bad_input_exits_with_2_and_says_why(tmp_path, capsys):
    """The command line's own function (the console script is run by the other tests): each case
    would cost a process start-up (~2.5 s) otherwise."""
    from sorting_line_gym.bag.cli import main

    corrupt = tmp_path / "corrupt"
    shutil.copytree(DATA / "basic_d", corrupt)
    mcap_file = next(corrupt.glob("*.mcap"))
    mcap_file.write_bytes(mcap_file.read_bytes()[:5000])
    (tmp_path / "empty").mkdir()
    cases = [
        (("replay", tmp_path / "missing"), "no such bag"),
        (("replay", tmp_path / "empty"), "no metadata.yaml"),
        (("replay", corrupt), "cannot read the bag"),
        (("play", DATA / "basic_d", "--topic", "sensors/ratio"), "no topic /golden_basic_d/sensors/ratio"),
        (("record", "--namespace", "/x", "-o", tmp_path / "empty"), "exists already"),
        (("info", corrupt), "cannot read the bag"),
    ]
    for args, message in cases:
        code = main([str(a) for a in args])
        err = capsys.readouterr().err
        assert (code, message in err) == (2, True), f"{args}: exit {code}, stderr {err!r}"
