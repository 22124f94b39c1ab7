"""The suite's one wait for conditions that need no rclpy spinning: a process exiting, a file or a log
line appearing, a port answering, a CLI's output showing something.

``wait_until(condition, timeout, what)`` polls ``condition()`` until it is truthy and returns that
value; after ``timeout`` s it raises WaitTimeout (defined here; ros_harness re-exports it) naming
``what``, the timeout and what ``context()`` says then. RosSession.spin_until, for waits that spin
rclpy, is this same loop with rclpy's spinning as its pause, so a failed wait reads the same either
way. ``abort()`` says why waiting on is pointless (the process that should write the line has
exited): the wait then ends at once, after one more look at the condition (spin_until looks for
half a second). No test sleeps to synchronise: it waits here, or in spin_until, for what it needs
to see.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


class WaitTimeout(AssertionError):
    """A wait that ended without its condition: the message names what was awaited, for how long or
    why it gave up, and the context of the wait (``support.ros_harness`` re-exports it)."""


def wait_until(
    condition: Callable[[], Any],
    timeout: float,
    what: str,
    *,
    poll: float = 0.05,
    context: Callable[[], str] = lambda: "",
    abort: Callable[[], str | None] = lambda: None,
    pause: Callable[[float], Any] = time.sleep,
    drain: float = 0.0,
) -> Any:
    """Calls ``condition()`` every ``poll`` s until it is truthy and returns its value; raises
    WaitTimeout naming ``what`` after ``timeout`` s, or soon after ``abort()`` gives a reason: the
    condition is looked at for ``drain`` s more first (0: once more), so that what a peer wrote
    just before it went still counts. ``pause(s)`` passes the time between looks: a sleep here,
    rclpy spinning in RosSession.spin_until, the one other user of this loop."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if result:
            return result
        reason = abort()
        if reason:
            result = _drained(condition, drain, poll, pause)
            if result:
                return result
            raise WaitTimeout(_with_context(f"gave up waiting for {what}: {reason}", context))
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise WaitTimeout(_with_context(f"timed out after {timeout:.1f} s waiting for {what}", context))
        pause(min(poll, remaining))


def _drained(condition: Callable[[], Any], seconds: float, poll: float, pause: Callable[[float], Any]) -> Any:
    """``condition()``'s value once it is truthy within ``seconds`` (looked at least once), else its last."""
    end = time.monotonic() + seconds
    while True:
        result = condition()
        left = end - time.monotonic()
        if result or left <= 0:
            return result
        pause(min(poll, left))


def _with_context(message: str, context: Callable[[], str]) -> str:
    extra = context()
    return message + (f"\n{extra}" if extra else "")
