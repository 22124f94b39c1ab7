"""The batch messages' numpy codec (bridge/sorting_line_gym/ros/batch_codec.py) against rclpy's own
serialisation: whatever the codec reads or writes, rclpy must read or write the same values. No
node is needed; rclpy serialises in-process.

On its own, outside the isolated network namespace that conftest.py insists on:
    .venv/bin/python -m pytest tests/python/test_batch_codec.py --noconftest -q
"""

from __future__ import annotations

import array

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sorting_line_interfaces.msg import LineCommands, LineState, LineStates

from sorting_line_gym.line.vocabulary import sim_seconds, state_info
from sorting_line_gym.ros.batch_codec import PRIMITIVES, BatchCodec, from_message

TYPECODES = {"<i4": "i", "<u4": "I", "<u8": "Q", "<f8": "d", "u1": "B"}


def random_states(
    rng: np.random.Generator, n: int, lengths: dict[str, int] | None = None, frame_id: str = ""
) -> LineStates:
    """A LineStates with values over each field's whole range (extremes included)."""
    m = LineStates()
    m.header.stamp.sec = int(rng.integers(-(2**31), 2**31))
    m.header.stamp.nanosec = int(rng.integers(0, 10**9))
    m.header.frame_id = frame_id
    for name, kind in LineStates.get_fields_and_field_types().items():
        if name == "header":
            continue
        fmt = PRIMITIVES[kind[len("sequence<") : -1]]
        count = (lengths or {}).get(name, n)
        if fmt == "?":
            setattr(m, name, [bool(x) for x in rng.integers(0, 2, count)])
        elif fmt == "<f8":
            values = rng.normal(0, 1e3, count)
            values[: min(count, 3)] = [np.inf, -0.0, 1e-308][: min(count, 3)]
            setattr(m, name, array.array("d", values))
        else:
            info = np.iinfo(np.dtype(fmt))
            values = rng.integers(info.min, info.max, count, dtype=np.dtype(fmt), endpoint=True)
            values[:1] = info.max
            setattr(m, name, array.array(TYPECODES[fmt], values.tolist()))
    return m


def assert_same(decoded, message) -> None:
    want = from_message(message)
    assert decoded.stamp_ns == want.stamp_ns
    for name, _ in BatchCodec(type(message), 0).sequences:
        got, expected = getattr(decoded, name), getattr(want, name)
        assert got.dtype == expected.dtype, name
        np.testing.assert_array_equal(got, expected, err_msg=name)


@pytest.mark.parametrize("n", [1, 2, 3, 16, 64])
def test_decode_equals_rclpy_on_random_states(n):
    rng = np.random.default_rng(n)
    codec = BatchCodec(LineStates, n)
    for _ in range(25):
        message = random_states(rng, n)
        raw = serialize_message(message)
        assert len(raw) == codec.size and codec.fits(raw)
        assert_same(codec.decode(raw), message)


def test_messages_that_do_not_fit_go_through_rclpy():
    rng = np.random.default_rng(7)
    codec = BatchCodec(LineStates, 4)
    cases = {
        "another number of lines": random_states(rng, 5),
        "one sequence shorter": random_states(rng, 4, lengths={"reward": 3}),
        "one sequence longer, same total size as none": random_states(rng, 4, lengths={"mode": 5, "speed_index": 3}),
        "a frame_id": random_states(rng, 4, frame_id="belt"),
    }
    for what, message in cases.items():
        raw = serialize_message(message)
        assert not codec.fits(raw), what
        assert_same(codec.decode(raw), message)


def test_big_endian_is_not_read_as_little():
    codec = BatchCodec(LineStates, 2)
    raw = bytearray(serialize_message(random_states(np.random.default_rng(1), 2)))
    raw[1] = 0x00  # encapsulation CDR_BE
    assert not codec.fits(bytes(raw))


@pytest.mark.parametrize("advanced", [True, False])
@pytest.mark.parametrize("n", [1, 16])
def test_encoded_commands_read_back_by_rclpy(n, advanced):
    rng = np.random.default_rng(n)
    codec = BatchCodec(LineCommands, n, None if advanced else {"modes": 0})
    stamp_sec = rng.integers(-(2**31), 2**31, n).astype(np.int32)
    stamp_nanosec = rng.integers(0, 10**9, n).astype(np.uint32)
    speeds = rng.choice([0.1, 0.2, 0.7, 1.0, np.nan], n)
    modes = rng.integers(0, 3, n)
    fields = {"stamp_sec": stamp_sec, "stamp_nanosec": stamp_nanosec, "speeds": speeds}
    if advanced:
        fields["modes"] = modes
    raw = codec.encode(**fields)
    assert len(raw) == codec.size
    message = deserialize_message(raw, LineCommands)
    assert message.header.stamp.sec == 0 and message.header.frame_id == ""
    np.testing.assert_array_equal(np.asarray(message.stamp_sec), stamp_sec)
    np.testing.assert_array_equal(np.asarray(message.stamp_nanosec), stamp_nanosec)
    np.testing.assert_array_equal(np.asarray(message.speeds), speeds)
    np.testing.assert_array_equal(np.asarray(message.modes), modes if advanced else [])
    assert codec.fits(raw) and codec.fits(serialize_message(message))
    # The bytes are a function of the values, padding included (rclpy leaves its padding undefined).
    assert codec.encode(**fields) == raw


def test_only_header_plus_primitive_sequences_are_laid_out():
    with pytest.raises(TypeError, match="LineState.*header|sequences of primitives"):
        BatchCodec(LineState, 4)


def test_decoded_arrays_own_their_memory():
    """What the vector env hands out (the batch's arrays, its info) is writable and shares memory
    neither with the received bytes nor with another batch."""
    n = 3
    codec = BatchCodec(LineStates, n)
    raw = serialize_message(random_states(np.random.default_rng(3), n))
    first, second = codec.decode(raw), codec.decode(raw)
    received = np.frombuffer(raw, np.uint8)
    info = state_info(first, sim_seconds(first.stamp_sec, first.stamp_nanosec) - np.zeros(n))
    for key, value in info.items():
        assert value.flags.writeable, key
        assert not np.shares_memory(value, received) and not np.shares_memory(value, second.reward), key
    first.reward[:] = -1.0
    assert (second.reward != -1.0).all()


def test_rows_of_several_nodes_read_as_one_batch():
    """The fleet's path: each node's message loaded into a row of one array, the rows read as one
    batch, equal to the messages read one by one and concatenated in row order."""
    rng = np.random.default_rng(11)
    n, nodes = 3, 4
    codec = BatchCodec(LineStates, n)
    messages = [random_states(rng, n) for _ in range(nodes)]
    rows = codec.records(nodes)
    for k in reversed(range(nodes)):  # the order of arrival does not matter
        assert codec.load(rows, k, serialize_message(messages[k]))
    batch = codec.fields(rows)
    assert batch.stamp_ns == from_message(messages[0]).stamp_ns
    for name, _ in codec.sequences:
        want = np.concatenate([getattr(from_message(m), name) for m in messages])
        got = getattr(batch, name)
        assert got.dtype == want.dtype, name
        np.testing.assert_array_equal(got, want, err_msg=name)
        assert got.flags.writeable and not np.shares_memory(got, rows), name


def test_a_row_takes_what_fits_its_lengths_and_nothing_else():
    rng = np.random.default_rng(12)
    codec = BatchCodec(LineStates, 4)
    rows = codec.records(2)
    framed = random_states(rng, 4, frame_id="belt")  # other layout, same lengths: through rclpy
    assert codec.load(rows, 1, serialize_message(framed))
    assert_same(codec.fields(rows[1:]), framed)
    before = rows.tobytes()
    for message in (random_states(rng, 5), random_states(rng, 4, lengths={"reward": 3})):
        assert not codec.load(rows, 0, serialize_message(message))
        assert not codec.assign(rows, 0, from_message(message))
    assert rows.tobytes() == before
