"""The transfer study's warm starts (studies/transfer_warm.py): shrink-and-perturb (Ash & Adams 2020)
on known weights and behaviour cloning of the exact oracle, for both engines, and the rule that
redoes a trained cell saved before forgetting was measured (transfer_cells ``outdated``):

- every parameter becomes SHRINK * theta + PERTURB * theta_fresh (to float32), theta_fresh a fresh
  initialisation of the same policy seeded FRESH_SEED + seed: the same on every call for a seed,
  another for another seed, and not the agent's own initial weights; the global generators are
  left as they were (the agent's training draws what it would have drawn);
- the batched trainer's weights after ``in_batched(shrink_perturb)`` are the SB3 engine's
  perturbation of the same models, to the bit, and its optimiser state is untouched; the same for
  cloning;
- the oracle's demonstrations replay its episodes to its reward on the changed line (on another
  line they are refused); cloning is the same for a seed, leaves the global generators alone,
  lowers its loss and makes the policy pick the oracle's action more often than a fresh one does;
- a transfer, scratch or perturbed cell without its evaluations on the line before the change is
  outdated (trained again), naming them; one with them, and a baselines cell with random, is not.

Native lines in this process for the batched trainer: no node, no DDS, no training.
"""

from __future__ import annotations

import random

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("sb3_contrib")
pytest.importorskip("jax")

from sorting_line_gym.envs.evolving import schedule_file  # noqa: E402
from sorting_line_gym.studies import transfer_cells as tc  # noqa: E402
from sorting_line_gym.studies import transfer_warm as warm  # noqa: E402
from sorting_line_gym.training.batched.models import new_models  # noqa: E402
from sorting_line_gym.training.batched.on_policy import OnPolicyTrainer  # noqa: E402

pytestmark = pytest.mark.usefixtures("one_torch_thread")

PARAMS = {"ppo": tc.hyperparameters("ppo"), "a2c": tc.hyperparameters("a2c")}
ENGINE_ALGO = {"ppo": "maskable_ppo", "a2c": "a2c"}
UPGRADE = str(schedule_file("upgrade"))


def models(algo: str, seeds: list[int]) -> list:
    """SB3's models of the study (MaskablePPO or A2C on the evolving line's spaces), as the batched
    trainer builds them."""
    trainer = OnPolicyTrainer(ENGINE_ALGO[algo], seeds, setup="B", variant="advanced", params=PARAMS[algo],
                              episode_steps=50, evolution=UPGRADE)  # fmt: skip
    trainer.close()
    return trainer.models


def weights(module) -> dict[str, torch.Tensor]:
    return {n: p.detach().clone() for n, p in module.named_parameters()}


@pytest.mark.parametrize("algo", ["ppo", "a2c"])
def test_shrink_and_perturb_is_the_papers_mix_of_the_weights_and_a_fresh_initialisation(algo):
    assert (warm.SHRINK, warm.PERTURB) == (0.4, 0.1)
    model = models(algo, [7])[0]
    theta = weights(model.policy)
    states = torch.get_rng_state(), np.random.get_state()[1].copy(), random.getstate()
    fresh = weights(warm.fresh_policy(model, warm.FRESH_SEED + 7))
    warm.shrink_perturb(model, 7)
    # The global generators are where they were: the agent's own draws go on unchanged.
    assert torch.equal(torch.get_rng_state(), states[0]) and random.getstate() == states[2]
    assert np.array_equal(np.random.get_state()[1], states[1])
    after = weights(model.policy)
    assert after.keys() == theta.keys() == fresh.keys()
    for name in theta:
        expected = theta[name].double() * warm.SHRINK + warm.PERTURB * fresh[name].double()
        assert torch.allclose(after[name].double(), expected, rtol=1e-6, atol=1e-7), name  # float32 rounding
    # The fresh initialisation: the same for a seed, another for another seed, not the agent's own init.
    again = weights(warm.fresh_policy(model, warm.FRESH_SEED + 7))
    other = weights(warm.fresh_policy(model, warm.FRESH_SEED + 8))
    own = weights(models(algo, [7])[0].policy)
    name = next(n for n in theta if n.endswith("weight"))
    assert torch.equal(again[name], fresh[name]) and not torch.equal(other[name], fresh[name])
    assert not torch.equal(own[name], fresh[name]) and torch.equal(own[name], theta[name])
    # Each layer's noise has its own initialisation's scale: a fresh policy, not one Gaussian.
    assert fresh["action_net.weight"].std() < 0.1 * fresh["mlp_extractor.policy_net.0.weight"].std()


@pytest.mark.parametrize("algo", ["ppo", "a2c"])
def test_the_batched_engine_perturbs_as_sb3_does(algo):
    seeds = [3, 5]
    trainer = OnPolicyTrainer(ENGINE_ALGO[algo], seeds, setup="B", variant="advanced", params=PARAMS[algo],
                              episode_steps=50, evolution=UPGRADE)  # fmt: skip
    try:
        opt_state = trainer.opt_state
        warm.in_batched(trainer, warm.shrink_perturb)
        stacked = [a for a, _ in trainer.weights()]
        assert trainer.opt_state is opt_state
    finally:
        trainer.close()
    reference = new_models(ENGINE_ALGO[algo], seeds, PARAMS[algo], (trainer.lines.observation_space,
                           trainer.lines.action_space), 1)  # fmt: skip
    for s, seed in enumerate(seeds):
        warm.shrink_perturb(reference[s].model, seed)
        expected = [p.detach().numpy() for p in reference[s].model.policy.parameters()]
        mine = [a[s] for a in stacked]
        assert sorted(e.shape for e in expected) == sorted(m.shape for m in mine)
        for m in mine:  # the trees' order need not be named_parameters': match each by its values
            assert any(e.shape == m.shape and np.array_equal(e, m) for e in expected), (seed, m.shape)


def test_a_trained_cell_without_its_evaluations_before_the_change_is_trained_again():
    for kind, keys in tc.BEFORE_EVALUATIONS.items():
        cell = {"cell": {"scenario": "upgrade", "kind": kind, "algo": "ppo", "seed": 1}}
        why = tc.outdated(cell)
        assert why is not None and f"a {kind} cell without evaluations on the line before the change" in why
        assert all(k in why for k in keys) and "trained again" in why
        assert tc.outdated({**cell, **{k: [1.0] for k in keys}}) is None
        if len(keys) > 1:  # one of two is not enough
            assert keys[1] in (tc.outdated({**cell, keys[0]: [1.0]}) or "")
    baselines = {"cell": {"kind": "baselines"}, "before": {"random": []}, "after": {"random": []}}
    assert tc.outdated(baselines) is None


def test_the_oracles_demonstrations_replay_its_episodes_on_the_changed_line(tmp_path):
    obs, actions = tc.oracle_demonstrations("upgrade", tc.schedules("upgrade", 10, tmp_path)[1])
    assert obs.shape == (warm.CLONE_EPISODES * 50, 2) and actions.shape == (warm.CLONE_EPISODES * 50,)
    assert actions.min() >= 0 and actions.max() < 30 and len(set(actions % 3)) > 1  # it uses the sort modes
    # Replayed on the line before the upgrade (no sort modes), the episodes are not the oracle's.
    env = tc.make_env(tc.before_path("upgrade", tmp_path), "native")
    try:
        with pytest.raises(ValueError, match="the line it was replayed on is another"):
            warm.oracle_demonstrations(tc.fixed_line(tc.line_states("upgrade")[1]), env, episodes=2)
    finally:
        env.close()


def agreement(model, demos) -> float:
    obs, actions = demos
    with torch.no_grad():
        picked = model.policy.get_distribution(torch.as_tensor(obs)).get_actions(deterministic=True)
    return float((picked.numpy() == actions).mean())


@pytest.mark.parametrize("algo", ["ppo", "a2c"])
def test_cloning_the_oracle_is_deterministic_per_seed_and_fits_its_actions(algo, tmp_path):
    demos = tc.oracle_demonstrations("upgrade", tc.schedules("upgrade", 10, tmp_path)[1])
    first, again, fresh = models(algo, [7]) + models(algo, [7]) + models(algo, [7])
    states = torch.get_rng_state(), random.getstate()
    losses = warm.clone_oracle(first, 7, demos)
    assert torch.equal(torch.get_rng_state(), states[0]) and random.getstate() == states[1]
    assert warm.clone_oracle(again, 7, demos) == losses and len(losses) == warm.CLONE_EPOCHS
    for name, theta in weights(first.policy).items():
        assert torch.equal(theta, weights(again.policy)[name]), name
    assert losses[-1] < losses[0]
    assert agreement(first, demos) > agreement(fresh, demos) + 0.2


def test_the_batched_engine_clones_as_sb3_does(tmp_path):
    demos = tc.oracle_demonstrations("upgrade", tc.schedules("upgrade", 10, tmp_path)[1])
    seeds = [3, 5]
    trainer = OnPolicyTrainer("a2c", seeds, setup="B", variant="advanced", params=PARAMS["a2c"], episode_steps=50,
                              evolution=UPGRADE)  # fmt: skip
    try:
        losses = warm.in_batched(trainer, lambda m, seed: warm.clone_oracle(m, seed, demos))
        stacked = [a for a, _ in trainer.weights()]
    finally:
        trainer.close()
    reference = new_models("a2c", seeds, PARAMS["a2c"], (trainer.lines.observation_space,
                           trainer.lines.action_space), 1)  # fmt: skip
    for s, seed in enumerate(seeds):
        assert warm.clone_oracle(reference[s].model, seed, demos) == losses[s]
        expected = [p.detach().numpy() for p in reference[s].model.policy.parameters()]
        for m in (a[s] for a in stacked):
            assert any(e.shape == m.shape and np.array_equal(e, m) for e in expected), (seed, m.shape)
