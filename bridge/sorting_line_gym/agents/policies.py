"""Non-learning agents for the sorting line, all with one interface.

- :class:`RuleBasedAgent` is the project's rule-based agent, ``rba`` (highest expected immediate
  reward) or ``rba-hold`` (changes speed only when that pays back the switching penalty). It is
  the Rust library's agent, called in this process through the extension (``_native.Agent``), so
  it makes the same decisions as ``sorting_line eval --agent rba|rba-hold``, and is what the
  controller node (``sorting-line-controller``) and Python evaluations run.
- :class:`ConstantAgent` keeps one speed (and a fixed mode, or the mode matching the observed
  ratio category): a baseline, and a predictable agent for tests.
- :class:`RandomAgent` draws uniformly from the action space with its own seeded NumPy generator:
  the paper's random baseline. Its draws are not those of ``sorting_line eval --agent random``
  (that one uses the library's own random stream).
- A saved Stable-Baselines3 model (``training.trained_agent.TrainedAgent``: ``ppo:PATH.zip``,
  ``dqn:...``, ``a2c:...``, as ``sorting-line-train`` writes them) acts through this interface too;
  ``training.trained_agent.make_agent`` makes any agent by its command-line name.

Interface of every agent:

- ``act(quantity, category, current_speed_index) -> (speed_index, mode)``: the decision for the
  input sensor's reading (0..1), the ratio category (0 basic (mixed), 1 positive (A-rich),
  2 negative (B-rich); ignored by the basic line) and the belt's current speed index (only
  ``rba-hold`` and nothing else uses it); mode is always 0 on the basic line.
- ``predict(obs, current_speed_index) -> action``: the same on a Gymnasium observation, returning
  the Gymnasium action (basic: speed index; advanced: speed index * 3 + mode).
- ``reset(seed=None)``: at the start of an episode (reseeds the random agent; no-op otherwise).

After a reset the belt runs at :data:`START_SPEED_INDEX` (speed 0.6); later the ``speed_index`` of
the env's ``info`` (or the ``belt/occupancy`` topic's ``speed``) is the current speed.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np

import sorting_line_gym._native as _native

from ..line.vocabulary import (
    ACTION_COUNTS,
    CATEGORIES,
    EPISODE_STEPS,
    MODES,
    SETUPS,
    SPEED_COUNT,
    START_SPEED_INDEX,  # noqa: F401  (re-exported: the belt's speed index after a reset)
    THRESHOLD,
    check,
    check_setup,
    check_variant,
    decode_action,
    encode_actions,
)

#: Reading levels 0.00, 0.01, ..., 1.00 of the input sensor (the rows of the rule table).
LEVELS: int = _native.LEVELS

#: The table row of a reading, the library's own (``observation::level``): ``round(quantity *
#: 100)`` with halves rounded away from zero (Rust's ``f64::round``, not Python's
#: round-half-to-even), clamped to 0..100; NaN gives 0.
level = _native.level


@functools.cache
def load_policy(setup: str, variant: str) -> dict:
    """The decision tables of ``sorting_line policy --setup SETUP --variant VARIANT``, from the
    library in this process (no CLI), read once per (setup, variant) and process. Keys: setup,
    variant, levels, rba (``[speed_index, mode]`` per cell ``level * 3 + category``), rba_hold (per
    cell, one pair per current speed 0..9), config."""
    policy = _native.policy(check_setup(setup), check_variant(variant))
    # Tuples: the cached tables are shared by every agent of this process and must not change.
    policy["rba"] = tuple(tuple(pair) for pair in policy["rba"])
    policy["rba_hold"] = tuple(tuple(tuple(pair) for pair in row) for row in policy["rba_hold"])
    return policy


@functools.cache
def library_agent(name: str, setup: str, variant: str):
    """The library's ``rba`` or ``rba-hold`` for a setup (``_native.Agent``: the same object
    ``sorting_line eval --agent`` decides with), built once per process: both keep no state
    between decisions, so every agent of that name and setup shares it."""
    settings = dict(SETUPS[check_setup(setup)], variant=check_variant(variant))
    settings.update(threshold=THRESHOLD, max_steps=EPISODE_STEPS)
    return _native.Agent(name, settings)


class Agent:
    """The common interface (see the module's docstring)."""

    variant: str = "basic"

    def act(self, quantity: float, category: int, current_speed_index: int) -> tuple[int, int]:
        raise NotImplementedError

    def reset(self, seed: int | None = None) -> None:
        """Called at the start of each episode; only the random agent uses it."""

    def predict(self, obs: Sequence[float], current_speed_index: int) -> int:
        """The Gymnasium action for an observation of the env (basic ``[quantity]``, advanced
        ``[quantity, category]``)."""
        quantity = float(obs[0])
        category = int(round(float(obs[1]))) if self.variant == "advanced" else 0
        speed_index, mode = self.act(quantity, category, current_speed_index)
        return encode_actions(self.variant, speed_index, mode)


class RuleBasedAgent(Agent):
    """``rba`` (``hold=False``) or ``rba-hold`` (``hold=True``) for one of the paper's setups.

    The decisions are the Rust library's agent's, in this process (``_native.Agent``, built once
    per process), so they equal ``sorting_line eval``'s for the same observations. ``rba`` ignores
    ``current_speed_index``; ``rba-hold`` needs the belt's current speed."""

    def __init__(self, setup: str, variant: str, hold: bool = False):
        self.setup, self.variant, self.hold = setup, check_variant(variant), hold
        self._agent = library_agent(self.name, setup, variant)
        self.config = load_policy(setup, variant)["config"]

    @property
    def name(self) -> str:
        return "rba-hold" if self.hold else "rba"

    def act(self, quantity: float, category: int, current_speed_index: int) -> tuple[int, int]:
        if self.variant == "basic":
            category = 0  # the basic line has no ratio sensor: its table has one category slot
        else:
            check("category", category, CATEGORIES.values())
        if not self.hold:
            current_speed_index = 0  # rba decides without it
        elif not (isinstance(current_speed_index, (int, np.integer)) and 0 <= current_speed_index < SPEED_COUNT):
            raise ValueError(
                f"current_speed_index = {current_speed_index!r} is not valid: allowed 0..{SPEED_COUNT - 1}"
            )
        # The table's rows clamp a reading to 0..1 (NaN: row 0); the agent takes only what a sensor
        # reads, so the same clamp first: any float decides as before.
        q = float(quantity)
        q = 0.0 if math.isnan(q) else min(max(q, 0.0), 1.0)
        action = self._agent.act(q, int(category), int(current_speed_index))
        return decode_action(self.variant, action)


class ConstantAgent(Agent):
    """Always ``speed_index``; on the advanced line mode ``mode`` (0..2), or ``"cat"``: the mode
    matching the observed ratio category (``sorting_line eval --agent constant:K[:M|:cat]``)."""

    def __init__(self, variant: str, speed_index: int, mode: int | str = 0):
        self.variant = check_variant(variant)
        if not 0 <= speed_index < SPEED_COUNT:
            raise ValueError(f"speed_index = {speed_index!r} is not valid: allowed 0..{SPEED_COUNT - 1}")
        if mode != "cat" and mode not in MODES.values():
            raise ValueError(f"mode = {mode!r} is not valid: allowed {', '.join(map(str, MODES.values()))} or 'cat'")
        if variant == "basic" and mode != 0:
            raise ValueError("a sort mode needs the advanced line")
        self.speed_index, self.mode = int(speed_index), mode

    def act(self, quantity: float, category: int, current_speed_index: int) -> tuple[int, int]:
        if self.variant == "basic":
            return self.speed_index, 0
        return self.speed_index, int(category) if self.mode == "cat" else int(self.mode)


class RandomAgent(Agent):
    """Uniform over the action space (10 speeds; x 3 modes on the advanced line), from a NumPy
    generator seeded with ``seed``; ``reset(seed)`` reseeds it (as the evaluation protocol reseeds
    the agent each episode), ``reset()`` carries on."""

    def __init__(self, variant: str, seed: int | None = None):
        self.variant = check_variant(variant)
        self.rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def act(self, quantity: float, category: int, current_speed_index: int) -> tuple[int, int]:
        return decode_action(self.variant, self.rng.integers(ACTION_COUNTS[self.variant]))
