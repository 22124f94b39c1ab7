"""The batch messages (``LineStates``, ``LineCommands``) read and written as numpy records, for
the vector environment's round trip.

Why not rclpy's own conversion: turning a 16-line ``LineStates`` into a Python message costs about
42 us (23 ``array.array`` objects plus the message's constructor), rosbags' CDR reader about 71 us,
in a round trip whose whole budget at 16 lines is a few hundred microseconds
(benches/bridge_throughput.py). Both batch messages are a ``std_msgs/Header`` followed by sequences
of primitives of one length N, so for a given N (and an empty ``frame_id``, which is what the node
and this bridge send) their CDR encoding has fixed offsets: one numpy structured dtype lays out the
whole message, so reading one is a copy of its bytes into a row of records (a vector env over
several nodes keeps one row a node and reads the rows as one batch), and writing one the reverse.

The codec changes speed, never results: a message that does not fit the layout (another length, a
``frame_id``, another encoding) is handed to rclpy's deserialisation instead, and the tests compare
both ways with rclpy's on many messages (tests/python/test_batch_codec.py).

Layout rules (CDR, XCDR1 as ROS 2 writes it): a 4-byte encapsulation header (``00 01`` = little
endian, then 2 option bytes), then the body, where each primitive is aligned to its size counted
from the body's start; a string is a uint32 length (NUL included) and its bytes; a sequence a uint32
count and its elements. Writers may pad the message to a multiple of 4 bytes (the last option
byte then says by how much); rclpy does not, and the codec reads either.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
from rclpy.serialization import deserialize_message

#: ROS primitive type -> numpy format (little endian).
PRIMITIVES = {
    "boolean": "?",
    "uint8": "u1",
    "int8": "i1",
    "uint16": "<u2",
    "int16": "<i2",
    "uint32": "<u4",
    "int32": "<i4",
    "uint64": "<u8",
    "int64": "<i8",
    "float": "<f4",
    "double": "<f8",
}

#: Encapsulation header of little-endian plain CDR, options zero.
CDR_LE = b"\x00\x01\x00\x00"

#: The record fields of the header: stamp, and the length (1: just the NUL) and NUL of an empty frame_id.
HEADER = (
    ("header_sec", "<i4", 0),
    ("header_nanosec", "<u4", 4),
    ("header_frame_id_len", "<u4", 8),
    ("header_frame_id", "u1", 12),
)
HEADER_SIZE = 13


def _sequences(msg_type) -> list[tuple[str, str]]:
    """The fields after the header as (name, numpy format); refuses a type the codec cannot lay out."""
    fields = list(msg_type.get_fields_and_field_types().items())
    if not fields or fields[0] != ("header", "std_msgs/Header"):
        raise TypeError(f"{msg_type.__name__}: the codec needs a std_msgs/Header as the first field")
    result = []
    for name, kind in fields[1:]:
        element = kind[len("sequence<") : -1] if kind.startswith("sequence<") else None
        if element not in PRIMITIVES:
            raise TypeError(
                f"{msg_type.__name__}.{name} is {kind}: the codec takes unbounded sequences of primitives only"
            )
        result.append((name, PRIMITIVES[element]))
    return result


def _align(position: int, size: int) -> int:
    return (position + size - 1) // size * size


class BatchCodec:
    """Reads and writes one message type whose sequences all have ``n`` entries (``lengths``
    overrides that per field, e.g. the empty ``modes`` of a basic line's commands)."""

    def __init__(self, msg_type, n: int, lengths: dict[str, int] | None = None):
        self.msg_type = msg_type
        self.n = n
        self.sequences = _sequences(msg_type)
        self.lengths = {name: n for name, _ in self.sequences} | (lengths or {})
        names, formats, offsets = [], [], []
        for name, fmt, offset in HEADER:
            names.append(name), formats.append(fmt), offsets.append(offset)
        position = HEADER_SIZE
        for name, fmt in self.sequences:
            count = self.lengths[name]
            position = _align(position, 4)
            names.append(f"{name}__count"), formats.append("<u4"), offsets.append(position)
            position += 4
            size = np.dtype(fmt).itemsize
            position = _align(position, size) if count else position
            names.append(name), formats.append((fmt, (count,))), offsets.append(position)
            position += size * count
        self.size = len(CDR_LE) + position
        self.dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": position})
        template = np.zeros((), dtype=self.dtype)
        template["header_frame_id_len"] = 1
        for name, count in self.lengths.items():
            template[f"{name}__count"] = count
        #: An empty message of the codec's lengths, as bytes: every record starts as a copy of it.
        self._template = template.tobytes()
        # The bytes that must be as in the template for a message to fit: the frame_id's length
        # and NUL, and every sequence's count.
        fixed = [range(8, 13)] + [
            range(offsets[i], offsets[i] + 4) for i, name in enumerate(names) if name.endswith("__count")
        ]
        self._fixed_at = np.array([len(CDR_LE) + i for r in fixed for i in r])
        self._fixed = np.frombuffer(CDR_LE + template.tobytes(), dtype=np.uint8)[self._fixed_at].tobytes()
        self._sizes = (self.size, _align(self.size, 4))
        self._names = [name for name, _ in self.sequences]

    # -- reading -------------------------------------------------------------------------------
    def fits(self, raw: bytes) -> bool:
        """Whether ``raw`` is this layout: little-endian CDR, the size, an empty frame_id, the counts."""
        if len(raw) not in self._sizes or raw[:2] != CDR_LE[:2]:
            return False
        return np.frombuffer(raw, dtype=np.uint8)[self._fixed_at].tobytes() == self._fixed

    def decode(self, raw: bytes) -> SimpleNamespace:
        """The message as a namespace of numpy arrays (one per sequence) plus ``stamp_ns`` of its
        header; through rclpy when ``raw`` does not fit. The arrays are copies owned by this
        message alone, so they can be handed out."""
        rows = self.records(1)
        if not self.load(rows, 0, raw):
            return from_message(deserialize_message(raw, self.msg_type))
        return self.fields(rows)

    # -- records: messages kept as rows of one array -------------------------------------------
    # The step loop keeps each node's newest state batch as a row of this layout and copies rows
    # as bytes: a few microseconds a node, where building a namespace of arrays per message and
    # concatenating them for several nodes cost tens (benches/multihost.py).

    def records(self, count: int) -> np.ndarray:
        """``count`` rows of this layout, each an empty message of the codec's lengths."""
        return np.frombuffer(bytearray(self._template * count), dtype=self.dtype)

    def load(self, rows: np.ndarray, k: int, raw: bytes) -> bool:
        """Copies the message ``raw`` into row k of ``rows``; through rclpy when it does not fit the
        layout. False, and the row untouched, when its sequences are not the codec's lengths."""
        if self.fits(raw):
            row_bytes(rows)[k] = np.frombuffer(raw, np.uint8, self.dtype.itemsize, len(CDR_LE))
            return True
        return self.assign(rows, k, from_message(deserialize_message(raw, self.msg_type)))

    def assign(self, rows: np.ndarray, k: int, batch: SimpleNamespace) -> bool:
        """Writes a batch as :func:`from_message` gives it into row k of ``rows``; False, and the
        row untouched, when its sequences are not the codec's lengths."""
        if any(len(getattr(batch, name)) != self.lengths[name] for name in self._names):
            return False
        row_bytes(rows)[k] = np.frombuffer(self._template, np.uint8)
        row = rows[k : k + 1]
        row["header_sec"], row["header_nanosec"] = divmod(batch.stamp_ns, 1_000_000_000)
        for name in self._names:
            row[name] = getattr(batch, name)
        return True

    def fields(self, rows: np.ndarray) -> SimpleNamespace:
        """Rows as one batch, as :meth:`decode` gives one message: per sequence, the entries of
        row 0, then of row 1, ... (copies owned by the batch), and ``stamp_ns`` of row 0's header."""
        stamp_ns = int(rows["header_sec"][0]) * 1_000_000_000 + int(rows["header_nanosec"][0])
        # One row: one copy of it (as bytes), every field a view on that copy, as reshape does
        # not copy a contiguous field. Several rows: reshape copies each field, whose entries
        # interleave across rows.
        own = row_bytes(rows).copy().view(self.dtype).reshape(1) if len(rows) == 1 else rows
        return SimpleNamespace(stamp_ns=stamp_ns, **{name: own[name].reshape(-1) for name in self._names})

    # -- writing -------------------------------------------------------------------------------
    def encode(self, **values: Any) -> bytes:
        """The serialised message with the given sequences (header stamp zero, empty frame_id)."""
        record = self.records(1)  # from the template's bytes: a structured copy leaves the padding undefined
        for name, value in values.items():
            record[name] = value
        return CDR_LE + record.tobytes()


def row_bytes(rows: np.ndarray) -> np.ndarray:
    """Records as a (rows, bytes) uint8 array on the same memory: rows are copied as bytes, which
    numpy does ten times faster than a structured copy (field by field, padding left undefined)."""
    return rows.view(np.uint8).reshape(len(rows), -1)


def from_message(message) -> SimpleNamespace:
    """A rclpy message of a batch type as :meth:`BatchCodec.decode` returns it."""
    fields = {name: np.asarray(getattr(message, name), dtype=fmt) for name, fmt in _sequences(type(message))}
    stamp = message.header.stamp
    return SimpleNamespace(stamp_ns=stamp.sec * 1_000_000_000 + stamp.nanosec, **fields)
