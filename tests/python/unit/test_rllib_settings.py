"""The RLlib PPO's settings (training/rllib.py ``paper_training``) are the paper's, read from
hyperparams/ppo.yml as `sorting-line-train` reads them, under RLlib's names; an id without such
settings fails naming the ids that have them. (Ray itself is not needed: test_rllib.py trains.)"""

from __future__ import annotations

import pytest

from sorting_line_gym.training import hyperparams, rllib


@pytest.mark.parametrize(
    ("env_id", "variant"),
    [
        ("sorting_line_gym:SortingLine-v0", "basic"),
        ("SortingLineAdvanced-v0", "advanced"),
        ("sorting_line_gym:SortingLineEvolving-v0", "advanced"),
    ],
)
def test_the_settings_are_ppo_yml_s_under_rllib_s_names(env_id, variant):
    _, kwargs = hyperparams.split(hyperparams.load("ppo", variant))
    assert rllib.paper_training(env_id) == {rllib.RLLIB_NAMES[k]: v for k, v in kwargs.items()}
    assert rllib.paper_training(env_id) == {"gamma": 0.85, "lr": 0.0007, "entropy_coeff": 0.03}


def test_an_id_without_the_paper_s_settings_is_refused():
    with pytest.raises(ValueError, match="--id Foo-v0: the paper's PPO settings exist for SortingLine-v0"):
        rllib.paper_training("Foo-v0")
