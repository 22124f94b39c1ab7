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

``backend="native"`` runs the same faces on N lines in this process (``native.NativeLines``: no node,
no rclpy), with the same seeding, autoreset and info.

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
    check,
    decode_actions,
    observations,
    sim_seconds,
    state_info,
)
from .env import action_space, observation_space
from .keywords import Keywords
from .native import BACKENDS, ros_backend
from .seeding import SeededLines


def node_namespaces(namespace: str | Sequence[str] | None) -> list[str] | None:
    """``namespace`` as a list of node namespaces (None: the bank chooses one)."""
    if namespace is None or isinstance(namespace, str):
        return None if namespace is None else [namespace]
    namespaces = [str(ns) for ns in namespace]
    if not namespaces:
        raise ValueError("namespace = []: name at least one node")
    return namespaces


class Lines(SeededLines):
    """The bank plus per-line seed generators: what both vector faces share."""

    def __init__(self, num_envs: int, options: LineOptions, namespaces: list[str] | None = None):
        # rclpy loads here, not with the module: the native backend's vector envs never need it.
        from ..ros.bank import LineBank
        from ..ros.fleet import NodeFleet, split_lines

        super().__init__(num_envs)
        self.variant = options.variant
        if namespaces is not None and len(namespaces) > 1:
            self.bank = NodeFleet(options, namespaces, split_lines(num_envs, len(namespaces)))
        else:
            self.bank = LineBank(options, lines=num_envs, batch=True)
        # Simulated time of each line's last reset: info["sim_time"] counts from there.
        self.episode_start = np.zeros(num_envs)

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


def make_lines(backend: str, num_envs: int, options: LineOptions, namespaces: list[str] | None):
    """The lines of a vector env: over ROS (:class:`Lines`) or in this process (``native.NativeLines``)."""
    if check("backend", backend, BACKENDS) == "native":
        from .native import NativeLines

        return NativeLines(num_envs, options)
    return ros_backend(lambda: Lines(num_envs, options, namespaces))


def final_entries(num_envs: int, done: list[int], obs: np.ndarray, info: dict[str, np.ndarray]) -> dict[str, Any]:
    """``final_obs``, ``final_info`` and their ``_`` masks for the lines ``done``: what
    ``VectorEnv._add_info`` builds from each line's last observation and (single-line) info, line by
    line, made here in one pass per key (256 lines ending together cost one pass, not 256)."""
    mask = np.zeros(num_envs, dtype=bool)
    mask[done] = True
    final_obs = np.full(num_envs, None, dtype=object)
    for k in done:
        final_obs[k] = obs[k].copy()
    final_info: dict[str, Any] = {}
    for key, column in info.items():
        values = column[done].tolist()
        if key == "containers":  # a tuple per line, as line_infos gives it: an object array
            array = np.full(num_envs, None, dtype=object)
            for k, v in zip(done, values, strict=True):
                array[k] = tuple(v)
        else:
            array = np.zeros(num_envs, dtype=type(values[0]))
            array[done] = values
        final_info[key], final_info[f"_{key}"] = array, mask.copy()
    return {"final_obs": final_obs, "_final_obs": mask.copy(), "final_info": final_info, "_final_info": mask.copy()}


def vector_keywords() -> Keywords:
    """The keywords of a vector face: the line options but ``namespace`` (a face's own parameter:
    one node's or a list of nodes'), with episodes of EPISODE_STEPS."""
    return Keywords(exclude=("evolution", "namespace"), max_episode_steps=EPISODE_STEPS)


KEYWORDS = vector_keywords()


@KEYWORDS
class SortingLineVectorEnv(VectorEnv):
    """Gymnasium VectorEnv over the lines of one node (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 4,
        *,
        namespace: str | Sequence[str] | None = None,
        render_mode: str | None = None,
        backend: str = "ros",
        **keywords: Any,
    ):
        if render_mode is not None:
            raise ValueError("the vector environment does not render; use SortingLineEnv for the dashboard")
        namespaces = node_namespaces(namespace)
        options = KEYWORDS.line_options(keywords, namespace=namespaces[0] if namespaces else None)
        variant = options.variant
        self.num_envs = num_envs
        self.single_observation_space = observation_space(variant)
        self.single_action_space = action_space(variant)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.render_mode = None
        self._lines = make_lines(backend, num_envs, options, namespaces)
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
            infos.update(final_entries(self.num_envs, done, obs, info))
            for k in done:
                obs[k] = fresh[k]
        return obs, rewards, terminated, truncated, infos

    def action_masks(self) -> np.ndarray:
        """Which actions are valid now, per line (num_envs x actions): all of them today."""
        return self._lines.action_masks()

    def close_extras(self, **kwargs):
        self._lines.close()
