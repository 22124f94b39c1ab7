"""An env's trajectory against the simulation library's (`sorting_line trace`), step for step and exactly:
the Gymnasium ids, the trace run with Gymnasium actions (and "r<seed>" resets), the observation and
step checks, seeded action sequences, and the info keys every step carries. Used by the bridge, vector,
env-argument, line-server and multi-host tests."""

from __future__ import annotations

import json
import subprocess

import numpy as np

from sorting_line_gym.line.vocabulary import MAX_EPISODE_STEPS
from support import ros_harness as h

BASIC = "sorting_line_gym:SortingLine-v0"


ADVANCED = "sorting_line_gym:SortingLineAdvanced-v0"


CATEGORY = {"basic": 0, "positive": 1, "negative": 2}


UNLIMITED = MAX_EPISODE_STEPS  # the env's node episode length when gymnasium's TimeLimit truncates


# The KPIs every step's info carries (env.py's docstring). Its "episode" (the node's episode number)
# and "sim_time" are not required here: see test_step_info_does_not_depend_on_earlier_episodes and
# the episode-statistics tests for why they cannot stay as they are.
INFO_KEYS = set(
    "accuracy purity recall_a recall_b speed speed_index mode occupancy containers speed_changes cumulative_reward "
    "step seed".split()
)


def trace(setup: str, variant: str, seed: int, actions, max_steps: int = UNLIMITED) -> list[dict]:
    """`sorting_line trace`: one dict per line; "reset" entries for (re)sets, step entries otherwise.
    `actions` are Gymnasium actions, or "r<seed>" to reset with a seed."""
    flags = f"--setup {setup} --variant {variant} --seed {seed} --max-steps {max_steps}"
    argv = [str(h.node_binary()), "trace", *flags.split(), "--actions", ",".join(str(a) for a in actions)]
    r = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, f"`{' '.join(argv)}` failed ({r.returncode}): {r.stderr}"
    return [json.loads(line) for line in r.stdout.splitlines() if line.strip()]


def expected_obs(variant: str, observation: dict) -> np.ndarray:
    """A trace observation as the env must return it (float32)."""
    q = np.float32(observation["quantity"])
    if variant == "advanced":
        return np.array([q, np.float32(CATEGORY[observation["category"]])], dtype=np.float32)
    return np.array([q], dtype=np.float32)


def assert_obs(obs, variant: str, observation: dict, where: str) -> None:
    want = expected_obs(variant, observation)
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32, f"{where}: obs {obs!r} is not float32"
    assert obs.shape == want.shape and np.array_equal(obs, want), f"{where}: obs {obs!r} != library {want!r}"


def assert_step(variant: str, obs, reward, info: dict, entry: dict, where: str) -> None:
    """One env step (obs, reward, info KPIs) against one trace step entry, exactly."""
    assert "step" in entry, f"{where}: the library has a reset here: {entry}"
    library = h.trace_step_view(entry)
    assert_obs(obs, variant, entry["step"]["observation"], where)
    assert reward == library["reward"], f"{where}: reward {reward!r} != library {library['reward']!r}"
    got = {k: info[k] for k in ("accuracy", "purity", "occupancy", "cumulative_reward")}
    got |= {k: int(info[k]) for k in ("speed_changes", "speed_index", "mode", "step")}
    want = {k: library[k] for k in got}
    got["containers"] = tuple(int(x) for x in info["containers"])
    want["containers"] = tuple(library[f"container_{k}"] for k in h.CONTAINERS)
    diff = {k: (got[k], want[k]) for k in want if got[k] != want[k]}
    assert not diff, f"{where}: info differs from the library (env, library): {diff}"


def assert_episode_follows_trace(env, setup: str, variant: str, seed: int, actions, what: str) -> None:
    """reset(seed) then ``actions`` on ``env`` == `sorting_line trace` of the same, step by step."""
    want = trace(setup, variant, seed, actions)
    obs, _ = env.reset(seed=seed)
    assert_obs(obs, variant, want[0]["reset"]["observation"], f"{what} reset")
    for t, a in enumerate(actions, start=1):
        obs, reward, _, _, info = env.step(a)
        assert_step(variant, obs, reward, info, want[t], f"{what} step {t}")


def fixed_actions(n_actions: int, count: int, seed: int) -> list[int]:
    return [int(a) for a in np.random.default_rng(seed).integers(0, n_actions, size=count)]


def strip_node_counters(info: dict) -> dict:
    """info without the node's process-wide counters (its episode number and simulated clock run
    on across resets): for comparing runs made one after the other in the same node."""
    return {k: v for k, v in info.items() if k not in ("episode", "sim_time")}
