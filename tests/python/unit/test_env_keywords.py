"""What a user hits first with the envs' arguments, before any node starts (no ROS, no node):

- ``input``, ``obs_noise``, ``action_penalty`` and ``threshold`` are accepted by ``gymnasium.make``; an
  out-of-range value fails at once naming the value and the range; an unknown keyword names itself in the
  error; ``help()`` shows each keyword with its default.

What the keywords do to a real node's line, that each reaches the ROS backend's line options, a bad
ROS_DOMAIN_ID and a closed env: tests/python/test_env_arguments.py.
"""

from __future__ import annotations

import inspect

import gymnasium
import pytest

import sorting_line_gym  # noqa: F401 - registers the Gymnasium ids
from sorting_line_gym import SortingLineSB3VecEnv, SortingLineVectorEnv
from support.env_trace import BASIC


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


@pytest.mark.parametrize(
    "make",
    [
        lambda **kw: gymnasium.make(BASIC, **kw),
        lambda **kw: gymnasium.make(BASIC, backend="native", **kw),
        lambda **kw: gymnasium.make("sorting_line_gym:SortingLineEvolving-v0", **kw),
        lambda **kw: gymnasium.make("sorting_line_gym:SortingLineEvolving-v0", backend="native", **kw),
        lambda **kw: gymnasium.make_vec(BASIC, num_envs=2, vectorization_mode="vector_entry_point", **kw),
        lambda **kw: SortingLineSB3VecEnv(2, **kw),
    ],
    ids=["make", "make-native", "evolving", "evolving-native", "make_vec", "sb3"],
)
def test_unknown_keyword_is_named_with_the_allowed_ones(make):
    """A misspelt keyword fails at once on every face, naming itself, the keyword meant and the allowed ones."""
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'setpu' \(did you mean 'setup'\?\): allowed .*"):
        make(setpu="B")
    with pytest.raises(TypeError, match="'noise'.*allowed .*step_timeout"):
        make(noise=0.3)


def test_help_shows_each_keyword_with_its_default_and_meaning():
    """``help()`` of each env class lists every keyword it takes, with its default, in the signature
    and in the docstring (written there from ``line/options.py`` and ``envs/keywords.py``)."""
    import pydoc

    from sorting_line_gym import SortingLineEnv
    from sorting_line_gym.envs.evolving import SortingLineEvolvingEnv

    for face in (SortingLineEnv, SortingLineEvolvingEnv, SortingLineVectorEnv, SortingLineSB3VecEnv):
        text = pydoc.render_doc(face, renderer=pydoc.plaintext)
        for name, parameter in inspect.signature(face).parameters.items():
            assert f"{name}: " in text.split("__init__", 1)[1], f"help({face.__name__}) shows no {name} in __init__"
            assert f"- `{name}={parameter.default!r}`: " in text, f"help({face.__name__}) lists no {name} default"
    assert "action_penalty: float | None = None" in pydoc.render_doc(SortingLineEnv, renderer=pydoc.plaintext)
