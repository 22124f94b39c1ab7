"""The S x L lines of a batched training, stepped in one call, seen by each seed as SB3 sees its
own VecEnv: the same seeding, auto-reset and episode statistics, so that seed s of the engine
trains on the lines SB3 with ``seed=s`` and ``n_envs=L`` would train on.

- Backends (``envs.vector.make_lines``, the vector envs' lines): ``"native"`` (default), the S x L
  lines in this process, one call a step; ``"ros"``, S x L lines of one `sorting_line node`
  (``--lines S*L``, batch topics), one round trip a step, which then sets the pace. Without
  ``namespace`` the node is started for the run and stopped with it (``node="spawn"``, as
  ``sorting-line-train --engine sb3 --backend ros`` starts its node); with it, the node(s) serving
  that namespace (or list of namespaces, the lines spread evenly) are used. Both backends give the
  same observations and rewards for the same seeds, so a training is the same on either.

- Seeding (envs/seeding.py, the rule of both backends and of ``VecEnv.seed``): line j of seed s
  starts from line seed ``s + j`` with the generator ``default_rng(s + j)``, whose draws seed its
  later episodes. For L = 1 that is also what ``DummyVecEnv`` over one env does (``reset(seed=s)``,
  then ``np_random``, which is ``default_rng(s)``).
- Auto-reset (DummyVecEnv.step_wait, SortingLineSB3VecEnv): a line whose episode ended restarts
  at once; its last observation is kept as the terminal observation, for SB3's bootstrap.
- Episode statistics (VecMonitor): per seed, the last ``stats_window`` episodes' return and length.

Used by the on-policy trainer and the batched DQN, which pass their ``backend`` and ``namespace`` on.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...envs.env import action_space, observation_space
from ...envs.native import BACKENDS
from ...envs.vector import make_lines, node_namespaces
from ...line.errors import BridgeError
from ...line.options import LineOptions
from ...line.vocabulary import NODE_LINES, check


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


def check_backend(
    backend: str, namespace: str | Sequence[str] | None, n_seeds: int, lines_per_seed: int, evolution: str | None
) -> list[str] | None:
    """The node namespaces of ``backend``'s lines (None: native lines, or a node started for the
    run), or a ValueError naming what cannot be: what the engines call before they build anything."""
    check("backend", backend, BACKENDS)
    namespaces = node_namespaces(namespace)
    if backend == "native":
        if namespaces is not None:
            raise ValueError(
                f"namespace = {namespace!r} with backend = 'native': native lines run in this process; "
                "a node's namespace is for backend = 'ros'"
            )
        return None
    if evolution is not None:
        # vector.Lines reports every action valid (the ROS vector faces do not run the evolving line).
        raise ValueError(
            f"evolution = {evolution!r} with backend = 'ros': the ROS lines of a vector env give no action masks "
            "of the evolving line; allowed backend = 'native' for the evolving line"
        )
    total, nodes = n_seeds * lines_per_seed, len(namespaces or [None])
    if total % nodes or total // nodes > NODE_LINES:
        raise ValueError(
            f"{n_seeds} seeds x {lines_per_seed} lines = {total} lines on {nodes} node(s): a node serves "
            f"1 ..= {NODE_LINES} lines, the same number on each; allowed seeds x lines <= {NODE_LINES * nodes}"
            f"{f' and a multiple of {nodes}' if nodes > 1 else ''} (fewer seeds or lines per seed)"
        )
    return namespaces


class BatchedLines:
    """S seeds x L lines of one native batch or of one node (see the module docstring)."""

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
        backend: str = "native",
        namespace: str | Sequence[str] | None = None,
    ) -> None:
        self.seeds = list(seeds)
        self.n_seeds, self.n_lines = len(self.seeds), lines_per_seed
        namespaces = check_backend(backend, namespace, self.n_seeds, lines_per_seed, evolution)
        self.backend, self.namespaces = backend, namespaces
        variant = "advanced" if evolution else variant
        # With namespaces the node is the user's (attach); without, a ROS run starts its own (spawn).
        node = "attach" if namespaces else "spawn"
        options = LineOptions(setup=setup, variant=variant, max_episode_steps=episode_steps, evolution=evolution,
                              node=node, namespace=namespaces[0] if namespaces else None)  # fmt: skip
        self.observation_space, self.action_space = observation_space(variant), action_space(variant)
        self._lines = make_lines(backend, self.n_seeds * lines_per_seed, options, namespaces)
        self._started = False
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
        obs = self._first_reset(first) if not self._started else self._lines.reset(first)
        self._returns[:] = 0
        self._lengths[:] = 0
        return np.stack([obs[k] for k in range(len(first))]).reshape(self.n_seeds, self.n_lines, -1)

    def _first_reset(self, seeds: dict[int, int]) -> dict[int, np.ndarray]:
        """The first reset; on a node's lines it is where a node of another number of lines shows
        (its refusal, or its reply of another size), so the error says what the run needs."""
        try:
            obs = self._lines.reset(seeds)
        except BridgeError as e:
            if self.namespaces is None:
                raise
            total = self.n_seeds * self.n_lines
            raise BridgeError(
                f"the batched engine's {self.n_seeds} seeds x {self.n_lines} lines need {total} lines on the node(s) "
                f"{', '.join(self.namespaces)} (sorting_line node --lines {total // len(self.namespaces)} each); "
                f"its first reset failed: {e}"
            ) from e
        self._started = True
        return obs

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
