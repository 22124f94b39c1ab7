"""One line's endpoints on the bridge's rclpy node (:class:`LineLink`), all lines of a node through
its batch topics (:class:`BatchLink`), and the lock-step position of each.

Rules kept here (docs/ros-without-a-ros-install.md explains why):
- QoS is explicit (reliable, volatile, keep-last 10, as the node);
- the first exchange is a handshake: a reset whose step-0 ``state`` must arrive, which proves
  that commands and states flow before the first step (volatile samples sent before matching
  are lost, and graph counts can lie for a while after a node dies)."""

from __future__ import annotations

from array import array
from collections import deque
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sorting_line_interfaces.msg import LineCommands, LineState, LineStates, SortModeCommand, SpeedCommand
from sorting_line_interfaces.srv import ResetLine, ResetLines

from ..line.errors import BridgeError
from ..line.topics import (
    BATCH_CMD,
    BATCH_RESET,
    BATCH_STATE,
    DIAGNOSTICS,
    NODE_QOS,
    RESET,
    SORT_MODE_CMD,
    SPEED_CMD,
    STATE,
)
from ..line.vocabulary import SPEEDS  # a speed index i commands SPEEDS[i]
from .batch_codec import BatchCodec, from_message, row_bytes

#: The node's QoS for commands and state (``line.topics.NODE_QOS``), as rclpy's profile.
QOS = QoSProfile(
    depth=NODE_QOS.depth,
    reliability=ReliabilityPolicy[NODE_QOS.reliability.upper()],
    durability=DurabilityPolicy[NODE_QOS.durability.upper()],
    history=HistoryPolicy.KEEP_LAST,
)


def stamp_key(t: Time) -> tuple[int, int]:
    return (t.sec, t.nanosec)


def publish_commands(speed_pub, mode_pub, stamp: Time, speed_index: int, mode: int) -> None:
    """Answers the tick stamped ``stamp`` on a line's command topics: the sort mode first (when
    the line has one, ``mode_pub`` not None), then the speed, which completes the tick."""
    if mode_pub is not None:
        m = SortModeCommand()
        m.header.stamp = stamp
        m.mode = int(mode)
        mode_pub.publish(m)
    s = SpeedCommand()
    s.header.stamp = stamp
    s.speed = SPEEDS[speed_index]
    speed_pub.publish(s)


@dataclass
class ResetResult:
    """What a reset tells about one line: its first observation and where it now stands."""

    quantity: float
    category: int
    episode: int
    seed: int
    stamp: Time


@dataclass
class Tick:
    """Where a line is: the stamp to answer, the episode and the step."""

    stamp: Time
    episode: int
    step: int


def check_not_taken_over(namespace: str, ours: int, seen: int) -> None:
    """A state of a later episode than ours means another client reset the line: our commands are
    refused from now on (the node lets one client drive an episode), so say so rather than wait."""
    if seen > ours:
        raise BridgeError(
            f"{namespace}: another client reset this line (episode {seen}; this bridge drives episode "
            f"{ours}); the node refuses this bridge's commands from now on ('not_owner' on {DIAGNOSTICS}). "
            "Call reset() to take the line back, or give each bridge a line of its own"
        )


def _drain(sub, inbox: deque) -> None:
    """Takes every message a subscription has already received, without the executor.

    The executor hands over one message per wake-up, each wake-up rebuilding a wait set over every
    entity; when several messages are due together (the states of a round trip), taking the rest
    directly, as the executor itself does (``Subscription.handle.take_message``), saves those
    wake-ups.
    """
    with sub.handle:
        while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
            inbox.append(taken[0])


class LineLink:
    """The endpoints of one line on the bridge's rclpy node, and its lock-step position.

    With ``per_line_topics=False`` (lines driven and reset through :class:`BatchLink`) it creates
    no endpoints at all: every entity is one more thing each executor wait scans."""

    def __init__(self, node: Node, namespace: str, advanced: bool, per_line_topics: bool = True):
        self.namespace = namespace.rstrip("/") or ""
        self.advanced = advanced
        self.node = node

        def name(rel):
            return f"{self.namespace}/{rel}"

        self.state_topic = name(STATE)
        self.speed_pub = self.mode_pub = self.state_sub = self.reset_client = None
        # States arrive in order; keep a short backlog so nothing is lost while we publish.
        self.inbox: deque[LineState] = deque(maxlen=64)
        if per_line_topics:
            self.reset_client = node.create_client(ResetLine, name(RESET), qos_profile=QOS)
            self.speed_pub = node.create_publisher(SpeedCommand, name(SPEED_CMD), QOS)
            self.mode_pub = node.create_publisher(SortModeCommand, name(SORT_MODE_CMD), QOS) if advanced else None
            self.state_sub = node.create_subscription(LineState, self.state_topic, lambda m: self.inbox.append(m), QOS)
        self.tick: Tick | None = None
        self.last_state: LineState | None = None
        self._reset_future = None

    # -- matching ----------------------------------------------------------------------------
    def endpoints_matched(self, node: Node) -> bool:
        """Commands have a reader and the state topic a writer (necessary, not sufficient)."""
        return all(self.matching(node).values())

    def matching(self, node: Node) -> dict[str, bool]:
        """Each endpoint of the node this line needs -> whether this bridge has discovered it."""
        seen = {}
        if self.reset_client is not None:
            seen["reset service"] = self.reset_client.service_is_ready()
        if self.speed_pub is not None:
            seen[f"{SPEED_CMD} reader"] = self.speed_pub.get_subscription_count() > 0
            seen["state writer"] = node.count_publishers(self.state_topic) > 0
        if self.mode_pub is not None:
            seen[f"{SORT_MODE_CMD} reader"] = self.mode_pub.get_subscription_count() > 0
        return seen

    # -- reset -------------------------------------------------------------------------------
    def send_reset(self, seed: int | None) -> None:
        request = ResetLine.Request()
        request.has_seed = seed is not None
        request.seed = int(seed) if seed is not None else 0
        self._reset_future = self.reset_client.call_async(request)

    def reset_done(self) -> bool:
        return self._reset_future is not None and self._reset_future.done()

    def finish_reset(self) -> ResetResult:
        response = self._reset_future.result()
        self._reset_future = None
        if response is None or not response.success:
            raise BridgeError(f"{self.namespace}/{RESET} refused: {getattr(response, 'message', 'no response')}")
        self.tick = Tick(response.stamp, response.episode, 0)
        # States of earlier ticks can no longer be what anyone waits for. The new episode's
        # step-0 state may already be here (the node publishes it before replying): keep it.
        start = stamp_key(response.stamp)
        kept = [s for s in self.inbox if stamp_key(s.header.stamp) >= start]
        self.inbox.clear()
        self.inbox.extend(kept)
        return ResetResult(response.quantity, response.category, response.episode, response.seed, response.stamp)

    def saw_state_of_current_tick(self) -> bool:
        """Whether the step-0 state of the current episode arrived (the handshake's proof)."""
        t = self.tick
        return any(s.episode == t.episode and stamp_key(s.header.stamp) == stamp_key(t.stamp) for s in self.inbox)

    # -- step --------------------------------------------------------------------------------
    def send_action(self, speed_index: int, mode: int) -> None:
        publish_commands(self.speed_pub, self.mode_pub, self.tick.stamp, speed_index, mode)

    def drain(self) -> None:
        _drain(self.state_sub, self.inbox)

    def take_next_state(self) -> bool:
        """Consumes the inbox up to the state of the tick after ours; True once it is there."""
        t = self.tick
        while self.inbox:
            s = self.inbox.popleft()
            if s.episode == t.episode and s.step == t.step + 1:
                self.last_state = s
                self.tick = Tick(s.header.stamp, s.episode, s.step)
                return True
            check_not_taken_over(self.namespace, t.episode, s.episode)
            # Anything else is older (the step-0 state, a previous episode): never returned.
        return False

    def describe_wait(self) -> str:
        t = self.tick
        return (
            f"{self.state_topic} of episode {t.episode} step {t.step + 1} "
            f"(answering the tick stamped {t.stamp.sec}.{t.stamp.nanosec:09d})"
        )


class BatchLink:
    """``batch/cmd`` and ``batch/state`` of a node: every line's command in one message and every
    line's state in one message of arrays, so a round trip over N lines costs two messages, not 2N.

    Both messages cross as bytes, read and written by :mod:`.batch_codec` as numpy records.
    Where the lines stand is the newest batch that showed them, kept as one record
    (``position_bytes``; as a namespace of arrays, entry k = line k, ``position``): its stamps are
    what the next command answers, and its episodes and steps are compared whole with the next
    batch's. Nothing is unpacked per line in the step loop; that keeps a 16-line round trip close
    to a one-line one (benches/bridge_throughput.py).
    """

    def __init__(self, node: Node, namespace: str, links: list[LineLink]):
        self.links = links
        n = len(links)
        base = namespace.rstrip("/")
        self.state_topic = f"{base}/{BATCH_STATE}"
        self.cmd_pub = node.create_publisher(LineCommands, f"{base}/{BATCH_CMD}", QOS)
        self.reset_name = f"{base}/{BATCH_RESET}"
        self.reset_client = node.create_client(ResetLines, self.reset_name, qos_profile=QOS)
        self._reset_future = None
        self.advanced = links[0].advanced
        self._states = BatchCodec(LineStates, n)
        self._commands = BatchCodec(LineCommands, n, None if self.advanced else {"modes": 0})
        #: Received ``batch/state`` messages, serialised (the executor's callback and ``_drain`` both append).
        self.inbox: deque[bytes] = deque(maxlen=64)
        self.state_sub = node.create_subscription(
            LineStates, self.state_topic, lambda raw: self.inbox.append(raw), QOS, raw=True
        )
        #: Lines no reset has started yet: they cannot be stepped.
        self.unstarted = set(range(n))
        #: The newest batch showing every line's current tick (after a reset: the reply's states),
        #: and where each received batch is read: two records that swap when one is taken.
        self._position = self._states.records(1)
        self._incoming = self._states.records(1)
        self._next_step = None
        self._speeds = np.array(SPEEDS)

    def matched(self, node: Node) -> bool:
        return all(self.matching(node).values())

    def matching(self, node: Node) -> dict[str, bool]:
        """Each batch endpoint of the node -> whether this bridge has discovered it."""
        return {
            f"{BATCH_RESET} service": self.reset_client.service_is_ready(),
            f"{BATCH_CMD} reader": self.cmd_pub.get_subscription_count() > 0,
            f"{BATCH_STATE} writer": node.count_publishers(self.state_topic) > 0,
        }

    def send_reset(self, seeds: dict[int, int | None]) -> None:
        request = ResetLines.Request()
        request.lines = array("I", seeds.keys())
        request.has_seed = [s is not None for s in seeds.values()]
        request.seeds = array("Q", (int(s) if s is not None else 0 for s in seeds.values()))
        self._reset_future = self.reset_client.call_async(request)

    def reset_done(self) -> bool:
        return self._reset_future is not None and self._reset_future.done()

    def finish_reset(self, seeds: dict[int, int | None]) -> dict[int, ResetResult]:
        response = self._reset_future.result()
        self._reset_future = None
        if response is None or not response.success:
            raise BridgeError(f"{self.reset_name} refused: {getattr(response, 'message', 'no response')}")
        # The reply carries every line's state after the reset; lines not reset are where they were.
        b = from_message(response.states)
        if not self._states.assign(self._position, 0, b):
            raise BridgeError(
                f"{self.reset_name} replied with the states of {len(b.step)} lines"
                f"; this bridge drives {len(self.links)}"
            )
        self.unstarted.difference_update(seeds)
        results = {}
        for k in seeds:
            stamp = Time(sec=int(b.stamp_sec[k]), nanosec=int(b.stamp_nanosec[k]))
            results[k] = ResetResult(
                float(b.observation_quantity[k]),
                int(b.observation_category[k]),
                int(b.episode[k]),
                int(b.seed[k]),
                stamp,
            )
        return results

    def check_started(self) -> None:
        if self.unstarted:
            k = min(self.unstarted)
            raise BridgeError(f"{self.links[k].namespace}: step() before reset()")

    @property
    def position(self) -> SimpleNamespace:
        """Where the lines stand, as a namespace of arrays (entry k = line k) the caller owns."""
        return self._states.fields(self._position)

    @property
    def position_bytes(self) -> np.ndarray:
        """Where the lines stand, as the record's bytes (valid until the next batch is taken)."""
        return row_bytes(self._position)[0]

    def send(self, speed_indices: np.ndarray, modes: np.ndarray) -> None:
        """Answers every line's current tick (the stamps of the position)."""
        p = self._position
        fields = {
            "stamp_sec": p["stamp_sec"][0],
            "stamp_nanosec": p["stamp_nanosec"][0],
            "speeds": self._speeds[speed_indices],
        }
        if self.advanced:
            fields["modes"] = modes
        self._next_step = p["step"][0] + 1
        self.cmd_pub.publish(self._commands.encode(**fields))

    def _advance(self, step: np.ndarray) -> bool:
        """Makes the first batch in the inbox showing every line in its current episode at
        ``step`` the position; older batches are dropped. False when none is there yet."""
        _drain(self.state_sub, self.inbox)
        episode = self._position["episode"][0]
        incoming = self._incoming
        while self.inbox:
            if not self._states.load(incoming, 0, self.inbox.popleft()):
                continue  # not a batch of this many lines: not what this bridge drives
            seen = incoming["episode"][0]
            if (seen == episode).all() and (incoming["step"][0] == step).all():
                self._position, self._incoming = incoming, self._position
                return True
            for link, ours, theirs in zip(self.links, episode.tolist(), seen.tolist(), strict=False):
                check_not_taken_over(link.namespace, ours, theirs)
        return False

    def saw_current_ticks(self) -> bool:
        """Whether a batch showed every line at its current tick (the handshake after a reset)."""
        return self._advance(self._position["step"][0].copy())

    def take_next_states(self) -> bool:
        return self._advance(self._next_step)

    def describe_wait(self) -> str:
        p, n = self.position, len(self.links)
        ticks = ", ".join(
            f"{self.links[k].namespace} episode {p.episode[k]} step {p.step[k] + 1}" for k in range(min(n, 4))
        )
        more = f" and {n - 4} more lines" if n > 4 else ""
        return f"{self.state_topic} with the next state of every line ({ticks}{more})"
