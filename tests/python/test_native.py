"""The native backend (``backend="native"``: the Rust line model in-process through the extension
``sorting_line_gym._native``) against the ROS backend (real nodes over DDS, so this file runs in the
tests' loopback-only network namespace like test_bridge.py): the native and the ROS env give identical
trajectories (observation, reward, flags, info dicts, action masks) for the same seeds and actions:
single, Gymnasium vector, SB3 VecEnv, and the evolving line for every ready schedule.

The native backend against `sorting_line trace`, its checkers and errors, without ROS:
unit/test_native_backend.py.
"""

from __future__ import annotations

import numpy as np
import pytest

import sorting_line_gym  # noqa: F401 - registers the ids
from sorting_line_gym import SortingLineSB3VecEnv, SortingLineVectorEnv
from sorting_line_gym.envs.evolving import READY_SCHEDULES
from sorting_line_gym.line.vocabulary import VARIANTS
from support.env_runs import COMBINATIONS, EVOLVING, IDS, first_difference, run_episodes, same, vector_run

# --------------------------------------------------------------------------------------------
# The single-line env against the ROS env


@pytest.mark.parametrize(("setup", "variant"), COMBINATIONS)
def test_native_env_equals_the_ros_env(setup, variant, make_env):
    """Same seeds (and an unseeded reset, drawn from the env's generator) and actions: the same
    returns, info types included, on both backends."""
    n = 30 if variant == "advanced" else 10
    seeds, actions = [5, None, 77], [[int(a) for a in np.random.default_rng(k).integers(0, n, 12)] for k in range(3)]
    runs = []
    for backend in ("native", "ros"):
        env = make_env(IDS[variant], setup=setup, backend=backend, max_episode_steps=12)
        runs.append(run_episodes(env, seeds, actions, masks=True))
    assert same(runs[0], runs[1]), first_difference(*runs)


# --------------------------------------------------------------------------------------------
# The vector envs


@pytest.mark.parametrize("variant", VARIANTS)
def test_vector_envs_equal_the_ros_ones(variant, make_vec):
    lines, seed = 3, 8
    actions = np.random.default_rng(1).integers(0, 30 if variant == "advanced" else 10, (25, lines))
    runs = []
    for backend in ("native", "ros"):
        env = make_vec(SortingLineVectorEnv, num_envs=lines, setup="D", variant=variant, backend=backend,
                       max_episode_steps=10)  # fmt: skip
        runs.append(vector_run(env, seed, actions))
    assert same(runs[0], runs[1]), first_difference(*runs)
    runs = []
    for backend in ("native", "ros"):
        env = make_vec(SortingLineSB3VecEnv, num_envs=lines, setup="B", variant=variant, backend=backend,
                       max_episode_steps=10, seed=seed)  # fmt: skip
        run = [env.reset(), env.reset_infos]
        for a in actions:
            run.append(env.step(a))
        runs.append(run)
    assert same(runs[0], runs[1]), first_difference(*runs)


# --------------------------------------------------------------------------------------------
# The evolving line

# Basic hardware until episode 3, then both upgrades; a drift and a fault at ticks (test_evolving's).
SMALL_SCHEDULE = """\
events:
  - at: {episode: 0}
    sort_modes: false
    ratio_sensor: false
  - at: {tick: 6}
    input_fault: {kind: dropped, ticks: 2}
  - at: {episode: 3}
    sort_modes: true
    ratio_sensor: true
  - at: {tick: 25}
    obs_noise: 0.1
"""


@pytest.mark.parametrize("schedule", ["small", *READY_SCHEDULES])
def test_evolving_native_equals_the_ros_env(schedule, tmp_path, make_env):
    if schedule == "small":
        schedule = tmp_path / "small.yaml"
        schedule.write_text(SMALL_SCHEDULE)
    seeds = [7, 8, None, 9]
    actions = [[int(a) for a in np.random.default_rng(k).integers(0, 30, 10)] for k in range(len(seeds))]
    runs = []
    for backend in ("native", "ros"):
        env = make_env(EVOLVING, evolution=str(schedule), backend=backend, max_episode_steps=10)
        runs.append(run_episodes(env, seeds, actions, masks=True))
    assert same(runs[0], runs[1]), first_difference(*runs)
