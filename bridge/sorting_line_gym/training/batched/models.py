"""The SB3 models behind the batched trainer's seeds: built by SB3 itself (so a seed's initial
weights, orthogonal init and gains, optimizer settings and schedules are SB3's for that seed),
loaded from SB3 zips (to continue training), and written back as the zip SB3 would have saved
(``PPO.load``, ``A2C.load``, ``MaskablePPO.load`` open it; ``predict`` gives the trainer's actions).

SB3 seeds its global generators when it builds a model (``set_random_seed``) and then draws
actions from torch's and minibatch permutations from numpy's: the states they are in right after
seed s's model is built are what seed s's own generators start from, so seed s samples what SB3
with ``seed=s`` would. The global generators are restored afterwards.
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from .checks import algorithm_class


class SpacesEnv(gym.Env):
    """The line's spaces without a line: what SB3 needs to build or load a model. The batched
    trainer steps the lines itself, so reset() and step() refuse."""

    def __init__(self, observation_space: gym.Space, action_space: gym.spaces.Discrete):
        self.observation_space, self.action_space = observation_space, action_space

    def reset(self, *, seed=None, options=None):
        raise RuntimeError("SpacesEnv has no line: the batched trainer steps its lines itself")

    def step(self, action):
        raise RuntimeError("SpacesEnv has no line: the batched trainer steps its lines itself")

    def action_masks(self) -> np.ndarray:  # sb3-contrib's is_masking_supported looks for it
        return np.ones(int(self.action_space.n), dtype=bool)


def spaces_vec_env(observation_space: gym.Space, action_space: gym.spaces.Discrete, n_lines: int):
    """A DummyVecEnv of ``n_lines`` :class:`SpacesEnv` (the model's n_envs is the seed's lines),
    each with spaces of its own: SB3 seeds a model's action space with its seed, and DQN draws its
    random actions from it, so two seeds' models must not share one space object."""
    import copy

    from stable_baselines3.common.vec_env import DummyVecEnv

    return DummyVecEnv(
        [lambda: SpacesEnv(copy.deepcopy(observation_space), copy.deepcopy(action_space)) for _ in range(n_lines)]
    )


@dataclass
class SeedModel:
    """One seed's SB3 model and the generator states its training starts from."""

    model: Any
    torch_state: torch.Tensor
    numpy_state: Any


def new_models(algo: str, seeds: Sequence[int], params: dict[str, Any], spaces: tuple, n_lines: int) -> list[SeedModel]:
    """SB3's model for each seed (``cls("MlpPolicy", env, seed=s, **params)``), with the states of
    torch's and numpy's global generators right after it was built (module docstring)."""
    cls = algorithm_class(algo)
    saved = torch.get_rng_state(), np.random.get_state(), random.getstate()
    built = []
    try:
        for seed in seeds:
            model = cls("MlpPolicy", spaces_vec_env(*spaces, n_lines), seed=seed, **params)
            built.append(SeedModel(model, torch.get_rng_state(), np.random.get_state()))
    finally:
        torch.set_rng_state(saved[0])
        np.random.set_state(saved[1])
        random.setstate(saved[2])
    return built


def check_model_file(path: str | Path, algo: str, spaces: tuple) -> None:
    """Refuses, naming ``path``, a file that is not an SB3 ``algo`` model of ``spaces`` (observation,
    action): what every engine checks before it loads a model to go on training it."""
    from ...agents.learned_policy import PolicyFileError, read_sb3_zip

    try:
        parts = read_sb3_zip(path)
    except PolicyFileError as e:
        raise ValueError(str(e)) from None
    if parts.algorithm != algo:
        raise ValueError(f"{path}: a {parts.algorithm} model; allowed here: {algo} models (the algorithm trained)")
    observation_space, action_space = spaces
    theirs = parts.data["observation_space"], parts.data["action_space"]
    if theirs[0] != observation_space or theirs[1] != action_space:
        raise ValueError(
            f"{path}: a model of observation space {theirs[0]} and action space {theirs[1]}; allowed here: "
            f"{observation_space} and {action_space} (this line's)"
        )


def load_models(algo: str, paths: Sequence[str | Path], seeds: Sequence[int], spaces: tuple, n_lines: int):
    """The SB3 models in ``paths`` (one per seed), refused with the path named when a file is not an
    ``algo`` model of the line's spaces. Seed s continues from generators seeded with s (SB3's
    ``load`` does not restore generator states, so an SB3 run that continues draws from wherever
    the process's generators are)."""
    cls = algorithm_class(algo)
    loaded = []
    for path, seed in zip(paths, seeds, strict=True):
        check_model_file(path, algo, spaces)
        model = cls.load(path, env=spaces_vec_env(*spaces, n_lines), device="cpu")
        generator = torch.Generator().manual_seed(seed)
        loaded.append(SeedModel(model, generator.get_state(), np.random.RandomState(seed).get_state()))
    check_alike([b.model for b in loaded], paths)
    return loaded


#: What the seeds of one trainer must share (one schedule and one update serve them all): the
#: attributes SB3 keeps of its constructor arguments, schedules read at the start of training.
SHARED = ("n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda", "ent_coef", "vf_coef", "max_grad_norm",
          "normalize_advantage", "policy_kwargs", "num_timesteps", "_n_updates")  # fmt: skip
SCHEDULES = ("lr_schedule", "clip_range", "clip_range_vf")


def check_alike(models: Sequence[Any], paths: Sequence[str | Path]) -> None:
    """Refuses models that differ in what the seeds share (:data:`SHARED`), naming the keys."""

    def settings(m: Any) -> dict[str, Any]:
        own = {k: getattr(m, k, None) for k in SHARED}
        for k in SCHEDULES:
            schedule = getattr(m, k, None)
            own[k] = schedule(1.0) if callable(schedule) else schedule
        return own

    first = settings(models[0])
    for model, path in zip(models[1:], paths[1:], strict=True):
        theirs = settings(model)
        differ = sorted(k for k in first if repr(theirs[k]) != repr(first[k]))
        if differ:
            raise ValueError(
                f"{path}: {', '.join(f'{k} = {theirs[k]!r}' for k in differ)} where {paths[0]} has "
                f"{', '.join(f'{first[k]!r}' for k in differ)}: allowed models of one setting and training length"
            )


def finish_model(model: Any, state: dict[str, Any]) -> None:
    """Sets what SB3's training loop leaves on a model (``state``: num_timesteps, _n_updates,
    _current_progress_remaining, _total_timesteps, _num_timesteps_at_start, _episode_num,
    ep_info_buffer, _last_obs, _last_episode_starts), so that the zip is SB3's after ``learn``."""
    from collections import deque

    for key, value in state.items():
        if key == "ep_info_buffer":
            value = deque(value, maxlen=model._stats_window_size)
        setattr(model, key, value)
    if model.ep_success_buffer is None:
        model.ep_success_buffer = deque(maxlen=model._stats_window_size)
