"""Our hyperparameter files (``hyperparams/<algo>.yml``) as RL Baselines3 Zoo conf files, so that
RL Zoo trains and replays the line with the paper's settings:

    python -m rl_zoo3.train --algo ppo --env SortingLine-v0 --gym-packages sorting_line_gym \\
        --conf-file sorting_line_gym.zoo.ppo
    python -m rl_zoo3.enjoy --algo ppo --env SortingLine-v0 --gym-packages sorting_line_gym -f logs/

RL Zoo takes a Python package as ``--conf-file`` when it exports a dict ``hyperparams`` (one
entry per Gymnasium id); ``zoo.ppo``, ``zoo.dqn`` and ``zoo.a2c`` are those. The YAML files stay
the one source: the entries are translated, not copied. Our ``episode_steps`` becomes RL Zoo's
``env_kwargs: {max_episode_steps: N}`` (the TimeLimit ``gymnasium.make`` applies).
"""

from __future__ import annotations

from typing import Any

from ..line.vocabulary import ENV_IDS
from ..training.hyperparams import load, split


def zoo_hyperparams(algo: str) -> dict[str, dict[str, Any]]:
    """RL Zoo's ``hyperparams`` dict for ``algo``: Gymnasium id -> entry."""
    entries = {}
    for variant, env_id in ENV_IDS.items():
        own, algorithm_kwargs = split(load(algo, variant))
        entries[env_id] = {
            "n_timesteps": own["n_timesteps"],
            "policy": own["policy"],
            "n_envs": own["n_envs"],
            "env_kwargs": {"max_episode_steps": own["episode_steps"]},
            **algorithm_kwargs,
        }
    return entries
