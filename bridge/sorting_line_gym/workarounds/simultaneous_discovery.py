"""Workaround: DDS participants starting together lose endpoint announcements, so banks join one at a time.

Measured (benches/discovery.py, docs/many-envs.md): when several client and node
participants start at the same moment (16 SubprocVecEnv workers, each starting a node), Fast DDS
2.14 (rclpy's) and RustDDS (the node's) lose some endpoint announcements between them for good (a
node's reset service never becomes ready for its client, even after 60 s): 4 AsyncVectorEnv workers
each starting rclpy and a node at the same moment failed 5 runs in 6; with this lock held from
participant start to the handshake, 3 of 3, and 16 workers ran 200 steps. One participant pair
joining at a time discovers completely, whatever the number of participants; it costs about 0.7 s
per env at start-up.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import time

from ..line.errors import BridgeTimeout
from ..line.host import host_state_directory, network_namespace


@contextlib.contextmanager
def joining_graph(timeout: float):
    """Holds this host's lock for joining the DDS graph of ``ROS_DOMAIN_ID`` (per network
    namespace) while a bank starts its participant and node and discovers the node's endpoints.

    A waiter gives up only when the queue stops moving: when one holder has kept the lock for
    ``timeout`` (a holder's own start is bounded by its startup_timeout, so that means it hangs).
    The whole queue may take longer: 16 workers joining one after the other at 1-2 s each on a
    busy machine must not time out for waiting their turn. Each holder writes its pid and the
    time of its turn into the lock file, which is how waiters see the lock change hands; a holder
    that dies frees the lock at once (flock)."""
    digest = hashlib.sha1(f"{network_namespace()}|{os.environ.get('ROS_DOMAIN_ID', '0')}".encode()).hexdigest()[:12]
    path = host_state_directory() / f"join-{digest}.lock"
    with open(path, "a+") as f:
        holder, since = None, time.monotonic()
        while True:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                now = time.monotonic()
                current = os.pread(f.fileno(), 64, 0)  # "pid time", as the holder wrote it
                if current != holder:
                    holder, since = current, now  # the lock changed hands: the queue moves
                elif now - since > timeout:
                    pid = holder.decode(errors="replace").split(" ")[0] or "?"
                    raise BridgeTimeout(
                        f"timed out after {timeout:g} s waiting for other environments of this host to join "
                        f"the DDS graph: pid {pid} has held the lock (file {path}) for {now - since:.0f} s"
                    ) from None
                time.sleep(0.01)
        try:
            f.seek(0)
            f.truncate()
            f.write(f"{os.getpid()} {time.time_ns()}")
            f.flush()
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)
