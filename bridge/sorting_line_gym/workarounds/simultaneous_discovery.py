"""Workaround: DDS participants starting together lose endpoint announcements, so banks join one at a time.

When several client and node participants start at the same moment (16 SubprocVecEnv workers,
each starting a node), Fast DDS 2.14 (rclpy's) and RustDDS (the node's) lose some endpoint
announcements between them for good: a node's reset service never becomes ready for its client,
even after 60 s. One participant pair joining at a time discovers completely, whatever the number
of participants, so a bank holds this lock from its participant's start to its handshake. The runs
that show it (benches/discovery.py and the bridge, with and without the lock) and what the lock
costs at start-up: docs/results/many-envs.md.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import time
from pathlib import Path

from ..line.errors import BridgeTimeout
from ..line.host import host_state_directory, network_namespace

#: How long past the end of its turn that it declared a holder may still keep the lock: the
#: exception that ends a failed turn on its way out, and a loaded machine's scheduling delay.
HANDOVER = 5.0


def _clock() -> float:
    # CLOCK_MONOTONIC is one clock for every process of the machine: a holder's declared end is
    # read by other processes. (time.monotonic promises only a clock per process.)
    return time.clock_gettime(time.CLOCK_MONOTONIC)


def join_lock_path() -> Path:
    """This host's lock file for joining the DDS graph of ``ROS_DOMAIN_ID`` in this network namespace."""
    digest = hashlib.sha1(f"{network_namespace()}|{os.environ.get('ROS_DOMAIN_ID', '0')}".encode()).hexdigest()[:12]
    return host_state_directory() / f"join-{digest}.lock"


@contextlib.contextmanager
def joining_graph(turn: float):
    """Holds this host's lock for joining the DDS graph of ``ROS_DOMAIN_ID`` (per network
    namespace) while a bank starts its participant and node and discovers the node's endpoints.

    ``turn`` is the longest this holder's turn can take, every wait in it at its bound (the bank
    adds them up: the start, the first reset's handshake). The holder writes its pid and the end
    of its turn into the lock file; a waiter gives up only when the holder in front of it has
    kept the lock more than ``HANDOVER`` past the end it declared, which means it hangs. A
    waiter never judges a holder by its own bound: another bank may have longer timeouts, and
    a slow start on a busy machine is a long turn, not a hang. The whole queue may take longer
    than any turn: 16 workers joining one after the other at 1-2 s each must not time out for
    waiting their turn. A holder that dies frees the lock at once (flock).

    A holder clears its declaration before it lets go. A declaration already over when a waiter
    first reads it is a leftover, not the holder's: one killed in its turn leaves its own in the
    file, and the next holder has the lock a moment before it writes its own, so a waiter can read
    a dead holder's declaration, hours old (docs/results/many-envs.md). The waiter then gives the
    holder its own ``turn``, the one bound it knows."""
    path = join_lock_path()
    with open(path, "a+") as f:
        seen, since, end = None, 0.0, 0.0  # set at the first look: the file never reads None
        while True:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                now = _clock()
                current = os.pread(f.fileno(), 64, 0)  # "pid start end", as the holder wrote it
                if current != seen:  # the lock changed hands: the queue moves
                    seen, (since, end) = current, _holders_turn(current, now, turn)
                elif now > end + HANDOVER:
                    pid = current.decode(errors="replace").split(" ")[0] or "?"
                    raise BridgeTimeout(
                        f"timed out waiting for other environments of this host to join the DDS graph: pid {pid} "
                        f"has held the lock (file {path}) for {now - since:.0f} s, {now - end:.0f} s past the end "
                        "of the turn it declared"
                    ) from None
                time.sleep(0.01)
        try:
            f.seek(0)
            f.truncate()
            now = _clock()
            f.write(f"{os.getpid()} {now:.3f} {now + turn:.3f}")
            f.flush()
            yield
        finally:
            f.truncate(0)  # no declaration outlives its turn
            fcntl.flock(f, fcntl.LOCK_UN)


def _holders_turn(declaration: bytes, now: float, turn: float) -> tuple[float, float]:
    """The start and end of the turn the holder wrote, as a waiter reading it at ``now`` first
    sees it; ``(now, now + turn)``, the waiter's own bound, when the file has nothing of the
    holder's to go by: empty (between the holder's truncate and its write) or a declaration
    already over (``HANDOVER`` included), a leftover of a holder killed in its turn."""
    try:
        _pid, start, end = declaration.split()
        declared = float(start), float(end)
    except ValueError:
        return now, now + turn
    return declared if now <= declared[1] + HANDOVER else (now, now + turn)
