"""A bag its recorder did not finish: telling so (:func:`check_complete`, which every reading
tool runs through ``open_bag``, :mod:`.reader`) and recovering it (:func:`reindex`, `sorting-line-bag reindex BAG`,
as `ros2 bag reindex` does for rosbag2).

A recorder killed by SIGKILL (the OOM killer, a crashed container, a pulled plug) leaves
metadata.yaml as it was last written (at the start or the last split) and an MCAP file without its
summary and footer; everything up to the last chunk it fsynced is on disk (see :mod:`.writer`).
`reindex` reads each such file with the `mcap` library's stream reader, chunk by chunk, until the
first chunk that was cut (its CRC or its decompression fails), writes what it read to a new MCAP
file with a summary, keeps the original next to it as ``<file>.cut``, and rebuilds metadata.yaml
from the MCAP files' summaries and their ``sorting_line`` metadata record (the line's description).

The reading tools do not recover a bag themselves: a bag may be read-only, still being recorded,
or evidence someone wants kept as it is; recovery writes files, so the user asks for it.
"""

from __future__ import annotations

import json
import os
import re
import socket
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path

import yaml
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from ..format.description import META_RECORD, RECORDING_KEY, RESERVE_NAME
from ..format.errors import BagError
from .metadata import FileStats, TopicStats, rosbag2_metadata, write_metadata

MAGIC = b"\x89MCAP0\r\n"
FOOTER_BYTES = 29  # opcode, length, summary start, summary offset start, CRC
CUT_SUFFIX = ".cut"


def has_footer(path: Path) -> bool:
    """Whether an MCAP file ends with its footer (a finished file)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            if f.tell() < 2 * len(MAGIC) + FOOTER_BYTES:
                return False
            f.seek(-(FOOTER_BYTES + len(MAGIC)), os.SEEK_END)
            tail = f.read()
    except OSError:
        return True  # not ours to judge: the reader says what is wrong
    return tail[0] == 0x02 and tail.endswith(MAGIC)


def mcap_files(path: Path) -> list[Path]:
    """The MCAP files of a bag directory in recording order (rosbag2's ``<bag>_<k>.mcap``)."""

    def order(p: Path):
        m = re.search(r"_(\d+)$", p.stem)
        return (p.stem[: m.start()] if m else p.stem, int(m.group(1)) if m else -1, p.name)

    return sorted(path.glob("*.mcap"), key=order)


def _metadata(path: Path) -> dict:
    try:
        return yaml.safe_load((path / "metadata.yaml").read_text()).get("rosbag2_bagfile_information") or {}
    except (OSError, yaml.YAMLError, AttributeError):
        return {}


def _live_recorder(info: dict) -> str:
    """ " (sorting-line-bag record, pid N, is still running)" when the bag's recorder seems alive."""
    try:
        rec = json.loads((info.get("custom_data") or {}).get(RECORDING_KEY, "{}"))
        if rec.get("state") != "recording" or rec.get("host") != socket.gethostname():
            return ""
        os.kill(int(rec["pid"]), 0)
    except (ValueError, KeyError, TypeError, ProcessLookupError, PermissionError):
        return ""
    return f" - or it is still being recorded: its recorder (pid {rec['pid']}) is running"


def check_complete(path: Path) -> None:
    """BagError naming the way out when ``path`` is a bag (or MCAP file) its recorder did not
    finish: no metadata.yaml next to MCAP files, MCAP files metadata.yaml does not list, or an
    MCAP file without its footer. Returns quietly otherwise (other faults are the reader's)."""
    how = "its recorder was killed or the disk filled"
    if path.is_file():
        if path.suffix == ".mcap" and not has_footer(path):
            raise BagError(
                f"{path}: cannot read the bag: the MCAP file ends without its summary and footer (the "
                f"recording was cut: {how}). `sorting-line-bag reindex DIR` recovers it in a bag "
                "directory: move the file into a directory of its own first"
            )
        return
    files = mcap_files(path)
    if not (path / "metadata.yaml").is_file():
        if files:
            raise BagError(
                f"{path}: not a ROS 2 bag directory (no metadata.yaml), but it holds {len(files)} MCAP "
                f"file(s), a recording that did not finish ({how}): `sorting-line-bag reindex {path}` "
                "rebuilds metadata.yaml from them"
            )
        return
    info = _metadata(path)
    listed = set(info.get("relative_file_paths") or [])
    cut = [f.name for f in files if f.name in listed and not has_footer(f)]
    unlisted = [f.name for f in files if f.name not in listed]
    if cut or unlisted:
        what = (
            f"{', '.join(cut)} end(s) without the MCAP summary and footer"
            if cut
            else f"metadata.yaml does not list {', '.join(unlisted)}"
        )
        raise BagError(
            f"{path}: cannot read the bag: {what}: the recording was cut ({how}){_live_recorder(info)}. "
            f"`sorting-line-bag reindex {path}` recovers what is on disk"
        )


@dataclass
class ReindexResult:
    path: Path
    files: list[FileStats] = field(default_factory=list)
    #: file name -> (messages kept, bytes of the cut end that were dropped)
    recovered: dict[str, tuple[int, int]] = field(default_factory=dict)

    def summary(self) -> str:
        total = sum(f.count for f in self.files)
        lines = [f"{self.path}: metadata.yaml rebuilt: {len(self.files)} MCAP file(s), {total} messages"]
        for name, (kept, dropped) in self.recovered.items():
            lines.append(
                f"  {name}: recovered {kept} messages (a cut end of {dropped} bytes dropped); "
                f"the file as found is kept as {name}{CUT_SUFFIX}"
            )
        return "\n".join(lines)


def reindex(path: str | Path) -> ReindexResult:
    """Recovers every MCAP file of bag directory ``path`` that has no footer and rebuilds
    metadata.yaml from the files; BagError when ``path`` is no such directory."""
    path = Path(path)
    if not path.is_dir():
        raise BagError(f"{path}: not a directory (reindex works on a bag directory holding .mcap files)")
    files = mcap_files(path)
    if not files:
        raise BagError(f"{path}: no .mcap files to reindex")
    old = _metadata(path)
    if _live_recorder(old):  # recovering a file under a live writer would take it from under it
        raise BagError(
            f"{path} is being recorded: its recorder{_live_recorder(old).split('recorder', 1)[1]}; "
            "reindex it once that has ended (or was killed)"
        )
    result = ReindexResult(path)
    for f in files:
        if not has_footer(f):
            result.recovered[f.name] = _recover(f)
    custom: dict[str, str] = {}
    topics: dict[str, TopicStats] = {}
    for f in files:
        stats, found = _index(f, topics)
        result.files.append(stats)
        custom = {**found, **custom}
    custom = {**custom, **(old.get("custom_data") or {})}
    custom[RECORDING_KEY] = _reindexed(custom.get(RECORDING_KEY), result)
    write_metadata(path, rosbag2_metadata(result.files, topics, custom))
    (path / RESERVE_NAME).unlink(missing_ok=True)
    return result


def _reindexed(text: str | None, result: ReindexResult) -> str:
    """The recording's description, saying it was reindexed (and closed, if it never was)."""
    try:
        rec = json.loads(text) if text else {}
    except ValueError:
        rec = {}
    if rec.get("state", "recording") == "recording":
        rec["state"] = "cut"
    rec["reindexed"] = {
        name: {"messages": kept, "dropped_bytes": dropped} for name, (kept, dropped) in result.recovered.items()
    }
    return json.dumps(rec, sort_keys=True)


def _index(path: Path, topics: dict[str, TopicStats]) -> tuple[FileStats, dict[str, str]]:
    """One finished MCAP file's statistics (added to ``topics``) and its line description."""
    stats = FileStats(path.name)
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            custom = next((dict(m.metadata) for m in reader.iter_metadata() if m.name == META_RECORD), {})
    except Exception as e:  # noqa: BLE001 - the mcap reader raises many kinds for a damaged file
        raise BagError(f"{path}: cannot read the MCAP file: {type(e).__name__}: {e}") from None
    if summary is None or summary.statistics is None:
        raise BagError(f"{path}: the MCAP file has no summary statistics to index")
    s = summary.statistics
    for cid, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        t = topics.setdefault(
            channel.topic, TopicStats(schema.name if schema else "", channel.metadata.get("offered_qos_profiles", ""))
        )
        t.count += s.channel_message_counts.get(cid, 0)
    stats.count = s.message_count
    if s.message_count:
        stats.start, stats.end = s.message_start_time, s.message_end_time
    return stats, custom


def _recover(path: Path) -> tuple[int, int]:
    """Rewrites a footerless MCAP file with everything before its cut; returns (messages, dropped bytes).
    Chunks keep their compression; records before the first chunk wait for it to tell which."""
    tmp = path.with_name(path.name + ".recovering")
    copier = _Copier()
    good_end = 0
    with open(path, "rb") as src, open(tmp, "wb") as dst:
        copier.stream = dst
        try:
            for record in StreamReader(src, emit_chunks=True).records:
                if isinstance(record, Chunk):
                    copier.add(breakup_chunk(record, validate_crc=True), record.compression)  # a cut chunk fails
                elif isinstance(record, (Metadata, Schema, Channel, Message)):
                    copier.add([record], None)
                good_end = src.tell()
        except Exception:  # noqa: BLE001 - the cut: a short or damaged record ends the readable part
            pass
        copier.writer_for("").finish()
        dst.flush()
        os.fsync(dst.fileno())
        dropped = os.fstat(src.fileno()).st_size - good_end
    os.replace(path, path.with_name(path.name + CUT_SUFFIX))
    os.replace(tmp, path)
    return copier.messages, max(0, dropped)


class _Copier:
    """Copies MCAP records into a new file (renumbering schema and channel ids)."""

    def __init__(self):
        self.stream = None
        self.writer: Writer | None = None
        self.waiting: list = []
        self.schemas: dict[int, int] = {}
        self.channels: dict[int, int] = {}
        self.messages = 0

    def writer_for(self, compression: str) -> Writer:
        if self.writer is None:
            kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}
            self.writer = Writer(self.stream, compression=kinds.get(compression, CompressionType.NONE))
            self.writer.start(profile="ros2", library=f"sorting_line_gym reindex, mcap {version('mcap')}")
            waiting, self.waiting = self.waiting, []
            self._copy(waiting)
        return self.writer

    def add(self, records: list, compression: str | None) -> None:
        if compression is None and self.writer is None:
            self.waiting.extend(records)
        else:
            self.writer_for(compression or "")
            self._copy(records)

    def _copy(self, records: list) -> None:
        w = self.writer
        for r in records:
            if isinstance(r, Metadata):
                w.add_metadata(r.name, dict(r.metadata))
            elif isinstance(r, Schema) and r.id not in self.schemas:
                self.schemas[r.id] = w.register_schema(r.name, r.encoding, r.data)
            elif isinstance(r, Channel) and r.id not in self.channels:
                self.channels[r.id] = w.register_channel(
                    r.topic, r.message_encoding, self.schemas.get(r.schema_id, 0), dict(r.metadata)
                )
            elif isinstance(r, Message) and r.channel_id in self.channels:
                w.add_message(self.channels[r.channel_id], r.log_time, r.data, r.publish_time, r.sequence)
                self.messages += 1
