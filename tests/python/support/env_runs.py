"""Everything an env or a vector env returns over given seeds and actions, for comparing two of them run
for run (the native backend against `sorting_line trace` and against the ROS backend): the env ids, the
setup x variant combinations, the runs, and exact equality of their returns (object arrays such as a
vector env's ``final_obs`` element by element)."""

from __future__ import annotations

import numpy as np

from sorting_line_gym.line.vocabulary import ENV_IDS, SETUPS, VARIANTS
from support.same_values import first_difference as values_first_difference
from support.same_values import same as same_value

IDS = {variant: f"sorting_line_gym:{env_id}" for variant, env_id in ENV_IDS.items()}


EVOLVING = "sorting_line_gym:SortingLineEvolving-v0"


COMBINATIONS = [(s, v) for s in SETUPS for v in VARIANTS]


def same(a, b) -> bool:
    """Exact equality of whatever two envs returned, types and dtypes included (test_bridge's
    ``same``, reaching into object arrays such as a vector env's ``final_obs``)."""
    if isinstance(a, np.ndarray) and a.dtype == object:
        return (
            isinstance(b, np.ndarray)
            and b.dtype == object
            and a.shape == b.shape
            and all(same(x, y) for x, y in zip(a.ravel(), b.ravel(), strict=True))
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=False))
    return same_value(a, b)


def first_difference(a: list, b: list) -> str:
    return values_first_difference(a, b, equal=same)


def run_episodes(env, seeds: list[int | None], actions: list[list[int]], masks: bool = False) -> list:
    """Everything ``env`` returns for episodes reset with ``seeds`` and stepped with ``actions``."""
    out = []
    for seed, acts in zip(seeds, actions, strict=True):
        out.append(env.reset(seed=seed))
        for a in acts:
            out.append(env.step(a))
            if masks:
                out.append(env.unwrapped.action_masks())
    return out


def vector_run(env, seed: int, actions: np.ndarray) -> list:
    out = [env.reset(seed=seed)]
    for a in actions:
        out.append(env.step(a))
        out.append(env.action_masks())
    return out
