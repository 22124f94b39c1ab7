"""The host's lock for joining the DDS graph one environment at a time, without ROS
(workarounds/simultaneous_discovery.py):
a queue that moves is waited out however long it is; a holder is waited out for the turn it
declared, whatever the waiter's own; one that keeps the lock past its turn makes the waiter
fail, naming it."""

from __future__ import annotations

import fcntl
import os
import threading
import time

import pytest

from sorting_line_gym import BridgeTimeout
from sorting_line_gym.workarounds.simultaneous_discovery import HANDOVER, join_lock_path, joining_graph


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
                time.sleep(hold)  # not a wait: holding the lock this long is the queue under test
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


def _holding(turn: float, keep: float):
    """A thread that takes the lock declaring ``turn`` and keeps it ``keep`` seconds (or until
    released); returns once it holds the lock, with the thread and the release event."""
    release, held = threading.Event(), threading.Event()

    def holder():
        with joining_graph(turn):
            held.set()
            release.wait(keep)

    t = threading.Thread(target=holder)
    t.start()
    assert held.wait(10), "the holder never got the lock"
    return t, release


def test_a_holder_that_keeps_the_lock_past_its_turn_makes_the_waiter_fail_naming_it():
    turn = 1.0
    t, release = _holding(turn, keep=60)
    try:
        t0 = time.monotonic()
        with pytest.raises(BridgeTimeout, match=rf"pid {os.getpid()} has held the lock .* for \d+ s, \d+ s past"):
            with joining_graph(60.0):  # the waiter's own bound does not matter: the holder's does
                pass
        waited = time.monotonic() - t0
        assert waited < turn + HANDOVER + 10, "the waiter waited for the holder to let go instead of timing out"
    finally:
        release.set()
        t.join(timeout=10)


def test_a_holder_within_a_turn_longer_than_the_waiters_own_is_waited_out():
    # A slow start on a busy machine is a long turn, not a hang: a waiter whose own bound is shorter
    # than the holder's declared turn must wait it out (a fresh-clone failure: docs/results/many-envs.md).
    t, release = _holding(turn=HANDOVER + 4.0, keep=HANDOVER + 2.0)
    try:
        t0 = time.monotonic()
        with joining_graph(0.5):
            waited = time.monotonic() - t0
        assert waited > 0.5 + HANDOVER, "the holder let go within the waiter's own bound: this test tests nothing"
    finally:
        release.set()
        t.join(timeout=10)


def test_a_declaration_left_from_an_earlier_turn_is_not_the_holders():
    # Between a holder taking the lock and writing its declaration, the file may still hold the
    # declaration of a holder killed long before (the same network namespace inode and domain,
    # reused): a waiter must not take it for the new holder's (a fresh-clone failure:
    # docs/results/many-envs.md).
    path = join_lock_path()
    now = time.clock_gettime(time.CLOCK_MONOTONIC)
    path.write_text(f"999999 {now - 3600:.3f} {now - 3500:.3f}")  # a dead holder's, over long ago
    keep = HANDOVER + 1.0
    with open(path, "a+") as newcomer:  # has the lock, has not declared yet: the window
        fcntl.flock(newcomer, fcntl.LOCK_EX)
        release = threading.Timer(keep, fcntl.flock, (newcomer, fcntl.LOCK_UN))
        release.start()
        t0 = time.monotonic()
        with joining_graph(keep + HANDOVER + 5.0):
            waited = time.monotonic() - t0
        release.join()
    assert waited > keep - 0.5, "the waiter got the lock before the holder let go: this test tests nothing"
    assert path.read_text() == "", "a holder's declaration outlived its turn"
