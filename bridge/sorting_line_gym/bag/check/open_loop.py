"""Open-loop `sorting-line-bag check`: the bag's node side is played to the controller tick by tick,
exactly as `play --lockstep` plays it (:mod:`..transport.play`'s selection, subscriber wait and pacing), and
the controller's answers (``cmd/speed``, ``cmd/sort_mode``, or entry k of ``batch/cmd``) are
compared with the bag's command for each tick.

- A tick the bag shows a command for is awaited (``answer_timeout``) until the controller answered
  it on every topic the bag answered it on, or sent a command with a stamp of no tick it could be
  answering (a wrong stamp: it answered, wrongly). A tick without an answer in time is *missing*
  and the play goes on; an answer that comes later is still compared, and marked late.
- Speeds are compared as the node compares them (the same one of the ten speeds, within 1e-6);
  a speed or mode the node would refuse is a difference carrying the node's reason, as is a
  stamp of no current tick (``unknown_tick``) or of a tick already answered (``stale``).
- Latency is from the tick's publication (its first message; the tick ends with its ``state``,
  published right after) to the arrival of the answer (DDS receive time).
"""

from __future__ import annotations

import time
from collections import defaultdict

from ...line.errors import BridgeTimeout
from ...line.topics import BATCH_CMD, SORT_MODE_CMD, SPEED_CMD
from ...line.vocabulary import MODES, speed_index_of
from ..format.topics import LINE_TYPES, join
from ..storage.reader import Bag
from ..storage.schema import decode, stamp_ns
from ..transport.play import Pace, Selection, wait_for_subscribers
from ..transport.progress import progress_bar
from ..transport.rosnode import ToolNode
from .options import RunOptions
from .verdict import Answer, Verdict, node_reason

#: The fields a command topic answers with: topic -> (field, batch/cmd array).
FIELDS = {SPEED_CMD: ("speed", "speeds"), SORT_MODE_CMD: ("mode", "modes")}
BATCH = BATCH_CMD
BATCH_TYPE = "sorting_line_interfaces/msg/LineCommands"


def expected_commands(bag: Bag) -> dict[int, dict[str, dict]]:
    """The bag's command for each tick (stamp -> topic -> message): the first one the node
    accepted, if it can be told (a valid speed), else the first."""
    out: dict[int, dict[str, dict]] = defaultdict(dict)
    rel = bag.by_relative_topic()
    for topic in FIELDS:
        for m in rel.get(topic, []):
            plain, stamp = m.plain, stamp_ns(m.plain)
            held = out[stamp].get(topic)
            if held is None or (
                topic == SPEED_CMD
                and speed_index_of(held["speed"]) is None
                and speed_index_of(plain["speed"]) is not None
            ):
                out[stamp][topic] = plain
    return dict(out)


class _Answers:
    """The controller's commands as they arrive, each filed under the tick it answers."""

    def __init__(self, ticks: set[int], batch_entry: int):
        self.ticks = ticks  # stamps of every tick played
        self.batch_entry = batch_entry
        self.current: int | None = None  # the tick published last
        self.got: dict[int, dict[str, tuple[str, dict, int]]] = defaultdict(dict)  # stamp -> topic -> (via, msg, t)
        self.wrong: list[tuple[int | None, str, str, dict, int]] = []  # (tick, topic, via, msg, t)
        self.wrong_during: set[int | None] = set()
        self.duplicates = 0

    def on_command(self, topic: str, via: str, plain: dict, received: int) -> None:
        s, now = stamp_ns(plain), self.current
        if s in self.ticks and topic not in self.got[s] and (now is None or s <= now):
            self.got[s][topic] = (via, plain, received)
        elif s == now:
            self.duplicates += 1  # a second command for the tick: the node drops it, the first counts
        else:
            self.wrong.append((now, topic, via, plain, received))
            self.wrong_during.add(now)

    def on_batch(self, plain: dict, received: int) -> None:
        k = 0 if len(plain["speeds"]) == 1 else self.batch_entry
        if k >= len(plain["speeds"]):
            return
        stamp = {"sec": plain["stamp_sec"][k], "nanosec": plain["stamp_nanosec"][k]}
        if len(plain["modes"]) > k:
            self.on_command(SORT_MODE_CMD, BATCH, {"header": {"stamp": stamp}, "mode": plain["modes"][k]}, received)
        self.on_command(SPEED_CMD, BATCH, {"header": {"stamp": stamp}, "speed": plain["speeds"][k]}, received)

    def answered(self, stamp: int, topics) -> bool:
        return stamp in self.wrong_during or all(t in self.got.get(stamp, {}) for t in topics)


class _CheckPace(Pace):
    """`play --lockstep`'s pacing, noting when each tick was published and awaiting the answers
    the bag shows for it (on every command topic, not only ``cmd/speed``)."""

    def __init__(
        self, tool, selection, pubs, stop, answers: _Answers, expected, answer_timeout: float, bar, subs: list[tuple]
    ):
        super().__init__(tool, selection, pubs, stop, set(), answer_timeout)
        self.answers, self.expected, self.bar, self.subs = answers, expected, bar, subs
        self.published_at: dict[int, int] = {}
        self.timed_out: set[int] = set()
        self.unread = 0  # messages not written: their topic had no reader

    def _publish(self, m) -> None:
        stamp = stamp_ns(m.plain)
        if stamp is not None and stamp not in self.published_at and (self.answers.current or -1) < stamp:
            self.published_at[stamp] = time.time_ns()
            self.answers.current = stamp
            self.bar.update(1)
        # As the node does: a topic nobody reads is not written (a volatile sample reaches no
        # reader that matches later anyway); the check's round trip is shorter for it.
        if self.pubs[m.topic].get_subscription_count() == 0:
            self.unread += 1
            return
        super()._publish(m)

    def _await_answer(self, stamp: int | None) -> None:
        topics = self.expected.get(stamp)
        if not topics:
            return

        def answered() -> bool:
            self.tool.take_into(self.subs)
            return self.answers.answered(stamp, topics) or self.stop()

        try:
            # On the command subscriptions alone, not the executor: the shorter round trip.
            self.tool.waiter.until_received(
                [sub for sub, _ in self.subs],
                answered,
                self.answer_timeout,
                lambda: f"the controller's answer to the tick stamped {stamp / 1e9:.3f} s",
            )
        except BridgeTimeout:
            self.timed_out.add(stamp)


def _subscribe_commands(tool: ToolNode, namespace: str, answers: _Answers) -> list[tuple]:
    """The raw command subscriptions, each with the callback that files what it receives."""

    def on_command(topic: str):
        return lambda data, t: answers.on_command(topic, topic, decode(data, LINE_TYPES[topic]), t)

    def on_batch(data: bytes, t: int) -> None:
        answers.on_batch(decode(data, BATCH_TYPE), t)

    handlers = [(join(namespace, topic), LINE_TYPES[topic], on_command(topic)) for topic in FIELDS]
    handlers.append((join(namespace, BATCH), BATCH_TYPE, on_batch))
    return [(tool.raw_subscription(name, msgtype, callback), callback) for name, msgtype, callback in handlers]


def _wait_for_controller(tool: ToolNode, selection: Selection, pubs: dict, subs: list, wait: float) -> None:
    """Its readers (as `play` waits for them), then a writer of any command topic: volatile
    samples sent before matching are lost, both ways."""
    started = time.monotonic()
    try:
        wait_for_subscribers(tool, selection, pubs, wait)
        tool.until(
            lambda: any(s.get_publisher_count() for s, _ in subs),
            max(0.1, wait - (time.monotonic() - started)),
            lambda: "a writer of " + ", ".join(s.topic_name for s, _ in subs),
        )
    except TimeoutError as e:
        raise BridgeTimeout(
            f"{e}: no controller answers in {selection.out_ns} (start one there, or pass --controller CMD)"
        ) from None
    tool.spin_for(0.5)  # our readers are matched; give theirs a moment too


def _tick_positions(selection: Selection) -> dict[int, tuple[int, int]]:
    """stamp -> (episode, step) of each played tick, from its messages that carry them."""
    out = {}
    for m in selection.messages:
        p = m.plain
        if "episode" in p and "step" in p and stamp_ns(p) is not None:
            out.setdefault(stamp_ns(p), (int(p["episode"]), int(p["step"])))
    return out


def run_open_loop(bag: Bag, verdict: Verdict, run: RunOptions, *, namespace: str | None, period_ns: int) -> None:
    """Plays ``bag`` to the controller and fills ``verdict``'s answers (see the module's docstring).
    Raises BridgeError (the controller died, nobody answers) for the caller to report."""
    answer_timeout, stop = run.answer_timeout, run.stop
    expected_msgs = expected_commands(bag)
    selection = Selection.of(bag, None, namespace, None, True)
    verdict.namespace = selection.out_ns
    ticks = {s for m in selection.messages if (s := stamp_ns(m.plain)) is not None}
    answers = _Answers(ticks, int((bag.info.node if bag.info else {}).get("line", 0) or 0))
    expected = {s: set(topics) for s, topics in expected_msgs.items() if s in ticks}
    tool = ToolNode("sorting_line_bag_check", run.process)
    bar = progress_bar(len(ticks), run.progress, "check", "tick")
    try:
        pubs = {t: tool.publisher(selection.target(t), bag.types[t]) for t in selection.chosen}
        subs = _subscribe_commands(tool, selection.out_ns, answers)
        _wait_for_controller(tool, selection, pubs, subs, run.wait)
        started = time.monotonic()
        pace = _CheckPace(tool, selection, pubs, stop, answers, expected, answer_timeout, bar, subs)
        pace.tick_by_tick()
        tool.spin_for(0.05)  # answers still in flight
        tool.take_into(subs)
        verdict.seconds = time.monotonic() - started
    finally:
        bar.close()
        tool.close()
    verdict.ticks = len(pace.published_at)
    _judge(verdict, expected_msgs, answers, pace, _tick_positions(selection), period_ns, answer_timeout)
    if answers.duplicates:
        verdict.notes.append(
            f"{answers.duplicates} second commands for a tick already answered (the node drops "
            "them; the first one is compared)"
        )
    unexpected = sum(1 for s, got in answers.got.items() for t in got if t not in expected_msgs.get(s, {}))
    if unexpected:
        verdict.notes.append(
            f"{unexpected} answers to ticks the bag shows no such command for (not compared: the "
            "recorded controller's was lost, or it did not answer there)"
        )


def _judge(
    verdict: Verdict,
    expected_msgs: dict,
    answers: _Answers,
    pace: _CheckPace,
    positions: dict,
    period_ns: int,
    answer_timeout: float,
) -> None:
    def answer(stamp: int, topic: str, via: str, recorded) -> Answer:
        episode, step = positions.get(stamp, (None, None))
        field = FIELDS[topic][0] if via != BATCH else f"{FIELDS[topic][1]}[{answers.batch_entry}]"
        return Answer(stamp // period_ns, stamp, via, field, recorded, episode=episode, step=step)

    for stamp in sorted(pace.published_at):
        for topic, recorded in sorted(expected_msgs.get(stamp, {}).items()):
            via, plain, received = answers.got.get(stamp, {}).get(topic, (topic, None, None))
            a = answer(stamp, topic, via, recorded[FIELDS[topic][0]])
            if plain is None:
                if not any(w[0] == stamp and w[1] == topic for w in answers.wrong):
                    verdict.answers.append(a)  # missing (a wrong stamp is reported as that instead)
                continue
            a.latency_ms = (received - pace.published_at[stamp]) / 1e6
            a.late = stamp in pace.timed_out
            a.answered = plain[FIELDS[topic][0]]
            a.status, a.reason = _compare(topic, a.recorded, a.answered)
            if a.late:
                a.status = "missing"
            verdict.answers.append(a)
    for tick, topic, via, plain, _received in answers.wrong:
        stamp = tick if tick is not None else 0
        a = answer(stamp, topic, via, {"sec": stamp // 10**9, "nanosec": stamp % 10**9})
        got = stamp_ns(plain)
        a.field, a.answered, a.status = "header.stamp", plain["header"]["stamp"], "differing"
        a.reason = node_reason("stale" if tick is not None and got < tick else "unknown_tick")
        verdict.wrong_stamps.append(a)


def _compare(topic: str, recorded, answered) -> tuple[str, str | None]:
    """(matching or differing, the node's reason to refuse the answer if it would)."""
    if topic == SPEED_CMD:
        index = speed_index_of(answered)
        if index is None:
            return "differing", node_reason("invalid_speed")
        return ("matching" if index == speed_index_of(recorded) else "differing"), None
    if int(answered) not in MODES.values():
        return "differing", node_reason("unknown_mode")
    return ("matching" if int(answered) == int(recorded) else "differing"), None
