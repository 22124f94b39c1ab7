"""Workaround: the first exchange right after discovery can be lost, so the first reset is retried.

Right after discovery the node can match our request writer before our reply reader, or before
our state reader: the first reset's reply, or its step-0 state, is then lost for good (volatile
samples sent before matching are; found by the node tests' harness). The node now waits for the
client's reply reader before it replies (at most 2 s); the step-0 state has no such guard. A reset with an explicit
seed repeated gives the same episode, so the handshake (the first reset, whose reply and step-0
state must both arrive) is retried, with short first attempts (0.2, 0.4, 0.8, ... s instead of
2 s): a lost exchange costs little at start-up (what it saved for 64 shared envs:
docs/results/many-envs.md).

A timeout alone cannot tell a lost exchange from a slow one: under load a reply slower than 0.2 s
means the repeated reset is the node's second. That is harmless only where resets do not count.
Who does what:

- Fixed lines (``ros.bank.LineBank`` without a schedule, the bag recorder's parameter query, the
  replay's handshake on a fixed line): ``retried_handshake`` with the short timeouts; a seeded
  reset repeated is the same episode (the node's episode counter moves on, but no observation or
  info depends on it).
- Evolving lines (``LineBank`` with an evolution schedule, ``SortingLineEvolving-v0``): every
  reset is the schedule's next episode, so the first reset goes once to each node and is waited
  for as any reset (``step_timeout``), slow or not. If its reply, its step-0 state or its
  announcement of the episode's setup (``events/evolution``) still does not come, a spawned node
  is replaced by a fresh one (``repeated_while_unanswered``, up to
  ``FRESH_NODE_ATTEMPTS`` nodes), which has had no reset; an attached node is never reset twice,
  the error goes on.
- Bag replay (``bag.transport.replay``): the bag's first reset is judged by every message of its tick
  arriving, and an unproven one goes to a fresh node (``repeated_while_unanswered``).
- Where other evidence tells whether an exchange had any effect (nobody answered the reset's
  tick, /diagnostics counts no new episode), the caller judges by it and
  ``repeated_while_unanswered`` repeats the exchange only while that evidence says nothing happened.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

#: Time allowed to each attempt of a bank's first reset (reply, then step-0 state) before it is
#: retried: a short first attempt keeps a lost exchange from costing every env seconds of start-up.
HANDSHAKE_TIMEOUTS = (0.2, 0.4, 0.8, 1.6, 2.0)

#: Nodes tried, each reset once, for a first reset that must not be repeated to the same node.
FRESH_NODE_ATTEMPTS = 3

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
