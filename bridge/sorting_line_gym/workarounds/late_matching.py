"""Workaround: the first exchange right after discovery can be lost, so the first reset is retried.

Right after discovery the node can match our request writer before our reply reader, or before
our state reader: the first reset's reply, or its step-0 state, is then lost for good (volatile
samples sent before matching are; found by the node tests' harness). A reset with an explicit
seed repeated gives the same episode, so the handshake (the first reset, whose reply and step-0
state must both arrive) is retried. Short first attempts (0.2, 0.4, 0.8, ... s instead of 2 s)
brought 64 shared envs' start-up from about 25 s to 11.5 s (load 12).

Where a timeout alone cannot tell a lost exchange from a slow one (a reset without a seed, or one
that may have happened with only its reply lost), the caller looks for evidence and
``repeated_while_unanswered`` repeats the exchange only while that evidence says nothing happened.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

#: Time allowed to each attempt of a bank's first reset (reply, then step-0 state) before it is
#: retried: a short first attempt keeps a lost exchange from costing every env seconds of start-up.
HANDSHAKE_TIMEOUTS = (0.2, 0.4, 0.8, 1.6, 2.0)

T = TypeVar("T")
R = TypeVar("R")


def retried_handshake(
    attempt: Callable[[float], T],
    timeouts: Sequence[float],
    lost: type[BaseException] | tuple[type[BaseException], ...],
    *,
    after_loss: Callable[[], None] | None = None,
    hopeless: Callable[[], bool] | None = None,
) -> T:
    """``attempt(timeout)`` for each of ``timeouts`` until one returns. An attempt that raises
    ``lost`` is retried after ``after_loss()`` (e.g. dropping the pending request), unless it was
    the last or ``hopeless()`` says another cannot help (the node died); then the error goes on."""
    for k, timeout in enumerate(timeouts):
        try:
            return attempt(timeout)
        except lost:
            if after_loss is not None:
                after_loss()
            if k == len(timeouts) - 1 or (hopeless is not None and hopeless()):
                raise
    raise ValueError("retried_handshake needs at least one timeout")


def repeated_while_unanswered(
    attempt: Callable[[int], R],
    unanswered: Callable[[R], bool],
    attempts: int,
    *,
    before_repeat: Callable[[R], None] | None = None,
) -> R:
    """``attempt(k)`` for k = 1, 2, ... up to ``attempts`` while ``unanswered(result)`` says its
    exchange was lost before it had any effect (the caller's evidence: nobody answered the reset's
    tick, /diagnostics counts no new episode); returns the last result, answered or not, for the
    caller to judge. ``before_repeat(result)`` runs before each repetition (e.g. restarting the node
    when the reset had no seed)."""
    if attempts < 1:
        raise ValueError(f"attempts = {attempts} is not valid: allowed 1 or more")
    result = attempt(1)
    for k in range(2, attempts + 1):
        if not unanswered(result):
            break
        if before_repeat is not None:
            before_repeat(result)
        result = attempt(k)
    return result
