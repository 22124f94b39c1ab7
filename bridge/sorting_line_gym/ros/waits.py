"""Waiting on rclpy with a deadline: every wait of the bridge goes through :class:`Waiter`, which
fails with an error naming what it waited for, and at once if the node process it watches died.

No ``spin_until_future_complete`` (it leaks a task per call in rclpy 7.1; ``workarounds`` lists
it): every wait is ``executor.spin_once`` (or an rcl wait set) in a loop with a deadline."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from rclpy.executors import SingleThreadedExecutor

from ..line.errors import BridgeError, BridgeTimeout

if TYPE_CHECKING:
    from ..line.process import HeldNode


#: Longest single wait: how soon a dead node or the deadline is noticed.
WAIT_SLICE = 0.05


class Waiter:
    """Waits until a condition holds, with a deadline and a liveness check: ``until`` spins the
    executor (services, any subscription); ``until_received`` waits on the given subscriptions
    alone, for conditions that take their messages themselves (the step loop)."""

    def __init__(self, executor: SingleThreadedExecutor, process: HeldNode | None):
        self.executor = executor
        self.process = process
        self._wait_set = None
        self._wait_handles: tuple = ()

    def _check(self, deadline: float, timeout: float, what: Callable[[], str]) -> float:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise BridgeTimeout(f"timed out after {timeout:g} s waiting for {what()}")
        if self.process is not None and not self.process.alive():
            raise BridgeError(f"while waiting for {what()}: {self.process.death_notice()}")
        return remaining

    def until(self, done: Callable[[], bool], timeout: float, what: Callable[[], str]) -> None:
        self.until_deadline(done, time.monotonic() + timeout, timeout, what)

    def until_deadline(
        self, done: Callable[[], bool], deadline: float, timeout: float, what: Callable[[], str]
    ) -> None:
        """``until`` for a wait that is the last part of a longer one: ``deadline`` (monotonic
        time) is when the whole of it, ``timeout`` seconds long, ends."""
        while not done():
            remaining = self._check(deadline, timeout, what)
            self.executor.spin_once(timeout_sec=min(remaining, WAIT_SLICE))

    def until_received(self, subscriptions, done: Callable[[], bool], timeout: float, what: Callable[[], str]) -> None:
        """Like ``until``, but sleeps on an rcl wait set holding only ``subscriptions``, kept
        across calls, instead of the executor, which rebuilds a wait set over every entity of
        the node and dispatches through Python on every wake-up: the step loop's round trip is
        shorter this way (benches/bridge_throughput.py). ``done`` must take the messages itself
        (``take_message``); nothing here runs callbacks. This is the wait that
        ``rclpy.wait_for_message`` performs, through rclpy's implementation module (rclpy is
        pinned exactly in requirements-ros.txt)."""
        if done():
            return
        deadline = time.monotonic() + timeout
        handles = tuple(sub.handle for sub in subscriptions)
        if self._wait_set is None or handles != self._wait_handles:
            from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

            self._wait_set = _rclpy.WaitSet(len(handles), 0, 0, 0, 0, 0, self.executor.context.handle)
            self._wait_handles = handles
        wait_set = self._wait_set
        while True:  # done() was just checked: wait first (each check takes from every subscription)
            remaining = self._check(deadline, timeout, what)
            wait_set.clear_entities()
            for handle in handles:
                wait_set.add_subscription(handle)
            wait_set.wait(int(min(remaining, WAIT_SLICE) * 1e9))
            if done():
                return
