"""What a training run writes beside its model: the record (:class:`TrainingRun`, the ``.json``,
built and written by :func:`write_record`), the model's file name (:func:`model_stem`) and the
versions that trained it. Shared by `sorting-line-train`'s two engines (``train``,
``train_batched``)."""

from __future__ import annotations

import json
import platform
from dataclasses import asdict, dataclass
from pathlib import Path
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


def write_record(
    algo: str, setup: str, variant: str, own: dict[str, Any], kwargs: dict[str, Any], seed: int, model_path: Path,
    *, episodes: int, wall: float, steps_per_s: float, torch_threads: int, engine: str | None = None,
) -> TrainingRun:  # fmt: skip
    """The record of one seed's training (``own``, ``kwargs``: ``hyperparams.split``'s halves),
    written beside its model as ``<model>.json``; ``engine`` names a trainer other than SB3's."""
    run = TrainingRun(
        algo=algo, setup=setup, variant=variant, seed=seed, n_timesteps=own["n_timesteps"], n_envs=own["n_envs"],
        episode_steps=own["episode_steps"], policy=own["policy"], hyperparams=kwargs, wall_s=wall,
        steps_per_s=steps_per_s, episodes=episodes, model_path=str(model_path), torch_threads=torch_threads,
        versions={**versions(), **({"engine": engine} if engine else {})},
    )  # fmt: skip
    model_path.with_suffix(".json").write_text(json.dumps(asdict(run), indent=2) + "\n")
    return run


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
