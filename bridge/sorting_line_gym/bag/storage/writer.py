"""Writing sorting_line bags so that a crash loses at most the last half second: a ROS 2 bag
directory (rosbag2 version 9: metadata.yaml + MCAP files, Jazzy's default storage) written with
the `mcap` library, every message's .msg schema embedded.

What makes it safe to lose the writing process at any moment (SIGKILL, the OOM killer, a pulled
plug):

- metadata.yaml is written when the bag is created (with the line's description and the
  recording's options under ``custom_data``) and rewritten, atomically, at every split and at the
  end; each MCAP file also opens with the same description as an MCAP metadata record
  (``sorting_line``), so ``sorting-line-bag reindex`` can rebuild metadata.yaml from the MCAP
  files alone;
- the MCAP chunk in progress is closed by time as well as by size: every ``flush_interval``
  seconds (0.5) it is written out and fsynced, so what arrived more than about that long ago is
  on disk. A file cut there has no summary and footer: `reindex` recovers it (see
  :mod:`.recovery`).

Splitting (``--max-bag-size``, ``--max-bag-duration``) finishes the current MCAP file and starts
``<bag>_<k+1>.mcap`` in the same directory, as rosbag2 does; ``--compression zstd`` (or ``lz4``)
compresses each MCAP chunk, which rosbag2, `rosbags`, the `mcap` tools and Foxglove read.

A full disk or an output that stops being writable ends the recording with :class:`BagWriteError`
naming the file and the cause. A reserve file in the bag directory (``.sorting_line_reserve``,
allocated at the start and removed at the end) is freed first, so the chunk in flight, the MCAP
summary and metadata.yaml can still be written: what was recorded before stays readable.

Memory hardly grows with the recording: one chunk in flight, and per file the MCAP summary's
index entry per chunk (packed: ~10 bytes a topic), which a split starts afresh.
"""

from __future__ import annotations

import errno
import json
import os
import socket
import time
from array import array
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from importlib.metadata import version
from pathlib import Path

import yaml
from mcap.writer import CompressionType, Writer
from rosbags.rosbag2.metadata import dump_qos_v9

from ..format.description import META_RECORD, RECORDING_KEY, RESERVE_NAME
from ..format.errors import BagError, BagWriteError
from ..format.options import WriteOptions
from .metadata import FileStats, TopicStats, rosbag2_metadata, write_metadata
from .schema import NODE_QOS, typestore

#: Seconds between closing the chunk in progress and fsyncing it.
FLUSH_INTERVAL = 0.5
#: A chunk is also closed when it reaches this many bytes (before compression).
CHUNK_SIZE = 256 * 1024
#: The MCAP chunk compression of each name ``--compression`` takes (format.options.COMPRESSION_NAMES).
COMPRESSIONS = {"none": CompressionType.NONE, "zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}
#: Space held back for writing the end of the bag after the disk filled; grown with the summary.
RESERVE_BYTES = 512 * 1024
#: An upper bound of the MCAP summary's bytes per chunk: a chunk index, and per channel its
#: message-index offset.
SUMMARY_BYTES_PER_CHUNK = 120
SUMMARY_BYTES_PER_CHANNEL = 10
#: An MCAP message's bytes besides its data: its record (opcode, length, channel, sequence, times)
#: and its entry in the chunk's message index (time, offset).
MESSAGE_RECORD_BYTES = 31 + 16
#: An MCAP record's opcode, length and a few small fields.
RECORD_BYTES = 16


class _SyncedStream:
    """The file an MCAP writer writes to: bytes are held until :meth:`commit`, which writes them
    and fsyncs, so the file on disk always ends where a commit ended (at a record boundary)."""

    def __init__(self, path: Path):
        self.path = path
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.pending = bytearray()
        self.written = 0  # bytes in the file
        self.committed = 0  # where the last complete commit ended

    def write(self, data) -> int:
        self.pending += data
        return len(data)

    def tell(self) -> int:
        return self.written + len(self.pending)

    def flush(self) -> None:  # the MCAP writer's; the data goes out at commit()
        pass

    def commit(self) -> None:
        while self.pending:
            n = os.write(self.fd, self.pending)
            del self.pending[:n]
            self.written += n
        os.fsync(self.fd)
        self.committed = self.written

    def cut_back(self) -> None:
        """Drops what a failed commit wrote in part: the file ends at the last complete commit."""
        self.pending.clear()
        os.ftruncate(self.fd, self.committed)
        self.written = self.committed

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class _PackedOffsets(Mapping):
    """A chunk index's channel -> message-index offset map in two arrays (what the summary writes)."""

    __slots__ = ("_ids", "_offsets")

    def __init__(self, offsets: dict[int, int]):
        self._ids = array("H", offsets.keys())
        self._offsets = array("Q", offsets.values())

    def __getitem__(self, channel: int) -> int:
        try:
            return self._offsets[self._ids.index(channel)]
        except ValueError:
            raise KeyError(channel) from None

    def __iter__(self):
        return iter(self._ids)

    def __len__(self) -> int:
        return len(self._ids)

    def items(self):
        return zip(self._ids, self._offsets, strict=True)


class _McapFile:
    """One MCAP file of the bag, its schemas and channels registered as topics come."""

    def __init__(self, path: Path, compression: str, description: dict[str, str]):
        self.stream = _SyncedStream(path)
        self.stats = FileStats(path.name)
        self.writer = Writer(self.stream, chunk_size=CHUNK_SIZE, compression=COMPRESSIONS[compression])
        self.writer.start(profile="ros2", library=f"sorting_line_gym, mcap {version('mcap')}")
        self.writer.add_metadata(META_RECORD, description)
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.chunks = 0
        self.summary_bytes = 0  # what the summary will take besides the chunk indexes
        self._packed = 0  # chunk indexes packed so far
        self.finished = False
        # Bytes of messages in the chunk in progress; of closed chunks after and before compression.
        self.unflushed = self.compressed = self.uncompressed = 0

    def add_topic(self, topic: str, msgtype: str, qos: str) -> None:
        if msgtype not in self.schemas:
            msgdef, _ = typestore().generate_msgdef(msgtype, ros_version=2)
            self.schemas[msgtype] = self.writer.register_schema(msgtype, "ros2msg", msgdef.encode())
            self.summary_bytes += len(msgdef) + len(msgtype) + RECORD_BYTES
        self.channels[topic] = self.writer.register_channel(
            topic, "cdr", self.schemas[msgtype], {"offered_qos_profiles": qos}
        )
        self.summary_bytes += len(topic) + len(qos) + 3 * RECORD_BYTES
        self.unflushed = self.summary_bytes  # schemas and channels go in the first chunk, and again in the summary

    def write(self, topic: str, log_time: int, data) -> None:
        before = self.stream.tell()
        self.unflushed += len(data) + MESSAGE_RECORD_BYTES
        self.writer.add_message(self.channels[topic], log_time=log_time, data=bytes(data), publish_time=log_time)
        if self.stream.tell() != before:  # the writer closed a chunk by size
            self._chunk_closed()
        s = self.stats
        s.count += 1
        s.start, s.end = min(s.start, log_time), max(s.end, log_time)

    def _chunk_closed(self) -> None:
        self.unflushed = 0
        self.chunks += 1
        # The mcap writer keeps each chunk's index, with a dict of every channel's message-index
        # offset, until it writes the summary: ~25 KB a chunk with 257 topics, two chunks a second.
        # Packed, the same offsets take 10 bytes a channel. (mcap 1.6.0, pinned: a private list.)
        indexes = self.writer._Writer__chunk_indices
        for index in indexes[self._packed :]:
            index.message_index_offsets = _PackedOffsets(index.message_index_offsets)
            self.compressed += index.compressed_size
            self.uncompressed += index.uncompressed_size
        self._packed = len(indexes)

    def size(self) -> int:
        """The file's size once the chunk in progress is written (compressed as the chunks so far were)."""
        ratio = self.compressed / self.uncompressed if self.uncompressed else 1.0
        summary = self.summary_bytes + (self.chunks + 1) * (SUMMARY_BYTES_PER_CHUNK + 10 * len(self.channels))
        return self.stream.tell() + int(self.unflushed * ratio) + summary

    def flush(self) -> None:
        self.writer.flush()
        if self.unflushed:
            self._chunk_closed()
        self.stream.commit()

    def finish(self) -> None:
        """Summary and footer (once, even when a commit failed and is tried again), then closes."""
        if not self.finished:
            self.finished = True
            self.writer.finish()
        self.stream.commit()
        self.stream.close()


@dataclass
class _Recording:
    """What metadata.yaml says about the recording (custom_data ``sorting_line_recording``)."""

    options: dict
    state: str = "recording"
    pid: int = field(default_factory=os.getpid)
    host: str = field(default_factory=socket.gethostname)
    error: str = ""
    losses: dict | None = None


class BagWriter:
    """A new bag directory: ``add_topic`` then ``write`` (any order of topics), ``flush`` now and
    then (``tick`` does it when due), ``close`` at the end. The line's description goes into
    ``custom`` (custom_data)."""

    def __init__(
        self,
        path: str | Path,
        custom: dict[str, str] | None = None,
        options: WriteOptions | None = None,
        flush_interval: float = FLUSH_INTERVAL,
    ):
        self.path = Path(path)
        self.options = (options or WriteOptions()).check()
        if self.path.exists():
            raise BagError(f"{self.path} exists already: choose a new output directory")
        try:
            self.path.mkdir(parents=False)
        except OSError as e:
            raise BagError(f"{self.path}: cannot create the bag directory: {e.strerror}") from None
        self.custom = {k: v for k, v in (custom or {}).items() if k != RECORDING_KEY}
        self.recording = _Recording(asdict(self.options))
        self.topics: dict[str, TopicStats] = {}
        self.counts: dict[str, int] = {}
        self.total = 0
        self.files: list[FileStats] = []
        self.flush_interval = flush_interval
        self._next_flush = time.monotonic() + flush_interval
        self._file: _McapFile | None = None
        self._closed = False
        try:
            self._reserve(RESERVE_BYTES)
            self._open_file()
        except OSError as e:
            raise BagError(f"{self.path}: cannot write the bag: {e.strerror}") from None

    # -- writing

    def add_topic(self, topic: str, msgtype: str) -> None:
        if topic in self.topics:
            return
        qos = yaml.safe_dump(dump_qos_v9([NODE_QOS]), default_flow_style=False).strip()
        self.topics[topic] = TopicStats(msgtype, qos)
        self.counts.setdefault(topic, 0)
        self._file.add_topic(topic, msgtype, qos)

    def write(self, topic: str, log_time: int, data: bytes | memoryview) -> None:
        if self._closed:
            return
        if self._split_due(log_time):
            self._guarded(self._split)
        self._file.write(topic, log_time, data)
        self.topics[topic].count += 1
        self.counts[topic] += 1
        self.total += 1
        self.tick()

    def tick(self) -> None:
        """Closes the chunk in progress and fsyncs it if ``flush_interval`` passed since the last time."""
        if not self._closed and time.monotonic() >= self._next_flush:
            self.flush()

    def flush(self) -> None:
        self._next_flush = time.monotonic() + self.flush_interval
        self._guarded(self._file.flush)
        per_chunk = SUMMARY_BYTES_PER_CHUNK + SUMMARY_BYTES_PER_CHANNEL * len(self.topics)
        summary = RESERVE_BYTES // 2 + per_chunk * self._file.chunks
        if summary > self._reserved:
            self._guarded(lambda: self._reserve(2 * summary))

    def close(self, state: str = "closed") -> None:
        """Finishes the MCAP file (summary, footer) and metadata.yaml; removes the reserve."""
        if self._closed:
            return
        self._closed = True
        self.recording.state = state
        self._guarded(self._finish)

    def set_losses(self, losses: dict | None) -> None:
        """What the recording knows it missed (see :mod:`.losses`): stored in metadata.yaml at close."""
        self.recording.losses = losses

    @property
    def size(self) -> int:
        """Bytes of the bag's MCAP files on disk."""
        return sum((self.path / f.path).stat().st_size for f in self.files if (self.path / f.path).exists())

    # -- files

    def _open_file(self) -> None:
        name = f"{self.path.name}_{len(self.files)}.mcap"
        self._file = _McapFile(self.path / name, self.options.compression, self._description())
        self.files.append(self._file.stats)
        for topic, t in self.topics.items():
            self._file.add_topic(topic, t.msgtype, t.qos)
        self._file.stream.commit()
        self._write_metadata()

    def _split_due(self, log_time: int) -> bool:
        o, f = self.options, self._file
        if o.max_bag_size and f.size() >= o.max_bag_size:
            return True
        return bool(o.max_bag_duration and f.stats.count and log_time - f.stats.start >= o.max_bag_duration * 1e9)

    def _split(self) -> None:
        self._file.finish()
        self._open_file()

    def _finish(self) -> None:
        self._file.finish()
        self._write_metadata()
        self._release_reserve()

    def _description(self) -> dict[str, str]:
        return {**self.custom, RECORDING_KEY: json.dumps(asdict(self.recording), sort_keys=True)}

    def _write_metadata(self) -> None:
        write_metadata(self.path, rosbag2_metadata(self.files, self.topics, self._description()))

    # -- a full disk

    def _reserve(self, size: int) -> None:
        fd = os.open(self.path / RESERVE_NAME, os.O_WRONLY | os.O_CREAT, 0o644)
        try:
            os.posix_fallocate(fd, 0, size)
        finally:
            os.close(fd)
        self._reserved = size

    def _release_reserve(self) -> None:
        (self.path / RESERVE_NAME).unlink(missing_ok=True)
        self._reserved = 0

    def _guarded(self, action) -> None:
        """Runs a step that writes; on an OSError ends the bag as well as it can and raises BagWriteError."""
        try:
            action()
        except OSError as e:
            self._closed = True
            raise self._fail(e) from None

    def _fail(self, error: OSError) -> BagWriteError:
        where = self._file.stream.path
        cause = f"{error.strerror or error} (errno {errno.errorcode.get(error.errno, error.errno)})"
        self.recording.state, self.recording.error = "failed", f"{where.name}: {cause}"
        self._release_reserve()
        ended = "the bag is readable"
        try:
            self._file.stream.commit()  # the chunk in flight, now that the reserve is free
            self._finish()
        except OSError:
            ended = f"it ends without its summary: `sorting-line-bag reindex {self.path}` recovers it"
            try:
                self._file.stream.cut_back()
                self._file.stream.close()
                self._write_metadata()
            except OSError:
                pass
        total = sum(f.count for f in self.files)
        return BagWriteError(
            f"cannot write to {where}: {cause}. Recording stopped; the {total} messages "
            f"received before are in {self.path}, and {ended}"
        )
