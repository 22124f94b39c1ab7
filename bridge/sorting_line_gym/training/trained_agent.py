"""Every agent by its command-line name (:func:`make_agent`): the non-learning agents of
``agents.policies`` and saved Stable-Baselines3 models (:class:`TrainedAgent`), which live here,
with training, so that ``agents/`` needs nothing of SB3 or of training."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..agents.policies import Agent, ConstantAgent, RandomAgent, RuleBasedAgent
from ..line.vocabulary import MODE_COUNT, SPEED_COUNT, check_variant, decode_action
from .hyperparams import ALGOS, algorithm_class


class TrainedAgent(Agent):
    """A saved SB3 model: ``predict`` is the model's deterministic action for the observation
    (``act`` decodes it into speed index and mode)."""

    def __init__(self, algo: str, path: str, variant: str):
        from ..envs.env import action_space

        self.variant = check_variant(variant)
        self.name = f"{algo}:{path}"
        cls = algorithm_class(algo)
        try:
            self.model = cls.load(path, device="cpu")
        except (OSError, ValueError) as e:
            raise ValueError(f"cannot load the {algo.upper()} model {path!r}: {e}") from None
        expected = action_space(variant)
        if self.model.action_space != expected:
            raise ValueError(
                f"the model {path!r} acts in {self.model.action_space}, the {variant} line needs {expected}"
            )

    @classmethod
    def of_model(cls, algo: str, model, variant: str, name: str) -> TrainedAgent:
        """The agent of an SB3 ``model`` in memory (one in training: its learning curve), acting as
        the same model loaded from its file would."""
        agent = cls.__new__(cls)
        agent.variant, agent.name, agent.model = check_variant(variant), name, model
        return agent

    def predict(self, obs: Sequence[float], current_speed_index: int) -> int:
        action, _ = self.model.predict(np.asarray(obs, dtype=np.float32), deterministic=True)
        return int(action)

    def act(self, quantity: float, category: int, current_speed_index: int) -> tuple[int, int]:
        obs = [quantity, category] if self.variant == "advanced" else [quantity]
        return decode_action(self.variant, self.predict(obs, current_speed_index))


def make_agent(spec: str, setup: str, variant: str, seed: int | None = None) -> Agent:
    """An agent by its command-line name: ``rba``, ``rba-hold``, ``random`` (seeded with ``seed``),
    ``constant:K``, ``constant:K:M`` or ``constant:K:cat`` (K = 0..9, M = 0..2), or a saved model
    ``ppo:PATH``, ``dqn:PATH``, ``a2c:PATH``."""
    algo, sep, path = spec.partition(":")
    if sep and algo in ALGOS:
        return TrainedAgent(algo, path, variant)
    if spec in ("rba", "rba-hold"):
        return RuleBasedAgent(setup, variant, hold=spec == "rba-hold")
    if spec == "random":
        return RandomAgent(variant, seed)
    parts = spec.split(":")
    try:
        if parts[0] != "constant" or len(parts) not in (2, 3):
            raise ValueError
        mode: int | str = 0 if len(parts) == 2 else ("cat" if parts[2] == "cat" else int(parts[2]))
        return ConstantAgent(variant, int(parts[1]), mode)
    except ValueError as e:
        detail = f" ({e})" if str(e) else ""
        raise ValueError(
            f"agent {spec!r} is not valid{detail}: allowed rba, rba-hold, random, constant:K, constant:K:M, "
            f"constant:K:cat (K = 0..{SPEED_COUNT - 1}, M = 0..{MODE_COUNT - 1}; modes on the advanced line only), "
            "ppo:PATH, dqn:PATH, a2c:PATH"
        ) from None
