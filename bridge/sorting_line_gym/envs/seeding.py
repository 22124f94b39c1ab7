"""The seeding rule of a vector env's N lines, on both backends: ``seed_lines(s)`` gives line k the
generator ``default_rng(s + k)``; each later reset of line k (an autoreset) draws its line seed from
that generator, so one seed reproduces a whole run, and the native and the ROS lines draw the same."""

from __future__ import annotations

import numpy as np

from .env import SEED_BOUND


class SeededLines:
    """Per-line seed generators; subclasses provide ``reset({line: seed}) -> {line: observation}``."""

    def __init__(self, num_envs: int):
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]

    def seed_lines(self, seed: int | None) -> None:
        if seed is not None:
            self.rngs = [np.random.default_rng(seed + k) for k in range(len(self.rngs))]

    def next_seed(self, k: int) -> int:
        return int(self.rngs[k].integers(0, SEED_BOUND))

    def restart(self, lines: list[int]) -> dict[int, np.ndarray]:
        """Autoreset: resets ``lines`` with seeds drawn from their generators."""
        return self.reset({k: self.next_seed(k) for k in lines})

    def reset(self, seeds: dict[int, int]) -> dict[int, np.ndarray]:
        raise NotImplementedError
