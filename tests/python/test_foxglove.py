"""The node's Foxglove live view (`--foxglove`, docs/foxglove.md) read by Foxglove's own client
libraries, headless (tests/python/support/foxglove_viewer.py runs them under Node.js), and the
recorder's bags read by Foxglove's MCAP reader:

- every channel decodes by the schema the server advertised, to the values an rclpy subscriber
  gets over DDS for the same ticks, from the same CDR bytes; /clock is the server's time;
- a viewer that stops reading does not slow the line (its outbox overflows; the ticks go on), nor
  the other viewers: several at once each get every tick;
- malformed and unsupported client messages are answered and counted, the line unaffected;
- bad `--foxglove` values fail at start naming the value;
- plain, zstd and split bags: every message decoded, counts equal to metadata.yaml.
"""

from __future__ import annotations

import json
import signal
import socket
import statistics
import time

import pytest
import yaml

from sorting_line_gym.bag.format.options import WriteOptions
from sorting_line_gym.bag.storage import schema
from sorting_line_gym.bag.storage.rewrite import rewrite_bag
from support import ros_harness
from support.foxglove_viewer import Viewer, live_view_url, message_bytes, read_bags
from support.ros_harness import TopicRecorder, diagnostic_values, join_ns, run_node_expecting_failure, stamp_ns

#: The topics a line publishes (the harness's, less the commands it subscribes to).
LINE_TYPES = {rel: ros_type for rel, ros_type in ros_harness.LINE_TYPES.items() if not rel.startswith("cmd/")}
LIVE = "sorting_line: foxglove"  # the live view's status on /diagnostics


def live_status(recorder: TopicRecorder, predicate, timeout: float, what: str) -> dict[str, str]:
    """The values of the first /diagnostics live-view status for which `predicate` holds."""

    def values(array):
        for status in array.status:
            if status.name == LIVE:
                return {kv.key: kv.value for kv in status.values}
        return None

    found = recorder.wait_for(lambda a: (v := values(a)) is not None and predicate(v), timeout, what)
    return values(found)


def test_every_channel_decodes_to_what_dds_carries(ros, start_node, namespace, client_factory, probe, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock

    from sorting_line_gym.bag.transport.rosnode import rclpy_class

    ns = namespace("live")
    node = start_node(
        "--variant", "advanced", "--max-steps", "3", "--foxglove", "0", "--ros-args", "-r", f"__ns:={ns}"
    )  # fmt: skip
    viewer = Viewer("record", live_view_url(node), tmp_path / "viewer.log")
    try:
        at_start = [join_ns(ns, t) for t in ("input", "belt/occupancy", "sensors/ratio", "state")] + ["/clock"]
        viewer.wait_for(lambda: all(viewer.of("subscribed", t) for t in at_start), 10.0, f"subscriptions to {at_start}")
        clock = TopicRecorder(ros, probe, "/clock", Clock)
        diagnostics = TopicRecorder(ros, probe, "/diagnostics", DiagnosticArray)
        # The CDR bytes DDS delivers, as they came (a writer's padding bytes are its own, so the
        # messages rclpy decoded, serialised again, need not have the same bytes).
        raw: dict[str, list[bytes]] = {rel: [] for rel in LINE_TYPES}
        subs = [
            probe.create_subscription(rclpy_class(t), join_ns(ns, rel), raw[rel].append, 10, raw=True)
            for rel, t in LINE_TYPES.items()
        ]
        client = client_factory(ns, "advanced", node_proc=node)
        client.wait_connected()
        ros.spin_until(lambda: all(s.get_publisher_count() for s in subs), 10.0, "the raw readers to match")
        client.reset(seed=7)
        for speed, mode in [(0.5, 1), (1.0, 0), (0.2, 2)]:
            state = client.step(speed, mode)
        assert state.truncated, state
        last = stamp_ns(state.header.stamp)
        # Every DDS message of the episode has reached the viewer, and a /diagnostics array
        # counting it as a viewer.
        status = live_status(diagnostics, lambda v: v["viewers"] == "1", 10.0, "the live view with one viewer")
        assert status["address"] == live_view_url(node), status
        state_topic = join_ns(ns, "state")
        viewer.wait_for(
            lambda: any(stamp_ns_of(e) == last for e in viewer.of("message", state_topic)),
            10.0,
            f"{state_topic} stamped {last}",
        )
        viewer.wait_for(lambda: viewer.of("message", "/diagnostics"), 10.0, "a /diagnostics message")
        ros.spin_until(
            lambda: any(time_ns(decode(d, LINE_TYPES["state"])["header"]["stamp"]) == last for d in raw["state"]),
            10.0,
            f"the raw reader of {state_topic}: the tick stamped {last}",
        )
    finally:
        assert viewer.close() == 0, viewer.describe()

    assert not viewer.of("decode_error") and not viewer.of("unreadable"), viewer.describe()
    expected = check_the_advertised_channels(viewer, ns, state)
    check_the_line_topics(viewer, ns, client, raw)
    check_clock_and_the_arrays(viewer, ns, client, clock, diagnostics, expected)


def check_the_advertised_channels(viewer: Viewer, ns: str, state) -> dict[str, str]:
    """Every topic advertised with its schema and encodings (the scene as protobuf, drawn from `state`); returns
    the ros2msg types by topic."""
    advertised = {e["topic"]: e for e in viewer.of("advertise")}
    expected = {join_ns(ns, t): ros_type for t, ros_type in LINE_TYPES.items()} | {
        join_ns(ns, "batch/state"): "sorting_line_interfaces/msg/LineStates",
        "/clock": "rosgraph_msgs/msg/Clock",
        "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    }
    for topic, ros_type in expected.items():
        assert topic in advertised, f"{topic} not advertised: {sorted(advertised)}"
        got = advertised[topic]
        assert (got["schema"], got["encoding"], got["schemaEncoding"]) == (ros_type, "cdr", "ros2msg"), got
    scene_topic = join_ns(ns, "scene")
    got = advertised[scene_topic]
    assert (got["schema"], got["encoding"], got["schemaEncoding"]) == ("foxglove.SceneUpdate", "protobuf", "protobuf")
    check_scene(viewer, scene_topic, state)
    return expected


def check_the_line_topics(viewer: Viewer, ns: str, client, raw: dict[str, list[bytes]]) -> None:
    """Each DDS message of the line's topics is on its channel with the same CDR bytes, decoded to rclpy's values."""
    from rclpy.serialization import serialize_message

    compared = 0
    for rel, ros_type in LINE_TYPES.items():
        topic = join_ns(ns, rel)
        live = viewer.of("message", topic)
        rclpy_values = {
            stamp_ns(m.header.stamp): decode(bytes(serialize_message(m)), ros_type) for m in client.msgs[rel]
        }
        for data in raw[rel]:
            value = decode(data, ros_type)
            stamp = time_ns(value["header"]["stamp"])
            if stamp < client.first_reset:
                continue
            assert rclpy_values.get(stamp) == value, (topic, stamp, rclpy_values.get(stamp), value)
            same = [e for e in live if stamp_ns_of(e) == stamp and cdr_equal(message_bytes(e), data)]
            assert same, (
                f"{topic} stamped {stamp}: not in the live view with the bytes DDS carried: {data.hex()}; "
                f"live: {[message_bytes(e).hex() for e in live if stamp_ns_of(e) == stamp]}"
            )
            assert same[0]["value"] == value, (same[0]["value"], value)
            assert int(same[0]["log_time"]) == stamp, "a message's log time is the tick's simulated time"
            compared += 1
    # The three steps' ticks of four topics at least (the raw readers are matched by the node
    # a little later than the client's, so the reset's own tick may precede them).
    assert compared >= 3 * 4, compared


def check_clock_and_the_arrays(viewer: Viewer, ns: str, client, clock, diagnostics, expected: dict[str, str]) -> None:
    """/clock's values are the server's time; /diagnostics and batch/state decode alike in Foxglove and in the
    bag tools."""
    from rclpy.serialization import serialize_message

    # /clock: the DDS values, and the server's time follows them.
    live_clock = {time_ns(e["value"]["clock"]) for e in viewer.of("message", "/clock")}
    dds_clock = {stamp_ns(m.clock) for m in clock.msgs if stamp_ns(m.clock) >= client.first_reset}
    assert dds_clock and dds_clock <= live_clock, (sorted(dds_clock), sorted(live_clock))
    assert dds_clock <= {int(e["time"]) for e in viewer.of("time")}, "the server's time is /clock's"
    # /diagnostics and batch/state: Foxglove's decoder and the bag tools' agree on every message,
    # and the arrays DDS delivered are among the live view's.
    for topic, ros_type in [
        ("/diagnostics", expected["/diagnostics"]),
        (join_ns(ns, "batch/state"), expected[join_ns(ns, "batch/state")]),
    ]:
        messages = viewer.of("message", topic)
        assert messages, f"no {topic} message in the live view"
        for e in messages:
            assert e["value"] == decode(message_bytes(e), ros_type), topic
    live_arrays = [e["value"] for e in viewer.of("message", "/diagnostics")]
    dds_arrays = [decode(bytes(serialize_message(m)), expected["/diagnostics"]) for m in diagnostics.msgs]
    assert any(a in live_arrays for a in dds_arrays), "no /diagnostics array of DDS is in the live view"
    assert diagnostic_values(diagnostics.msgs[-1], ns) is not None


def decode(data: bytes, ros_type: str):
    """CDR bytes decoded by the bag tools (rosbags), as plain values without the type's constants
    (which rosbags lists beside the fields)."""

    def fields(v):
        if isinstance(v, dict):
            return {k: fields(x) for k, x in v.items() if not k.isupper()}
        if isinstance(v, list):
            return [fields(x) for x in v]
        return v

    return fields(schema.decode(data, ros_type))


def check_scene(viewer: Viewer, topic: str, state) -> None:
    """The scene of the tick of `state` draws the line as that state says it is."""
    stamp = stamp_ns(state.header.stamp)
    scenes = [e["value"] for e in viewer.of("message", topic) if int(e["log_time"]) == stamp]
    assert scenes, f"no {topic} message for the tick stamped {stamp}"
    (entity,) = scenes[0]["entities"]
    assert (entity["id"], entity["frame_id"]) == ("line_0", "sorting_line"), entity["id"]
    assert int(entity["timestamp"]["seconds"]) * 1_000_000_000 + int(entity["timestamp"]["nanos"]) == stamp
    texts = [t["text"] for t in entity["texts"]]
    want = [
        f"step {state.step}",
        f"reward {state.reward:+.2f} (total {state.cumulative_reward:+.2f})",
        f"speed {state.speed:.1f}",
        f"A: {state.container_a} + {state.container_a_false} wrong",
        f"B: {state.container_b} + {state.container_b_false} wrong",
        f"mode {['basic', 'positive (A-rich)', 'negative (B-rich)'][state.mode]}",
    ]
    for w in want:
        assert any(w in t for t in texts), (w, texts)
    # Hopper, belt, machine, two container floors at least; every box has a size and a colour.
    assert len(entity["cubes"]) >= 5 and all(c["size"] and c["color"] for c in entity["cubes"]), entity["cubes"]


def time_ns(t: dict) -> int:
    """A decoded builtin_interfaces/Time, in ns."""
    return int(t["sec"]) * 1_000_000_000 + int(t["nanosec"])


def stamp_ns_of(event) -> int:
    return time_ns(event["value"]["header"]["stamp"])


def cdr_equal(a: bytes, b: bytes) -> bool:
    """The same CDR message: equal, but for the alignment padding a writer may append."""
    n = min(len(a), len(b))
    return a[:n] == b[:n] and not a[n:].strip(b"\0") and not b[n:].strip(b"\0") and abs(len(a) - len(b)) < 4


def test_a_viewer_that_stops_reading_does_not_slow_the_line(ros, start_node, namespace, probe, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray

    ns = namespace("stall")
    rate, lines = 1000, 16
    node = start_node(
        "--mode", "realtime", "--rate", rate, "--lines", lines, "--max-steps", 1_000_000, "--foxglove", "0",
        "--ros-args", "-r", f"__ns:={ns}",
    )  # fmt: skip
    diagnostics = TopicRecorder(ros, probe, "/diagnostics", DiagnosticArray)
    line0 = join_ns(ns, "line_0")

    def tick_rates(after: float, count: int, what: str) -> list[float]:
        """Line 0's tick rate in the first `count` /diagnostics reports received after `after`."""
        got: list[float] = []

        def enough():
            got[:] = [float(diagnostic_values(a, line0)["tick_rate"]) for t, a in stamped if t > after]
            return len(got) >= count

        ros.spin_until(enough, count + 10.0, what, lambda: node.describe())
        return got[:count]

    stamped: list[tuple[float, object]] = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", lambda a: stamped.append((time.monotonic(), a)), 10)
    alone = tick_rates(time.monotonic() + 1.0, 3, "3 reports of the line's tick rate without a viewer")
    viewer = Viewer("stall", live_view_url(node), tmp_path / "viewer.log")
    try:
        viewer.wait_for(lambda: viewer.of("stalled"), 10.0, "the viewer subscribed and stopped reading")
        # The viewer's outbox overflows: its socket and the server's queue for it are full.
        live_status(
            diagnostics,
            lambda v: int(v["viewer_outbox_full_reports"]) >= 1,
            30.0,
            "the stalled viewer's outbox to overflow",
        )
        stalled = tick_rates(time.monotonic(), 3, "3 reports of the line's tick rate with the stalled viewer")
        status = next({kv.key: kv.value for kv in st.values} for st in stamped[-1][1].status if st.name == LIVE)
        assert status["viewers"] == "1", status  # still connected, never read from
        # Nor does it hold the node when it leaves: SIGINT, exit 0 within 5 s (node.stop's limit).
        assert node.running(), node.describe()
        assert node.stop(signal.SIGINT, timeout=5.0) == 0, node.describe()
    finally:
        viewer.close()
    # A tick waiting for the viewer would stop the line (lock-step) or drop its rate to what the
    # viewer reads (nothing); the margin is for a machine busy with other work.
    print(f"tick rates: alone {alone}, with the stalled viewer {stalled}; live view {status}")
    assert statistics.median(stalled) >= 0.5 * statistics.median(alone), (alone, stalled)


def test_several_viewers_at_once_each_get_every_tick(ros, start_node, namespace, client_factory, probe, tmp_path):
    """Three viewers at once, one of which subscribes and never reads: the other two each get every tick of
    the episode, with the same bytes, and /diagnostics counts three viewers."""
    from diagnostic_msgs.msg import DiagnosticArray

    ns = namespace("viewers")
    node = start_node("--max-steps", "4", "--foxglove", "0", "--ros-args", "-r", f"__ns:={ns}")
    url, state_topic = live_view_url(node), join_ns(ns, "state")
    stalled = Viewer("stall", url, tmp_path / "stalled.log")
    readers = [Viewer("record", url, tmp_path / f"viewer{k}.log") for k in range(2)]
    try:
        stalled.wait_for(lambda: stalled.of("stalled"), 10.0, "the third viewer subscribed and stopped reading")
        for viewer in readers:
            viewer.wait_for(lambda v=viewer: v.of("subscribed", state_topic), 10.0, f"a subscription to {state_topic}")
        diagnostics = TopicRecorder(ros, probe, "/diagnostics", DiagnosticArray)
        live_status(diagnostics, lambda v: v["viewers"] == "3", 10.0, "the live view with three viewers")
        client = client_factory(ns, "basic", node_proc=node)
        client.wait_connected()
        client.reset(seed=3)
        stamps = [stamp_ns(client.step(speed).header.stamp) for speed in (0.3, 0.6, 0.9, 0.5)]
        got = []
        for viewer in readers:
            viewer.wait_for(
                lambda v=viewer: {stamp_ns_of(e) for e in v.of("message", state_topic)} >= set(stamps),
                10.0,
                f"{state_topic} of each of the episode's 4 steps",
            )
            got.append({stamp_ns_of(e): message_bytes(e) for e in viewer.of("message", state_topic)})
        assert all(got[0][t] == got[1][t] for t in stamps), "two viewers got different bytes for one tick"
        assert stalled.proc.poll() is None and node.running(), node.describe()
    finally:
        codes = [viewer.close() for viewer in readers]
        stalled.close()
    assert codes == [0, 0], [viewer.describe() for viewer in readers]


def test_garbage_from_a_viewer_is_answered_and_counted(ros, start_node, namespace, client_factory, probe, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray

    ns = namespace("garbage")
    node = start_node("--foxglove", "0", "--ros-args", "-r", f"__ns:={ns}")
    diagnostics = TopicRecorder(ros, probe, "/diagnostics", DiagnosticArray)
    viewer = Viewer("garbage", live_view_url(node), tmp_path / "viewer.log")
    try:
        sent = viewer.wait_for(lambda: viewer.of("sent"), 10.0, "the garbage sent")[0]["count"]
        viewer.wait_for(lambda: len(viewer.of("status")) >= 200, 10.0, "error statuses for the flood")
        status = live_status(
            diagnostics, lambda v: int(v["client_messages_refused"]) >= 200, 10.0, "the refusals counted"
        )
        assert int(status["client_messages_refused"]) <= sent, status
        assert all(s["level"] >= 1 for s in viewer.of("status")), viewer.of("status")[:5]
        # The line is unaffected: it still steps.
        client = client_factory(ns, "basic", node_proc=node)
        client.wait_connected()
        client.reset(seed=1)
        assert client.step(0.5).step == 1
    finally:
        assert viewer.close() == 0, viewer.describe()
    assert node.running(), node.describe()


def test_a_reset_through_the_service_capability_restarts_the_episode(start_node, namespace, tmp_path):
    ns = namespace("reset")
    node = start_node("--variant", "advanced", "--foxglove", "0", "--ros-args", "-r", f"__ns:={ns}")
    service, state_topic = join_ns(ns, "reset"), join_ns(ns, "state")
    viewer = Viewer("reset", live_view_url(node), tmp_path / "viewer.log", service, 11)
    try:
        ok = viewer.wait_for(lambda: [e for e in viewer.of("service_response") if e["callId"] == 1], 10.0, "the reply")
        failed = viewer.wait_for(lambda: viewer.of("service_failure"), 10.0, "the malformed call's failure")
        reply = ok[0]["value"]
        assert (reply["success"], reply["seed"], reply["episode"]) == (True, 11, 1), reply
        # The new episode's first tick, on the line's state channel: the stamp the reply named.
        viewer.wait_for(
            lambda: any(
                e["value"]["episode"] == 1 and e["value"]["seed"] == 11 and e["value"]["step"] == 0
                and e["value"]["header"]["stamp"] == reply["stamp"]
                for e in viewer.of("message", state_topic)
            ),
            10.0,
            f"{state_topic}: episode 1's first tick",
        )  # fmt: skip
    finally:
        assert viewer.close() == 0, viewer.describe()
    assert [e["callId"] for e in failed] == [2] and "ResetLine" in failed[0]["message"], failed
    assert node.running(), node.describe()


def test_the_parameters_are_readable_and_fixed(start_node, namespace, tmp_path):
    ns = namespace("params")
    node = start_node("--setup", "B", "--seed", "9", "--foxglove", "0", "--ros-args", "-r", f"__ns:={ns}")
    url = live_view_url(node)
    viewer = Viewer("params", url, tmp_path / "viewer.log")
    try:
        answers = viewer.wait_for(
            lambda: len(viewer.of("parameters")) >= 2 and viewer.of("parameters"), 10.0, "both parameter answers"
        )
    finally:
        assert viewer.close() == 0, viewer.describe()
    by_id = {a["id"]: {p["name"]: p.get("value") for p in a["parameters"]} for a in answers}
    got = by_id["all"]
    assert {k: got[k] for k in ("setup", "input", "obs_noise", "action_penalty", "seed", "foxglove")} == {
        "setup": "B",
        "input": "seasonal",
        "obs_noise": 0.0,
        "action_penalty": 0.5,
        "seed": 9,
        "foxglove": url.removeprefix("ws://").replace(url.rsplit(":", 1)[1], "0"),
    }, got
    assert by_id["set-seed"] == {}, "a set request applies nothing: the parameters are fixed for the run"


def test_bad_foxglove_values_fail_at_start_naming_them():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        for value, words in [
            (str(port), [f"foxglove = 127.0.0.1:{port}", "cannot listen there"]),
            ("65536", ["foxglove = 65536", "is not valid", "PORT 0 ..= 65535"]),
            ("192.0.2.1:8765", ["foxglove = 192.0.2.1:8765", "cannot listen there"]),
            ("somehost:80", ["foxglove = somehost:80", "is not valid"]),
        ]:
            code, err = run_node_expecting_failure(["--foxglove", value])
            assert code != 0 and all(w in err for w in words), (value, code, err)


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """The golden bags (plain), and copies written zstd-compressed and split, as the recorder writes them."""
    from support.bag_golden import DATA

    out = tmp_path_factory.mktemp("foxglove_bags")
    plain = [DATA / name for name in ("basic_d", "advanced_b", "ppo_advanced_b")]
    zstd, split = out / "basic_d_zstd", out / "advanced_b_split"
    rewrite_bag(DATA / "basic_d", zstd, options=WriteOptions(compression="zstd"))
    rewrite_bag(DATA / "advanced_b", split, options=WriteOptions(max_bag_size=48 * 1024))
    return [*plain, zstd, split]


def test_bags_are_read_by_foxglove_readers(bags):
    report = read_bags(bags)
    for bag in bags:
        got = report[str(bag)]
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        want = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
        assert not got["errors"], (bag.name, got["errors"][:5])
        assert got["counts"] == want, (bag.name, got["counts"], want)
        assert got["files"] == len(meta["relative_file_paths"]), (bag.name, got["files"])
    assert report[str(bags[-1])]["files"] >= 3, "the split bag has several files"


def test_the_layout_shows_what_the_node_serves():
    """launch_scripts/sorting_line.foxglove.json: every panel of the tree is configured, and every
    message path names a topic the node serves (default namespace) and a field of its type."""
    from support.ros_harness import ROOT

    layout = json.loads((ROOT / "launch_scripts" / "sorting_line.foxglove.json").read_text())

    def panels(node):
        return [node] if isinstance(node, str) else panels(node["first"]) + panels(node["second"])

    assert sorted(panels(layout["layout"])) == sorted(layout["configById"]), "panels without config or unused configs"
    types = {"/state": "LineState", "/input": "MaterialInput", "/belt/occupancy": "BeltOccupancy"}
    fields = {
        topic: {line.split()[1] for line in (ROOT / "msg" / "msg" / f"{t}.msg").read_text().splitlines()
                if line.split() and not line.startswith("#") and "=" not in line}
        for topic, t in types.items()
    }  # fmt: skip
    paths = [p["value"] for c in layout["configById"].values() for p in c.get("paths", [])]
    assert len(paths) >= 9, paths
    for path in paths:
        topic, _, field = path.rpartition(".")
        assert topic in fields and field in fields[topic], f"{path}: no such topic or field"
    config = layout["configById"]
    assert config["3D!scene"]["topics"] == {"/scene": {"visible": True}}
    assert config["3D!scene"]["followTf"] == "sorting_line"  # the scene's frame (src/ros/node/scene.rs)
    assert config["DiagnosticSummary!diagnostics"]["topicToRender"] == "/diagnostics"
    assert {p["value"] for p in config["StateTransitions!mode"]["paths"]} >= {"/state.mode"}


def test_an_env_asks_its_node_for_the_live_view(make_env, tmp_path):
    """`foxglove=PORT`: the node the env spawns serves the live view there; a viewer sees the
    env's steps. Only a spawned node (ROS backend) can: the other ways say why."""
    import gymnasium

    with socket.socket() as probe_port:  # a port free now (the test's network namespace is its own)
        probe_port.bind(("127.0.0.1", 0))
        port = probe_port.getsockname()[1]
    env = make_env(None, setup="B", foxglove=port)
    env.reset(seed=3)
    state_topic = join_ns(env.bank.namespace, "state")
    viewer = Viewer("record", f"ws://127.0.0.1:{port}", tmp_path / "viewer.log")
    try:
        viewer.wait_for(lambda: viewer.of("subscribed", state_topic), 10.0, f"a subscription to {state_topic}")
        env.step(4)
        env.step(7)
        viewer.wait_for(
            lambda: any(e["value"]["step"] == 2 for e in viewer.of("message", state_topic)), 10.0, "step 2's state"
        )
    finally:
        assert viewer.close() == 0, viewer.describe()
    for kwargs, words in [
        ({"node": "attach", "namespace": "/x"}, "node='spawn'"),
        ({"backend": "native"}, "backend='ros'"),
        ({"foxglove": True}, "allowed a port"),
    ]:
        with pytest.raises(ValueError, match=words):
            gymnasium.make("sorting_line_gym:SortingLine-v0", **{"foxglove": 8765, **kwargs})
