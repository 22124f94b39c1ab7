"""Field-by-field comparison of what a bag recorded with what a replay published: decoded values,
never bytes (Fast DDS leaves garbage in CDR padding), ordered by tick and, within a tick, by the
order the node publishes (``events/reset``, the sensors, ``state``, then ``/clock``), so the first
difference reported is the earliest one, named by topic, tick and field."""

from __future__ import annotations

import copy
from collections import defaultdict
from dataclasses import dataclass
from typing import Any

from ..format.topics import CLOCK, PUBLISHED
from ..storage.schema import stamp_ns

NS_PER_S = 1_000_000_000
#: Topic order within a tick.
ORDER = {t: k for k, t in enumerate([*PUBLISHED, CLOCK])}


def show_ns(ns: int) -> str:
    return f"{ns // NS_PER_S}.{ns % NS_PER_S:09d}"


def _time(ns: int) -> dict:
    return {"sec": ns // NS_PER_S, "nanosec": ns % NS_PER_S}


def shifted(message: dict, stamp_shift: int, episode_shift: int) -> dict:
    """``message`` (plain values) as it reads ``stamp_shift`` ns and ``episode_shift`` episodes
    later: how a replay node, which started its own tick and episode counters afresh, lines up
    with the recorded one."""
    m = copy.deepcopy(message)
    header = m.get("header")
    if isinstance(header, dict) and "stamp" in header:
        header["stamp"] = _time(stamp_ns(m) + stamp_shift)
    elif "clock" in m:
        m["clock"] = _time(stamp_ns(m) + stamp_shift)
    if isinstance(m.get("episode"), int):
        m["episode"] += episode_shift
    return m


def first_field_difference(a: Any, b: Any, path: str = "") -> tuple[str, Any, Any] | None:
    """The first field (dotted path, ``[i]`` for sequence items) where ``a`` and ``b`` differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        for key in a:
            if key not in b:
                return (f"{path}.{key}".lstrip("."), a[key], "<missing>")
            found = first_field_difference(a[key], b[key], f"{path}.{key}")
            if found:
                return found
        for key in b:
            if key not in a:
                return (f"{path}.{key}".lstrip("."), "<missing>", b[key])
        return None
    if isinstance(a, list) and isinstance(b, list):
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            found = first_field_difference(x, y, f"{path}[{i}]")
            if found:
                return found
        if len(a) != len(b):
            return (f"{path}.length".lstrip("."), len(a), len(b))
        return None
    if type(a) is not type(b) and not (isinstance(a, (int, float)) and isinstance(b, (int, float))):
        return (path.lstrip(".") or "<message>", a, b)
    return None if a == b else (path.lstrip(".") or "<message>", a, b)


@dataclass
class Difference:
    """The first place where the replay does not reproduce the bag."""

    topic: str
    tick: int
    stamp_ns: int
    field: str
    recorded: Any
    replayed: Any
    episode: int | None = None
    step: int | None = None

    def __str__(self) -> str:
        where = f"tick {self.tick} (stamp {show_ns(self.stamp_ns)} s"
        if self.episode is not None:
            where += f", episode {self.episode}" + (f" step {self.step}" if self.step is not None else "")
        where += ")"
        if self.field in ("<message>",):
            return f"{self.topic} at {where}: bag {self.recorded}, replay {self.replayed}"
        return f"{self.topic} at {where}, field {self.field}: bag {self.recorded!r}, replay {self.replayed!r}"


@dataclass
class Comparison:
    difference: Difference | None
    compared: dict[str, int]  # messages compared per topic
    ignored_after_end: int  # replay messages past the end of the bag's recording of their topic

    @property
    def identical(self) -> bool:
        return self.difference is None


def compare(recorded: dict[str, list[dict]], replayed: dict[str, list[dict]], period_ns: int) -> Comparison:
    """Compares per topic (relative names, or /clock) lists of plain messages already lined up
    (see :func:`shifted`). Every recorded message must be replayed identically; a replayed message
    the bag lacks is a difference too, unless it lies past the last recorded one of its topic
    (the recording ended)."""

    def keyed(messages: dict[str, list[dict]]) -> dict[tuple[int, int, str], list[dict]]:
        out: dict[tuple[int, int, str], list[dict]] = defaultdict(list)
        for topic, items in messages.items():
            for m in items:
                out[(stamp_ns(m), ORDER.get(topic, len(ORDER)), topic)].append(m)
        return out

    bag, rep = keyed(recorded), keyed(replayed)
    last = {t: max((stamp_ns(m) for m in items), default=-1) for t, items in recorded.items()}
    compared: dict[str, int] = defaultdict(int)
    ignored = 0
    for key in sorted(set(bag) | set(rep)):
        stamp, _, topic = key
        ours, theirs = bag.get(key, []), rep.get(key, [])
        if not ours and stamp > last.get(topic, -1):
            ignored += len(theirs)
            continue
        tick = stamp // period_ns if period_ns else 0
        sample = (ours or theirs)[0]
        ctx = dict(episode=sample.get("episode"), step=sample.get("step"))
        if not theirs:
            return Comparison(
                Difference(
                    topic,
                    tick,
                    stamp,
                    "<message>",
                    "has it",
                    "did not publish it (the replay node did not reach this tick)",
                    **ctx,
                ),
                dict(compared),
                ignored,
            )
        if not ours:
            return Comparison(
                Difference(topic, tick, stamp, "<message>", "has none", f"published {theirs[0]}", **ctx),
                dict(compared),
                ignored,
            )
        for a, b in zip(ours, theirs, strict=False):
            found = first_field_difference(a, b)
            if found:
                return Comparison(Difference(topic, tick, stamp, *found, **ctx), dict(compared), ignored)
            compared[topic] += 1
        if len(ours) != len(theirs):
            return Comparison(
                Difference(topic, tick, stamp, "<message>", f"{len(ours)} messages", f"{len(theirs)} messages", **ctx),
                dict(compared),
                ignored,
            )
    return Comparison(None, dict(compared), ignored)
