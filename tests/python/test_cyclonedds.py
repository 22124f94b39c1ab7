"""A second DDS vendor, without ROS: Eclipse Cyclone DDS (the `cyclonedds` Python package) drives a
lock-step line through the ROS 2 wire conventions alone, and the trajectory is the library's.

The ROS 2 mapping onto DDS that this relies on (what rmw_fastrtps and rmw_cyclonedds do):
- topic `<ns>/state` is DDS topic `rt/<ns>/state`; a service `<ns>/reset` is the request topic
  `rq/<ns>/resetRequest` and the reply topic `rr/<ns>/resetReply`;
- message `pkg/msg/Type` is DDS type `pkg::msg::dds_::Type_` (services: `pkg::srv::dds_::Type_Request_`
  and `..._Response_`), a final struct with the fields in .msg order, nested types by value;
- the default ROS QoS: reliable, volatile, keep-last 10; plain (XCDR1) CDR, little endian.

Cyclone is confined to loopback on the test's domain (CYCLONEDDS_URI: interface lo, no multicast,
unicast discovery to 127.0.0.1), inside the test network namespace like every other test.

The reset service interoperates: the node (ros2-client's Enhanced service mapping, made for Fast
DDS, which carries the request id in the RTPS inline QoS) answers a request Cyclone writes without
one, on the reply topic, where Cyclone's plain reader takes it. (No `from __future__ import
annotations` here: cyclonedds resolves the field annotations at run time.)
"""

import os
import random
from dataclasses import dataclass

import pytest

from support import ros_harness as h
from support.ros_harness import NS_PER_S
from support.waits import wait_until

cyclonedds = pytest.importorskip("cyclonedds", reason="cyclonedds (launch_scripts/requirements-bridge.txt) missing")

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct, make_idl_struct  # noqa: E402
from cyclonedds.idl import types as t  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402
from rosbags.typesys import get_types_from_msg  # noqa: E402
from rosbags.typesys.base import Nodetype  # noqa: E402

from sorting_line_gym.workarounds.late_matching import HANDSHAKE_TIMEOUTS, retried_handshake  # noqa: E402

# Loopback only; participant indices let the node's unicast discovery (ports of indices 0..) reach us.
CYCLONE_CONFIG = """<CycloneDDS><Domain Id="any">
  <General><Interfaces><NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast></General>
  <Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>
    <Peers><Peer address="127.0.0.1"/></Peers></Discovery>
</Domain></CycloneDDS>"""


# ---- The ROS types as DDS sees them: ours built from the repository's .msg/.srv files (fields in
# file order), so the node is checked against the definitions; the standard ones they nest written out.


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


#: The field types our definitions use (a base type, or a nested message by name), as Cyclone's.
IDL_TYPES = {
    "bool": bool,
    "string": str,
    "uint8": t.uint8,
    "uint32": t.uint32,
    "uint64": t.uint64,
    "float64": t.float64,
    "std_msgs/msg/Header": Header,
    "builtin_interfaces/msg/Time": Time,
}


def idl_struct(ros_type: str, definition: str) -> type[IdlStruct]:
    """The DDS type of ``pkg/kind/Name`` (``pkg::kind::dds_::Name_``) with the fields of ``definition``
    (a .msg file's text or one half of a .srv's), in order; constants and comments are no fields."""
    ((_constants, fields),) = get_types_from_msg(definition, ros_type).values()
    types = {field: IDL_TYPES[spec[0] if node is Nodetype.BASE else spec] for field, (node, spec) in fields}
    package, kind, name = ros_type.split("/")
    return make_idl_struct(name, f"{package}::{kind}::dds_::{name}_", types)


def message(name: str) -> type[IdlStruct]:
    return idl_struct(f"sorting_line_interfaces/msg/{name}", (h.ROOT / "msg" / "msg" / f"{name}.msg").read_text())


def service(name: str) -> tuple[type[IdlStruct], type[IdlStruct]]:
    """The request and the response type of a service."""
    request, response = (h.ROOT / "msg" / "srv" / f"{name}.srv").read_text().split("\n---\n")
    ros_type = f"sorting_line_interfaces/srv/{name}"
    return idl_struct(f"{ros_type}_Request", request), idl_struct(f"{ros_type}_Response", response)


LineState = message("LineState")
SpeedCommand = message("SpeedCommand")
SortModeCommand = message("SortModeCommand")
ResetLineRequest, ResetLineResponse = service("ResetLine")


ROS_QOS = Qos(
    Policy.Reliability.Reliable(duration(seconds=1)),
    Policy.Durability.Volatile,
    Policy.History.KeepLast(10),
    Policy.DataRepresentation(use_cdrv0_representation=True),
)


class CycloneLine:
    """One line of the node, through Cyclone DDS only."""

    def __init__(self, domain: int, ns: str):
        self.dp = DomainParticipant(domain)
        self.ns = ns

        def topic(prefix, rel, kind):
            return Topic(self.dp, f"{prefix}{ns}/{rel}", kind, qos=ROS_QOS)

        self.state = DataReader(self.dp, topic("rt", "state", LineState), qos=ROS_QOS)
        self.speed = DataWriter(self.dp, topic("rt", "cmd/speed", SpeedCommand), qos=ROS_QOS)
        self.mode = DataWriter(self.dp, topic("rt", "cmd/sort_mode", SortModeCommand), qos=ROS_QOS)
        self.request = DataWriter(self.dp, topic("rq", "resetRequest", ResetLineRequest), qos=ROS_QOS)
        self.reply = DataReader(self.dp, topic("rr", "resetReply", ResetLineResponse), qos=ROS_QOS)
        self.states: dict[int, LineState] = {}

    def matched(self) -> dict[str, int]:
        return {
            "state": len(self.state.get_matched_publications()),
            "cmd/speed": len(self.speed.get_matched_subscriptions()),
            "cmd/sort_mode": len(self.mode.get_matched_subscriptions()),
            "resetRequest": len(self.request.get_matched_subscriptions()),
            "resetReply": len(self.reply.get_matched_publications()),
        }

    def wait(self, condition, timeout: float, what: str, context=lambda: ""):
        def collected():
            self.collect()
            return condition()

        def seen() -> str:
            states = [(s.episode, s.step) for s in self.states.values()]
            return f"matched {self.matched()}; states seen (episode, step): {states}\n{context()}"

        return wait_until(collected, timeout, f"cyclone: {what}", poll=0.002, context=seen)

    def collect(self) -> None:
        for s in self.state.take(N=100):
            self.states[h.stamp_ns(s.header.stamp)] = s

    def send(self, stamp: int, speed: float, mode: int) -> None:
        header = Header(stamp=Time(sec=stamp // NS_PER_S, nanosec=stamp % NS_PER_S), frame_id="")
        self.mode.write(SortModeCommand(header=header, mode=mode))
        self.speed.write(SpeedCommand(header=header, speed=speed))

    def close(self) -> None:
        self.dp = None  # the participant and its entities go with the last reference


class StepZeroStateLost(AssertionError):
    """The reset was answered, its step-0 state did not come: the one loss a handshake repeats."""


@pytest.fixture
def cyclone_env(monkeypatch):
    monkeypatch.setenv("CYCLONEDDS_URI", CYCLONE_CONFIG)


def test_cyclone_participant_drives_a_lockstep_episode_like_the_library(cyclone_env, start_node, namespace):
    setup, variant, seed, episode_seed = "D", "advanced", 3, 2024
    ns = namespace("cyclone")
    node = start_node(
        "--variant", variant, *h.SETUP_FLAGS[setup], "--seed", str(seed), "--ros-args", "-r", f"__ns:={ns}"
    )
    line = CycloneLine(int(os.environ["ROS_DOMAIN_ID"]), ns)
    context = node.describe
    line.wait(lambda: all(v >= 1 for v in line.matched().values()), 15.0, "every endpoint to match", context)

    # The episode starts from a reset through the node's service, called over Cyclone: every reply
    # must come (the node waits for our reply reader before it answers). The reset's step-0 state is
    # a topic's: published before the node matched our state reader, it is lost, and the seeded
    # reset (the same episode again, the episode counter one further) is repeated for it, as the
    # bridge's handshake does.
    resets = 0

    def handshake(state_timeout: float):
        nonlocal resets
        line.request.write(ResetLineRequest(has_seed=True, seed=episode_seed))
        replies = []
        line.wait(lambda: replies.extend(line.reply.take(N=10)) or replies, 10.0, "the reset reply", context)
        (reply,) = replies  # one request, one reply
        resets += 1
        assert reply.success and reply.seed == episode_seed, reply
        stamp = h.stamp_ns(reply.stamp)
        try:
            state = line.wait(lambda: line.states.get(stamp), state_timeout, "the state of the reset's tick", context)
        except AssertionError as lost:
            raise StepZeroStateLost(str(lost)) from None
        return stamp, state

    stamp, first = retried_handshake(handshake, HANDSHAKE_TIMEOUTS, StepZeroStateLost)

    # The library's trajectory: the node's start (trace line 0), the seeded resets, then the actions.
    rng = random.Random(episode_seed)
    actions = [rng.randrange(30) for _ in range(50)]
    trace = h.run_trace(setup, variant, seed, [f"r{episode_seed}"] * resets + actions)
    assert h.state_reset_view(first) == h.trace_reset_view(trace[resets]) and first.step == 0, first
    for k, action in enumerate(actions):
        speed, mode = h.decode_action(variant, action)
        line.send(stamp, speed, mode)  # answers the tick stamped `stamp`
        stamp += NS_PER_S  # tick_period 1 s
        state = line.wait(lambda: line.states.get(stamp), 5.0, f"the state of step {k + 1}", context)
        assert h.state_step_view(state) == h.trace_step_view(trace[resets + k + 1]), f"step {k + 1}"
    assert state.truncated and state.step == 50, state
    line.close()
