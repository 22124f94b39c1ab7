"""N lines of one `sorting_line node` as a Stable-Baselines3 ``VecEnv`` (the SB3 face of
:mod:`.vector`, over the same bank of lines): same-step reset, ``terminal_observation`` and
``TimeLimit.truncated`` in each line's info, as SB3's own VecEnvs report them.

A module of its own because it imports SB3, and so torch (about 500 MB and seconds of start-up),
which users of the Gymnasium faces never need. ``backend="native"`` runs it on lines in this process.
"""

from __future__ import annotations

from typing import Any

import numpy as np

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as e:  # a core install: say where SB3 comes from rather than only that it is missing
    raise ImportError(
        f"SortingLineSB3VecEnv needs stable-baselines3 (the training stack; missing: {e.name}): "
        "bash launch_scripts/setup.sh --train"
    ) from e

from ..line.vocabulary import line_infos
from .env import action_space, observation_space
from .vector import make_lines, node_namespaces, vector_keywords

KEYWORDS = vector_keywords()


@KEYWORDS
class SortingLineSB3VecEnv(VecEnv):
    """Stable-Baselines3 VecEnv over the lines of one node (see the module docstring)."""

    def __init__(
        self,
        num_envs: int = 4,
        *,
        namespace: str | list[str] | None = None,
        seed: int | None = None,
        backend: str = "ros",
        **keywords: Any,
    ):
        namespaces = node_namespaces(namespace)
        options = KEYWORDS.line_options(keywords, namespace=namespaces[0] if namespaces else None)
        variant = options.variant
        self._lines = make_lines(backend, num_envs, options, namespaces)
        self.render_mode = None
        super().__init__(num_envs, observation_space(variant), action_space(variant))
        self._actions = None
        if seed is not None:
            self.seed(seed)  # line k starts from seed + k, as with VecEnv.seed() and PPO(seed=...)

    def reset(self):
        # seed() sets self._seeds = [s + k]: those lines start from those seeds and their generators.
        seeds = {}
        for k in range(self.num_envs):
            if self._seeds[k] is not None:
                self._lines.rngs[k] = np.random.default_rng(self._seeds[k])
                seeds[k] = int(self._seeds[k])
            else:
                seeds[k] = self._lines.next_seed(k)
        obs = self._lines.reset(seeds)
        self.reset_infos = [{"seed": seeds[k]} for k in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return np.stack([obs[k] for k in range(self.num_envs)])

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rewards, truncated, info = self._lines.step(self._actions)
        infos = line_infos(info)
        done = np.flatnonzero(truncated).tolist()
        if done:
            fresh = self._lines.restart(done)
            for k in done:
                infos[k]["terminal_observation"] = obs[k].copy()
                infos[k]["TimeLimit.truncated"] = True
                obs[k] = fresh[k]
        return obs, rewards.astype(np.float32), truncated.copy(), infos

    def close(self) -> None:
        self._lines.close()

    # The lines are not separate Python envs: attribute access answers for this object.
    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self, attr_name, value)

    def action_masks(self) -> np.ndarray:
        """Which actions are valid now, per line: all of them today (sb3-contrib's MaskablePPO
        asks through ``env_method("action_masks")``)."""
        return self._lines.action_masks()

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        if method_name == "action_masks":
            masks = self._lines.action_masks()
            return [masks[k] for k in self._get_indices(indices)]
        raise AttributeError(f"the lines of SortingLineSB3VecEnv have no per-line method {method_name!r}")

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
