"""What a user hits first with the envs' arguments: the line's settings as keyword arguments, and a closed env.

- ``input``, ``obs_noise``, ``action_penalty`` and ``threshold`` are accepted by ``gymnasium.make`` (as the
  node's options of the same name, on top of the setup); an out-of-range value fails at once naming the value
  and the range, before any node starts; an unknown keyword names itself in the error.
- Stepping or resetting a closed env raises our ``BridgeError`` saying the env is closed, not rclpy's
  ``InvalidHandle`` of a destroyed node.

Real node, real rclpy: about 10 s.
"""

from __future__ import annotations

import gymnasium
import pytest

import sorting_line_gym  # noqa: F401 - registers the Gymnasium ids
from sorting_line_gym import BridgeError, SortingLineSB3VecEnv, SortingLineVectorEnv
from test_bridge import BASIC, assert_episode_follows_trace, fixed_actions


def test_setup_a_with_obs_noise_is_setup_c(make_env):
    """Setup C is setup A with sensor noise 0.3: the keyword must give C's trajectory exactly."""
    env = make_env(BASIC, setup="A", obs_noise=0.3, max_episode_steps=20)
    assert_episode_follows_trace(env, "C", "basic", 5, fixed_actions(10, 20, 5), "setup A + obs_noise=0.3")


def test_threshold_moves_the_reward_cut(make_env):
    env = make_env(BASIC, setup="A", threshold=0.8, max_episode_steps=50)
    env.reset(seed=11)
    below = above = 0
    for action in fixed_actions(10, 50, 11):
        _, reward, _, _, info = env.step(action)
        if info["accuracy"] < 0.8:
            assert reward == pytest.approx(-0.1), (info["accuracy"], reward)
            below += 1 if info["accuracy"] >= 0.7 else 0  # would have been rewarded at the default 0.7
        else:
            assert reward > 0, (info["accuracy"], reward)
            above += 1
    assert below and above, f"the episode never tested the cut: {below} steps in 0.7..0.8, {above} above 0.8"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"obs_noise": 1.5}, "obs_noise = 1.5 is out of range: allowed 0.0 ..= 1.0"),
        ({"threshold": 1.0}, "threshold = 1.0 is out of range: allowed 0.0 ..< 1.0"),
        ({"action_penalty": -0.5}, "action_penalty = -0.5 is out of range: allowed 0.0 ..= 10.0"),
        ({"input": "bursty"}, "input = 'bursty' is not valid: allowed random, seasonal, seasonal3"),
    ],
)
def test_bad_settings_fail_at_make_naming_value_and_range(kwargs, message):
    for make in (
        lambda: gymnasium.make(BASIC, **kwargs),
        lambda: SortingLineVectorEnv(2, **kwargs),
        lambda: SortingLineSB3VecEnv(2, **kwargs),
    ):
        with pytest.raises(ValueError, match=message.replace(".", r"\.").replace("(", r"\(")):
            make()


def test_unknown_keyword_is_named():
    with pytest.raises(TypeError, match="noise"):
        gymnasium.make(BASIC, noise=0.3)


def test_closed_env_raises_our_error(make_env):
    env = make_env(BASIC, setup="B")
    env.reset(seed=1)
    env.step(3)
    env.close()
    for use in (lambda: env.step(3), lambda: env.reset(seed=1)):
        with pytest.raises(BridgeError, match="the environment is closed"):
            use()
