"""Workaround: deleting a DDS participant can hang in Fast DDS 2.14, so some processes never delete theirs.

Destroying a context's last node deletes its Fast DDS participant, and that can hang for minutes
when other participants of the domain close at the same moment, as a vectorizer's workers all do
on ``close()``: rmw_fastrtps first calls ``DomainParticipant::set_listener(nullptr)``, which waits
for the discovery callbacks in flight, and Fast DDS 2.14 (the only one rclpy's wheels have) waited
so at 78 % CPU while its discovery thread, in ``onReaderDiscovery``, waited for the participant's
mutex (gdb stacks of a SubprocVecEnv-16 worker stuck 4 min in ``env.close()``; in CI an
AsyncVectorEnv (fork) hung 240 s in its ``close()``, with no stacks taken; a remote Ray EnvRunner
spun there for a test's whole 400 s). Running the deletion at ``SCHED_IDLE`` priority did not help
(one hang in 5 runs under load, as before).

So a process that ends without deleting its participant anyway keeps it, as a node of the bridge's
own that is never destroyed (:func:`keep_participant`): closing an env then never deletes the
participant, and rclpy is never shut down. That is a forked child (it ends with ``os._exit``) and a
process its host ends by killing it (:func:`keep_participant_until_killed`: Ray's EnvRunners). The
others drop the participant when its lease expires, as for a killed process. Such a process keeps
the nodes its envs close as well (:func:`retire_node`): destroying one hung the same way with the
participant kept (a SubprocVecEnv-16 worker (fork) in ``destroy_node``, in ``rcl_node_fini``, for the
test's 240 s, in a quiet fresh-clone run of the suite on 2026-11-26), and the process is about to
end. Other processes
delete their participant: they may fork after their envs are closed, which needs rclpy shut down
(``fork_unsafe_dds.fork_error``), and they end through interpreter finalisation.
"""

from __future__ import annotations

import os

from .fork_unsafe_dds import in_forked_child

#: Whether this process's host ends it by killing it (keep_participant_until_killed).
_killed_at_end = False
#: In a forked child or one killed at its end, once rclpy is up: a node never destroyed.
_participant_anchor = None
#: The nodes closed envs left to such a process (retire_node): never destroyed either.
_retired_nodes: list = []


def keep_participant() -> None:
    """Called by ``ros.context`` right after it initialised rclpy (with its lock held): in a
    forked child or a process killed at its end, creates the node that keeps the participant."""
    global _participant_anchor
    if (in_forked_child() or _killed_at_end) and _participant_anchor is None:
        import rclpy

        _participant_anchor = rclpy.create_node(
            f"sorting_line_gym_keepalive_{os.getpid()}", start_parameter_services=False, enable_rosout=False
        )


def keep_participant_until_killed() -> None:
    """Declares that this process is ended by being killed, never by closing its envs and
    returning: closing an env then leaves the DDS participant alone.

    For Ray's EnvRunners (``training.rllib`` calls it in each): RLlib stops one by closing its
    envs, then ends it with ``ray.kill``. A run in CI hung there: an EnvRunner spun in
    ``destroy_node`` (Fast DDS ``DomainParticipant::set_listener(nullptr)``, gdb) for the whole
    400 s of the test while the other EnvRunner closed its envs."""
    global _killed_at_end
    from ..ros import context  # the rclpy this process initialised, if any (imports rclpy)

    with context.rclpy_lock:
        _killed_at_end = True
        if context.rclpy_is_ours():
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
