"""What the envs' line keywords do on a real node, and a closed env:

- ``obs_noise`` and ``threshold`` given to ``gymnasium.make`` (on top of the setup) give the trajectory of
  the node's options of the same name (setup A + obs_noise 0.3 is setup C; the reward cut moves).
- Every keyword reaches the line options of each face (making an env starts no node, but loads rclpy).
- A ROS_DOMAIN_ID that DDS cannot use fails at the first reset naming it (rmw_fastrtps would end the
  process without a word).
- Stepping or resetting a closed env raises our ``BridgeError`` saying the env is closed, not rclpy's
  ``InvalidHandle`` of a destroyed node.

Real node, real rclpy: about 10 s. The keywords' checks that need no ROS at all:
unit/test_env_keywords.py.
"""

from __future__ import annotations

import inspect

import gymnasium
import pytest

import sorting_line_gym  # noqa: F401 - registers the Gymnasium ids
from sorting_line_gym import BridgeError, SortingLineSB3VecEnv, SortingLineVectorEnv
from support.env_trace import BASIC, assert_episode_follows_trace, fixed_actions


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


def test_closed_env_raises_our_error(make_env):
    env = make_env(BASIC, setup="B")
    env.reset(seed=1)
    env.step(3)
    env.close()
    for use in (lambda: env.step(3), lambda: env.reset(seed=1)):
        with pytest.raises(BridgeError, match="the environment is closed"):
            use()


#: A value other than the default for every line option (with node="attach", the namespace it needs).
NOT_DEFAULTS = {
    "setup": "D",
    "variant": "advanced",
    "namespace": "/elsewhere",
    "node": "attach",
    "max_episode_steps": 7,
    "step_timeout": 3.5,
    "startup_timeout": 21.0,
    "threshold": 0.6,
    "input": "seasonal3",
    "obs_noise": 0.1,
    "action_penalty": 0.2,
}


def test_every_keyword_reaches_the_line_options():
    """Each face hands every line option it takes to its bank as given: none falls back to its
    default (what the constructors' locals() allowed when a name changed on one side only). Making
    an env starts nothing, so no node is needed."""
    from sorting_line_gym import SortingLineEnv
    from sorting_line_gym.envs.evolving import SortingLineEvolvingEnv

    for face, bank in (
        (SortingLineEnv, lambda env: env.bank),
        (SortingLineEvolvingEnv, lambda env: env.bank),
        (SortingLineVectorEnv, lambda env: env._lines.bank),
        (SortingLineSB3VecEnv, lambda env: env._lines.bank),
    ):
        given = {k: v for k, v in NOT_DEFAULTS.items() if k in inspect.signature(face).parameters}
        options = bank(face(**given)).options
        assert {k: getattr(options, k) for k in given} == given, face.__name__
        assert len(given) >= 6, f"{face.__name__} takes only {sorted(given)}"


@pytest.mark.parametrize("domain", ["233", "1000", "-1", "abc"])
def test_a_domain_id_dds_cannot_use_fails_naming_it(monkeypatch, domain):
    """rmw_fastrtps ends the whole process (exit code 1, no message) when asked for a participant on a
    ROS_DOMAIN_ID beyond 232: the env refuses it first, naming the value and the range, before any
    node or rclpy starts."""
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    env = gymnasium.make(BASIC, setup="B")
    try:
        expected = rf"ROS_DOMAIN_ID = '{domain}' is out of range: allowed an integer 0 \.\.= 232"
        with pytest.raises(BridgeError, match=expected):
            env.reset(seed=1)
    finally:
        env.close()
