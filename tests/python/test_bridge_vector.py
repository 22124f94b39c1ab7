"""The vector faces of the Gymnasium bridge against the REAL node, continued from test_bridge.py
(the trace checks they share: support/env_trace.py): SortingLineVectorEnv and the SB3 VecEnv equal the simulation
library's trajectories (line k = seed S + k) across SAME_STEP autoresets, one seed reproduces a
run, gymnasium.make_vec uses the vector entry point, and the ecosystem's episode statistics
(Gymnasium's RecordEpisodeStatistics, SB3's Monitor convention) work on every face. Runs in the
loopback-only network namespace, as test_bridge.py does."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

from sorting_line_gym import SortingLineVectorEnv
from support.env_trace import (
    ADVANCED,
    BASIC,
    INFO_KEYS,
    assert_obs,
    assert_step,
    fixed_actions,
    strip_node_counters,
    trace,
)
from support.same_values import first_difference, same
from support.training_stack import needs_training


def _run_vector(env: SortingLineVectorEnv, seed: int, actions: np.ndarray) -> dict:
    """reset(seed) and every step of `actions` (T x N); the raw results."""
    obs, info = env.reset(seed=seed)
    run = {"reset": (obs.copy(), info), "steps": []}
    for a in actions:
        obs, rewards, terminated, truncated, infos = env.step(a)
        run["steps"].append((obs.copy(), rewards.copy(), terminated.copy(), truncated.copy(), infos))
    return run


def _final_info(infos: dict, k: int) -> dict:
    """Line k's final_info (Gymnasium nests a dict as a dict of arrays with `_key` masks)."""
    fi = infos["final_info"]
    return {key: v[k] for key, v in fi.items() if not key.startswith("_")}


@pytest.mark.parametrize("setup,variant", [("B", "advanced"), ("D", "basic")])
def test_vector_env_matches_the_library_across_autoreset(setup, variant, make_vec):
    """SortingLineVectorEnv(4): line k == `trace --seed S+k`; at step 50 every line truncates and is
    reset in the same step (SAME_STEP): final_obs / final_info are the library's step 50, the
    returned observation is the new episode's reset observation, and the rest of the run equals the
    library's run after `r<seed>` with the seed the line reports for its new episode."""
    n, seed, steps = 4, 100, 65
    env = make_vec(SortingLineVectorEnv, num_envs=n, setup=setup, variant=variant)
    assert env.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.SAME_STEP
    actions = np.stack([fixed_actions(env.single_action_space.n, n, seed=t) for t in range(steps)])
    run = _run_vector(env, seed, actions)

    obs0 = run["reset"][0]
    assert obs0.shape == (n, env.single_observation_space.shape[0]) and obs0.dtype == np.float32
    new_seeds = [int(run["steps"][50][4]["seed"][k]) for k in range(n)]
    for k in range(n):
        tokens = [int(a) for a in actions[:50, k]] + [f"r{new_seeds[k]}"] + [int(a) for a in actions[50:, k]]
        want = trace(setup, variant, seed + k, tokens, max_steps=50)
        where = f"line {k} (seed {seed + k})"
        assert want[0]["reset"]["seed"] == seed + k
        assert_obs(obs0[k], variant, want[0]["reset"]["observation"], f"{where} reset")
        for t in range(1, steps + 1):
            obs, rewards, terminated, truncated, infos = run["steps"][t - 1]
            assert not terminated[k]
            info_k = {key: infos[key][k] for key in INFO_KEYS}
            if t < 50:
                assert not truncated[k] and "final_obs" not in infos, f"{where} step {t}"
                assert_step(variant, obs[k], float(rewards[k]), info_k, want[t], f"{where} step {t}")
            elif t == 50:
                assert truncated[k] and want[50]["step"]["truncated"], f"{where}: no truncation at step 50"
                assert infos["_final_obs"][k] and infos["_final_info"][k]
                final = infos["final_obs"][k]
                assert_step(variant, final, float(rewards[k]), info_k, want[50], f"{where} step 50 (info)")
                assert_step(
                    variant, final, float(rewards[k]), _final_info(infos, k), want[50], f"{where} step 50 (final_info)"
                )
                # The observation returned is the new episode's first one.
                assert obs[k] in env.single_observation_space
                assert want[51]["reset"]["seed"] == new_seeds[k]
                assert_obs(obs[k], variant, want[51]["reset"]["observation"], f"{where} post-reset obs")
            else:
                assert not truncated[k] and "final_obs" not in infos, f"{where} step {t}"
                assert int(info_k["seed"]) == new_seeds[k]
                assert_step(variant, obs[k], float(rewards[k]), info_k, want[t + 1], f"{where} step {t}")


def _flatten_vector_run(run: dict, keep_counters: bool) -> list:
    out = [("reset", run["reset"][0])]
    for obs, rewards, terminated, truncated, infos in run["steps"]:
        infos = dict(infos)
        if "final_info" in infos:
            infos["final_info"] = dict(infos["final_info"])
        if not keep_counters:
            for d in (infos, infos.get("final_info", {})):
                for key in ("episode", "sim_time", "_episode", "_sim_time"):
                    d.pop(key, None)
        if "final_obs" in infos:
            infos["final_obs"] = [np.asarray(x) for x in infos["final_obs"]]
        out.append((obs, rewards, terminated, truncated, infos))
    return out


def test_vector_env_same_seed_same_run_including_autoresets(make_vec):
    """Two separately spawned vector envs, reset(seed=S), the same actions over three episodes:
    identical trajectories, autoresets (their drawn seeds and observations) included. A second
    reset(seed=S) of the first env reproduces it as well (the node's process-wide episode counter
    and clock aside)."""
    n, seed, steps = 4, 9, 120
    kwargs = dict(num_envs=n, setup="D", variant="advanced")
    first = make_vec(SortingLineVectorEnv, **kwargs)
    second = make_vec(SortingLineVectorEnv, **kwargs)
    actions = np.stack([fixed_actions(30, n, seed=1000 + t) for t in range(steps)])
    a = _run_vector(first, seed, actions)
    b = _run_vector(second, seed, actions)
    assert sum(bool(s[3].any()) for s in a["steps"]) == 2  # two autoresets of every line
    fa, fb = _flatten_vector_run(a, True), _flatten_vector_run(b, True)
    assert same(fa, fb), "two nodes, same seed: runs differ at " + first_difference(fa, fb)
    again = _run_vector(first, seed, actions)
    fa, fc = _flatten_vector_run(a, False), _flatten_vector_run(again, False)
    assert same(fa, fc), "same env, reset(seed) again: runs differ at " + first_difference(fa, fc)


@needs_training
def test_sb3_vec_env_matches_the_library_across_autoreset(make_vec):
    """SortingLineSB3VecEnv(seed=S): line k == `trace --seed S+k`; at truncation SB3's conventions
    (done, terminal_observation, TimeLimit.truncated) and the new episode's observation."""
    from sorting_line_gym import SortingLineSB3VecEnv

    n, seed, steps = 3, 21, 55
    env = make_vec(SortingLineSB3VecEnv, num_envs=n, setup="B", variant="advanced", seed=seed)
    env.seed(seed)
    obs0 = env.reset()
    assert [i["seed"] for i in env.reset_infos] == [seed + k for k in range(n)]
    actions = np.stack([fixed_actions(30, n, seed=500 + t) for t in range(steps)])
    results = []
    for a in actions:
        env.step_async(a)
        results.append(env.step_wait())
    new_seeds = [results[50][3][k]["seed"] for k in range(n)]
    for k in range(n):
        tokens = [int(x) for x in actions[:50, k]] + [f"r{new_seeds[k]}"] + [int(x) for x in actions[50:, k]]
        want = trace("B", "advanced", seed + k, tokens, max_steps=50)
        assert_obs(obs0[k], "advanced", want[0]["reset"]["observation"], f"line {k} reset")
        for t in range(1, steps + 1):
            obs, rewards, dones, infos = results[t - 1]
            entry = want[t] if t <= 50 else want[t + 1]
            assert rewards.dtype == np.float32 and bool(dones[k]) == (t == 50)
            if t == 50:
                assert infos[k]["TimeLimit.truncated"] is True
                assert_obs(
                    infos[k]["terminal_observation"],
                    "advanced",
                    entry["step"]["observation"],
                    f"line {k} terminal_observation",
                )
                assert_obs(obs[k], "advanced", want[51]["reset"]["observation"], f"line {k} post-reset obs")
            else:
                assert "terminal_observation" not in infos[k]
                assert_obs(obs[k], "advanced", entry["step"]["observation"], f"line {k} step {t}")
            # SB3 hands rewards over as float32: the library's reward, rounded to float32.
            assert rewards[k] == np.float32(entry["step"]["reward"]), f"line {k} step {t}"
            assert infos[k]["accuracy"] == entry["step"]["accuracy"] and infos[k]["purity"] == entry["purity"]


@needs_training
def test_sb3_vec_env_constructor_seed_reproduces(make_vec):
    """SortingLineSB3VecEnv(seed=S) without a later seed(): two envs give the same run."""
    from sorting_line_gym import SortingLineSB3VecEnv

    runs = []
    actions = np.stack([fixed_actions(10, 2, seed=900 + t) for t in range(60)])
    for _ in range(2):
        env = make_vec(SortingLineSB3VecEnv, num_envs=2, setup="D", variant="basic", seed=5)
        run = [env.reset()]
        for a in actions:
            env.step_async(a)
            obs, rewards, dones, infos = env.step_wait()
            run.append((obs, rewards, dones, [strip_node_counters(i) for i in infos]))
        runs.append(run)
    assert same(runs[0], runs[1]), "same constructor seed, different runs: " + first_difference(*runs)


def test_make_vec_uses_the_vector_entry_point(make_vec):
    env = make_vec(
        lambda **kw: gymnasium.make_vec(ADVANCED, vectorization_mode="vector_entry_point", **kw), num_envs=2, setup="B"
    )
    assert isinstance(env, SortingLineVectorEnv) and env.num_envs == 2
    assert env.single_action_space == gymnasium.spaces.Discrete(30)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (2, 2)
    for t in range(1, 51):
        obs, rewards, terminated, truncated, infos = env.step(np.array([3, 4]))
        assert list(truncated) == [t == 50] * 2, f"step {t}"
    assert obs in env.observation_space


# --------------------------------------------------------------------------------------------
# The ecosystem's episode statistics: Gymnasium's RecordEpisodeStatistics (single and vector) and
# SB3 (Monitor / VecMonitor / its algorithms) put {"r", "l", "t"} under info["episode"]; SB3's
# algorithms read info["episode"] of EVERY step as such a dict.


def test_record_episode_statistics_single(make_env):
    env = gymnasium.wrappers.RecordEpisodeStatistics(make_env(BASIC, setup="A"))
    env.reset(seed=1)
    for t in range(1, 51):
        _, _, _, truncated, info = env.step(t % 10)
    assert truncated and info["episode"]["l"] == 50


def test_record_episode_statistics_vector(make_vec):
    env = make_vec(
        lambda **kw: gymnasium.wrappers.vector.RecordEpisodeStatistics(SortingLineVectorEnv(**kw)),
        num_envs=2,
        setup="A",
        variant="basic",
    )
    env.reset(seed=1)
    for t in range(1, 51):
        _, _, _, truncated, infos = env.step(np.array([t % 10, 9 - t % 10]))
    assert truncated.all() and list(infos["episode"]["l"]) == [50, 50]


@needs_training
def test_sb3_infos_keep_sb3s_episode_convention(make_vec):
    """Every step's info["episode"], if present, must be SB3's episode-statistics dict: PPO/A2C/DQN
    feed it into their ep_info_buffer and crash on anything else (see test_short_ppo_run)."""
    from sorting_line_gym import SortingLineSB3VecEnv

    env = make_vec(SortingLineSB3VecEnv, num_envs=2, setup="A", variant="basic", seed=1)
    env.reset()
    env.step_async(np.array([3, 4]))
    _, _, _, infos = env.step_wait()
    for k, info in enumerate(infos):
        episode = info.get("episode")
        assert episode is None or (isinstance(episode, dict) and {"r", "l", "t"} <= episode.keys()), (
            f"line {k}: info['episode'] = {episode!r} is not SB3's episode-statistics dict"
        )
