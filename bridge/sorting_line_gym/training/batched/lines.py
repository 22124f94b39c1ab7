"""The S x L native lines of a batched training, stepped in one call, seen by each seed as SB3
sees its own VecEnv: the same seeding, auto-reset and episode statistics, so that seed s of the
engine trains on the lines SB3 with ``seed=s`` and ``n_envs=L`` would train on.

- Seeding (envs/seeding.py, the rule of both backends and of ``VecEnv.seed``): line j of seed s
  starts from line seed ``s + j`` with the generator ``default_rng(s + j)``, whose draws seed its
  later episodes. For L = 1 that is also what ``DummyVecEnv`` over one env does (``reset(seed=s)``,
  then ``np_random``, which is ``default_rng(s)``).
- Auto-reset (DummyVecEnv.step_wait, SortingLineSB3VecEnv): a line whose episode ended restarts
  at once; its last observation is kept as the terminal observation, for SB3's bootstrap.
- Episode statistics (VecMonitor): per seed, the last ``stats_window`` episodes' return and length.

Used by the on-policy driver and meant for any batched learner (DQN's too).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...envs.env import action_space, observation_space
from ...envs.native import NativeLines
from ...line.options import LineOptions


@dataclass
class Step:
    """What one step of all lines gives, each (S, L, ...): ``obs`` are the observations to act on
    next (a fresh episode's where one ended), ``terminal_obs`` the step's own observations (for the
    lines in ``dones``, their episode's last one)."""

    obs: np.ndarray
    rewards: np.ndarray
    dones: np.ndarray
    truncated: np.ndarray
    terminal_obs: np.ndarray


class BatchedLines:
    """S seeds x L lines of one native batch (see the module docstring)."""

    def __init__(
        self,
        seeds: Sequence[int],
        lines_per_seed: int,
        *,
        setup: str,
        variant: str,
        episode_steps: int,
        evolution: str | None = None,
        stats_window: int = 100,
    ) -> None:
        self.seeds = list(seeds)
        self.n_seeds, self.n_lines = len(self.seeds), lines_per_seed
        variant = "advanced" if evolution else variant
        options = LineOptions(setup=setup, variant=variant, max_episode_steps=episode_steps, evolution=evolution)
        self.observation_space, self.action_space = observation_space(variant), action_space(variant)
        self._lines = NativeLines(self.n_seeds * lines_per_seed, options)
        self.episodes: list[deque[dict[str, float]]] = [deque(maxlen=stats_window) for _ in self.seeds]
        self.episode_counts = np.zeros(self.n_seeds, dtype=np.int64)
        self._returns = np.zeros((self.n_seeds, lines_per_seed), dtype=np.float32)
        self._lengths = np.zeros((self.n_seeds, lines_per_seed), dtype=np.int64)
        self._t_start = time.time()

    @property
    def obs_dim(self) -> int:
        return int(self.observation_space.shape[0])  # type: ignore[index]

    @property
    def n_actions(self) -> int:
        return int(self.action_space.n)

    def reset(self) -> np.ndarray:
        """The first observations (S, L, obs_dim): line j of seed s from line seed s + j."""
        first = {}
        for i, seed in enumerate(self.seeds):
            for j in range(self.n_lines):
                k = i * self.n_lines + j
                self._lines.rngs[k] = np.random.default_rng(seed + j)
                first[k] = seed + j
        obs = self._lines.reset(first)
        self._returns[:] = 0
        self._lengths[:] = 0
        return np.stack([obs[k] for k in range(len(first))]).reshape(self.n_seeds, self.n_lines, -1)

    def action_masks(self) -> np.ndarray:
        """(S, L, n_actions) bool: which actions are valid now (``get_action_masks`` of sb3-contrib)."""
        return self._lines.action_masks().astype(bool).reshape(self.n_seeds, self.n_lines, -1)

    def step(self, actions: np.ndarray) -> Step:
        """One step of every line with ``actions`` (S, L); ended episodes restart (module docstring)."""
        obs, rewards, truncated, _ = self._lines.step(np.asarray(actions, dtype=np.int64).reshape(-1))
        rewards = rewards.astype(np.float32).reshape(self.n_seeds, self.n_lines)
        truncated = truncated.astype(bool).reshape(self.n_seeds, self.n_lines)
        terminal = obs.astype(np.float32).reshape(self.n_seeds, self.n_lines, -1)
        # VecMonitor: returns in float32, as its episode_returns array.
        self._returns += rewards
        self._lengths += 1
        nxt = terminal
        if truncated.any():
            nxt = terminal.copy()
            done = np.flatnonzero(truncated.reshape(-1)).tolist()
            fresh = self._lines.restart(done)
            for k in done:
                i, j = divmod(k, self.n_lines)
                nxt[i, j] = fresh[k]
                self.episodes[i].append(
                    {"r": float(self._returns[i, j]), "l": int(self._lengths[i, j]), "t": time.time() - self._t_start}
                )
                self.episode_counts[i] += 1
            self._returns[truncated] = 0
            self._lengths[truncated] = 0
        # The line has no terminal state: an episode ends by its time limit only (terminated never).
        return Step(nxt, rewards, truncated.copy(), truncated, terminal)

    def mean_returns(self) -> np.ndarray:
        """(S,) mean return of each seed's recent episodes (rollout/ep_rew_mean); NaN before the first."""
        return np.array([np.mean([e["r"] for e in eps]) if eps else np.nan for eps in self.episodes])

    def close(self) -> None:
        self._lines.close()
