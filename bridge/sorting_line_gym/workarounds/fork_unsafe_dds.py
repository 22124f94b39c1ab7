"""Workaround: rclpy over Fast DDS is not fork-safe, so a forked child refuses an inherited context.

A child forked while rclpy was live inherits the context's memory but not the threads that serve
it (Fast DDS's), so its first wait blocks forever on a lock a vanished thread held. The fork hooks
here remember whether rclpy was live when a process forked, so that the child's first use fails at
once with an error naming the cause and the fix instead (:func:`fork_error`), and so that
:mod:`.participant_deletion_hang` knows a forked child.

Imports no rclpy itself: ``ros.context`` tells it, through :func:`watch_rclpy_users`, whether this
process uses rclpy.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

from ..line.errors import BridgeError

#: In a forked child: the pid of the parent, when rclpy (so DDS: Fast DDS's threads, sockets and
#: locks) was live there at the fork. Set by the fork hooks below, inherited by the child.
_forked_from_live: int | None = None
#: Whether this process was forked (a multiprocessing worker with the fork context: SB3's
#: SubprocVecEnv, Gymnasium's AsyncVectorEnv, the benchmark's pool).
_in_forked_child = False


def _no_users() -> int:
    return 0


#: How many users of rclpy this process has (``ros.context`` sets it; see watch_rclpy_users).
_rclpy_users: Callable[[], int] = _no_users


def watch_rclpy_users(users: Callable[[], int]) -> None:
    """Gives the fork hooks the count of this process's rclpy users (``ros.context``'s)."""
    global _rclpy_users
    _rclpy_users = users


def _default_context_live() -> bool:
    """Whether rclpy's default context is initialised. Reads the attribute without rclpy's lock
    (this runs in a fork hook), and only if rclpy was imported."""
    utilities = sys.modules.get("rclpy.utilities")
    context = getattr(utilities, "g_default_context", None)
    return context is not None and context.handle is not None


def _before_fork() -> None:
    global _forked_from_live
    if _forked_from_live is None and (_rclpy_users() > 0 or _default_context_live()):
        _forked_from_live = os.getpid()


def _after_fork_in_parent() -> None:
    global _forked_from_live
    if _forked_from_live == os.getpid():
        _forked_from_live = None


def _after_fork_in_child() -> None:
    global _in_forked_child
    _in_forked_child = True


os.register_at_fork(before=_before_fork, after_in_parent=_after_fork_in_parent, after_in_child=_after_fork_in_child)


def in_forked_child() -> bool:
    """Whether this process was forked from another (whatever the other had live)."""
    return _in_forked_child


def fork_error() -> BridgeError | None:
    """The error to raise when this process was forked from one where rclpy was live, else None."""
    if _forked_from_live is None or _forked_from_live == os.getpid():
        return None
    return BridgeError(
        f"rclpy/DDS is not fork-safe: a context initialised in pid {_forked_from_live} cannot be used in pid "
        f"{os.getpid()}, a process forked from it. Make the environments in the child (sorting_line_gym "
        "envs connect at their first reset(), so constructing them before the fork is fine as long as "
        "nothing used rclpy yet), or start the children with the multiprocessing context 'spawn' or "
        "'forkserver' (e.g. AsyncVectorEnv(..., context='spawn'), SubprocVecEnv(..., start_method='spawn'))"
    )


def check_not_forked() -> None:
    error = fork_error()
    if error is not None:
        raise error
