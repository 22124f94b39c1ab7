"""The host's lock for joining the DDS graph one environment at a time, without ROS
(workarounds/simultaneous_discovery.py):
a queue that moves is waited out however long it is; a holder that keeps the lock past the
timeout makes the waiter fail, naming the holder."""

from __future__ import annotations

import os
import threading
import time

import pytest

from sorting_line_gym import BridgeTimeout
from sorting_line_gym.workarounds.simultaneous_discovery import joining_graph


@pytest.fixture(autouse=True)
def own_lock(monkeypatch):
    # The lock is per network namespace and ROS_DOMAIN_ID: one of this test's own.
    monkeypatch.setenv("ROS_DOMAIN_ID", f"join-lock-test-{os.getpid()}-{time.monotonic_ns()}")


def test_a_queue_longer_than_the_timeout_is_waited_out_while_it_moves():
    hold, timeout, holders = 0.6, 2.0, 5  # 3 s of queue against a 2 s timeout; each turn well within it
    turns, errors = [], []
    started = threading.Barrier(holders)

    def holder(k):
        started.wait()
        try:
            with joining_graph(timeout):
                turns.append(k)
                time.sleep(hold)
        except BaseException as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=holder, args=(k,)) for k in range(holders)]
    t0 = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert not errors, f"a waiter gave up while the queue moved: {errors}"
    assert sorted(turns) == list(range(holders))
    assert time.monotonic() - t0 > timeout, "the queue took less than the timeout: this test tests nothing"


def test_a_holder_that_keeps_the_lock_makes_the_waiter_fail_naming_it():
    release, held = threading.Event(), threading.Event()

    def holder():
        with joining_graph(60):
            held.set()
            release.wait(30)

    t = threading.Thread(target=holder)
    t.start()
    try:
        assert held.wait(10)
        t0 = time.monotonic()
        with pytest.raises(BridgeTimeout, match=rf"pid {os.getpid()} has held the lock .* for \d+ s"):
            with joining_graph(1.0):
                pass
        assert time.monotonic() - t0 < 25, "the waiter waited for the holder to let go instead of timing out"
    finally:
        release.set()
        t.join(timeout=10)
