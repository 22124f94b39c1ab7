"""Workaround: a process whose parent dies is not told, so what the bridge started outlives it.

Linux does not end a process's children when it dies, and a process killed with SIGKILL runs no
cleanup of its own; and a multiprocessing worker of a vectorizer (SB3's SubprocVecEnv,
Gymnasium's AsyncVectorEnv) waits on its command pipe, whose write ends, with the fork start
method, every sibling holds open too, so no EOF ever comes when the parent dies. The kernel's
parent-death signal (``PR_SET_PDEATHSIG``) covers both: :func:`die_with_multiprocessing_parent`
for an env in a multiprocessing worker, :func:`die_with_parent` for a pool that picks its own signal
(``studies.cell_pool``). The node processes (and test processes) we start get the same signal from
``line.process.with_parent_death_signal``: for them it is the design, not a workaround (the
kernel's behaviour is by design), so it lives with the node process.

Standard library only.
"""

from __future__ import annotations

import os
import signal
import sys


def die_with_parent(sig: int, keep_existing: bool = False) -> None:
    """Asks the kernel to send ``sig`` to this process when its parent dies (Linux
    ``PR_SET_PDEATHSIG``; the parent is the thread that started this process, so a process that
    outlives a parent that already died before this call gets nothing: callers check that
    themselves). ``keep_existing`` leaves a signal the process chose before in place. Does nothing
    elsewhere than on Linux."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    PR_SET_PDEATHSIG, PR_GET_PDEATHSIG = 1, 2
    libc = ctypes.CDLL(None, use_errno=True)
    current = ctypes.c_int(0)
    libc.prctl(PR_GET_PDEATHSIG, ctypes.byref(current))
    if not (keep_existing and current.value):
        libc.prctl(PR_SET_PDEATHSIG, sig)


def die_with_multiprocessing_parent() -> None:
    """In a multiprocessing child: SIGTERM when the parent dies (the kernel ties it to the thread
    that started the child, which is the main thread in SB3's, Gymnasium's and the benchmark's
    pools), unless the process chose a parent-death signal itself (the benchmark's pool: SIGKILL).
    Elsewhere: nothing.

    With the forkserver start method the child's parent in the kernel's eyes is the fork server,
    not the process that asked for the child; the fork server exits when that process is gone, so
    the signal still comes. The check below must tell that case from a parent that died before
    the signal was asked for (the child then belongs to init or a subreaper, and no signal will
    ever come): it once took the fork server for a dead parent and killed every forkserver worker
    at its first reset."""
    import multiprocessing

    parent = multiprocessing.parent_process()
    if parent is None:
        return
    die_with_parent(signal.SIGTERM, keep_existing=True)
    ppid = os.getppid()
    if ppid == parent.pid:
        return
    # is_alive() reads the parent's sentinel, a pipe whose write end only the real parent keeps
    # with forkserver (with fork, siblings inherit it too, hence not asked there).
    if _is_fork_server(ppid) and parent.is_alive():
        return
    os.kill(os.getpid(), signal.SIGTERM)


def _is_fork_server(pid: int) -> bool:
    """Whether ``pid`` is a multiprocessing fork server (its command line runs
    ``multiprocessing.forkserver``'s main)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return b"multiprocessing.forkserver" in f.read()
    except OSError:
        return False
