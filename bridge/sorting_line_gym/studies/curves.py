"""Learning curves of a study's RL cells: during a training, every ``every`` steps, the
deterministic policy's mean score on the first ``episodes`` held-out seeds, scored as the cell's
final evaluation scores (``evaluate``'s episodes: seed ``seed + i`` for episode i, 50 steps, the
summed reward), so that the curve's last point is the final model's score on those seeds.

When a point is taken (the same rule for both engines, so their curves share their steps): at step
0 (the untrained policy), then after the first update (PPO, A2C: a rollout and its update; DQN: a
rollout and its gradient steps) that brings the step count to the next multiple of ``every`` or past
it, and after the last update (the final model). A point is the policy as it stands between two
updates, never half-updated: SB3's callback takes it when the next rollout starts
(``_on_rollout_start``, which follows ``train()``) and at the end of training; the batched engine's
progress callback, which runs after each update, takes it for all seeds at once. PPO's rollouts of
2048 steps put its points at 0, 6144, 10240, ...; DQN's (4 steps) and A2C's (5) at the multiples.

Scoring: an SB3 model goes through ``evaluate.evaluate_agent`` (the final evaluation's own code)
on the native line in this process, whatever the cell's backend (the ROS line gives the same
episodes, which the test suite holds): a curve on a ROS node would cost a node and a thousand round
trips a point. The batched engine's S seeds are scored at once (:func:`batched_rewards`: S x M
native lines stepped together, ``engine.predict`` on (S, M, obs)), which gives each seed what
``evaluate_agent`` gives its model alone (tested). Taking a point draws from no generator the
training uses (deterministic actions, lines of its own), so a training with a curve learns what
it learns without one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..line.options import LineOptions
from ..line.vocabulary import EPISODE_STEPS

#: The defaults of issue 54 / 56: every 5000 steps, on the first 20 held-out seeds.
DEFAULT_EVERY = 5000
DEFAULT_EPISODES = 20


@dataclass(frozen=True)
class CurveSettings:
    """What a curve records: a point every ``every`` steps (0: no curve) on ``episodes`` episodes
    seeded ``seed``, ``seed + 1``, ... (the first held-out seeds)."""

    every: int = DEFAULT_EVERY
    episodes: int = DEFAULT_EPISODES
    seed: int = 10_000

    @property
    def on(self) -> bool:
        return self.every > 0

    def fields(self) -> dict[str, int]:
        return asdict(self)


def mean(values: list[float]) -> float:
    """Summed left to right, as ``evaluate.Evaluation.of`` sums: a point equals its reward_mean."""
    total = 0.0
    for v in values:
        total += v
    return total / len(values)


@dataclass
class Curve:
    """The points of one run: step, mean and per-episode rewards; ``wall_s`` spent taking them."""

    settings: CurveSettings
    points: list[dict[str, Any]] = field(default_factory=list)
    wall_s: float = 0.0

    def add(self, step: int, rewards: list[float], seconds: float) -> None:
        self.points.append({"step": int(step), "reward_mean": mean(rewards), "rewards": rewards})
        self.wall_s += seconds

    @property
    def last_step(self) -> int | None:
        return self.points[-1]["step"] if self.points else None

    def due(self, step: int) -> bool:
        """After an update at ``step``: whether it reached the next multiple of ``every``."""
        last = self.last_step
        return last is None or step // self.settings.every > last // self.settings.every

    def record(self) -> dict[str, Any]:
        """As a cell's record keeps it."""
        return {**self.settings.fields(), "wall_s": self.wall_s, "points": self.points}


# ----------------------------------------------------------------------------------------------
# SB3: a callback


def sb3_callback(algo: str, setup: str, variant: str, settings: CurveSettings):
    """An SB3 callback that records the curve of the model it trains in ``.curve`` (module
    docstring: when; scored by ``evaluate_agent`` on native lines)."""
    from stable_baselines3.common.callbacks import BaseCallback

    from ..training.trained_agent import TrainedAgent
    from .evaluate import evaluate_agent

    class CurveCallback(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.curve = Curve(settings)

        def _point(self) -> None:
            start = time.perf_counter()
            agent = TrainedAgent.of_model(algo, self.model, variant, f"{algo}:in training")
            result = evaluate_agent(
                agent, agent.name, setup, variant, episodes=settings.episodes, seed=settings.seed, backend="native"
            )
            self.curve.add(
                self.model.num_timesteps, [e.reward for e in result.per_episode], time.perf_counter() - start
            )

        def _on_training_start(self) -> None:
            self._point()

        def _on_rollout_start(self) -> None:  # after the previous rollout's train(): a whole update
            if self.model.num_timesteps > 0 and self.curve.due(self.model.num_timesteps):
                self._point()

        def _on_step(self) -> bool:
            return True

        def _on_training_end(self) -> None:
            if self.curve.last_step != self.model.num_timesteps:
                self._point()

    return CurveCallback()


# ----------------------------------------------------------------------------------------------
# The batched engine: all seeds at once


def batched_rewards(
    predict: Callable[[np.ndarray], np.ndarray], n_policies: int, setup: str, variant: str, seed: int, episodes: int
) -> np.ndarray:
    """(n_policies, episodes) summed rewards: policy p's episode i from seed ``seed + i``, 50 steps,
    every policy's lines stepped together; ``predict`` maps observations (P, M, obs_dim) float32 to
    actions (P, M), each policy's deterministic action (``engine.predict``)."""
    from ..envs.native import NativeLines

    n = n_policies * episodes
    lines = NativeLines(n, LineOptions(setup=setup, variant=variant, max_episode_steps=EPISODE_STEPS))
    try:
        first = lines.reset({k: seed + k % episodes for k in range(n)})
        obs = np.stack([first[k] for k in range(n)])
        totals = np.zeros(n, dtype=np.float64)
        for step in range(EPISODE_STEPS):
            actions = np.asarray(predict(obs.reshape(n_policies, episodes, -1).astype(np.float32)))
            obs, rewards, truncated, _ = lines.step(actions.reshape(n).astype(np.int64))
            totals += rewards  # per episode, left to right: run_episode's `reward += r`
            if bool(truncated.any()) != (step == EPISODE_STEPS - 1):
                raise RuntimeError(f"episodes ended at step {step + 1}: expected all at {EPISODE_STEPS}")
    finally:
        lines.close()
    return totals.reshape(n_policies, episodes)


class BatchedCurves:
    """The curves of a batched training's seeds: call it as the engine's progress callback
    (``train_batched(on_update=...)``), before the first step and after each update."""

    def __init__(self, setup: str, variant: str, n_seeds: int, total_timesteps: int, settings: CurveSettings):
        self.setup, self.variant, self.total, self.settings = setup, variant, total_timesteps, settings
        self.curves = [Curve(settings) for _ in range(n_seeds)]

    def __call__(self, engine) -> None:
        step = int(engine.num_timesteps)
        first = self.curves[0]
        if first.points and not (first.due(step) or (step >= self.total and first.last_step != step)):
            return
        start = time.perf_counter()
        rewards = batched_rewards(
            engine.predict, len(self.curves), self.setup, self.variant, self.settings.seed, self.settings.episodes
        )
        share = (time.perf_counter() - start) / len(self.curves)
        for curve, row in zip(self.curves, rewards, strict=True):
            curve.add(step, [float(r) for r in row], share)
