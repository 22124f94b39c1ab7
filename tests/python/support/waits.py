"""The suite's one wait for conditions that need no rclpy spinning: a process exiting, a file or a log
line appearing, a port answering, a CLI's output showing something.

``wait_until(condition, timeout, what)`` polls ``condition()`` until it is truthy and returns that value;
after ``timeout`` s it raises ros_harness.WaitTimeout naming ``what``, the timeout and what ``context()``
says then, so that a failed wait reads the same as one of RosSession.spin_until (which waits that spin
rclpy keep using). ``abort()`` says why waiting on is pointless (the process that should write the line
has exited): the wait then ends at once, after one more look at the condition. No test sleeps to
synchronise: it waits here, or in spin_until, for what it needs to see.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from support.ros_harness import WaitTimeout


def wait_until(
    condition: Callable[[], Any],
    timeout: float,
    what: str,
    *,
    poll: float = 0.05,
    context: Callable[[], str] = lambda: "",
    abort: Callable[[], str | None] = lambda: None,
) -> Any:
    """Calls ``condition()`` every ``poll`` s until it is truthy and returns its value; raises
    WaitTimeout naming ``what`` after ``timeout`` s, or as soon as ``abort()`` gives a reason (the
    condition is looked at once more first: what a process wrote just before it exited counts)."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if result:
            return result
        reason = abort()
        if reason:
            result = condition()
            if result:
                return result
            extra = context()
            raise WaitTimeout(f"gave up waiting for {what}: {reason}" + (f"\n{extra}" if extra else ""))
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            extra = context()
            raise WaitTimeout(f"timed out after {timeout:.1f} s waiting for {what}" + (f"\n{extra}" if extra else ""))
        time.sleep(min(poll, remaining))
