"""The suite's wait for conditions outside rclpy (tests/python/support/waits.py): what it returns, and what a
failed wait says (the same error as RosSession.spin_until's)."""

from __future__ import annotations

import itertools
import time

import pytest

from support import ros_harness as h
from support import waits
from support.waits import wait_until


def test_the_conditions_first_truthy_value_is_returned():
    calls = itertools.count(1)
    assert wait_until(lambda: next(calls) >= 3 and "ready", 5.0, "the third call", poll=0.001) == "ready"
    assert next(calls) == 4, "polled again after the condition held"


def test_a_timeout_names_what_it_waited_for_how_long_and_the_context():
    start = time.monotonic()
    with pytest.raises(h.WaitTimeout) as failure:
        wait_until(lambda: None, 0.2, "the answer", poll=0.01, context=lambda: "last seen: nothing")
    assert time.monotonic() - start >= 0.2, "gave up before its timeout"
    assert str(failure.value) == "timed out after 0.2 s waiting for the answer\nlast seen: nothing"


def test_an_abort_ends_the_wait_at_once_after_one_more_look():
    start = time.monotonic()
    with pytest.raises(h.WaitTimeout, match=r"^gave up waiting for the log line: the writer exited\nits log$"):
        wait_until(lambda: False, 60.0, "the log line", context=lambda: "its log", abort=lambda: "the writer exited")
    assert time.monotonic() - start < 5.0, "an abort did not end the wait"
    # What the writer wrote just before it exited counts: the condition is looked at once more.
    looks = itertools.count(1)
    assert wait_until(lambda: next(looks) == 2, 60.0, "the log line", abort=lambda: "the writer exited") is True


def test_a_drain_keeps_looking_after_an_abort_pausing_as_it_is_told():
    # RosSession.spin_until's use: after the peer is gone, what it sent may still be on its way, so
    # the condition is looked at for `drain` s more, with rclpy's spinning as the pause.
    pauses: list[float] = []
    arrives = time.monotonic() + 0.1
    found = wait_until(
        lambda: time.monotonic() >= arrives and "late message",
        60.0,
        "the message",
        poll=0.01,
        abort=lambda: "the peer exited",
        pause=lambda seconds: (pauses.append(seconds), time.sleep(seconds)),
        drain=2.0,
    )
    assert found == "late message" and pauses and max(pauses) <= 0.01
    start = time.monotonic()
    with pytest.raises(h.WaitTimeout, match="^gave up waiting for the message: the peer exited$"):
        wait_until(lambda: None, 60.0, "the message", poll=0.01, abort=lambda: "the peer exited", drain=0.2)
    assert 0.2 <= time.monotonic() - start < 5.0, "the drain did not last its time, or did not end"
    assert h.WaitTimeout is waits.WaitTimeout, "one error for both waits"
