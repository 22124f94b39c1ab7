"""N lines of one `sorting_line node` (``--lines N``) as one vectorised environment: one round
trip steps every line. With ``namespace`` a list of several nodes' namespaces (several hosts of one
DDS domain, say), the N lines are spread evenly over them and each step is one round trip per node,
all in flight at once (``ros/fleet.py``). Two faces over the same bank of lines:

- :class:`SortingLineVectorEnv`, a Gymnasium ``VectorEnv`` (``gymnasium.make_vec(id, num_envs=N,
  vectorization_mode="vector_entry_point")``), autoreset mode SAME_STEP: a line whose episode ends
  is reset within the same step; its last observation and info are in ``infos["final_obs"]`` and
  ``infos["final_info"]``.
- ``sb3_vec_env.SortingLineSB3VecEnv``, a Stable-Baselines3 ``VecEnv`` with SB3's conventions
  (a module of its own: it imports SB3 and torch).

Seeding: ``reset(seed=s)`` seeds line k with s + k (as the node seeds line k of ``--seed s``);
every later reset of a line draws its node seed from that line's generator, so one seed reproduces
the whole run.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..line.options import LineOptions
from ..line.vocabulary import (
    EPISODE_STEPS,
    THRESHOLD,
    decode_actions,
    line_infos,
    observations,
    sim_seconds,
    state_info,
)
from ..ros.bank import LineBank
from ..ros.fleet import NodeFleet, split_lines
from .env import SEED_BOUND, action_space, observation_space


def node_namespaces(namespace: str | Sequence[str] | None) -> list[str] | None:
    """``namespace`` as a list of node namespaces (None: the bank chooses one)."""
    if namespace is None or isinstance(namespace, str):
        return None if namespace is None else [namespace]
    namespaces = [str(ns) for ns in namespace]
    if not namespaces:
        raise ValueError("namespace = []: name at least one node")
    return namespaces


class Lines:
    """The bank plus per-line seed generators: what both vector faces share."""

    def __init__(self, num_envs: int, options: LineOptions, namespaces: list[str] | None = None):
        self.variant = options.variant
        if namespaces is not None and len(namespaces) > 1:
            self.bank = NodeFleet(options, namespaces, split_lines(num_envs, len(namespaces)))
        else:
            self.bank = LineBank(options, lines=num_envs, batch=True)
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]
        # Simulated time of each line's last reset: info["sim_time"] counts from there.
        self.episode_start = np.zeros(num_envs)

    def seed_lines(self, seed: int | None) -> None:
        if seed is not None:
            self.rngs = [np.random.default_rng(seed + k) for k in range(len(self.rngs))]

    def next_seed(self, k: int) -> int:
        return int(self.rngs[k].integers(0, SEED_BOUND))

    def restart(self, lines: list[int]) -> dict[int, np.ndarray]:
        """Autoreset: resets ``lines`` with seeds drawn from their generators."""
        return self.reset({k: self.next_seed(k) for k in lines})

    def reset(self, seeds: dict[int, int]) -> dict[int, np.ndarray]:
        responses = self.bank.reset(seeds)
        for k, r in responses.items():
            self.episode_start[k] = sim_seconds(r.stamp.sec, r.stamp.nanosec)
        return {k: observations(self.variant, r.quantity, r.category) for k, r in responses.items()}

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        b = self.bank.step_batch(*decode_actions(self.variant, actions))
        obs = observations(self.variant, b.observation_quantity, b.observation_category)
        info = state_info(b, sim_seconds(b.stamp_sec, b.stamp_nanosec) - self.episode_start)
        return obs, b.reward, b.truncated, info

    def action_masks(self) -> np.ndarray:
        return np.ones((len(self.rngs), action_space(self.variant).n), dtype=bool)

    def close(self):
        self.bank.close()


class SortingLineVectorEnv(VectorEnv):
    """Gymnasium VectorEnv over the lines of one node (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 4,
        setup: str = "A",
        variant: str = "basic",
        namespace: str | Sequence[str] | None = None,
        node: str = "spawn",
        max_episode_steps: int | None = EPISODE_STEPS,
        step_timeout: float = 2.0,
        startup_timeout: float = 20.0,
        render_mode: str | None = None,
        input: str | None = None,
        obs_noise: float | None = None,
        action_penalty: float | None = None,
        threshold: float = THRESHOLD,
    ):
        if render_mode is not None:
            raise ValueError("the vector environment does not render; use SortingLineEnv for the dashboard")
        namespaces = node_namespaces(namespace)
        options = LineOptions.among(locals(), namespace=namespaces[0] if namespaces else None)
        self.num_envs = num_envs
        self.single_observation_space = observation_space(variant)
        self.single_action_space = action_space(variant)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.render_mode = None
        self._lines = Lines(num_envs, options, namespaces)
        # Every line reports every key, so each ``_key`` mask is all true: one shared, read-only array.
        self._all_lines = np.ones(num_envs, dtype=bool)
        self._all_lines.flags.writeable = False

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict | None = None):
        if isinstance(seed, (list, tuple)):
            seeds = [int(s) for s in seed]
            super().reset(seed=seeds[0])
            for k, s in enumerate(seeds):
                self._lines.rngs[k] = np.random.default_rng(s)
        else:
            super().reset(seed=seed)
            self._lines.seed_lines(seed)
            seeds = [seed + k if seed is not None else self._lines.next_seed(k) for k in range(self.num_envs)]
        obs = self._lines.reset(dict(enumerate(seeds)))
        return np.stack([obs[k] for k in range(self.num_envs)]), {}

    def step(self, actions):
        obs, rewards, truncated, info = self._lines.step(actions)
        terminated = np.zeros(self.num_envs, dtype=bool)
        infos: dict[str, Any] = dict(info)
        for key in info:
            infos[f"_{key}"] = self._all_lines
        done = np.flatnonzero(truncated).tolist()
        if done:
            fresh = self._lines.restart(done)
            final_infos = line_infos(info)
            for k in done:
                infos = self._add_info(infos, {"final_obs": obs[k].copy(), "final_info": final_infos[k]}, k)
                obs[k] = fresh[k]
        return obs, rewards, terminated, truncated, infos

    def action_masks(self) -> np.ndarray:
        """Which actions are valid now, per line (num_envs x actions): all of them today."""
        return self._lines.action_masks()

    def close_extras(self, **kwargs):
        self._lines.close()
