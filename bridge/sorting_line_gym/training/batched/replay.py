"""The replay buffers of S independent DQN runs, held in one set of arrays with a leading seed axis.

Seed s's entries are SB3's ``ReplayBuffer`` (stable_baselines3/common/buffers.py) of that run, entry for
entry: ``buffer_size // n_envs`` rows of ``n_envs`` transitions, written at one position shared by
all seeds (they step together), with the timeouts of ``handle_timeout_termination``. A sample draws
its indices from seed s's own generator, by SB3's calls in SB3's order (``BaseBuffer.sample`` then
``ReplayBuffer._get_samples``), so each seed's batch is the one SB3 would have drawn from that
generator and no seed reads another's rows. ``optimize_memory_usage`` is not mirrored (the engine
refuses it). The arrays are numpy's: the gradient steps (q_learning, JAX) take the batches of all
of one ``train`` call at once.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np


class ReplaySamples(NamedTuple):
    """Replay batches, SB3's ``ReplayBufferSamples`` of one seed under the gradient step's vmap
    (observations and next_observations (B, obs_dim), actions (B,) integers, dones and rewards (B,)
    float32, dones already cleared where the episode was cut by a time limit); a sample of all
    seeds has two axes in front, the seed and the gradient step: (S, G, B, ...)."""

    observations: Any
    actions: Any
    next_observations: Any
    dones: Any
    rewards: Any


class BatchedReplayBuffer:
    """S replay buffers of ``buffer_size`` transitions each over ``n_envs`` lines per seed."""

    def __init__(self, seeds: int, buffer_size: int, obs_dim: int, n_envs: int, handle_timeout_termination: bool):
        # ReplayBuffer.__init__: the rows are buffer_size // n_envs, at least one.
        self.buffer_size = max(buffer_size // n_envs, 1)
        self.seeds, self.n_envs = seeds, n_envs
        self.handle_timeout_termination = handle_timeout_termination
        # Row-major over the positions, (buffer_size, S, n_envs, ...): a step of all seeds writes
        # one contiguous block (a seed-major layout scattered each add over S pages, several
        # times slower: docs/performance.md), and the sample's gather is one flat take either
        # way. np.zeros as SB3: the pages of rows never written are never touched, so a buffer
        # far larger than a run's steps costs the memory of the steps only.
        shape = (self.buffer_size, seeds, n_envs)
        self.observations = np.zeros((*shape, obs_dim), dtype=np.float32)
        self.next_observations = np.zeros((*shape, obs_dim), dtype=np.float32)
        self.actions = np.zeros(shape, dtype=np.int64)
        self.rewards = np.zeros(shape, dtype=np.float32)
        self.dones = np.zeros(shape, dtype=np.float32)
        self.timeouts = np.zeros(shape, dtype=np.float32)
        self.pos, self.full = 0, False
        self._seed_index = np.arange(seeds)[:, None, None]

    @staticmethod
    def bytes_per_transition(obs_dim: int) -> int:
        """What one stored transition takes: two float32 observations, an int64 action, float32
        reward, done and timeout."""
        return 2 * 4 * obs_dim + 8 + 3 * 4

    def add(self, obs, next_obs, actions, rewards, dones, timeouts) -> None:
        """One vector step of every seed: arrays (S, n_envs[, obs_dim]). ``next_obs`` holds the
        terminal observation where an episode ended (OffPolicyAlgorithm._store_transition)."""
        # ReplayBuffer.add: copy into row pos, timeouts only with handle_timeout_termination.
        p = self.pos
        self.observations[p] = obs
        self.next_observations[p] = next_obs
        self.actions[p] = actions
        self.rewards[p] = rewards
        self.dones[p] = dones
        if self.handle_timeout_termination:
            self.timeouts[p] = timeouts
        self.pos += 1
        if self.pos == self.buffer_size:
            self.full, self.pos = True, 0

    def of_seed(self, name: str, seed: int) -> np.ndarray:
        """Seed ``seed``'s (by index) array ``name`` as its SB3 ReplayBuffer holds it: (buffer_size, n_envs, ...)."""
        return getattr(self, name)[:, seed]

    def sample(self, n_batches: int, batch_size: int, rngs: list[np.random.RandomState]) -> ReplaySamples:
        """``n_batches`` batches of ``batch_size`` transitions of each seed s, drawn with ``rngs[s]``
        (the generator that is np.random's global one in SB3's run of that seed) in the order of
        ``n_batches`` calls of SB3's ``sample``: arrays (S, n_batches, batch_size, ...)."""
        # BaseBuffer.sample: rows uniform below pos (or all of them once full) ...
        upper_bound = self.buffer_size if self.full else self.pos
        rows = np.empty((self.seeds, n_batches, batch_size), dtype=np.int64)
        lines = np.empty((self.seeds, n_batches, batch_size), dtype=np.int64)
        for s, rng in enumerate(rngs):
            for g in range(n_batches):
                rows[s, g] = rng.randint(0, upper_bound, size=batch_size)
                # ... then ReplayBuffer._get_samples: a line per sample, from the same generator
                # (randint(0, 1) draws nothing: all zeros, and the generator left as it was).
                lines[s, g] = rng.randint(0, high=self.n_envs, size=(batch_size,)) if self.n_envs > 1 else 0
        # Entry (row, seed, line) of the arrays flattened over their first three axes.
        at = ((rows * self.seeds + self._seed_index) * self.n_envs + lines).ravel()
        shape = (self.seeds, n_batches, batch_size)

        def take(a: np.ndarray) -> np.ndarray:
            flat = a.reshape(-1, *a.shape[3:])
            return flat.take(at, axis=0).reshape(*shape, *a.shape[3:])

        # _get_samples: dones only where the episode was not cut by a time limit.
        dones = take(self.dones) * (1 - take(self.timeouts))
        return ReplaySamples(
            take(self.observations), take(self.actions), take(self.next_observations), dones, take(self.rewards)
        )
