"""`sorting-line-bag replay`: feeds a bag's resets and commands into a fresh lock-step node and
compares what the node publishes with what the bag recorded, field by field. What to send and
compare is worked out from the bag first (:mod:`.replay_plan`); this module drives the node.

- The node: started with the options the bag stores (see :mod:`..storage.reader`; flags may override
  them), lock-step, one line, in a private namespace, its ``/clock`` and ``/diagnostics``
  remapped into that namespace so that other nodes on the domain cannot mix in.
- Handshake: a reset seeded with the line's seed (which puts the random streams exactly where a
  fresh node has them) is repeated until its reply and its step-0 state arrive, proving that
  the reset service and ``state`` are matched.
- The bag's first reset is proven too: its reply and, on every compared topic, as many messages
  of its tick as the bag has there must arrive (the node publishes only to readers it has
  matched, and may match ours one by one). Otherwise the node is replaced by a fresh one (a new
  namespace) and the reset is sent to that one: repeating it to the same node could run the
  episode twice (an unseeded reset moves the streams on; an evolving line's schedule counts it
  as its next episode). See ``workarounds.late_matching``.
- Seeds: each ``events/reset`` of the bag becomes a reset of the replay node, with the event's
  ``seed`` when ``seeded`` is true (the streams restarted) and without one otherwise (they
  carried on). A bag that starts with an unseeded reset is replayable only if that reset was
  the node's first act (tick 1, episode 1): otherwise the streams had moved on unseen.
- Commands: ``cmd/speed`` and ``cmd/sort_mode`` in the order the recorder received them (each
  after the reset whose episode it belongs to), restamped onto the replay node's ticks. No
  wall-clock playback: before a command for tick T the replay waits for the node's state of
  T, before a reset for the states the bag shows before it. Commands for a tick the recorded
  node never stepped from (no state of step > 0 at T+1 in the bag: the episode was over, a reset came
  first, or the recording ended) are not sent: they changed nothing there.
- Lining up: the replay node counts its ticks and episodes from its own start, so its stamps
  and episode numbers are shifted by the difference at the first reset; everything else must
  be equal. The comparison (:mod:`.compare`) covers every message from the bag's first reset on,
  of ``events/reset``, ``input``, ``belt/occupancy``, ``sensors/ratio``, ``state`` and ``/clock``
  as far as the bag has them, and names the first difference by topic, tick and field.
- Evolving lines: the bag carries the schedule (``evolution`` in its description), which the
  replay node runs by; ``events/evolution`` is compared like the other topics. The recording must
  start at the node's first reset (episode 1, tick 0: the schedule counts episodes and ticks from
  the node's start), and there is no handshake reset (it would be an episode of the schedule).
  ``cmd/sort_mode`` is sent while the recorded line had sort modes (its ``events/evolution`` say
  when), once the replay node's subscription, which appears with the machine upgrade, is matched.
  ``sensors/ratio`` is not compared: its publisher appears with the sensor upgrade, and which of
  its first messages a recorder had matched in time is discovery timing, not the line (the
  reading itself is compared, in every state's ``observation_category``).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from ...line.errors import BridgeTimeout
from ...line.process import private_namespace
from ...line.topics import DIAGNOSTICS, RESET, RESET_EVENT, SENSORS_RATIO, SORT_MODE_CMD, SPEED_CMD, STATE
from ...ros.links import LineLink
from ...workarounds.late_matching import repeated_while_unanswered, retried_handshake
from ..format.options import NodeOverrides
from ..format.topics import CLOCK, GLOBAL_TYPES, HARDWARE, LINE_TYPES, join
from ..storage.foreign import REQUIRED
from ..storage.reader import Bag, BagMessage, open_bag
from ..storage.schema import decode, stamp_ns, typestore
from .compare import Comparison, Difference, compare, shifted
from .progress import progress_bar
from .replay_plan import ReplayPlan, lockstep_node, plan_replay
from .rosnode import ToolNode

HANDSHAKE_ATTEMPTS = 3
#: Fresh nodes a replay may start before one has taken the bag's first reset with all its messages.
FIRST_RESET_ATTEMPTS = 3


@dataclass
class ReplayResult:
    bag: Bag
    options: dict
    resets: int = 0
    commands: int = 0
    tick_shift: int = 0  # ticks: bag tick = replay tick + tick_shift
    episode_shift: int = 0
    comparison: Comparison | None = None
    difference: Difference | None = None
    seconds: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return self.difference is None

    def report(self) -> str:
        counts = ", ".join(f"{t} {n}" for t, n in sorted((self.comparison.compared if self.comparison else {}).items()))
        head = (
            f"replayed {self.bag.path}: {self.resets} resets and {self.commands} commands into a fresh lock-step "
            f"node ({', '.join(f'{k}={self.options[k]}' for k in REQUIRED)}) in {self.seconds:.1f} s; "
            f"lined up as bag tick = replay tick {self.tick_shift:+d}, bag episode = replay episode "
            f"{self.episode_shift:+d}"
        )
        lines = [head, f"compared: {counts or 'nothing'}"]
        lines += self.notes
        if self.difference is None:
            lines.append("identical: every recorded message was reproduced field by field")
        else:
            lines.append(f"first difference: {self.difference}")
        return "\n".join(lines)


class _Capture:
    """What the replay node publishes, per relative topic (and /clock), as (stamp, raw bytes)."""

    def __init__(self, tool: ToolNode, namespace: str, topics: list[str]):
        self.raw: dict[str, list[bytes]] = {t: [] for t in topics}
        self.states: dict[int, dict] = {}
        self.subs = {}
        for rel in topics:
            name = join(namespace, rel) if rel != CLOCK else join(namespace, "clock")
            msgtype = LINE_TYPES.get(rel) or GLOBAL_TYPES[rel]
            self.subs[rel] = tool.raw_subscription(name, msgtype, self._keeper(rel))

    def _keeper(self, rel: str):
        store = self.raw[rel]

        def keep(data: bytes, _received: int) -> None:
            store.append(data)
            if rel == STATE:
                m = decode(data, LINE_TYPES[STATE])
                self.states[stamp_ns(m)] = m

        return keep

    def plain(self, rel: str) -> list[dict]:
        msgtype = LINE_TYPES.get(rel) or GLOBAL_TYPES[rel]
        return [decode(d, msgtype) for d in self.raw[rel]]


def replay(
    path,
    overrides: NodeOverrides | None = None,
    *,
    step_timeout: float = 5.0,
    startup_timeout: float = 20.0,
    progress: bool = False,
) -> ReplayResult:
    """Replays the bag at ``path`` (see the module docstring) in three phases: plan (what to send,
    from the bag alone), drive (a fresh node, fed resets and commands tick by tick) and compare
    (what it published against the recording). Raises BagError for a bag that cannot be
    replayed, BridgeError when the replay node fails; a difference is a result."""
    started = time.monotonic()
    plan = plan_replay(open_bag(path), overrides)
    result = ReplayResult(plan.bag, plan.options)
    if plan.ineffective:
        result.notes.append(
            f"not sent: {plan.ineffective} commands for ticks the recorded node did not step from "
            "(the episode was over, a reset came first, or the recording ended)"
        )
    scratch = tempfile.TemporaryDirectory(prefix="sorting_line_replay_")
    if plan.evolution is not None:
        result.notes.append(
            f"evolving line: replayed with the schedule stored in the bag; {SENSORS_RATIO} not compared "
            "(its publisher appears with the sensor upgrade; the reading is compared in state)"
        )
    run = None
    try:
        run = _first_reset_proven(plan, result, Path(scratch.name), step_timeout, startup_timeout)
        capture = run.drive(progress)
        _compare(plan, result, capture)
        result.seconds = time.monotonic() - started
        return result
    finally:
        if run is not None:
            run.close()
        scratch.cleanup()


def _first_reset_proven(
    plan: ReplayPlan, result: ReplayResult, scratch: Path, step_timeout: float, startup_timeout: float
) -> _Replay:
    """A replay node that took the bag's first reset with every message of its tick arriving (see
    the module docstring); up to FIRST_RESET_ATTEMPTS fresh nodes, each reset once. The last one
    goes on even unproven: the comparison then names what is missing."""

    def attempt(_k: int) -> _Replay:
        run = _Replay(plan, result, scratch, step_timeout)
        try:
            run.connect(startup_timeout)
            run.take_first_reset()
        except BaseException:
            run.close()
            raise
        return run

    def fresh_node(run: _Replay) -> None:
        result.notes.append(f"{run.namespace}: {run.first_reset_unproven}; replayed again into a fresh node")
        run.close()
        result.resets = 0

    return repeated_while_unanswered(
        attempt, lambda run: run.first_reset_unproven is not None, FIRST_RESET_ATTEMPTS, before_repeat=fresh_node
    )


class _Replay:
    """The drive phase: one fresh lock-step node in a private namespace, fed the plan's resets and
    commands, each once the node has reached the tick the bag sent it at."""

    def __init__(self, plan: ReplayPlan, result: ReplayResult, scratch: Path, step_timeout: float):
        self.plan, self.result, self.step_timeout = plan, result, step_timeout
        self.namespace = private_namespace()
        self.process = lockstep_node(
            plan,
            self.namespace,
            scratch,
            ("-r", f"{CLOCK}:={self.namespace}{CLOCK}", "-r", f"{DIAGNOSTICS}:={self.namespace}{DIAGNOSTICS}"),
        )
        self.tool = None
        try:
            self.tool = ToolNode("sorting_line_bag_replay", self.process)
            # An evolving line's cmd/sort_mode comes with its machine upgrade: created when needed.
            advanced = plan.options["variant"] == "advanced" and plan.evolution is None
            self.link = LineLink(self.tool.node, self.namespace, advanced)
            self.capture = _Capture(self.tool, self.namespace, plan.compared_topics)
        except BaseException:
            self.close()
            raise
        self.publishers = {SPEED_CMD: self.link.speed_pub, SORT_MODE_CMD: self.link.mode_pub}
        self.store = typestore()
        self.sent = 0  # drivers sent so far
        #: Why the bag's first reset is not proven (None: it is; see take_first_reset).
        self.first_reset_unproven: str | None = "the bag's first reset is not sent yet"

    def close(self) -> None:
        if self.tool is not None:
            self.tool.close()
            self.tool = None
        self.process.stop()

    def connect(self, startup_timeout: float) -> None:
        """Waits until this side has discovered the node's endpoints; then, on a fixed line, the
        handshake (a seeded reset with the line's seed, repeated until answered)."""
        link, tool, plan = self.link, self.tool, self.plan
        fixed = [s for rel, s in self.capture.subs.items() if not (plan.evolution and rel in HARDWARE)]
        tool.until(
            lambda: link.endpoints_matched(tool.node) and all(s.get_publisher_count() for s in fixed),
            startup_timeout,
            f"the replay node serving {self.namespace} (its reset service and topics)",
        )
        if plan.evolution is None:
            _handshake(tool, link, int(plan.options["seed"]), self.step_timeout)
        else:
            # No handshake reset: it would be an episode of the schedule. A moment for the node to
            # match our readers too (only to make a fresh node for the first reset rarer).
            tool.spin_for(0.5)

    def take_first_reset(self) -> None:
        """Sends the bag's first reset and judges it (``first_reset_unproven``): proven once its
        reply came and every compared topic brought as many messages of its tick as the bag has."""
        _, first = self.plan.drivers[0]
        try:
            self._reset(first)
        except BridgeTimeout as e:
            self.first_reset_unproven = str(e)
            return
        self.sent = 1
        want = {t: n for t, n in self.plan.at_start.items() if n}
        shift = self.result.tick_shift * self.plan.period

        def arrived(topic: str) -> int:
            return sum(1 for m in self.capture.plain(topic) if stamp_ns(m) + shift == self.plan.start)

        try:
            self.tool.until(
                lambda: all(arrived(t) >= n for t, n in want.items()),
                self.step_timeout,
                lambda: (
                    f"the first reset's messages ({', '.join(f'{t} {arrived(t)} of {n}' for t, n in want.items())})"
                ),
            )
            self.first_reset_unproven = None
        except BridgeTimeout as e:
            self.first_reset_unproven = str(e)

    def drive(self, progress: bool) -> _Capture:
        """Sends the drivers not yet sent; stops at the first tick the node does not reach
        (result.difference)."""
        plan = self.plan
        bar = progress_bar(len(plan.drivers), progress)
        bar.update(self.sent)
        try:
            for rel, m in plan.drivers[self.sent :]:
                bar.update(1)
                sent = self._reset(m) if rel == RESET_EVENT else self._command(rel, m)
                if not sent:
                    return self.capture
            later = [s for s in plan.bag_states if s >= plan.start]
            if later:
                self._reached(max(later), "the bag's last state")
            self.tool.spin_for(0.3)  # /clock and anything else still in flight
        finally:
            bar.close()
        return self.capture

    def _reached(self, bag_stamp: int, why: str) -> bool:
        """Waits for the replay node's state of the bag's tick ``bag_stamp``; False (and the
        result's difference set) when it does not come."""
        period = self.plan.period
        want = bag_stamp - self.result.tick_shift * period
        try:
            self.tool.until(
                lambda: want in self.capture.states,
                self.step_timeout,
                f"{self.namespace}/{STATE} of tick {want // period} ({why})",
            )
            return True
        except BridgeTimeout:
            self.result.difference = _missing_state(bag_stamp, period, self.plan.rel_msgs)
            return False

    def _reset(self, m: BagMessage) -> bool:
        plain, stamp, result = m.plain, stamp_ns(m.plain), self.result
        earlier = [s for s in self.plan.bag_states if self.plan.start <= s < stamp]
        if result.resets and earlier and not self._reached(max(earlier), "the last state before a reset"):
            return False
        self.link.send_reset(int(plain["seed"]) if plain.get("seeded", True) else None)
        self.tool.until(self.link.reset_done, self.step_timeout, f"the reply of {self.namespace}/{RESET}")
        reply = self.link.finish_reset()
        if result.resets == 0:
            result.tick_shift = (stamp - (reply.stamp.sec * 1_000_000_000 + reply.stamp.nanosec)) // self.plan.period
            result.episode_shift = int(plain["episode"]) - int(reply.episode)
        result.resets += 1
        return True

    def _command(self, rel: str, m: BagMessage) -> bool:
        # Wait until the replay node is at the command's tick, if the recorded one got there.
        stamp = stamp_ns(m.plain)
        if stamp in self.plan.bag_states and not self._reached(stamp, f"to answer with the bag's {rel}"):
            return False
        pub = self.publishers.get(rel)
        if pub is None:  # a sort mode sent to a basic line: the node refuses it, as it did then
            pub = self.publishers[rel] = self.tool.publisher(join(self.namespace, rel), LINE_TYPES[rel])
        if self.plan.evolution is not None and rel == SORT_MODE_CMD:
            if not self.plan.had_sort_modes(stamp):
                return True  # the recorded node had no cmd/sort_mode then: it never got this command
            self.tool.until(
                lambda: pub.get_subscription_count() > 0,
                self.step_timeout,
                f"{self.namespace}/{SORT_MODE_CMD}, subscribed since the machine upgrade, to match",
            )
        pub.publish(_restamped(self.store, m, stamp - self.result.tick_shift * self.plan.period))
        self.result.commands += 1
        return True


def _compare(plan: ReplayPlan, result: ReplayResult, capture: _Capture) -> None:
    """The compare phase: every recorded message from the first reset on against the replayed
    one of the same (shifted) tick; up to where the node stopped, if it stopped short."""
    shift = result.tick_shift * plan.period
    recorded = {t: [m.plain for m in plan.rel_msgs[t] if stamp_ns(m.plain) >= plan.start] for t in plan.compared_topics}
    replayed = {}
    for t in plan.compared_topics:
        items = [shifted(m, shift, result.episode_shift) for m in capture.plain(t)]
        replayed[t] = [m for m in items if stamp_ns(m) >= plan.start]
    if result.difference is not None:
        # The node stopped short; anything before that point may still differ earlier.
        cut = result.difference.stamp_ns
        recorded = {t: [m for m in ms if stamp_ns(m) < cut] for t, ms in recorded.items()}
        replayed = {t: [m for m in ms if stamp_ns(m) < cut] for t, ms in replayed.items()}
    result.comparison = compare(recorded, replayed, plan.period)
    if result.comparison.difference is not None:
        result.difference = result.comparison.difference
    if result.comparison.ignored_after_end:
        result.notes.append(
            f"not compared: {result.comparison.ignored_after_end} replayed messages after the end of the recording"
        )


def _handshake(tool: ToolNode, link: LineLink, seed: int, timeout: float) -> None:
    """A seeded reset, repeated until its reply and its step-0 state arrive (either can be lost
    while the node is still matching our endpoints, ``workarounds.late_matching``; a seeded reset
    repeated is the same)."""

    def attempt(limit: float) -> None:
        link.send_reset(seed)
        tool.until(link.reset_done, limit, f"the reply of {link.namespace}/{RESET} (handshake)")
        link.finish_reset()
        tool.until(link.saw_state_of_current_tick, limit, f"{link.state_topic} after the handshake reset")

    def drop_pending_request() -> None:
        if link._reset_future is not None:
            link.reset_client.remove_pending_request(link._reset_future)
            link._reset_future = None

    limits = [min(2.0, timeout)] * HANDSHAKE_ATTEMPTS
    retried_handshake(attempt, limits, BridgeTimeout, after_loss=drop_pending_request)


def _restamped(store, m: BagMessage, stamp: int) -> bytes:
    msg = store.deserialize_cdr(m.data, m.msgtype)
    header = msg.header
    new_stamp = dataclasses.replace(header.stamp, sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
    msg = dataclasses.replace(msg, header=dataclasses.replace(header, stamp=new_stamp))
    return bytes(store.serialize_cdr(msg, m.msgtype))


def _missing_state(stamp: int, period: int, rel_msgs: dict[str, list[BagMessage]]) -> Difference:
    recorded = next((m.plain for m in rel_msgs.get(STATE, []) if stamp_ns(m.plain) == stamp), {})
    return Difference(
        STATE,
        stamp // period,
        stamp,
        "<message>",
        "has it",
        "the replay node did not publish it (it did not step as the recorded node did)",
        recorded.get("episode"),
        recorded.get("step"),
    )
