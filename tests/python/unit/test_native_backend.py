"""The native backend (``backend="native"``: the Rust line model in-process through the extension
``sorting_line_gym._native``) against `sorting_line trace`, without ROS:

- for every setup x variant, the single-line env reproduces `sorting_line trace` step for step,
  every info field with its type, across seeded resets; the vector env likewise, line k seeded
  S + k, across SAME_STEP autoresets (the next seed drawn from line k's generator); the ready
  schedules' late events against the trace;
- Gymnasium's and SB3's env checkers pass; bad input raises a clear exception naming the value;
  the native backend never imports rclpy; the library's agents and oracle answer from Python as
  the CLI does.

The native backend against the ROS backend (real nodes): tests/python/test_native.py.
"""

from __future__ import annotations

import json
import subprocess
import sys

import gymnasium
import numpy as np
import pytest

import sorting_line_gym  # noqa: F401 - registers the ids
from sorting_line_gym import BridgeError, SortingLineVectorEnv
from sorting_line_gym.envs.evolving import READY_SCHEDULES, schedule_file
from sorting_line_gym.line.vocabulary import SPEEDS
from support import ros_harness as h
from support.env_runs import COMBINATIONS, EVOLVING, IDS, run_episodes, same, vector_run

SEED_BOUND = 2**63


def run_trace(setup: str, variant: str, seed: int, tokens, evolution=None) -> list[dict]:
    argv = [str(h.node_binary()), "trace", "--setup", setup, "--variant", variant, "--seed", str(seed)]
    argv += ["--max-steps", "1000000", "--actions", ",".join(map(str, tokens))]
    if evolution is not None:
        argv += ["--evolution", str(evolution)]
    out = subprocess.run(argv, capture_output=True, text=True, timeout=60, check=True).stdout
    return [json.loads(line) for line in out.splitlines()]


def ratio(num: int, den: int) -> float:
    return num / den if den else 0.0


def trace_info(entry: dict, seed: int) -> dict:
    """The single-line env's info for a trace step entry (of an episode reset with ``seed``)."""
    s, c = entry["step"], entry["containers"]
    return {
        "accuracy": s["accuracy"],
        "purity": entry["purity"],
        "recall_a": ratio(c["a"], c["a"] + c["a_false"]),
        "recall_b": ratio(c["b"], c["b"] + c["b_false"]),
        "speed": SPEEDS[s["action"]["speed_index"]],
        "speed_index": s["action"]["speed_index"],
        "mode": h.MODES[s["action"]["mode"]],
        "occupancy": s["occupancy"],
        "containers": tuple(c[k] for k in h.CONTAINERS),
        "speed_changes": entry["speed_changes"],
        "cumulative_reward": entry["cumulative_reward"],
        "step": s["step"],
        "sim_time": float(s["step"]),
        "seed": seed,
    }


def trace_obs(variant: str, observation: dict, category_reading: int | None = None) -> np.ndarray:
    category = h.CATEGORIES[observation["category"]] if category_reading is None else category_reading
    values = [observation["quantity"]] + ([0.5 if category == 3 else category] if variant == "advanced" else [])
    return np.array(values, dtype=np.float32)


# --------------------------------------------------------------------------------------------
# The single-line env against the trace


@pytest.mark.parametrize(("setup", "variant"), COMBINATIONS)
def test_single_env_follows_the_trace_across_resets(setup, variant):
    n = gymnasium.make(IDS[variant], backend="native").action_space.n
    seeds, steps = [11, 9_000_000_000_000_000_000, 3], 20
    actions = [[int(a) for a in np.random.default_rng(seed % 1000).integers(0, n, steps)] for seed in seeds]
    env = gymnasium.make(IDS[variant], setup=setup, backend="native", max_episode_steps=steps)
    got = run_episodes(env, seeds, actions)
    tokens = [t for seed, acts in zip(seeds, actions, strict=True) for t in [f"r{seed}", *acts]]
    want = run_trace(setup, variant, seeds[0], tokens)[1:]
    episode_seed = None
    for t, (entry, returned) in enumerate(zip(want, got, strict=True)):
        if "reset" in entry:
            episode_seed = entry["reset"]["seed"]
            expected = (trace_obs(variant, entry["reset"]["observation"]), {"seed": episode_seed, "step": 0})
        else:
            s = entry["step"]
            obs = trace_obs(variant, s["observation"])
            expected = (obs, s["reward"], False, s["step"] == steps, trace_info(entry, episode_seed))
        assert same(tuple(returned), expected), f"entry {t}: {returned!r}\n    vs {expected!r}"


# --------------------------------------------------------------------------------------------
# The vector envs


@pytest.mark.parametrize(("setup", "variant"), COMBINATIONS)
def test_vector_env_follows_the_trace_across_autoresets(setup, variant):
    lines, steps, episode, seed = 3, 20, 8, 40
    env = gymnasium.make_vec(
        IDS[variant], num_envs=lines, vectorization_mode="vector_entry_point", backend="native", setup=setup,
        max_episode_steps=episode,
    )  # fmt: skip
    actions = np.random.default_rng(seed).integers(0, env.single_action_space.n, (steps, lines))
    run = vector_run(env, seed, actions)
    for k in range(lines):
        rng, tokens = np.random.default_rng(seed + k), []
        for t in range(steps):
            tokens.append(int(actions[t, k]))
            if (t + 1) % episode == 0:
                tokens.append(f"r{int(rng.integers(0, SEED_BOUND))}")
        want = iter(run_trace(setup, variant, seed + k, tokens))
        reset = next(want)["reset"]
        assert np.array_equal(run[0][0][k], trace_obs(variant, reset["observation"]))
        episode_seed = reset["seed"]
        for t in range(steps):
            obs, rewards, terminated, truncated, infos = run[1 + 2 * t]
            entry = next(want)
            info = {key: infos[key][k] for key in trace_info(entry, episode_seed)}
            info["containers"] = tuple(info["containers"].tolist())
            assert info == trace_info(entry, episode_seed), f"line {k} step {t}"
            assert rewards[k] == entry["step"]["reward"] and not terminated[k]
            step_obs = trace_obs(variant, entry["step"]["observation"])
            if truncated[k]:
                assert np.array_equal(infos["final_obs"][k], step_obs)
                reset = next(want)["reset"]
                episode_seed = reset["seed"]
                step_obs = trace_obs(variant, reset["observation"])
            assert np.array_equal(obs[k], step_obs), f"line {k} step {t}"


# --------------------------------------------------------------------------------------------
# The evolving line


#: A setting each ready schedule has changed by its last event (episode 2201 at the latest), and its value then.
CHANGED = {
    "upgrade": ("sort_modes", True),
    "drift": ("obs_noise", 0.3),
    "sensor": ("ratio_sensor", True),
    "machine": ("sort_modes", True),
    "noise-drift": ("obs_noise", 0.3),
    "threshold-drift": ("threshold", 0.8),
    "setup-a-to-b": ("input", "seasonal"),
}


def test_every_ready_schedule_names_what_it_changes():
    assert sorted(CHANGED) == sorted(READY_SCHEDULES)


@pytest.mark.parametrize("schedule", READY_SCHEDULES)
def test_ready_schedules_follow_the_trace_through_their_events(schedule):
    """2,203 one-step episodes: past the upgrade (episode 2001) and the drift's steps (2101, 2201)."""
    env = gymnasium.make(EVOLVING, evolution=schedule, backend="native", max_episode_steps=1)
    rng = np.random.default_rng(0)
    tokens, got = [], []
    for _ in range(1, 2204):
        seed, action = int(rng.integers(0, 1000)), int(rng.integers(0, 30))
        obs, info = env.reset(seed=seed)
        last = info["settings"]
        got.append((obs, info["settings"]["obs_noise"], info["settings"]["sort_modes"]))
        got.append(env.step(action)[:2])
        tokens += [f"r{seed}", action]
    want = run_trace("B", "advanced", 0, tokens, evolution=schedule_file(schedule))[1:]
    for t, (entry, returned) in enumerate(zip(want, got, strict=True)):
        if "reset" in entry:
            s = entry["settings"]
            expected = (trace_obs("advanced", entry["reset"]["observation"], entry["category_reading"]),
                        s["obs_noise"], s["sort_modes"])  # fmt: skip
        else:
            expected = (trace_obs("advanced", entry["step"]["observation"], entry["category_reading"]),
                        entry["step"]["reward"])  # fmt: skip
        assert same(tuple(returned), expected), f"entry {t}: {returned!r} vs {expected!r}"
    field, value = CHANGED[schedule]
    assert last[field] == value, f"{schedule}: {field} = {last[field]!r} at the last reset, want {value!r}"


# --------------------------------------------------------------------------------------------
# Checkers, bad input, no ROS, agents


@pytest.mark.parametrize("env_id", [*IDS.values(), EVOLVING])
def test_gymnasium_and_sb3_checkers(env_id):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    if env_id != EVOLVING:
        check_env(gymnasium.make(env_id, backend="native").unwrapped)
    else:
        evolving_passes_gymnasiums_checks_but_step_determinism(gymnasium.make(env_id, backend="native").unwrapped)
    sb3_check_env(gymnasium.make(env_id, backend="native", max_episode_steps=250), warn=True)


def evolving_passes_gymnasiums_checks_but_step_determinism(env) -> None:
    """Every check of Gymnasium's check_env but one: the evolving line's info carries the line's tick
    (`line_tick`), which runs on across resets by design (the schedule is in the line's episodes and
    ticks), so two episodes from one seed differ there. That they differ there only is checked."""
    import gymnasium.utils.env_checker as checker
    from gymnasium.utils.passive_env_checker import (
        check_action_space,
        check_observation_space,
        env_reset_passive_checker,
        env_step_passive_checker,
    )

    check_action_space(env.action_space)
    check_observation_space(env.observation_space)
    for space, name in [(env.action_space, "action"), (env.observation_space, "observation")]:
        checker.check_space_limit(space, name)
    for check in (
        checker.check_seed_deprecation,
        checker.check_reset_return_info_deprecation,
        checker.check_reset_return_type,
        checker.check_reset_seed_determinism,
        checker.check_reset_options,
        env_reset_passive_checker,
        checker.check_returned_data_not_reused,
    ):
        check(env)
    env_step_passive_checker(env, env.action_space.sample())
    env.reset(seed=5)
    first = env.step(3)
    env.reset(seed=5)
    second = env.step(3)
    assert checker.data_equivalence(first[:4], second[:4])
    differ = {k for k in first[4] if not checker.data_equivalence(first[4][k], second[4][k])}
    assert differ == {"line_tick"} and second[4]["line_tick"] > first[4]["line_tick"], differ


def test_bad_input_raises_naming_the_value():
    env = gymnasium.make(IDS["basic"], backend="native").unwrapped
    with pytest.raises(BridgeError, match=r"step\(\) before reset\(\)"):
        env.step(0)
    env.reset(seed=1)
    for bad, shown in [(10, "10"), (-1, "-1"), (3.0, "3.0"), (float("nan"), "nan"), ("2", "'2'"), ([1], r"\[1\]")]:
        with pytest.raises(ValueError, match=rf"action {shown} is not in Discrete\(10\): allowed integers 0 \.\.= 9"):
            env.step(bad)
    assert env.step(np.int64(3))[4]["step"] == 1, "a refused action leaves the line as it was"
    short = sorting_line_gym.envs.backends.line_env(backend="native", max_episode_steps=1)
    short.reset(seed=2)
    short.step(0)
    with pytest.raises(BridgeError, match="after the end of the episode .*max_episode_steps = 1"):
        short.step(0)
    vec = SortingLineVectorEnv(num_envs=3, backend="native", variant="advanced")
    vec.reset(seed=1)
    for bad, message in [
        ([1, 2], r"shape \(2,\): allowed one action per line, shape \(3,\)"),
        ([1.0, 2.0, 3.0], "dtype float64: allowed integers"),
        ([0, 30, 1], r"action 30 of line 1 is not in Discrete\(30\): allowed integers 0 \.\.= 29"),
        ([0, 1, -2], r"action -2 of line 2"),
    ]:
        with pytest.raises(ValueError, match=message):
            vec.step(np.array(bad))
    for kwargs, message in [
        ({"backend": "dds"}, "backend = 'dds' is not valid: allowed ros, native"),
        ({"backend": "native", "node": "attach", "namespace": "/x"}, "the native backend runs the line in this"),
        ({"backend": "native", "render_mode": "rgb_array"}, "the dashboard needs backend='ros'"),
        ({"backend": "native", "obs_noise": 2.0}, r"obs_noise = 2.0 is out of range: allowed 0.0 ..= 1.0"),
        ({"backend": "native", "max_episode_steps": 0}, "max_steps"),
    ]:
        with pytest.raises(ValueError, match=message):
            sorting_line_gym.envs.backends.line_env(**kwargs)


def test_the_native_backend_never_imports_rclpy():
    code = (
        "import sys, gymnasium, sorting_line_gym\n"
        "env = gymnasium.make('sorting_line_gym:SortingLineAdvanced-v0', backend='native')\n"
        "env.reset(seed=1); env.step(4)\n"
        "vec = gymnasium.make_vec('sorting_line_gym:SortingLine-v0', num_envs=2, "
        "vectorization_mode='vector_entry_point', backend='native')\n"
        "vec.reset(seed=1); vec.step([1, 2])\n"
        "evo = gymnasium.make('sorting_line_gym:SortingLineEvolving-v0', backend='native')\n"
        "evo.reset(seed=1); evo.step(0)\n"
        "assert 'rclpy' not in sys.modules, [m for m in sys.modules if 'rclpy' in m]\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.parametrize("agent", ["rba", "rba-hold", "random", "constant:4:cat"])
def test_agents_and_oracle_answer_as_the_cli(agent):
    from sorting_line_gym import _native

    settings = dict(
        variant="advanced", input="seasonal", obs_noise=0.3, action_penalty=0.5, threshold=0.7, max_steps=50
    )
    cli = [str(h.node_binary()), "eval", "--agent", agent, "--setup", "D", "--variant", "advanced"]
    want = json.loads(subprocess.run([*cli, "--episodes", "5", "--json"], capture_output=True, text=True,
                                     check=True).stdout)  # fmt: skip
    assert _native.evaluate(agent, settings, episodes=5, seed=42) == want
    oracle = [str(h.node_binary()), "oracle", "--setup", "D", "--variant", "advanced", "--episodes", "2", "--json"]
    want = json.loads(subprocess.run(oracle, capture_output=True, text=True, check=True).stdout)
    assert _native.oracle_eval(settings, episodes=2, seed=42) == want
    reward, actions = _native.oracle(settings, seed=42)
    assert reward == want["per_episode"][0]["reward"] and len(actions) == 50
