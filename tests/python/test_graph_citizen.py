"""The node as a Jazzy graph sees it, checked with rclpy's graph API (the data `ros2 topic info
-v`, `ros2 param describe` and the ros2 daemon use):

- every endpoint announces the RIHS01 hash rosidl computed for its type, the same an rclpy
  endpoint of that type announces, and src/ros/type_hash_table.rs equals rosidl's output;
- /clock carries one type, rosgraph_msgs/msg/Clock, and the node does not subscribe it;
- DescribeParameters gives descriptions, read-only and the enforced ranges; sets stay refused;
- a peer that was running stops listing the node and its endpoints soon after SIGINT/SIGTERM
  (not after the DDS lease); the measured time is printed.
"""

import signal
import time

import pytest

from support import ros_harness as h
from support import type_hashes


def test_type_hash_table_is_rosidls():
    """Fails when a .msg/.srv (or a dependency) changed and the table was not regenerated with
    `.venv/bin/python tests/python/support/type_hashes.py --write`."""
    assert type_hashes.checked_in() == type_hashes.expected()


def ros_type(dds_or_ros: str) -> str:
    """`pkg::srv::dds_::X_Request_` -> `pkg/srv/X_Request`; ROS names unchanged."""
    if "::" not in dds_or_ros:
        return dds_or_ros
    pkg, kind, _, name = dds_or_ros.split("::")
    return f"{pkg}/{kind}/{name.rstrip('_')}"


def endpoints_of(probe, node_name: str, namespace: str):
    """(topic, kind, type, hash) of every endpoint of the node, service topics included."""
    found = []
    for topic, _ in probe.get_topic_names_and_types(no_demangle=True):
        for kind, getter in (
            ("pub", probe.get_publishers_info_by_topic),
            ("sub", probe.get_subscriptions_info_by_topic),
        ):
            for info in getter(topic, no_mangle=True):
                if (info.node_name, info.node_namespace) == (node_name, namespace):
                    found.append((topic, kind, ros_type(info.topic_type), str(info.topic_type_hash)))
    return found


def test_endpoints_announce_rosidls_hashes_and_clock_has_one_type(ros, start_node, namespace):
    from sorting_line_interfaces.msg import LineState
    from sorting_line_interfaces.srv import ResetLine

    ns = namespace("hash")
    node = start_node("--variant", "advanced", "--ros-args", "-r", f"__ns:={ns}")
    probe = ros.make_node("hash_probe")
    try:
        ours_pub = probe.create_publisher(LineState, f"{ns}_probe/state", 10)
        ours_srv = probe.create_service(ResetLine, f"{ns}_probe/reset", lambda req, resp: resp)
        expected = type_hashes.expected()
        # Every endpoint the node makes: the advanced line's 5 publishers and 2 subscriptions,
        # batch/cmd and batch/state, /clock, /diagnostics, /rosout, /parameter_events, and a
        # request and a reply endpoint for reset, batch/reset, the six parameter services and the
        # five simulation_interfaces services.
        want = 5 + 2 + 2 + 4 + 2 * (8 + 5)

        def all_there():
            eps = endpoints_of(probe, "sorting_line", ns)
            return eps if len(eps) >= want else None

        eps = ros.spin_until(all_there, 15.0, f"the node's {want} endpoints", node.describe)
        wrong = [(t, k, ty, got, expected.get(ty)) for t, k, ty, got in eps if got != expected.get(ty)]
        assert not wrong, "\n".join(map(str, wrong))

        # The same hash as an rclpy endpoint of the same type (a topic and a service).
        rclpy_state = ros.spin_until(lambda: probe.get_publishers_info_by_topic(f"{ns}_probe/state"), 5.0, "rclpy pub")
        node_state = probe.get_publishers_info_by_topic(f"{ns}/state")
        print(f"\n{ns}/state: node {node_state[0].topic_type_hash}, rclpy {rclpy_state[0].topic_type_hash}")
        assert str(node_state[0].topic_type_hash) == str(rclpy_state[0].topic_type_hash)
        for suffix, getter in (
            ("resetRequest", probe.get_subscriptions_info_by_topic),
            ("resetReply", probe.get_publishers_info_by_topic),
        ):
            prefix = "rq" if suffix.endswith("Request") else "rr"
            mine = ros.spin_until(lambda: getter(f"{prefix}{ns}_probe/{suffix}", no_mangle=True), 5.0, "rclpy service")
            theirs = getter(f"{prefix}{ns}/{suffix}", no_mangle=True)
            print(f"{prefix}{ns}/{suffix}: node {theirs[0].topic_type_hash}, rclpy {mine[0].topic_type_hash}")
            assert str(theirs[0].topic_type_hash) == str(mine[0].topic_type_hash)

        # /clock: one type in the whole graph, published by the node, subscribed by no one of ours.
        types = dict(probe.get_topic_names_and_types())["/clock"]
        assert types == ["rosgraph_msgs/msg/Clock"], types
        assert not [i for i in probe.get_subscriptions_info_by_topic("/clock") if i.node_name == "sorting_line"]
        del ours_pub, ours_srv
    finally:
        ros.destroy_node(probe)


def test_parameters_are_described_read_only_with_ranges(ros, start_node, namespace):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import DescribeParameters, SetParameters

    ns = namespace("describe")
    node = start_node("--ros-args", "-r", f"__ns:={ns}")
    probe = ros.make_node("describe_probe")
    try:
        describe = probe.create_client(DescribeParameters, f"{ns}/sorting_line/describe_parameters")
        names = ["rate", "threshold", "max_steps", "lines", "variant", "seed"]
        reply = ros.call_service(
            describe, DescribeParameters.Request(names=names), "describe_parameters", context=node.describe
        )
        d = {x.name: x for x in reply.descriptors}
        for name in names:
            assert d[name].read_only and d[name].description, d[name]
            assert "missing" not in d[name].description

        def fp(n):
            return (d[n].floating_point_range[0].from_value, d[n].floating_point_range[0].to_value)

        def ir(n):
            return (d[n].integer_range[0].from_value, d[n].integer_range[0].to_value)

        assert fp("rate") == (0.0, 100000.0) and "0.0 <.." in d["rate"].additional_constraints
        assert fp("threshold") == (0.0, 1.0) and "..< 1.0" in d["threshold"].additional_constraints
        assert ir("max_steps") == (1, 1_000_000) and ir("lines") == (1, 64) and ir("seed") == (0, 2**63 - 1)
        assert (
            d["variant"].type == ParameterType.PARAMETER_STRING
            and "basic or advanced" in d["variant"].additional_constraints
        )
        print("\n" + str(d["threshold"]))

        setter = probe.create_client(SetParameters, f"{ns}/sorting_line/set_parameters")
        request = SetParameters.Request(
            parameters=[
                Parameter(name="rate", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=5.0))
            ]
        )
        result = ros.call_service(setter, request, "set_parameters", context=node.describe).results[0]
        assert not result.successful and "fixed for the run" in result.reason, result
    finally:
        ros.destroy_node(probe)


def leave_after(ros, start_node, namespace, sig, listed_in) -> float:
    """Starts a node, waits until `listed_in(probe, ns)`, stops it with `sig` and returns how
    long the peer kept listing it (WaitTimeout after 5 s)."""
    ns = namespace("leave")
    node = start_node("--ros-args", "-r", f"__ns:={ns}")
    probe = ros.make_node("leave_probe")
    try:

        def listed():
            return listed_in(probe, ns)

        ros.spin_until(listed, 15.0, f"{ns} in the peer's graph", node.describe)
        ros.spin_for(0.5)
        t0 = time.monotonic()
        assert node.stop(sig, timeout=5.0) == 0, node.describe()
        ros.spin_until(
            lambda: not listed(), 5.0, f"{ns} to leave the peer's graph after {sig.name}", node.describe, step=0.01
        )
        return time.monotonic() - t0
    finally:
        ros.destroy_node(probe)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_running_peer_stops_listing_the_node_and_its_endpoints(ros, start_node, namespace, sig):
    """The goal is 2 s (without the disposes a peer kept them for the DDS lease, 50 s);
    the check allows 5 s for a loaded machine and prints the measured time."""
    took = leave_after(
        ros,
        start_node,
        namespace,
        sig,
        lambda probe, ns: (
            ("sorting_line", ns) in probe.get_node_names_and_namespaces()
            or probe.get_publishers_info_by_topic(f"{ns}/state")
            or probe.get_subscriptions_info_by_topic(f"{ns}/cmd/speed")
        ),
    )
    print(f"\n{sig.name}: the peer stopped listing the node and its endpoints after {took:.3f} s")


@pytest.mark.parametrize(
    "env,expected",
    [
        (
            {"ROS_AUTOMATIC_DISCOVERY_RANGE": "localhost"},
            "ROS_AUTOMATIC_DISCOVERY_RANGE = localhost is not valid: allowed SUBNET, LOCALHOST, OFF, SYSTEM_DEFAULT",
        ),
        ({"ROS_STATIC_PEERS": "::1"}, "ROS_STATIC_PEERS: peer '::1' is IPv6"),
    ],
    ids=["range", "peer"],
)
def test_bad_discovery_variables_fail_at_start(env, expected):
    code, stderr = h.run_node_expecting_failure([], env=env)
    assert code == 2 and expected in stderr, f"exit {code}:\n{stderr}"


@pytest.mark.parametrize(
    "range_,visible", [("SUBNET", True), ("LOCALHOST", True), ("SYSTEM_DEFAULT", True), ("OFF", False)]
)
def test_the_node_follows_the_discovery_range(ros, start_node, namespace, range_, visible):
    """Same host, the peer (rclpy) under LOCALHOST: every range but OFF finds it (the multi-host
    cases need a second network namespace: the veth test)."""
    ns = namespace(range_.lower())
    node = start_node("--ros-args", "-r", f"__ns:={ns}", env={"ROS_AUTOMATIC_DISCOVERY_RANGE": range_})
    probe = ros.make_node("range_probe")
    try:

        def seen():
            return probe.get_publishers_info_by_topic(f"{ns}/state")

        if visible:
            ros.spin_until(seen, 10.0, f"{ns}/state under {range_}", node.describe)
        else:
            ros.spin_for(3.0)
            assert not seen(), f"found under {range_}\n{node.describe()}"
        # The node logs its start line after its endpoints exist, so a peer may see it first: wait for the line.
        line = f"discovery range {range_}"
        ros.spin_until(lambda: line in node.log(), 10.0, f"the node's start line naming {line!r}", node.describe)
    finally:
        ros.destroy_node(probe)
