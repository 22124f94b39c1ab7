"""`sorting-line-bag play`: publishes a bag's recorded data again, with its original timing (or
``rate`` times faster), for testing a controller (e.g. `sorting-line-controller`) against
recorded data instead of a live node.

By default it plays everything the node published (the sensors ``input``, ``belt/occupancy``,
``sensors/ratio``, and ``state``, ``events/reset``, ``/clock``), not the commands: those are the
controller's to send. ``namespace`` moves the line's topics to another namespace. The CDR bytes
are published as recorded (stamps unchanged). Timing follows the recorder's receive times.

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
from .schema import COMMANDS, join, relative_to


@dataclass
class PlayResult:
    counts: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    recorded_seconds: float = 0.0

    def summary(self) -> str:
        per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        return (f"played {sum(self.counts.values())} messages in {self.seconds:.2f} s "
                f"(recorded over {self.recorded_seconds:.2f} s): {per_topic}")


def play(path, *, rate: float = 1.0, topics: list[str] | None = None, namespace: str | None = None,
         wait_for: list[str] | None = None, wait: float = 10.0, stop: Callable[[], bool] = lambda: False,
         on_ready: Callable[[str], None] = print) -> PlayResult:
    """Plays the bag at ``path``. ``rate``: speed factor (2 = twice as fast; 0 = as fast as
    possible). ``topics``: absolute or relative to the recorded line (default: all but the
    commands). Raises BagError for bad input, TimeoutError when nobody subscribes in time."""
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
    tool = ToolNode("sorting_line_bag_play")
    try:
        pubs = {t: tool.publisher(target(t), bag.types[t]) for t in chosen}
        by_name = {target(t): p for t, p in pubs.items()}
        for w in waits:
            name = join(out_ns, w) if not w.startswith("/") else w
            if name not in by_name:
                raise BagError(f"--wait-for {w}: not one of the played topics ({', '.join(sorted(by_name))})")
            tool.until(lambda p=by_name[name]: p.get_subscription_count() > 0, wait, f"a subscriber on {name}")
        on_ready(f"playing {len(messages)} messages on {len(pubs)} topics" + (f" into {namespace}" if namespace else ""))
        result = PlayResult()
        counts: dict[str, int] = {}
        t0 = messages[0].log_time if messages else 0
        started = time.monotonic()
        for m in messages:
            if stop():
                break
            if rate > 0:
                due = started + (m.log_time - t0) / 1e9 / rate
                while (left := due - time.monotonic()) > 0:
                    if stop():
                        break
                    time.sleep(min(left, 0.05))
            pubs[m.topic].publish(m.data)
            counts[target(m.topic)] = counts.get(target(m.topic), 0) + 1
        for p in pubs.values():
            p.wait_for_all_acked(Duration(seconds=5))
        result.counts = counts
        result.seconds = time.monotonic() - started
        result.recorded_seconds = (messages[-1].log_time - t0) / 1e9 if messages else 0.0
        return result
    finally:
        tool.close()
