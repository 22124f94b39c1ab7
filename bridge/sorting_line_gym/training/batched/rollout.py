"""The rollout buffer of the on-policy learners for S seeds of L lines each: SB3's ``RolloutBuffer``
(stable_baselines3/common/buffers.py) with a seed axis, and SB3's bootstrap of a truncated
episode from its terminal observation (``OnPolicyAlgorithm.collect_rollouts``).

Arrays are (n_steps, S, L, ...) numpy float32 as SB3 keeps them, so that the returns and
advantages are computed by SB3's own arithmetic, elementwise over seeds and lines. :meth:`flat`
gives each seed's data in the order SB3's ``get()`` indexes it (``swap_and_flatten``: line-major,
index = line * n_steps + step), as arrays (S, L * n_steps, ...) that the JAX updates take whole
(they gather each minibatch themselves, inside one compiled update).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class FlatRollout:
    """One rollout per seed as the learners read it: each field (S, N, ...), N = L * n_steps."""

    observations: np.ndarray
    actions: np.ndarray
    values: np.ndarray
    log_probs: np.ndarray
    advantages: np.ndarray
    returns: np.ndarray
    action_masks: np.ndarray | None

    @property
    def size(self) -> int:
        return int(self.actions.shape[1])

    def arrays(self, *names: str) -> dict[str, np.ndarray]:
        """The fields ``names`` (and the action masks, when there are any) as a loss reads them:
        the actions as int32, the index type of JAX's gathers."""
        fields = {name: getattr(self, name) for name in names}
        if "actions" in fields:
            fields["actions"] = self.actions.astype(np.int32)
        if self.action_masks is not None:
            fields["action_masks"] = self.action_masks
        return fields


class RolloutBuffer:
    """SB3's RolloutBuffer (reset, add, compute_returns_and_advantage, get) for S seeds x L lines."""

    def __init__(
        self, n_steps: int, n_seeds: int, n_lines: int, obs_dim: int, n_actions: int, masked: bool = False
    ) -> None:
        self.n_steps, self.n_seeds, self.n_lines = n_steps, n_seeds, n_lines
        shape = (n_steps, n_seeds, n_lines)
        self.observations = np.zeros((*shape, obs_dim), dtype=np.float32)
        self.actions = np.zeros(shape, dtype=np.int64)
        self.rewards = np.zeros(shape, dtype=np.float32)
        self.episode_starts = np.zeros(shape, dtype=np.float32)
        self.values = np.zeros(shape, dtype=np.float32)
        self.log_probs = np.zeros(shape, dtype=np.float32)
        self.advantages = np.zeros(shape, dtype=np.float32)
        self.returns = np.zeros(shape, dtype=np.float32)
        # MaskableRolloutBuffer (sb3_contrib/common/maskable/buffers.py) keeps the masks of each step.
        self.action_masks = np.ones((*shape, n_actions), dtype=bool) if masked else None
        self.pos = 0

    def reset(self) -> None:
        self.pos = 0

    @property
    def full(self) -> bool:
        return self.pos == self.n_steps

    def add(
        self,
        obs: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        episode_starts: np.ndarray,
        values: np.ndarray,
        log_probs: np.ndarray,
        action_masks: np.ndarray | None = None,
    ) -> None:
        """One step of all S x L lines (RolloutBuffer.add): each argument (S, L, ...)."""
        if self.full:
            raise RuntimeError(f"the rollout buffer is full ({self.n_steps} steps): reset() it first")
        k = self.pos
        self.observations[k] = obs
        self.actions[k] = actions
        self.rewards[k] = rewards
        self.episode_starts[k] = episode_starts
        self.values[k] = values
        self.log_probs[k] = log_probs
        if self.action_masks is not None and action_masks is not None:
            self.action_masks[k] = action_masks
        self.pos += 1

    def compute_returns_and_advantage(
        self, last_values: np.ndarray, dones: np.ndarray, gamma: float, gae_lambda: float
    ) -> None:
        """RolloutBuffer.compute_returns_and_advantage, line for line, on (S, L) arrays: GAE(lambda)
        from the values, cut where an episode starts, and returns = advantages + values."""
        last_values = np.asarray(last_values, dtype=np.float32)
        last_gae_lam: np.ndarray | float = 0
        for step in reversed(range(self.n_steps)):
            if step == self.n_steps - 1:
                next_non_terminal = 1.0 - dones.astype(np.float32)
                next_values = last_values
            else:
                next_non_terminal = 1.0 - self.episode_starts[step + 1]
                next_values = self.values[step + 1]
            delta = self.rewards[step] + gamma * next_values * next_non_terminal - self.values[step]
            last_gae_lam = delta + gamma * gae_lambda * next_non_terminal * last_gae_lam
            self.advantages[step] = last_gae_lam
        self.returns = self.advantages + self.values

    def flat(self) -> FlatRollout:
        """Each seed's rollout in SB3's ``get()`` order (swap_and_flatten: index = line * n_steps + step)."""
        if not self.full:
            raise RuntimeError(f"the rollout buffer holds {self.pos} of {self.n_steps} steps")

        def seed_major(a: np.ndarray) -> np.ndarray:
            # (n_steps, S, L, ...) -> (S, L, n_steps, ...) -> (S, L * n_steps, ...)
            moved = np.moveaxis(a, 0, 2)
            return np.ascontiguousarray(moved).reshape(self.n_seeds, -1, *a.shape[3:])

        masks = None if self.action_masks is None else seed_major(self.action_masks)
        return FlatRollout(
            seed_major(self.observations),
            seed_major(self.actions),
            seed_major(self.values),
            seed_major(self.log_probs),
            seed_major(self.advantages),
            seed_major(self.returns),
            masks,
        )


def bootstrap_truncated(rewards: np.ndarray, truncated: np.ndarray, terminal_values: np.ndarray, gamma: float) -> None:
    """OnPolicyAlgorithm.collect_rollouts' timeout handling (SB3 issue #633), in place: the reward
    of a line whose episode was truncated (not terminated) gets ``gamma * V(terminal observation)``,
    in float32 as SB3 adds the torch value to its float32 rewards."""
    if truncated.any():
        rewards[truncated] += np.float32(gamma) * terminal_values[truncated].astype(np.float32)
