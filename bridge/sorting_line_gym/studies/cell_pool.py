"""Cells of a study run several at a time, each in a worker process of its own (with its own
node), for the benchmark and the transfer study.

Workers are fresh interpreters (spawn: rclpy is not fork-safe) that the kernel kills when the
study's process dies, however it dies (a study killed with SIGKILL runs no handler). Ctrl-C or
SIGTERM (made a KeyboardInterrupt by ``interrupt``) kills the workers at once, their nodes with
them through their parent-death signal, instead of waiting for their cells (minutes of training).
"""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from ..workarounds.orphaned_processes import die_with_parent
from ..workarounds.participant_deletion_hang import outlives_its_envs


def interrupt(signum, frame):
    """A SIGTERM handler: stop as Ctrl-C does."""
    raise KeyboardInterrupt


def die_with_the_study() -> None:
    """Worker initializer: the kernel kills this worker when the study's process dies; it runs
    cell after cell, so it closes its DDS participant after each (``outlives_its_envs``)."""
    die_with_parent(signal.SIGKILL)
    outlives_its_envs()


def stop_workers(pool: ProcessPoolExecutor) -> None:
    """Kills the pool's workers at once (their nodes get SIGTERM through their parent-death
    signal): a worker would otherwise finish its cell before the pool's shutdown reached it."""
    for child in multiprocessing.active_children():
        child.kill()
    pool.shutdown(wait=False, cancel_futures=True)


def run_parallel(
    todo: Iterable[Any],
    call: Callable[[Any], tuple],
    jobs: int,
    finished: Callable[[Any, Any], None],
    running: Callable[[list[Any]], None] = lambda items: None,
) -> None:
    """Runs ``call(item)`` = (function, *arguments) for each item, ``jobs`` at a time in workers;
    ``finished(item, result or exception)`` here as each ends; ``running(items)`` when the set of
    running items changes. A KeyboardInterrupt kills the workers and goes on up."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=die_with_the_study) as pool:
        try:
            pending = {}
            queue = list(todo)
            while queue or pending:
                while queue and len(pending) < jobs:
                    item = queue.pop(0)
                    pending[pool.submit(*call(item))] = item
                    running(list(pending.values()))
                complete, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in complete:
                    item = pending.pop(future)
                    try:
                        outcome = future.result()
                    except Exception as e:  # noqa: BLE001 - report every failed cell, keep the others
                        outcome = e
                    finished(item, outcome)
        except KeyboardInterrupt:
            stop_workers(pool)  # before the with-block's shutdown, which would wait for the cells
            raise
