"""rclpy, initialised once per process, shut down when its last user is gone, never used across a fork.

An env is a guest in its user's process, so rclpy is initialised without its signal handlers:
with them, SIGTERM only shut rclpy down and the process lived on, so ``Process.terminate()``
(multiprocessing's exit handler, SB3's and Gymnasium's vectorizers after a worker failed, a killed
benchmark's pool) left workers blocked and their parents waiting on them forever. SIGINT keeps
Python's own handler (KeyboardInterrupt), which the waits notice within one wait slice.

Three workarounds hook in here (``workarounds/`` says why and when each can go): a process forked
from one where rclpy was live refuses to use it (``fork_unsafe_dds``); an env in a multiprocessing
worker dies with the worker's parent (``orphaned_processes``); a worker process (forked, started by
multiprocessing, or ended by being killed) keeps its DDS participant and ends without DDS teardown
(``participant_deletion_hang``).
"""

from __future__ import annotations

import os
import threading

import rclpy
from rclpy.signals import SignalHandlerOptions

from ..line.errors import BridgeError
from ..workarounds import participant_deletion_hang
from ..workarounds.fork_unsafe_dds import check_not_forked, fork_error, watch_rclpy_users
from ..workarounds.orphaned_processes import die_with_multiprocessing_parent

#: Held while rclpy is initialised or shut down here (and by participant_deletion_hang).
rclpy_lock = threading.Lock()
_rclpy_users = 0
_rclpy_ours = False

watch_rclpy_users(lambda: _rclpy_users)


#: The highest DDS domain id: RTPS ports are 7400 + 250 * domain + offsets, below 65,536.
MAX_DOMAIN_ID = 232


def check_domain_id() -> None:
    """Raises, naming the value and the allowed range, unless ``ROS_DOMAIN_ID`` is unset or an
    integer 0 ..= 232: with one beyond, rmw_fastrtps ends the process (exit code 1, no message)
    when rclpy makes its first node, and a vectorizer's worker then vanishes without a word."""
    raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if raw and not (raw.isdigit() and int(raw) <= MAX_DOMAIN_ID):
        raise BridgeError(f"ROS_DOMAIN_ID = {raw!r} is out of range: allowed an integer 0 ..= {MAX_DOMAIN_ID}")


def rclpy_is_ours() -> bool:
    """Whether this module initialised rclpy and someone still uses it (call with rclpy_lock held)."""
    return _rclpy_users > 0 and _rclpy_ours


participant_deletion_hang.watch_rclpy_context(rclpy_lock, rclpy_is_ours)


def acquire_rclpy() -> None:
    """Initialises rclpy if nobody has; paired with :func:`release_rclpy`. Raises instead of
    blocking when this process was forked from one where rclpy was live (``fork_error``)."""
    global _rclpy_users, _rclpy_ours
    check_not_forked()
    check_domain_id()
    with rclpy_lock:
        if _rclpy_users == 0 and not rclpy.ok():
            die_with_multiprocessing_parent()
            rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
            _rclpy_ours = True
            participant_deletion_hang.keep_participant()
        _rclpy_users += 1


def release_rclpy() -> None:
    """Shuts rclpy down when the last user that needed it to be initialised is gone."""
    global _rclpy_users, _rclpy_ours
    if fork_error() is not None:
        return  # the inherited context is not ours to shut down here
    with rclpy_lock:
        _rclpy_users = max(0, _rclpy_users - 1)
        if _rclpy_users == 0 and _rclpy_ours and rclpy.ok() and not participant_deletion_hang.keeps_participant():
            rclpy.shutdown()
            _rclpy_ours = False
