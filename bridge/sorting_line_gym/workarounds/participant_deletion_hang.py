"""Workaround: deleting a DDS participant can hang in Fast DDS 2.14, so a process that is about to end
never deletes its own, and ends without DDS teardown.

Destroying a context's last node deletes its Fast DDS participant, and that can spin for minutes
when other participants of the domain come or go at the same moment, as a vectorizer's workers all
do on ``close()``: rmw_fastrtps first calls ``DomainParticipant::set_listener(nullptr)``, whose
default timeout is infinite and which waits for the discovery callbacks in flight, busy, where
libstdc++'s condition variable does not wait on ``steady_clock`` (as in the manylinux_2_28 wheels
of Fast DDS 2.14.5 that rclpy's Jazzy wheels bring): eProsima/Fast-DDS issue 6513, open, no
release fixes it. The hangs seen (in ``env.close()`` and, with the participant kept, in
``destroy_node``), and what did not help, are in docs/results/reliability.md, "Closing under CPU
hogs". Running the deletion at a lower scheduling priority did not help, and a bounded deletion in
a helper thread cannot: the deletion spins with the GIL held.

So the rule is: **a worker never deletes its participant nor its nodes, and ends without DDS
teardown**. A worker is a process that ends when its work returns or when its host kills it: a
forked child, a multiprocessing worker of any start method (fork, forkserver, spawn: Gymnasium's
AsyncVectorEnv, SB3's SubprocVecEnv, the benchmark's pool) and a process ended by being killed
(Ray's EnvRunners, :func:`keep_participant_until_killed`). Such a process keeps its participant as
a node of the bridge's own that is never destroyed (:func:`keep_participant`, called when rclpy
comes up) and keeps the nodes its closed envs leave (:func:`retire_node`); closing an env then
deletes no DDS entity and never shuts rclpy down. How each kind ends without teardown:
- fork and forkserver workers end with ``os._exit`` (multiprocessing's own code), which runs no
  destructor;
- spawn workers end with ``sys.exit`` from ``multiprocessing.spawn.spawn_main``, whose interpreter
  finalisation would destroy rclpy's handles and then Fast DDS's ``DomainParticipantFactory``
  (which disables, so ``set_listener(nullptr)``, every participant left): :func:`_end_spawn_worker_as_forked`
  makes that one call end as a forked worker ends, ``os._exit`` with the same exit code after the
  flush ``multiprocessing`` already did;
- killed processes run no teardown.
Any other process (a script, a test, the benchmark's main process) deletes its participant when its
last env closes, so that it may fork afterwards (``fork_unsafe_dds.fork_error``), and before it
stops the node process it started (``ros.bank``: the node's departure is a discovery event).

How to tell when this can go: with a Fast DDS whose ``set_listener`` waits without spinning (the
fix of issue 6513 in a wheel rclpy uses), ``python benches/close_stress.py`` under two CPU hogs
with :func:`keep_participant` and :func:`retire_node` reduced to ``destroy_node`` everywhere prints
0 hangs, and so do the SubprocVecEnv-16 and AsyncVectorEnv tests of test_vectorizers and test_rllib
run repeatedly under load.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from collections.abc import Callable
from typing import Any

from .fork_unsafe_dds import in_forked_child

#: Whether this process's host ends it by killing it (keep_participant_until_killed).
_killed_at_end = False
#: Whether this worker lives on after each of its envs, running many in turn (outlives_its_envs).
_outlives_its_envs = False
#: In a worker, once rclpy is up: a node never destroyed, that keeps the participant.
_participant_anchor = None
#: The nodes closed envs left to such a process (retire_node): never destroyed either.
_retired_nodes: list = []
#: ``ros.context``'s lock and its "rclpy is ours and in use" test, once it is imported
#: (watch_rclpy_context): this module imports no rclpy, and nothing of ``ros``, itself.
_rclpy_context: tuple[Any, Callable[[], bool]] | None = None


def watch_rclpy_context(lock, rclpy_is_ours: Callable[[], bool]) -> None:
    """Called by ``ros.context`` when it is imported: the lock it holds while it initialises or
    shuts down rclpy, and whether it initialised rclpy and someone uses it (call with the lock held)."""
    global _rclpy_context
    _rclpy_context = (lock, rclpy_is_ours)


def is_worker() -> bool:
    """Whether this process ends when its work returns or is killed at its end: forked, or a
    multiprocessing worker of any start method (unless it declared outlives_its_envs), or one
    declared by keep_participant_until_killed."""
    forked_or_started = in_forked_child() or multiprocessing.parent_process() is not None
    return (forked_or_started and not _outlives_its_envs) or _killed_at_end


def outlives_its_envs() -> None:
    """Declares (before its first env) a worker that runs many envs one after another and lives on
    after each: the studies' cell pool (``studies.cell_pool``), whose workers train cell after cell
    for hours. It deletes its participant when its last env closes, as a script does, rather than
    keeping every node it ever closed with their DDS endpoints, which each new node would then
    discover. Its envs close at their own times, one cell at a time, not all at once with their
    siblings'."""
    global _outlives_its_envs
    _outlives_its_envs = True


def keep_participant() -> None:
    """Called by ``ros.context`` right after it initialised rclpy (with its lock held): in a
    worker, creates the node that keeps the participant, and makes a spawn worker end without
    DDS teardown."""
    global _participant_anchor
    if is_worker() and _participant_anchor is None:
        import rclpy

        _participant_anchor = rclpy.create_node(
            f"sorting_line_gym_keepalive_{os.getpid()}", start_parameter_services=False, enable_rosout=False
        )
        _end_spawn_worker_as_forked()


def keep_participant_until_killed() -> None:
    """Declares that this process is ended by being killed, never by closing its envs and
    returning: closing an env then leaves the DDS participant alone.

    For Ray's EnvRunners (``training.rllib`` calls it in each): RLlib stops one by closing its
    envs, then ends it with ``ray.kill``. A run in CI hung there: an EnvRunner spun in
    ``destroy_node`` (Fast DDS ``DomainParticipant::set_listener(nullptr)``, gdb) for the whole
    400 s of the test while the other EnvRunner closed its envs."""
    global _killed_at_end
    # The flag first: a ``ros.context`` imported after the test below reads it when it brings
    # rclpy up (keep_participant, with its lock held); one imported before is asked here.
    _killed_at_end = True
    if _rclpy_context is not None:
        lock, rclpy_is_ours = _rclpy_context
        with lock:
            if rclpy_is_ours():
                keep_participant()


def keeps_participant() -> bool:
    """Whether this process's DDS participant outlives its envs."""
    return _participant_anchor is not None


def retire_node(node) -> None:
    """Ends the use of ``node`` (already out of its executor): destroys it, or, in a process that
    keeps its participant, keeps it undestroyed until the process ends (its entities' deletion can
    hang as the participant's does; a closed env's node is never spun again)."""
    if keeps_participant():
        _retired_nodes.append(node)
    else:
        node.destroy_node()


def _end_spawn_worker_as_forked() -> None:
    """In a multiprocessing worker: replaces ``sys.exit`` with a function that, called by
    ``multiprocessing.spawn.spawn_main`` with the worker's exit code (its last act, after the
    worker's target returned and multiprocessing flushed the standard streams), ends the process
    with ``os._exit`` as fork and forkserver workers end; any other call goes to ``sys.exit`` as
    before. Outside spawn workers spawn_main never calls it, so it changes nothing there."""
    import multiprocessing.spawn

    spawn_main = multiprocessing.spawn.spawn_main.__code__
    system_exit = sys.exit
    if getattr(system_exit, "ends_spawn_worker_as_forked", False):
        return

    def exit(status=None):  # noqa: A001 (it stands in for sys.exit)
        if sys._getframe(1).f_code is spawn_main and isinstance(status, int):
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except (AttributeError, OSError, ValueError):
                    pass
            os._exit(status)
        system_exit(status)

    exit.ends_spawn_worker_as_forked = True
    sys.exit = exit
