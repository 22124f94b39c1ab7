"""rclpy, initialised once per process and never used across a fork.

rclpy over Fast DDS is not fork-safe (shared/platform/ros2-without-a-ros-install.md): the fork
hooks here remember whether rclpy was live when a process forked, so that a child's first use
fails at once with an error naming the cause and the fix instead of blocking forever.

An env is a guest in its user's process, so rclpy is initialised without its signal handlers:
with them, SIGTERM only shut rclpy down and the process lived on, so ``Process.terminate()``
(multiprocessing's exit handler, SB3's and Gymnasium's vectorizers after a worker failed, a killed
benchmark's pool) left workers blocked and their parents waiting on them forever. SIGINT keeps
Python's own handler (KeyboardInterrupt), which the waits notice within one wait slice.

An env in a multiprocessing worker (SB3's SubprocVecEnv, Gymnasium's AsyncVectorEnv, a pool)
asks the kernel for SIGTERM when the worker's parent dies: a vectorizer's workers wait on their
command pipe, and with fork every sibling holds the parent's ends open, so no EOF ever came; a
training script killed (or timed out) left its 15 other workers, and their leased lines, behind
for good.

In a forked child, and in a process its host ends by killing it (Ray's EnvRunners,
:func:`keep_participant_until_killed`), the DDS participant lives as long as the process
(``_keep_participant``): deleting it while the other workers close can hang for minutes in Fast
DDS 2.14."""

from __future__ import annotations

import os
import signal
import threading

import rclpy
from rclpy.signals import SignalHandlerOptions

from ..line.errors import BridgeError
from ..line.process import die_with_parent

_rclpy_lock = threading.Lock()
_rclpy_users = 0
_rclpy_ours = False
#: In a forked child: the pid of the parent, when rclpy (so DDS: Fast DDS's threads, sockets and
#: locks) was live there at the fork. Set by the fork hooks below, inherited by the child.
_forked_from_live: int | None = None
#: Whether this process was forked (a multiprocessing worker with the fork context: SB3's
#: SubprocVecEnv, Gymnasium's AsyncVectorEnv, the benchmark's pool); see _keep_participant.
_in_forked_child = False
#: Whether this process's host ends it by killing it (keep_participant_until_killed).
_killed_at_end = False
#: In a forked child or one killed at its end, once rclpy is up: a node never destroyed, see
#: _keep_participant.
_participant_anchor = None


def _default_context_live() -> bool:
    """Whether rclpy's default context is initialised. Reads the attribute without rclpy's lock
    (this runs in a fork hook)."""
    import rclpy.utilities

    context = getattr(rclpy.utilities, "g_default_context", None)
    return context is not None and context.handle is not None


def _before_fork() -> None:
    global _forked_from_live
    if _forked_from_live is None and (_rclpy_users > 0 or _default_context_live()):
        _forked_from_live = os.getpid()


def _after_fork_in_parent() -> None:
    global _forked_from_live
    if _forked_from_live == os.getpid():
        _forked_from_live = None


def _after_fork_in_child() -> None:
    global _in_forked_child
    _in_forked_child = True


os.register_at_fork(before=_before_fork, after_in_parent=_after_fork_in_parent, after_in_child=_after_fork_in_child)


def fork_error() -> BridgeError | None:
    """The error to raise when this process was forked from one where rclpy was live, else None.

    rclpy over Fast DDS is not fork-safe: the child inherits the context's memory but not the
    threads that serve it, so its first wait blocks forever on a lock a vanished thread held."""
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


def _die_with_multiprocessing_parent() -> None:
    """In a multiprocessing child: SIGTERM when the parent dies (the kernel ties it to the thread
    that started the child, which is the main thread in SB3's, Gymnasium's and the benchmark's
    pools), unless the process chose a parent-death signal itself (the benchmark's pool: SIGKILL).

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


def _keep_participant() -> None:
    """In a forked child: a node of the bridge's own that is never destroyed, so that closing an
    env never deletes the process's DDS participant, and rclpy is never shut down.

    Why: destroying a context's last node deletes its Fast DDS participant, and that can hang for
    minutes when other participants of the domain close at the same moment, as a vectorizer's
    workers all do on ``close()``: rmw_fastrtps first calls ``DomainParticipant::set_listener
    (nullptr)``, which waits for the discovery callbacks in flight, and Fast DDS 2.14 (the only
    one rclpy's wheels have) waited so at 78 % CPU while its discovery thread, in
    ``onReaderDiscovery``, waited for the participant's mutex (gdb stacks of a SubprocVecEnv-16
    worker stuck 4 min in ``env.close()``; in CI an AsyncVectorEnv (fork) hung 240 s in its
    ``close()``, with no stacks taken). Running the deletion at ``SCHED_IDLE`` priority did not
    help (one hang in 5 runs under load, as before). A forked worker ends with ``os._exit``, so its
    participant is never deleted at all: the others drop it when its lease expires, as for a killed
    process. The same holds for a process its host kills at the end
    (:func:`keep_participant_until_killed`). Other processes delete their participant: they may fork
    after their envs are closed, which needs rclpy shut down (``fork_error``), and they end through
    interpreter finalisation."""
    global _participant_anchor
    if (_in_forked_child or _killed_at_end) and _participant_anchor is None:
        _participant_anchor = rclpy.create_node(
            f"sorting_line_gym_keepalive_{os.getpid()}", start_parameter_services=False, enable_rosout=False
        )


def keep_participant_until_killed() -> None:
    """Declares that this process is ended by being killed, never by closing its envs and
    returning: closing an env then leaves the DDS participant alone (see ``_keep_participant``).

    For Ray's EnvRunners (``training.rllib`` calls it in each): RLlib stops one by closing its
    envs, then ends it with ``ray.kill``. A run in CI hung there: an EnvRunner spun in
    ``destroy_node`` (Fast DDS ``DomainParticipant::set_listener(nullptr)``, gdb) for the whole
    400 s of the test while the other EnvRunner closed its envs."""
    global _killed_at_end
    with _rclpy_lock:
        _killed_at_end = True
        if _rclpy_users > 0 and _rclpy_ours:
            _keep_participant()


def keeps_participant() -> bool:
    """Whether this process's DDS participant outlives its envs (``_keep_participant``)."""
    return _participant_anchor is not None


def acquire_rclpy() -> None:
    """Initialises rclpy if nobody has; paired with :func:`release_rclpy`. Raises instead of
    blocking when this process was forked from one where rclpy was live (:func:`fork_error`)."""
    global _rclpy_users, _rclpy_ours
    check_not_forked()
    with _rclpy_lock:
        if _rclpy_users == 0 and not rclpy.ok():
            _die_with_multiprocessing_parent()
            rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
            _rclpy_ours = True
            _keep_participant()
        _rclpy_users += 1


def release_rclpy() -> None:
    """Shuts rclpy down when the last user that needed it to be initialised is gone."""
    global _rclpy_users, _rclpy_ours
    if fork_error() is not None:
        return  # the inherited context is not ours to shut down here
    with _rclpy_lock:
        _rclpy_users = max(0, _rclpy_users - 1)
        if _rclpy_users == 0 and _rclpy_ours and rclpy.ok() and _participant_anchor is None:
            rclpy.shutdown()
            _rclpy_ours = False
