"""What a training run writes beside its model: the record (:class:`TrainingRun`, the ``.json``),
the model's file name (:func:`model_stem`) and the versions that trained it. Shared by
`sorting-line-train`'s two engines (``train``, ``train_batched``)."""

from __future__ import annotations

import platform
from dataclasses import dataclass
from typing import Any


@dataclass
class TrainingRun:
    """What one training did: written next to the model as JSON."""

    algo: str
    setup: str
    variant: str
    seed: int
    n_timesteps: int
    n_envs: int
    episode_steps: int
    policy: str
    hyperparams: dict[str, Any]
    wall_s: float
    steps_per_s: float
    episodes: int
    model_path: str
    torch_threads: int
    versions: dict[str, str]


def model_stem(algo: str, setup: str, variant: str, seed: int) -> str:
    return f"{algo}_{setup}_{variant}_seed{seed}"


def versions() -> dict[str, str]:
    import gymnasium
    import stable_baselines3
    import torch

    return {
        "python": platform.python_version(),
        "stable_baselines3": stable_baselines3.__version__,
        "gymnasium": gymnasium.__version__,
        "torch": torch.__version__,
    }
