"""What a recording missed, from the node's own counters: nothing is lost silently.

The node reports each line on /diagnostics once a second (wall time), between ticks: among its
values ``messages_published`` (messages of the line's own topics it sent) and ``sim_time`` (the
stamp of its last tick; tick k is stamped k * tick_period). Between two such reports the node sent
``published`` messages, all stamped in ``(sim_time_0, sim_time_1]``; the recorder counts what it
received with stamps in that window (every line message opens with its std_msgs/Header). The
difference is what the recorder missed: its DDS queue overflowed while it fell behind, or the
messages were lost on the way. Per topic, each per-tick topic (input, belt/occupancy, state, the
ratio sensor of an advanced line) has one message per tick of the window.

The comparison needs every topic the node publishes for the line to be recorded (the default); with
a ``--topic`` selection that leaves some out, the recorder says it could not compare.
"""

from __future__ import annotations

import json
import struct
from collections import deque

from ...line.topics import BELT_OCCUPANCY, DIAGNOSTICS, EVOLUTION_EVENT, INPUT, SENSORS_RATIO, STATE
from ..format.description import RECORDING_KEY
from ..format.topics import PUBLISHED, relative_to

#: Topics with exactly one message per tick (the ratio sensor only on a non-evolving advanced line).
PER_TICK = (INPUT, BELT_OCCUPANCY, STATE)
#: Latest stamps kept per topic: far more than arrive between the last report and the end.
RECENT = 4096


def header_stamp(data: bytes | memoryview) -> int | None:
    """The header stamp (ns) of a line message's CDR bytes (header first; little-endian CDR)."""
    if len(data) < 12 or data[1] != 1:  # encapsulation CDR_LE
        return None
    sec, nanosec = struct.unpack_from("<iI", data, 4)
    return sec * 1_000_000_000 + nanosec


def _stamp(text: str) -> int:
    sec, _, frac = text.partition(".")
    return int(sec) * 1_000_000_000 + int((frac + "000000000")[:9])


class LossCounter:
    """Fed the line's /diagnostics statuses and the stamps of the line messages received."""

    def __init__(self, namespace: str, recorded: list[str], variant: str | None, evolving: bool, tick_period: float):
        self.namespace = namespace
        self.period = max(1, round(tick_period * 1e9))
        rel = {relative_to(namespace, t) for t in recorded}
        published = [t for t in PUBLISHED if t != EVOLUTION_EVENT or evolving]
        if variant == "basic" and not evolving:
            published.remove(SENSORS_RATIO)
        self.missing_topics = [t for t in published if t not in rel]
        self.per_tick = list(PER_TICK) + ([SENSORS_RATIO] if variant == "advanced" and not evolving else [])
        self.first: tuple[int, int] | None = None  # (sim_time, published) of the first report
        self.last: tuple[int, int] | None = None
        # Per topic: messages stamped after the first report, and the latest stamps (for those
        # after the last report). Before the first report arrives, stamps wait in `early`.
        self.after_first = {t: 0 for t in published}
        self.recent = {t: deque(maxlen=RECENT) for t in published}
        self.early: list[tuple[str, int]] = []

    def on_status(self, values: dict[str, str]) -> None:
        try:
            point = (_stamp(values["sim_time"]), int(values["messages_published"]))
        except (KeyError, ValueError):
            return
        if self.first is None:
            self.first = point
            for rel, stamp in self.early:
                self.after_first[rel] += stamp > point[0]
            self.early = []
        self.last = point

    def on_message(self, topic: str, data: bytes | memoryview) -> None:
        rel = relative_to(self.namespace, topic)
        stamp = header_stamp(data) if rel in self.recent else None
        if stamp is None:
            return
        if self.first is None:
            self.early.append((rel, stamp))
        else:
            self.after_first[rel] += stamp > self.first[0]
        self.recent[rel].append(stamp)

    def report(self) -> dict:
        """``{"compared": bool, ...}``: the window, published, received, missing, per-topic missing."""
        if self.missing_topics:
            return {
                "compared": False,
                "why": f"not every topic of the line was recorded ({', '.join(self.missing_topics)} left out)",
            }
        if self.first is None or self.last is None or self.last == self.first:
            return {"compared": False, "why": f"fewer than two {DIAGNOSTICS} reports of the line arrived"}
        (t0, p0), (t1, p1) = self.first, self.last
        received = {rel: n - sum(1 for s in self.recent[rel] if s > t1) for rel, n in self.after_first.items()}
        ticks = (t1 - t0) // self.period
        topics = {rel: ticks - received[rel] for rel in self.per_tick if received[rel] < ticks}
        missing = (p1 - p0) - sum(received.values())
        return {
            "compared": True,
            "window_ns": [t0, t1],
            "ticks": ticks,
            "published": p1 - p0,
            "received": sum(received.values()),
            "missing": max(0, missing),
            "topics": topics,
        }


def _window(r: dict) -> str:
    return f"sim time {r['window_ns'][0] / 1e9:g}-{r['window_ns'][1] / 1e9:g} s"


def describe_losses(report: dict | None) -> str:
    """One line for the end of `record` and for `info`."""
    if not report:
        return "messages missed: not known (no comparison with the node's counters)"
    if not report.get("compared"):
        return f"messages missed: not compared with the node's counters: {report.get('why')}"
    window = _window(report)
    if report["missing"] == 0:
        return (
            f"messages missed: none (the node published {report['published']} messages of the line in "
            f"{window}, {report['ticks']} ticks; all are in the bag)"
        )
    per_topic = ", ".join(f"{t} {n}" for t, n in sorted(report["topics"].items())) or "events"
    return (
        f"MESSAGES MISSED: {report['missing']} of the {report['published']} the node published in {window} "
        f"are not in the bag ({per_topic}): the recorder fell behind or they were lost on the way"
    )


def recording_notes(custom: dict[str, str]) -> list[str]:
    """What `info` says about the recording: its options, how it ended, what it missed."""
    try:
        rec = json.loads(custom.get(RECORDING_KEY, ""))
    except ValueError:
        return []
    o = rec.get("options") or {}
    split = [f"{k} {o[k]:g}" for k in ("max_bag_size", "max_bag_duration") if o.get(k)]
    notes = [
        f"  recording: {rec.get('state', '?')}; compression {o.get('compression', 'none')}"
        + (f"; split at {', '.join(split)}" if split else "")
    ]
    if rec.get("error"):
        notes.append(f"  recording failed: {rec['error']}")
    if rec.get("reindexed"):
        notes.append(f"  reindexed after a cut: {json.dumps(rec['reindexed'], sort_keys=True)}")
    if rec.get("state") not in ("recording", "cut"):
        notes.append("  " + describe_losses(rec.get("losses")))
    return notes
