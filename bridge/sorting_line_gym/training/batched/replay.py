"""The replay buffers of S independent DQN runs, held in one set of arrays with a leading seed axis.

Seed s's entries are SB3's ``ReplayBuffer`` (stable_baselines3/common/buffers.py) of that run, entry for
entry: ``buffer_size // n_envs`` rows of ``n_envs`` transitions, written at one position shared by
all seeds (they step together), with the timeouts of ``handle_timeout_termination``. A sample draws
its indices from seed s's own generator, by SB3's calls in SB3's order (``BaseBuffer.sample`` then
``ReplayBuffer._get_samples``), so each seed's batch is the one SB3 would have drawn from that
generator and no seed reads another's rows. ``optimize_memory_usage`` is not mirrored (the engine
refuses it). The arrays are numpy's: the gradient steps (q_learning, JAX) take the batches of all
of one ``train`` call at once.

A sample is two parts, so that the trainer can draw a cycle's indices while the previous
gradient step still runs (dqn.py): :meth:`BatchedReplayBuffer.draw` (the seeds' generators only,
against the bound the buffer will have) and :meth:`BatchedReplayBuffer.gather` (the rows).
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

    #: The columns of a stored transition, in order: (name, width in float32 values; 0: obs_dim).
    COLUMNS = (
        ("observations", 0),
        ("next_observations", 0),
        ("actions", 1),
        ("rewards", 1),
        ("dones", 1),
        ("timeouts", 1),
    )

    def __init__(self, seeds: int, buffer_size: int, obs_dim: int, n_envs: int, handle_timeout_termination: bool):
        # ReplayBuffer.__init__: the rows are buffer_size // n_envs, at least one.
        self.buffer_size = max(buffer_size // n_envs, 1)
        self.seeds, self.n_envs = seeds, n_envs
        self.handle_timeout_termination = handle_timeout_termination
        # One float32 array, row-major over the positions, (buffer_size, S, n_envs, columns): a
        # step of all seeds writes one contiguous block (a seed-major layout scattered each add
        # over S pages, several times slower: docs/results/performance.md), and a sample is one flat take
        # of whole transitions (six arrays took six). The action is stored as a float32, exact for
        # any integer below 2**24 (a Discrete space of the line has 30 at most). np.zeros as SB3:
        # the pages of rows never written are never touched, so a buffer far larger than a run's
        # steps costs the memory of the steps only.
        self._slices: dict[str, slice] = {}
        at = 0
        for name, width in self.COLUMNS:
            width = width or obs_dim
            self._slices[name] = slice(at, at + width)
            at += width
        self.data = np.zeros((self.buffer_size, seeds, n_envs, at), dtype=np.float32)
        self.pos, self.full = 0, False
        self._seed_index = np.arange(seeds)[:, None, None]

    @staticmethod
    def bytes_per_transition(obs_dim: int) -> int:
        """What one stored transition takes: two observations, the action, reward, done and
        timeout, float32 each."""
        return 4 * (2 * obs_dim + 4)

    def add(self, obs, next_obs, actions, rewards, dones, timeouts) -> None:
        """One vector step of every seed: arrays (S, n_envs[, obs_dim]). ``next_obs`` holds the
        terminal observation where an episode ended (OffPolicyAlgorithm._store_transition)."""
        # ReplayBuffer.add: copy into row pos, timeouts only with handle_timeout_termination.
        row, cut = self.data[self.pos], self._slices
        row[..., cut["observations"]] = obs
        row[..., cut["next_observations"]] = next_obs
        row[..., cut["actions"]] = np.asarray(actions)[..., None]
        row[..., cut["rewards"]] = np.asarray(rewards)[..., None]
        row[..., cut["dones"]] = np.asarray(dones)[..., None]
        if self.handle_timeout_termination:
            row[..., cut["timeouts"]] = np.asarray(timeouts)[..., None]
        self.pos += 1
        if self.pos == self.buffer_size:
            self.full, self.pos = True, 0

    def of_seed(self, name: str, seed: int) -> np.ndarray:
        """Seed ``seed``'s (by index) array ``name`` as its SB3 ReplayBuffer holds it: (buffer_size,
        n_envs, obs_dim) for the observations, (buffer_size, n_envs) for the others (actions int64)."""
        column = self.data[:, seed, :, self._slices[name]]
        if name == "actions":
            return column[..., 0].astype(np.int64)
        return column if name.endswith("observations") else column[..., 0]

    def upper_bound(self, adds: int = 0) -> int:
        """BaseBuffer.sample's bound on the rows, once ``adds`` more steps have been added."""
        if self.full or self.pos + adds >= self.buffer_size:
            return self.buffer_size
        return self.pos + adds

    def draw(self, n_batches: int, batch_size: int, rngs: list[np.random.RandomState], upper_bound: int) -> np.ndarray:
        """The indices of ``n_batches`` batches of ``batch_size`` transitions of each seed s, drawn
        with ``rngs[s]`` (the generator that is np.random's global one in SB3's run of that seed)
        in the order of ``n_batches`` calls of SB3's ``sample`` on a buffer whose bound is
        ``upper_bound`` (:meth:`upper_bound`); for :meth:`gather`."""
        rows = np.empty((self.seeds, n_batches, batch_size), dtype=np.int64)
        lines = np.empty((self.seeds, n_batches, batch_size), dtype=np.int64)
        for s, rng in enumerate(rngs):
            for g in range(n_batches):
                # BaseBuffer.sample: rows uniform below the bound (all of them once full) ...
                rows[s, g] = rng.randint(0, upper_bound, size=batch_size)
                # ... then ReplayBuffer._get_samples: a line per sample, from the same generator
                # (randint(0, 1) draws nothing: all zeros, and the generator left as it was).
                lines[s, g] = rng.randint(0, high=self.n_envs, size=(batch_size,)) if self.n_envs > 1 else 0
        # Entry (row, seed, line) of the array flattened over its first three axes.
        return (rows * self.seeds + self._seed_index) * self.n_envs + lines

    def gather(self, at: np.ndarray) -> ReplaySamples:
        """The transitions at the indices ``at`` (S, n_batches, batch_size) of :meth:`draw`."""
        taken = self.data.reshape(-1, self.data.shape[-1]).take(at.ravel(), axis=0).reshape(*at.shape, -1)
        cut = self._slices

        def column(name: str) -> np.ndarray:
            return taken[..., cut[name]][..., 0]  # a view; the arithmetic and astype below copy it

        # _get_samples: dones only where the episode was not cut by a time limit.
        dones = column("dones") * (1 - column("timeouts"))
        return ReplaySamples(
            np.ascontiguousarray(taken[..., cut["observations"]]),
            column("actions").astype(np.int64),
            np.ascontiguousarray(taken[..., cut["next_observations"]]),
            dones,
            np.ascontiguousarray(column("rewards")),
        )

    def sample(self, n_batches: int, batch_size: int, rngs: list[np.random.RandomState]) -> ReplaySamples:
        """``n_batches`` batches of ``batch_size`` transitions of each seed, drawn now (:meth:`draw`
        against the present bound, then :meth:`gather`): arrays (S, n_batches, batch_size, ...)."""
        return self.gather(self.draw(n_batches, batch_size, rngs, self.upper_bound()))
