"""`sorting-line-bag play`: publishes a bag's recorded data again, with its original timing (or
``rate`` times faster), for testing a controller (e.g. `sorting-line-controller`) against
recorded data instead of a live node.

By default it plays everything the node published (the sensors ``input``, ``belt/occupancy``,
``sensors/ratio``, and ``state``, ``events/reset``, ``/clock``), not the commands: those are the
controller's to send; nor what a bag of another recorder holds besides (``/rosout``,
``/parameter_events``: they describe the recorded graph's nodes; topics of types not known here).
``namespace`` moves the line's topics to another namespace. The CDR bytes
are published as recorded (stamps unchanged). Timing follows the recorder's receive times.

With ``lockstep`` it ignores the timing and plays tick by tick, as a lock-step node would: a
tick's messages, then a wait (``answer_timeout``) for the controller's ``cmd/speed`` stamped
with that tick, if the bag shows an answer to it; then the next tick. A controller that stalls
for a moment (a busy machine) then loses nothing from its keep-last-10 queues.

Before the first message it waits until the ``wait_for`` topics (default: the line's ``input``)
have a subscriber, since volatile samples sent before matching are lost; at the end it waits
until every subscriber has acknowledged every sample (reliable QoS), so nothing is cut off.

The three phases (:class:`Selection`, :func:`wait_for_subscribers`, :class:`Pace`) are public: the
open-loop check (:mod:`..check.open_loop`) plays a bag to a controller with them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from rclpy.duration import Duration

from ...line.topics import INPUT, PARAMETER_EVENTS, ROSOUT, SPEED_CMD
from ..format.errors import BagError
from ..format.topics import COMMANDS, LINE_TYPES, join, relative_to
from ..storage.reader import Bag, BagMessage, open_bag, topics_of
from ..storage.schema import decode, stamp_ns
from .rosnode import ToolNode, rclpy_class


@dataclass
class PlayResult:
    counts: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    recorded_seconds: float = 0.0
    #: lockstep: stamps (ns) of the ticks whose answer did not come in time
    unanswered: list[int] = field(default_factory=list)
    #: topics of the bag not played by default (a bag of another recorder), with why
    skipped: dict[str, str] = field(default_factory=dict)

    def summary(self) -> str:
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        text = (
            f"played {sum(self.counts.values())} messages in {self.seconds:.2f} s "
            f"(recorded over {self.recorded_seconds:.2f} s): {per_topic}"
        )
        if self.unanswered:
            text += f"; no answer in time for {len(self.unanswered)} ticks (first at {self.unanswered[0] / 1e9:.3f} s)"
        if self.skipped:
            text += "; not played: " + ", ".join(f"{t} ({why})" for t, why in sorted(self.skipped.items()))
        return text


def play(
    path,
    *,
    rate: float = 1.0,
    topics: list[str] | None = None,
    namespace: str | None = None,
    wait_for: list[str] | None = None,
    wait: float = 10.0,
    stop: Callable[[], bool] = lambda: False,
    on_ready: Callable[[str], None] = print,
    lockstep: bool = False,
    answer_timeout: float = 5.0,
) -> PlayResult:
    """Plays the bag at ``path``. ``rate``: speed factor (2 = twice as fast; 0 = as fast as
    possible). ``topics``: absolute or relative to the recorded line (default: all but the
    commands). ``lockstep``: tick by tick, each after the controller's answer (see the module's
    docstring). Raises BagError for bad input, TimeoutError when nobody subscribes in time.

    Three phases: select (the messages and where they go), wait for subscribers, pace (publish
    on the recorded timing, or tick by tick)."""
    if rate < 0:
        raise BagError(f"--rate {rate}: must be >= 0 (0 plays as fast as possible)")
    selection = Selection.of(open_bag(path), topics, namespace, wait_for, lockstep)
    tool = ToolNode("sorting_line_bag_play")
    try:
        pubs = {t: tool.publisher(selection.target(t), selection.bag.types[t]) for t in selection.chosen}
        answered: set[int] = set()
        if lockstep:
            answers = LINE_TYPES[SPEED_CMD]
            tool.raw_subscription(
                join(selection.out_ns, SPEED_CMD),
                answers,
                lambda data, _t: answered.add(stamp_ns(decode(data, answers))),
            )
        wait_for_subscribers(tool, selection, pubs, wait)
        on_ready(
            f"playing {len(selection.messages)} messages on {len(pubs)} topics"
            + (f" into {namespace}" if namespace else "")
        )
        pace = Pace(tool, selection, pubs, stop, answered, answer_timeout)
        pace.result.skipped = selection.skipped
        return pace.tick_by_tick() if lockstep else pace.timed(rate)
    finally:
        tool.close()


@dataclass
class Selection:
    """The select phase: which recorded messages are played, on which topics, and what is waited for."""

    bag: Bag
    line_ns: str  # the recorded line's namespace ("" if the bag does not say)
    namespace: str | None  # where the line's topics go instead, if anywhere
    chosen: list[str]  # recorded topics played
    waits: list[str]  # topics that need a subscriber before the first message
    messages: list[BagMessage]
    recorded_answers: set[int]  # lockstep: stamps of the ticks the bag shows a cmd/speed for
    skipped: dict[str, str] = field(default_factory=dict)  # topics not played by default, and why

    @property
    def out_ns(self) -> str:
        return self.namespace or self.line_ns

    def target(self, topic: str) -> str:
        rel = relative_to(self.line_ns, topic) if self.line_ns else None
        return join(self.namespace, rel) if self.namespace and rel is not None else topic

    @classmethod
    def of(
        cls, bag: Bag, topics: list[str] | None, namespace: str | None, wait_for: list[str] | None, lockstep: bool
    ) -> Selection:
        line_ns = bag.info.namespace if bag.info else ""
        skipped: dict[str, str] = {}
        if topics:
            chosen = topics_of(bag, topics)
            for t in chosen:
                if why := _unplayable(bag, t):
                    raise BagError(f"{bag.path}: cannot play {t}: {why}")
        else:
            chosen = [t for t in bag.types if (relative_to(line_ns, t) if line_ns else None) not in COMMANDS]
            skipped = {t: why for t in chosen if (why := _not_played_by_default(bag, t))}
            chosen = [t for t in chosen if t not in skipped]
        waits = wait_for if wait_for is not None else ([INPUT] if join(line_ns, INPUT) in chosen else [])
        recorded_answers: set[int] = set()
        if lockstep:
            answers = join(line_ns, SPEED_CMD) if line_ns else None
            if answers not in bag.types:
                raise BagError(f"{bag.path}: --lockstep needs the bag's {SPEED_CMD}, the answers it waits for")
            recorded_answers = {stamp_ns(m.plain) for m in bag.on(answers)}
        messages = [m for m in bag.messages if m.topic in chosen]
        return cls(bag, line_ns, namespace, chosen, waits, messages, recorded_answers, skipped)


#: Topics of a recorded graph's nodes, not of the line: played again they would describe nodes
#: that are not there.
GRAPH_TOPICS = (ROSOUT, PARAMETER_EVENTS)


def _unplayable(bag: Bag, topic: str) -> str | None:
    """Why ``topic`` cannot be published from here (None: it can)."""
    msgtype = bag.types[topic]
    if topic in bag.unknown:
        return f"type {msgtype} not known here"
    try:
        rclpy_class(msgtype)
    except ImportError:
        return f"no rclpy class of {msgtype} here"
    return None


def _not_played_by_default(bag: Bag, topic: str) -> str | None:
    if topic in GRAPH_TOPICS:
        return "the recorded nodes' own topic"
    return _unplayable(bag, topic)


def wait_for_subscribers(tool: ToolNode, selection: Selection, pubs: dict, wait: float) -> None:
    """Volatile samples sent before a reader matches are lost: wait for the ``waits`` topics'
    subscribers, then (briefly) for the other known readers of the played topics."""
    by_name = {selection.target(t): p for t, p in pubs.items()}
    for w in selection.waits:
        name = join(selection.out_ns, w) if not w.startswith("/") else w
        if name not in by_name:
            raise BagError(f"--wait-for {w}: not one of the played topics ({', '.join(sorted(by_name))})")
        tool.until(lambda p=by_name[name]: p.get_subscription_count() > 0, wait, f"a subscriber on {name}")
    if not selection.waits:
        return

    # A controller's other readers (ratio, belt) are announced with the one waited for: give them
    # a moment to match too (best effort: stale graph entries may never match).
    def known_matched() -> bool:
        return all(p.get_subscription_count() >= tool.node.count_subscribers(n) for n, p in by_name.items())

    try:
        tool.until(known_matched, 1.0, "the other subscribers of the played topics")
    except TimeoutError:
        pass


class Pace:
    """The pace phase: publishes the selected messages on the recorder's timing, or tick by tick."""

    def __init__(
        self,
        tool: ToolNode,
        selection: Selection,
        pubs: dict,
        stop: Callable[[], bool],
        answered: set[int],
        answer_timeout: float,
    ):
        self.tool, self.selection, self.pubs, self.stop = tool, selection, pubs, stop
        self.answered, self.answer_timeout = answered, answer_timeout
        self.result = PlayResult()
        self.started = time.monotonic()

    def _publish(self, m: BagMessage) -> None:
        self.pubs[m.topic].publish(m.data)
        name = self.selection.target(m.topic)
        self.result.counts[name] = self.result.counts.get(name, 0) + 1

    def _done(self) -> PlayResult:
        """Waits until every subscriber has every sample (reliable QoS), so nothing is cut off."""
        for p in self.pubs.values():
            p.wait_for_all_acked(Duration(seconds=5))
        messages = self.selection.messages
        self.result.seconds = time.monotonic() - self.started
        self.result.recorded_seconds = (messages[-1].log_time - messages[0].log_time) / 1e9 if messages else 0.0
        return self.result

    def timed(self, rate: float) -> PlayResult:
        """Each message at its receive time in the recording, ``rate`` times faster (0: at once)."""
        messages = self.selection.messages
        t0 = messages[0].log_time if messages else 0
        for m in messages:
            if self.stop():
                break
            if rate > 0:
                due = self.started + (m.log_time - t0) / 1e9 / rate
                while (left := due - time.monotonic()) > 0 and not self.stop():
                    time.sleep(min(left, 0.05))
            self._publish(m)
        return self._done()

    def tick_by_tick(self) -> PlayResult:
        """A tick's messages, then the controller's answer to that tick (if the bag shows one)."""
        tick: int | None = None
        for m in self.selection.messages:
            if self.stop():
                break
            stamp = stamp_ns(m.plain)
            if stamp is not None and stamp != tick and (tick is None or stamp > tick):
                self._await_answer(tick)
                tick = stamp
            self._publish(m)
        if not self.stop():
            self._await_answer(tick)
        return self._done()

    def _await_answer(self, stamp: int | None) -> None:
        if stamp is None or stamp not in self.selection.recorded_answers:
            return
        topic = join(self.selection.out_ns, SPEED_CMD)
        try:
            self.tool.until(
                lambda: stamp in self.answered or self.stop(),
                self.answer_timeout,
                f"an answer on {topic} for the tick stamped {stamp / 1e9:.3f} s",
            )
        except TimeoutError:
            self.result.unanswered.append(stamp)
