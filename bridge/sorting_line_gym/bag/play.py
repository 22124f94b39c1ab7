"""`sorting-line-bag play`: publishes a bag's recorded data again, with its original timing (or
``rate`` times faster), for testing a controller (e.g. `sorting-line-controller`) against
recorded data instead of a live node.

By default it plays everything the node published (the sensors ``input``, ``belt/occupancy``,
``sensors/ratio``, and ``state``, ``events/reset``, ``/clock``), not the commands: those are the
controller's to send. ``namespace`` moves the line's topics to another namespace. The CDR bytes
are published as recorded (stamps unchanged). Timing follows the recorder's receive times.

With ``lockstep`` it ignores the timing and plays tick by tick, as a lock-step node would: a
tick's messages, then a wait (``answer_timeout``) for the controller's ``cmd/speed`` stamped
with that tick, if the bag shows an answer to it; then the next tick. A controller that stalls
for a moment (a busy machine) then loses nothing from its keep-last-10 queues.

Before the first message it waits until the ``wait_for`` topics (default: the line's ``input``)
have a subscriber, since volatile samples sent before matching are lost; at the end it waits
until every subscriber has acknowledged every sample (reliable QoS), so nothing is cut off.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

from rclpy.duration import Duration

from .bagfile import BagError, open_bag, topics_of
from .rosnode import ToolNode
from .schema import COMMANDS, LINE_TYPES, decode, join, relative_to, stamp_ns


@dataclass
class PlayResult:
    counts: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    recorded_seconds: float = 0.0
    #: lockstep: stamps (ns) of the ticks whose answer did not come in time
    unanswered: list[int] = field(default_factory=list)

    def summary(self) -> str:
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        text = (f"played {sum(self.counts.values())} messages in {self.seconds:.2f} s "
                f"(recorded over {self.recorded_seconds:.2f} s): {per_topic}")
        if self.unanswered:
            text += f"; no answer in time for {len(self.unanswered)} ticks (first at {self.unanswered[0] / 1e9:.3f} s)"
        return text


def play(path, *, rate: float = 1.0, topics: list[str] | None = None, namespace: str | None = None,
         wait_for: list[str] | None = None, wait: float = 10.0, stop: Callable[[], bool] = lambda: False,
         on_ready: Callable[[str], None] = print, lockstep: bool = False,
         answer_timeout: float = 5.0) -> PlayResult:
    """Plays the bag at ``path``. ``rate``: speed factor (2 = twice as fast; 0 = as fast as
    possible). ``topics``: absolute or relative to the recorded line (default: all but the
    commands). ``lockstep``: tick by tick, each after the controller's answer (see the module's
    docstring). Raises BagError for bad input, TimeoutError when nobody subscribes in time."""
    if rate < 0:
        raise BagError(f"--rate {rate}: must be >= 0 (0 plays as fast as possible)")
    bag = open_bag(path)
    line_ns = bag.info.namespace if bag.info else ""
    if topics:
        chosen = topics_of(bag, topics)
    else:
        chosen = [t for t in bag.types if (relative_to(line_ns, t) if line_ns else None) not in COMMANDS]

    def target(topic: str) -> str:
        rel = relative_to(line_ns, topic) if line_ns else None
        return join(namespace, rel) if namespace and rel is not None else topic

    out_ns = namespace or line_ns
    waits = wait_for if wait_for is not None else (["input"] if join(line_ns, "input") in chosen else [])
    messages = [m for m in bag.messages if m.topic in chosen]
    recorded_answers: set[int] = set()
    if lockstep:
        answers = join(line_ns, "cmd/speed") if line_ns else None
        if answers not in bag.types:
            raise BagError(f"{bag.path}: --lockstep needs the bag's cmd/speed, the answers it waits for")
        recorded_answers = {stamp_ns(m.plain) for m in bag.on(answers)}
    tool = ToolNode("sorting_line_bag_play")
    try:
        pubs = {t: tool.publisher(target(t), bag.types[t]) for t in chosen}
        answered: set[int] = set()
        if lockstep:
            tool.raw_subscription(join(out_ns, "cmd/speed"), LINE_TYPES["cmd/speed"],
                                  lambda data, _t: answered.add(stamp_ns(decode(data, LINE_TYPES["cmd/speed"]))))
        by_name = {target(t): p for t, p in pubs.items()}
        for w in waits:
            name = join(out_ns, w) if not w.startswith("/") else w
            if name not in by_name:
                raise BagError(f"--wait-for {w}: not one of the played topics ({', '.join(sorted(by_name))})")
            tool.until(lambda p=by_name[name]: p.get_subscription_count() > 0, wait, f"a subscriber on {name}")
        if waits:
            # A controller's other readers (ratio, belt) are announced with the one waited for:
            # give them a moment to match too (best effort: stale graph entries may never match).
            def known_matched() -> bool:
                return all(p.get_subscription_count() >= tool.node.count_subscribers(n) for n, p in by_name.items())

            try:
                tool.until(known_matched, 1.0, "the other subscribers of the played topics")
            except TimeoutError:
                pass
        on_ready(f"playing {len(messages)} messages on {len(pubs)} topics" + (f" into {namespace}" if namespace else ""))
        result = PlayResult()
        counts: dict[str, int] = {}
        t0 = messages[0].log_time if messages else 0
        started = time.monotonic()
        tick: int | None = None

        def await_answer(stamp: int | None) -> None:
            if stamp is None or stamp not in recorded_answers:
                return
            try:
                tool.until(lambda: stamp in answered or stop(), answer_timeout,
                           f"an answer on {join(out_ns, 'cmd/speed')} for the tick stamped {stamp / 1e9:.3f} s")
            except TimeoutError:
                result.unanswered.append(stamp)

        for m in messages:
            if stop():
                break
            if lockstep:
                stamp = stamp_ns(m.plain)
                if stamp is not None and stamp != tick:
                    if tick is None or stamp > tick:
                        await_answer(tick)
                        tick = stamp
            elif rate > 0:
                due = started + (m.log_time - t0) / 1e9 / rate
                while (left := due - time.monotonic()) > 0:
                    if stop():
                        break
                    time.sleep(min(left, 0.05))
            pubs[m.topic].publish(m.data)
            counts[target(m.topic)] = counts.get(target(m.topic), 0) + 1
        if lockstep and not stop():
            await_answer(tick)
        for p in pubs.values():
            p.wait_for_all_acked(Duration(seconds=5))
        result.counts = counts
        result.seconds = time.monotonic() - started
        result.recorded_seconds = (messages[-1].log_time - t0) / 1e9 if messages else 0.0
        return result
    finally:
        tool.close()
