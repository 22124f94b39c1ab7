"""RTPS datagrams for the wire fuzz test (test_wire_fuzz.py): what the node's UDP ports receive.

- `node_udp_ports(pid, domain)`: the node's own UDP sockets (its fds matched with /proc/PID/net/udp),
  each named by the RTPS port formula (discovery or user unicast port of participant id k).
- `LoopbackCapture`: an AF_PACKET socket on `lo` (needs the test's own network namespace, as root)
  that keeps the RTPS datagrams to and from given ports: the corpus that replays mutate.
- `Fuzzer`: seeded generators of malformed and mutated datagrams, by kind (truncated headers, wrong
  submessage lengths, bad submessage ids, absurd DATA_FRAG fragment fields, absurd HEARTBEAT and GAP
  ranges, valid headers around random bytes, captured datagrams with flipped bits). One seed gives
  the same datagrams in the same order, so a failure is reproduced by its seed.
- `regression_datagrams(...)`: the datagrams that took the node down before the rustdds fixes
  (vendor/README.md, rustdds patch 10), sent as such by the test.

Datagrams are only ever sent to 127.0.0.1 (`send_to_node`). Layouts follow the RTPS 2.5 spec,
section 9.4 (header 20 bytes; submessage header: id, flags with bit 0 = little endian, octetsToNextHeader).
"""

from __future__ import annotations

import random
import socket
import struct
import threading
from collections import Counter
from pathlib import Path

LOCALHOST = "127.0.0.1"
RTPS_HEADER = b"RTPS\x02\x04\x01\x0f"  # protocol 2.4, vendor 01.0f (eProsima); the prefix follows
PORT_BASE, DOMAIN_GAIN, PARTICIPANT_GAIN, DISCOVERY_OFFSET, USER_OFFSET = 7400, 250, 2, 10, 11

# Submessage ids (RTPS 2.5, 9.4.5.1.1) and flags.
PAD, ACKNACK, HEARTBEAT, GAP, INFO_TS, INFO_SRC, INFO_REPLY_IP4, INFO_DST, INFO_REPLY = (
    0x01, 0x06, 0x07, 0x08, 0x09, 0x0C, 0x0D, 0x0E, 0x0F,
)  # fmt: skip
NACK_FRAG, HEARTBEAT_FRAG, DATA, DATA_FRAG = 0x12, 0x13, 0x15, 0x16
SECURITY_IDS = (0x30, 0x31, 0x32, 0x33, 0x34)
KNOWN_IDS = {PAD, ACKNACK, HEARTBEAT, GAP, INFO_TS, INFO_SRC, INFO_REPLY_IP4, INFO_DST, INFO_REPLY}
KNOWN_IDS |= {NACK_FRAG, HEARTBEAT_FRAG, DATA, DATA_FRAG, *SECURITY_IDS}
LITTLE = 0x01

# Builtin entity ids (RTPS 2.5, 9.3.1.3): readers the node has whoever sends.
SPDP_READER, SPDP_WRITER = 0x000100C7, 0x000100C2
SEDP_PUB_READER, SEDP_SUB_READER = 0x000003C7, 0x000004C7
P2P_MSG_READER, UNKNOWN_ENTITY = 0x000200C7, 0x00000000
BUILTIN_READERS = (SPDP_READER, SEDP_PUB_READER, SEDP_SUB_READER, P2P_MSG_READER, UNKNOWN_ENTITY)

#: Values that break arithmetic: zero, one, sign and width edges.
EDGE_U32 = (0, 1, 2, 0x7FFF, 0x8000, 0xFFFF, 0x10000, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFE, 0xFFFFFFFF)

KINDS = (
    "truncated",
    "bad_length",
    "bad_submessage_id",
    "huge_fragments",
    "huge_ranges",
    "random_payload",
    "replay_flipped",
)


# --------------------------------------------------------------------------------------------
# Ports and sending


def participant_ports(domain: int, participant_id: int) -> dict[str, int]:
    base = PORT_BASE + DOMAIN_GAIN * domain + PARTICIPANT_GAIN * participant_id
    return {"discovery": base + DISCOVERY_OFFSET, "user": base + USER_OFFSET}


def node_udp_ports(pid: int, domain: int) -> dict[int, str]:
    """The UDP ports the process `pid` has bound (its socket fds found in /proc/PID/net/udp), each
    named `discovery` or `user` (unicast ports of some participant id, RTPS 9.6.1.1) or `other`."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = fd.readlink().name
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[len("socket:[") : -1])
    ports = {}
    for line in Path(f"/proc/{pid}/net/udp").read_text().splitlines()[1:]:
        fields = line.split()
        if fields[9] in inodes:
            ports[int(fields[1].split(":")[1], 16)] = "other"
    for k in range(120):
        for name, port in participant_ports(domain, k).items():
            if port in ports:
                ports[port] = name
    return ports


def udp_receive_buffer_errors() -> int:
    """UDP datagrams this network namespace's kernel dropped for a full receive buffer (RcvbufErrors
    of /proc/net/snmp): in the test's own namespace, the node's and the client's sockets only."""
    rows = [line.split() for line in Path("/proc/net/snmp").read_text().splitlines() if line.startswith("Udp:")]
    return int(rows[1][rows[0].index("RcvbufErrors")])


def send_to_node(sock: socket.socket, port: int, datagram: bytes) -> None:
    """One datagram to 127.0.0.1:port (never anywhere else); a full socket buffer drops it, as UDP does."""
    try:
        sock.sendto(datagram, (LOCALHOST, port))
    except (BlockingIOError, ConnectionRefusedError):
        pass


# --------------------------------------------------------------------------------------------
# Capture


class LoopbackCapture:
    """Keeps the RTPS datagrams to or from `ports` seen on `lo` while running (a thread reading an
    AF_PACKET socket; only packets as received, not their outgoing copies)."""

    PACKET_HOST = 0

    def __init__(self, ports: set[int]):
        self.ports = ports
        self.datagrams: list[tuple[int, bytes]] = []  # (destination port, UDP payload)
        self._sock = socket.socket(socket.AF_PACKET, socket.SOCK_DGRAM, socket.htons(0x0800))
        self._sock.bind(("lo", 0x0800))
        self._sock.settimeout(0.1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> LoopbackCapture:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._sock.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                packet, address = self._sock.recvfrom(70000)
            except TimeoutError:
                continue
            if address[2] != self.PACKET_HOST or len(packet) < 28 or packet[9] != socket.IPPROTO_UDP:
                continue
            header = (packet[0] & 0x0F) * 4
            src, dst = struct.unpack_from("!HH", packet, header)
            payload = packet[header + 8 :]
            if (src in self.ports or dst in self.ports) and payload[:4] == b"RTPS":
                self.datagrams.append((dst, bytes(payload)))


def submessages(datagram: bytes):
    """(id, flags, body) of each submessage of a well-formed datagram (stops at the first bad length)."""
    pos = 20
    while pos + 4 <= len(datagram):
        sid, flags = datagram[pos], datagram[pos + 1]
        (length,) = struct.unpack_from("<H" if flags & LITTLE else ">H", datagram, pos + 2)
        body = datagram[pos + 4 : pos + 4 + length] if length else datagram[pos + 4 :]
        yield sid, flags, body
        if length == 0 or pos + 4 + length > len(datagram):
            return
        pos += 4 + length


def writer_guids(datagrams: list[tuple[int, bytes]], node_ports: set[int]) -> list[tuple[bytes, int, int, int]]:
    """(guid prefix, reader id, writer id, port) of the little-endian HEARTBEATs sent to the node
    (to one of `node_ports`): writers the node has matched, to which a HEARTBEAT or GAP is applied.
    (Only those: the client's Fast DDS 2.14.5 has the GAP defect the node had, CVE-2025-64438, and
    a GAP sent to it grew the test process by 2 GB in two minutes; docs/security.md.)"""
    found = {}
    for port, datagram in datagrams:
        if port not in node_ports:
            continue
        for sid, flags, body in submessages(datagram):
            if sid == HEARTBEAT and flags & LITTLE and len(body) >= 8:
                reader, writer = struct.unpack_from(">II", body)
                found[(datagram[8:20], reader, writer)] = port
    return [(*key, port) for key, port in found.items()]


# --------------------------------------------------------------------------------------------
# Building datagrams


def header(prefix: bytes) -> bytes:
    return RTPS_HEADER + prefix


def submessage(sid: int, body: bytes, flags: int = LITTLE, length: int | None = None) -> bytes:
    return struct.pack("<BBH", sid, flags | LITTLE, len(body) if length is None else length) + body


def sequence_number(sn: int) -> bytes:
    return struct.pack("<iI", sn >> 32, sn & 0xFFFFFFFF)


def data_frag(reader: int, writer: int, sn: int, start: int, count: int, size: int, sample: int, payload: bytes):
    """A DATA_FRAG submessage (9.4.5.4): no inline QoS, so octetsToInlineQos = 28."""
    body = struct.pack("<HH", 0, 28) + struct.pack(">II", reader, writer) + sequence_number(sn)
    body += struct.pack("<IHHI", start, count, size, sample) + payload
    return submessage(DATA_FRAG, body)


def heartbeat(reader: int, writer: int, first: int, last: int, count: int) -> bytes:
    body = struct.pack(">II", reader, writer) + sequence_number(first) + sequence_number(last)
    return submessage(HEARTBEAT, body + struct.pack("<I", count))


def gap(reader: int, writer: int, start: int, base: int, num_bits: int = 0, words: int = 0) -> bytes:
    body = struct.pack(">II", reader, writer) + sequence_number(start) + sequence_number(base)
    return submessage(GAP, body + struct.pack("<I", num_bits) + b"\xff\xff\xff\xff" * words)


def regression_datagrams(prefix: bytes, matched: list[tuple[bytes, int, int, int]]) -> list[tuple[str, bytes]]:
    """What took the node down before rustdds patch 10: a DATA_FRAG announcing a 4 GB sample (the
    reader allocated and zeroed it), and from each writer the node matched, a HEARTBEAT and a GAP
    spanning 2^62 sequence numbers (the reader listed or inserted every one of them), and a GAP
    whose gapList base is 2^63 - 1 (the reader's count of that writer wrapped to -2^63) followed
    by an ordinary one."""
    huge, most = 1 << 62, (1 << 63) - 1
    cases = [("data_frag_4GB", header(prefix) + data_frag(SPDP_READER, SPDP_WRITER, 1, 1, 1, 1, 0xFFFFFFFF, b"x"))]
    for writer_prefix, reader, writer, _ in matched[:4]:
        cases.append(("heartbeat_2^62", header(writer_prefix) + heartbeat(reader, writer, 1, huge, 0x7FFF0001)))
        cases.append(("gap_2^62", header(writer_prefix) + gap(reader, writer, huge // 2, huge)))
        cases.append(("gap_base_2^63-1", header(writer_prefix) + gap(reader, writer, 1, most, 1, 1)))
        cases.append(("gap_after_it", header(writer_prefix) + gap(reader, writer, 5, 1 << 40)))
    return cases


# --------------------------------------------------------------------------------------------
# The fuzzer


class Fuzzer:
    """Seeded malformed and mutated datagrams. `corpus`: captured datagrams (destination port, bytes);
    `matched`: writer_guids(corpus, node ports)."""

    def __init__(self, seed: int, corpus: list[tuple[int, bytes]], matched: list[tuple[bytes, int, int, int]]):
        self.rng = random.Random(seed)
        self.corpus = [d for _, d in corpus] or [header(bytes(12)) + heartbeat(0, SPDP_WRITER, 1, 1, 1)]
        self.matched = matched
        self.counts: Counter[str] = Counter()
        self._kinds = {name: getattr(self, f"_{name}") for name in KINDS}

    def next(self) -> tuple[str, bytes]:
        kind = self.rng.choice(KINDS)
        self.counts[kind] += 1
        return kind, self._kinds[kind]()

    def _prefix(self) -> bytes:
        """A captured participant's prefix (it passes as a known peer) or a random one."""
        if self.rng.random() < 0.5:
            return self.rng.choice(self.corpus)[8:20]
        return self.rng.randbytes(12)

    def _u32(self) -> int:
        return self.rng.choice(EDGE_U32) if self.rng.random() < 0.7 else self.rng.getrandbits(32)

    def _truncated(self) -> bytes:
        datagram = self.rng.choice(self.corpus)
        cut = self.rng.randrange(0, 24) if self.rng.random() < 0.5 else self.rng.randrange(0, len(datagram))
        return datagram[:cut]

    def _bad_length(self) -> bytes:
        """A captured datagram whose submessages declare other lengths (0, too long, off by a few, odd)."""
        datagram = bytearray(self.rng.choice(self.corpus))
        pos = 20
        while pos + 4 <= len(datagram):
            little = datagram[pos + 1] & LITTLE
            (length,) = struct.unpack_from("<H" if little else ">H", datagram, pos + 2)
            if self.rng.random() < 0.5:
                wrong = self.rng.choice(
                    (0, 1, 3, length + 4, length - 4, len(datagram), 0xFFFF, self.rng.getrandbits(16))
                )
                struct.pack_into("<H" if little else ">H", datagram, pos + 2, wrong % 0x10000)
            if length == 0:
                break
            pos += 4 + length
        return bytes(datagram)

    def _bad_submessage_id(self) -> bytes:
        unknown = [i for i in range(256) if i not in KNOWN_IDS]
        parts = []
        for _ in range(self.rng.randrange(1, 5)):
            sid = self.rng.choice(unknown) if self.rng.random() < 0.6 else self.rng.choice(sorted(KNOWN_IDS))
            body = self.rng.randbytes(self.rng.choice((0, 4, 8, 24, 64, 300)))
            parts.append(submessage(sid, body, self.rng.getrandbits(8)))
        return header(self._prefix()) + b"".join(parts)

    def _huge_fragments(self) -> bytes:
        reader = self.rng.choice(BUILTIN_READERS + tuple(m[1] for m in self.matched))
        writer = self.rng.choice((SPDP_WRITER, *(m[2] for m in self.matched), self.rng.getrandbits(32)))
        start, sample = self._u32(), self._u32()
        count, size = (
            self.rng.choice((0, 1, 2, 0xFFFF, self.rng.getrandbits(16))),
            self.rng.choice((0, 1, 8, 1024, 0xFFFF)),
        )
        payload = self.rng.randbytes(self.rng.choice((0, 1, 8, 100, 1400)))
        sn = self.rng.choice((1, 2, self.rng.getrandbits(31)))
        frag = data_frag(reader, writer, sn, start, count, size, sample, payload)
        if self.rng.random() < 0.3:  # HEARTBEAT_FRAG / NACK_FRAG with absurd fragment numbers
            extra = (
                struct.pack(">II", reader, writer) + sequence_number(sn) + struct.pack("<II", self._u32(), self._u32())
            )
            frag += submessage(self.rng.choice((HEARTBEAT_FRAG, NACK_FRAG)), extra)
        return header(self._prefix()) + frag

    def _huge_ranges(self) -> bytes:
        """HEARTBEATs, GAPs and ACKNACK-like sequence number sets with absurd ranges and bitmaps,
        from matched writers (the node applies them) or unknown ones."""
        if self.matched and self.rng.random() < 0.7:
            prefix, reader, writer, _ = self.rng.choice(self.matched)
        else:
            prefix, reader, writer = self._prefix(), self.rng.choice(BUILTIN_READERS), self.rng.getrandbits(32)
        big = self.rng.choice((1 << 31, 1 << 40, 1 << 62, (1 << 63) - 1, self.rng.getrandbits(63)))
        low = self.rng.choice((-1, 0, 1, 2, big // 2, big - 1))
        if self.rng.random() < 0.5:
            return header(prefix) + heartbeat(reader, writer, low, big, self.rng.getrandbits(32))
        bits = self.rng.choice((0, 1, 255, 256, 257, 0xFFFFFFFF))
        return header(prefix) + gap(reader, writer, low, big, bits, self.rng.randrange(0, 9))

    def _random_payload(self) -> bytes:
        return header(self._prefix()) + self.rng.randbytes(self.rng.choice((0, 1, 3, 4, 16, 64, 512, 4096)))

    def _replay_flipped(self) -> bytes:
        """A captured datagram with 1-8 bits flipped, or a 32-bit field overwritten with an edge value."""
        datagram = bytearray(self.rng.choice(self.corpus))
        for _ in range(self.rng.randrange(1, 9)):
            if self.rng.random() < 0.8 or len(datagram) < 24:
                i = self.rng.randrange(len(datagram))
                datagram[i] ^= 1 << self.rng.randrange(8)
            else:
                i = self.rng.randrange(20, len(datagram) - 3)
                struct.pack_into(self.rng.choice(("<I", ">I")), datagram, i, self._u32())
        return bytes(datagram)
