"""The Gymnasium bridge (bridge/sorting_line_gym) against the REAL node (target/release/sorting_line).

Every environment here spawns (or attaches to) a real `sorting_line node` process over Fast DDS, so
this file runs inside the loopback-only network namespace that launch_scripts/test.sh creates
(conftest.py refuses to run elsewhere):

    unshare -n bash -c 'ip link set lo up; source launch_scripts/env.sh; export ROS_DOMAIN_ID=91;
                        python -m pytest tests/python/test_bridge.py -q'

What is checked:
- Gymnasium's and Stable-Baselines3's environment checkers, for both ids (Gymnasium's includes
  reset-seed determinism, step determinism, returned-data reuse, render modes and double close);
- the trajectories equal the simulation library's (`sorting_line trace`) number for number, through
  the single-line env (one seeded episode; several episodes with unseeded resets) and through the
  vector envs (line k = seed S + k, across SAME_STEP autoresets: test_bridge_vector.py);
- reproducibility: one seed reproduces a whole multi-episode run, in two separately spawned nodes;
- failures: a node killed mid-episode makes the next step fail fast, naming the namespace, and a
  new env works afterwards; attaching to a namespace where nothing runs times out, naming it;
- render_mode="rgb_array", the spaces, the info keys, truncation (TimeLimit of gymnasium.make,
  the node's own max_episode_steps), and a short PPO run on the SB3 VecEnv.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium
import numpy as np
import pytest

import sorting_line_gym  # noqa: F401 - registers the Gymnasium ids
from sorting_line_gym import BridgeError, BridgeTimeout
from support.env_trace import (
    ADVANCED,
    BASIC,
    INFO_KEYS,
    assert_episode_follows_trace,
    assert_obs,
    assert_step,
    fixed_actions,
    strip_node_counters,
    trace,
)
from support.same_values import first_difference, same
from support.training_stack import needs_training

ROOT = Path(__file__).resolve().parents[2]
IDS = {"basic": BASIC, "advanced": ADVANCED}


# --------------------------------------------------------------------------------------------
# Helpers


# --------------------------------------------------------------------------------------------
# Environment checkers


@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_gymnasium_check_env(variant, make_env):
    """Gymnasium's checker on the unwrapped env, render check included (it makes an env per
    render mode from the spec and renders it) as well as the close check; the env must stay
    usable afterwards."""
    from gymnasium.utils.env_checker import check_env

    env = make_env(IDS[variant], setup="B")
    check_env(env.unwrapped)
    obs, _ = env.reset(seed=3)
    assert obs in env.observation_space


def test_step_info_does_not_depend_on_earlier_episodes(make_env):
    """What Gymnasium's step-determinism check demands, spelled out: after reset(seed=s), the same
    action gives the same observation, reward AND info, however many episodes ran before."""
    env = make_env(BASIC, setup="B")
    env.reset(seed=123)
    first = env.step(3)
    env.reset(seed=123)
    second = env.step(3)
    assert same(first[0], second[0]) and first[1:4] == second[1:4]
    differing = {k: (first[4][k], second[4][k]) for k in first[4] if not same(first[4][k], second[4][k])}
    assert not differing, (
        f"the same seed and action give a different info in a later episode (first, second): {differing}; "
        "gymnasium.utils.env_checker.check_step_determinism fails on this"
    )


@needs_training
@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_sb3_check_env(variant, make_env):
    from stable_baselines3.common.env_checker import check_env

    env = make_env(IDS[variant], setup="D")
    check_env(env, warn=True)
    check_env(env.unwrapped, warn=True)


# --------------------------------------------------------------------------------------------
# The library's trajectories


@pytest.mark.parametrize("setup,variant,seed", [("B", "advanced", 42), ("D", "basic", 7)])
def test_single_env_matches_the_library(setup, variant, seed, make_env):
    """reset(seed=S) then a fixed action list == `sorting_line trace --seed S --actions ...`,
    beyond the 50 steps of the default TimeLimit (here 200)."""
    env = make_env(IDS[variant], setup=setup, max_episode_steps=200)
    actions = fixed_actions(env.action_space.n, 120, seed=seed)
    want = trace(setup, variant, seed, actions)
    obs, info = env.reset(seed=seed)
    assert info["seed"] == seed and want[0]["reset"]["seed"] == seed
    assert_obs(obs, variant, want[0]["reset"]["observation"], "reset")
    for t, action in enumerate(actions, start=1):
        obs, reward, terminated, truncated, info = env.step(action)
        assert type(reward) is float
        assert terminated is False and truncated is False, f"step {t}: {terminated=} {truncated=}"
        assert_step(variant, obs, reward, info, want[t], f"{setup} {variant} seed {seed} step {t}")


@pytest.mark.parametrize("setup,variant", [("B", "advanced"), ("D", "basic")])
def test_unseeded_resets_continue_like_the_library(setup, variant, make_env):
    """A seeded reset, then 3 episodes under the TimeLimit of 50 with reset() in between: each
    unseeded reset reports the node seed it drew (info["seed"]), and the whole run equals the
    library's run with those resets (`r<seed>`)."""
    env = make_env(IDS[variant], setup=setup)
    actions = fixed_actions(env.action_space.n, 150, seed=11)
    obs, info = env.reset(seed=5)
    got = [("reset", obs, info)]
    tokens = []
    for t, action in enumerate(actions, start=1):
        obs, reward, terminated, truncated, info = env.step(action)
        got.append(("step", obs, reward, info))
        tokens.append(action)
        assert truncated == (t % 50 == 0) and not terminated, f"step {t}: {terminated=} {truncated=}"
        if truncated and t < len(actions):
            obs, info = env.reset()
            assert isinstance(info["seed"], int) and 0 <= info["seed"] < 2**63
            got.append(("reset", obs, info))
            tokens.append(f"r{info['seed']}")
    want = trace(setup, variant, 5, tokens)
    assert len(want) == len(got)
    for i, (entry, mine) in enumerate(zip(want, got, strict=False)):
        if mine[0] == "reset":
            assert "reset" in entry, f"entry {i}: a reset in the env, a step in the library"
            assert entry["reset"]["seed"] == mine[2]["seed"]
            assert_obs(mine[1], variant, entry["reset"]["observation"], f"entry {i} (reset)")
        else:
            assert_step(variant, mine[1], mine[2], mine[3], entry, f"entry {i}")


# --------------------------------------------------------------------------------------------
# Reproducibility


def _run_single(env, seed: int, actions: list[int]) -> list:
    """reset(seed) once, then the actions; reset() (unseeded) whenever an episode ends."""
    obs, info = env.reset(seed=seed)
    out = [("reset", obs, info)]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append(("step", obs, reward, terminated, truncated, info))
        if terminated or truncated:
            obs, info = env.reset()
            out.append(("reset", obs, info))
    return out


@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_one_seed_reproduces_a_multi_episode_run(variant, make_env):
    """Two separately spawned envs, seeded once: identical 3-episode runs (unseeded resets drawn
    from the env's np_random), infos included. The first env, seeded again, repeats the run too
    (its node's process-wide episode counter and clock aside)."""
    one = make_env(IDS[variant], setup="D")
    two = make_env(IDS[variant], setup="D")
    actions = fixed_actions(one.action_space.n, 160, seed=77)
    a = _run_single(one, 2024, actions)
    b = _run_single(two, 2024, actions)
    assert sum(1 for x in a if x[0] == "reset") == 4
    assert same(a, b), "two envs, same seed: runs differ at " + first_difference(a, b)
    c = _run_single(one, 2024, actions)
    strip = lambda run: [x[:-1] + (strip_node_counters(x[-1]),) for x in run]  # noqa: E731
    sa, sc = strip(a), strip(c)
    assert same(sa, sc), "same env, seeded again: runs differ at " + first_difference(sa, sc)
    # A different seed gives a different run (the seed is not ignored).
    d = _run_single(two, 2025, actions[:60])
    assert not same(strip(a[: len(d)]), strip(d))


# --------------------------------------------------------------------------------------------
# Failures


def test_killed_node_fails_the_next_step_then_a_new_env_works(make_env):
    env = make_env(BASIC, setup="A", step_timeout=2.0, node="spawn")
    namespace = env.unwrapped.namespace
    env.reset(seed=1)
    for _ in range(5):
        env.step(4)
    os.kill(env.unwrapped.bank.process.process.pid, signal.SIGKILL)
    start = time.monotonic()
    with pytest.raises(BridgeError) as excinfo:
        env.step(4)
    elapsed = time.monotonic() - start
    assert elapsed < 2.0 + 1.0, f"the failure took {elapsed:.2f} s (step_timeout 2 s)"
    assert namespace in str(excinfo.value), f"the error does not name {namespace}: {excinfo.value}"
    env.close()  # closing an env whose node was killed is not an error

    fresh = make_env(BASIC, setup="A")
    assert fresh.unwrapped.namespace != namespace
    assert_episode_follows_trace(fresh, "A", "basic", 1, [4, 5, 6, 7, 8], "fresh env")


def test_attach_to_nothing_times_out_naming_the_namespace(make_env):
    namespace = f"/sl_nobody_{os.getpid()}"
    env = make_env(BASIC, setup="A", node="attach", namespace=namespace, startup_timeout=1.5)
    assert env.unwrapped.bank.process is None  # attach starts nothing
    start = time.monotonic()
    with pytest.raises(BridgeTimeout) as excinfo:
        env.reset(seed=1)
    elapsed = time.monotonic() - start
    assert elapsed < 1.5 + 0.5, f"reset gave up after {elapsed:.2f} s (startup_timeout 1.5 s)"
    assert namespace in str(excinfo.value), f"the error does not name {namespace}: {excinfo.value}"
    missing = f"not yet discovered: {namespace} reset service, {namespace} cmd/speed reader, {namespace} state writer"
    assert missing in str(excinfo.value), f"the error does not list the endpoints it lacks: {excinfo.value}"


def test_attach_to_a_running_node(make_env):
    """node="attach" drives the line of a node started by someone else (here: another env)."""
    owner = make_env(None, setup="B", variant="basic")
    owner.reset(seed=0)  # envs start their node at the first reset
    guest = make_env(BASIC, setup="B", node="attach", namespace=owner.namespace)
    assert_episode_follows_trace(guest, "B", "basic", 8, [2, 3, 9, 0], "attached")
    guest.close()
    assert owner.bank.process.alive(), "closing an attached env stopped the node it does not own"


# --------------------------------------------------------------------------------------------
# Render


@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_render_rgb_array(variant, make_env):
    env = make_env(IDS[variant], setup="B", render_mode="rgb_array")
    env.reset(seed=4)

    def check(frame, when):
        assert isinstance(frame, np.ndarray), f"{when}: render() returned {type(frame)}"
        assert frame.shape == (800, 1600, 3) and frame.dtype == np.uint8, f"{when}: {frame.shape} {frame.dtype}"
        colours = np.unique(frame.reshape(-1, 3)[::7], axis=0)
        assert len(colours) > 20, f"{when}: only {len(colours)} colours: blank?"
        assert (frame < 250).any(axis=2).mean() > 0.02, f"{when}: almost all white"

    first = env.render()
    check(first, "after reset")
    for a in (3, 7, 1, 9, 5):
        env.step(a)
    later = env.render()
    check(later, "after 5 steps")
    assert not np.array_equal(first, later), "the dashboard did not change in 5 steps"


# --------------------------------------------------------------------------------------------
# Spaces, info, truncation


@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_spaces_and_info_keys(variant, make_env):
    env = make_env(IDS[variant], setup="C")
    n, high, dim = (10, 1.0, 1) if variant == "basic" else (30, 2.0, 2)
    assert env.action_space == gymnasium.spaces.Discrete(n)
    assert env.observation_space == gymnasium.spaces.Box(0.0, high, (dim,), np.float32)
    obs, info = env.reset(seed=0)
    assert obs in env.observation_space and info["seed"] == 0
    for a in range(n):
        obs, reward, terminated, truncated, info = env.step(a)
        assert obs in env.observation_space and obs.dtype == np.float32
        assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
        assert INFO_KEYS <= info.keys(), f"missing info keys: {INFO_KEYS - info.keys()}"
        speed, mode = (a, 0) if variant == "basic" else (a // 3, a % 3)
        assert info["speed_index"] == speed and info["mode"] == mode
        assert info["speed"] == pytest.approx((speed + 1) / 10)
    with pytest.raises(ValueError, match="is not in Discrete"):
        env.step(n)  # outside the action space


@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_make_truncates_at_50(variant, make_env):
    env = make_env(IDS[variant], setup="A")
    for episode in range(2):
        env.reset(seed=episode)
        for t in range(1, 51):
            _, _, terminated, truncated, info = env.step(t % env.action_space.n)
            assert not terminated and truncated == (t == 50), f"episode {episode} step {t}: {truncated=}"
            assert info["step"] == t


def test_direct_max_episode_steps_truncates_in_the_node(make_env):
    env = make_env(None, setup="B", variant="advanced", max_episode_steps=7)
    for episode in range(2):
        env.reset(seed=30 + episode)
        for t in range(1, 8):
            _, _, terminated, truncated, info = env.step(t)
            assert not terminated and truncated == (t == 7), f"episode {episode} step {t}: {truncated=}"
    # The node says the same as the library with --max-steps 7.
    want = trace("B", "advanced", 31, list(range(1, 8)), max_steps=7)
    assert [e["step"]["truncated"] for e in want[1:]] == [False] * 6 + [True]


def test_make_max_episode_steps_250(make_env):
    env = make_env(BASIC, setup="B", max_episode_steps=250)
    assert env.spec.max_episode_steps == 250
    env.reset(seed=12)
    truncated_at = None
    for t in range(1, 251):
        _, _, _, truncated, info = env.step(t % 10)
        if truncated:
            truncated_at = t
            break
        if t == 51:
            assert info["step"] == 51
    assert truncated_at == 250
    obs, _ = env.reset()
    assert obs in env.observation_space


# --------------------------------------------------------------------------------------------
# Training


@needs_training
def test_short_ppo_run(make_vec):
    """PPO on 4 advanced lines for 2048 steps: completes, and the policy predicts valid actions."""
    import torch
    from stable_baselines3 import PPO

    from sorting_line_gym import SortingLineSB3VecEnv

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        env = make_vec(SortingLineSB3VecEnv, num_envs=4, setup="B", variant="advanced", seed=42)
        model = PPO("MlpPolicy", env, n_steps=128, batch_size=128, seed=42, device="cpu", verbose=0)
        model.learn(total_timesteps=2048)
        assert model.num_timesteps >= 2048
        obs = env.reset()
        for deterministic in (True, False):
            actions, _ = model.predict(obs, deterministic=deterministic)
            assert actions.shape == (4,) and all(0 <= int(a) < 30 for a in actions)
        env.step_async(actions)
        obs, rewards, dones, infos = env.step_wait()
        assert obs.shape == (4, 2) and rewards.shape == (4,)
    finally:
        torch.set_num_threads(threads)


# --------------------------------------------------------------------------------------------
# The throughput benchmark still runs (its figures are not checked here: speed is the
# benchmark's business, not a test's)


def test_throughput_benchmark_runs_and_reports_the_targets(tmp_path):
    plot = tmp_path / "throughput.png"
    result = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benches" / "bridge_throughput.py"),
            "--rounds",
            "2",
            "--single",
            "60",
            "--vector",
            "30",
            "--lines",
            "1",
            "16",
            "--domain",
            os.environ["ROS_DOMAIN_ID"],
            "--plot",
            str(plot),
        ],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = result.stdout
    for row in (
        "(a) raw rclpy lock-step loop",
        "(b) SortingLineEnv",
        "(b) gymnasium.make",
        "(c) SortingLineVectorEnv(16 lines), no episode ends",
    ):
        assert row in out, out
    assert "16 lines (VectorEnv) / single-line env (SortingLineEnv" in out and "one line, SortingLineEnv" in out, out
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot.with_suffix(".svg").is_file()
