"""Reading sorting_line bags: ROS 2 bag directories (metadata.yaml + MCAP files, Jazzy's default
storage) through `rosbags`, with every message's schema embedded (:mod:`.writer` writes them).
The reading side of storage, as rosbag2's reader: the tools above read bags only through here.

Besides the messages, a bag of a line carries under ``custom_data`` (metadata.yaml) the key
``sorting_line`` (:mod:`..format.description`): JSON with the line's namespace and the options of
the node that served it (variant, input, noise, penalty, threshold, max_steps, the line's seed,
mode, tick_period), so that ``sorting-line-bag replay BAG`` can start an identical node with nothing else given.

A bag recorded by another tool (`ros2 bag record`: MCAP or sqlite3 storage, no ``custom_data``,
extra topics, any namespace) gets its description from its topics instead (:mod:`.foreign`),
with the source of each option in ``LineInfo.sources``; topics of types this tool does not know
are listed but never decoded or played.

Bad input (a missing path, something that is not a bag, a corrupt file, a topic the bag does not
have) raises :class:`BagError`, which the command line turns into a message and exit code 2.
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from rosbags.rosbag2 import Reader

from ..format.description import META_KEY, LineInfo
from ..format.errors import BagError
from ..format.topics import relative_to
from .foreign import describe_sources, line_namespace_of, options_from_topics
from .losses import recording_notes
from .recovery import check_complete
from .schema import decode, typestore


@dataclass
class BagMessage:
    topic: str
    msgtype: str
    log_time: int  # ns, when the recorder received it
    data: bytes
    _plain: dict | None = None

    @property
    def plain(self) -> dict:
        """The decoded message as plain values (decoded once)."""
        if self._plain is None:
            self._plain = decode(self.data, self.msgtype)
        return self._plain


@dataclass
class Bag:
    """A whole bag in memory (sorting_line bags are small: a tick is a few hundred bytes)."""

    path: Path
    types: dict[str, str]  # topic -> msgtype
    messages: list[BagMessage]  # in log-time order
    info: LineInfo | None
    custom: dict[str, str]
    #: Topics whose types this tool does not know (a bag of another recorder's extra topics).
    unknown: dict[str, str] = field(default_factory=dict)

    def on(self, topic: str) -> list[BagMessage]:
        return [m for m in self.messages if m.topic == topic]

    def by_relative_topic(self) -> dict[str, list[BagMessage]]:
        """The messages of the line's topics, keyed by their name relative to the line."""
        out: dict[str, list[BagMessage]] = defaultdict(list)
        ns = self.info.namespace if self.info else ""
        for m in self.messages:
            rel = relative_to(ns, m.topic) if ns else None
            out[rel if rel is not None else m.topic].append(m)
        return out


def _custom_data(path: Path) -> dict[str, str]:
    meta = path / "metadata.yaml"
    if not meta.is_file():
        return {}
    try:
        info = yaml.safe_load(meta.read_text()) or {}
        return dict(info.get("rosbag2_bagfile_information", {}).get("custom_data") or {})
    except (yaml.YAMLError, AttributeError, TypeError, ValueError) as e:
        raise BagError(f"{meta}: unreadable metadata ({e})") from None


def open_bag(path: str | Path) -> Bag:
    """Reads a bag directory (or a bare .mcap file) completely; BagError when it cannot."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path}: no such bag (expected a bag directory with metadata.yaml, or an .mcap file)")
    check_complete(path)  # a recording that was cut: says how to recover it
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise BagError(f"{path}: not a ROS 2 bag directory (no metadata.yaml)")
    store = typestore()
    try:
        with Reader(path) as reader:
            types = {c.topic: c.msgtype for c in reader.connections}
            messages = [BagMessage(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages()]
    except BagError:
        raise
    except Exception as e:  # noqa: BLE001 - rosbags raises many kinds for a corrupt file; all are bad input
        raise BagError(f"{path}: cannot read the bag: {type(e).__name__}: {e}") from None
    messages.sort(key=lambda m: m.log_time)
    custom = _custom_data(path) if path.is_dir() else {}
    info = None
    if META_KEY in custom:
        try:
            info = LineInfo.from_json(custom[META_KEY])
        except (ValueError, KeyError, TypeError) as e:
            raise BagError(f"{path}: custom_data {META_KEY!r} is not valid ({e})") from None
    unknown = {topic: t for topic, t in types.items() if t not in store.fielddefs}
    if info is None:
        info = _described_by_topics(types, [m for m in messages if m.topic not in unknown])
    if unknown and info is None:
        raise BagError(
            f"{path}: message types this tool does not know: {', '.join(sorted(set(unknown.values())))} "
            "(and no sorting line's state topic)"
        )
    return Bag(path, types, messages, info, custom, unknown)


def _described_by_topics(types: dict[str, str], messages: list[BagMessage]) -> LineInfo | None:
    """A bag of another recorder: its one line and what its topics tell of the node."""
    namespace = line_namespace_of(types)
    if namespace is None:
        return None
    by_topic: dict[str, list[BagMessage]] = defaultdict(list)
    for m in messages:
        by_topic[m.topic].append(m)
    try:
        options, sources = options_from_topics(namespace, by_topic)
    except (KeyError, TypeError, ValueError) as e:
        raise BagError(f"cannot read the line's description from its topics ({type(e).__name__}: {e})") from None
    return LineInfo(namespace, options, sources)


def describe(bag: Bag) -> str:
    """A short summary: topics with types and counts, and the line's description."""
    counts: dict[str, int] = defaultdict(int)
    for m in bag.messages:
        counts[m.topic] += 1
    lines = [f"{bag.path}: {len(bag.messages)} messages"]
    for topic in sorted(bag.types):
        unknown = "  (type not known here: not decoded or played)" if topic in bag.unknown else ""
        lines.append(f"  {topic:40s} {bag.types[topic]:45s} {counts[topic]:6d}{unknown}")
    if bag.info and bag.info.sources:
        lines += describe_sources(bag.info)
    elif bag.info:
        lines.append(f"  line {bag.info.namespace}: {json.dumps(bag.info.node, sort_keys=True)}")
    lines.extend(recording_notes(bag.custom))  # how the recording went, what it missed
    return "\n".join(lines)


def topics_of(bag: Bag, wanted: Iterable[str]) -> list[str]:
    """Absolute topic names for ``wanted`` (absolute, or relative to the bag's line); BagError
    naming any the bag does not have."""
    ns = bag.info.namespace if bag.info else ""
    out = []
    for t in wanted:
        name = t if t.startswith("/") else f"{ns.rstrip('/')}/{t}"
        if name not in bag.types:
            raise BagError(f"{bag.path}: no topic {name} in this bag (it has {', '.join(sorted(bag.types))})")
        out.append(name)
    return out
