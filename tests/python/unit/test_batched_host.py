"""The rollout's forward pass on the host (training/batched/host.py) against the jitted one it
replaces and the torch networks both mirror: the same actions, values and log-probabilities (to
float32 rounding) for every seed, with and without MaskablePPO's masks, and DQN's greedy actions;
a network with a layer the host does not evaluate is left to the jitted path. No node, no DDS.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
jax = pytest.importorskip("jax")
from torch import nn  # noqa: E402

from sorting_line_gym.training.batched import host, params  # noqa: E402
from sorting_line_gym.training.batched.actor_critic import JittedPolicy, compiled  # noqa: E402

S, L, OBS, A = 3, 4, 8, 30
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def policy_nets(seed: int) -> dict[str, nn.Module]:
    """An MlpPolicy's networks as SB3 builds them for PPO and A2C (tanh, 64 x 64)."""
    torch.manual_seed(seed)

    def tower() -> nn.Sequential:
        return nn.Sequential(nn.Linear(OBS, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh())

    heads = {"action_net": nn.Linear(64, A), "value_net": nn.Linear(64, 1)}
    return {"policy_net": tower(), "value_latent": tower(), **heads}


def stacked_policies():
    per_seed = [policy_nets(s) for s in range(S)]
    return per_seed, params.specs_of(per_seed), params.stack([params.torch_tree(n) for n in per_seed])


def inputs(masked: bool):
    rng = np.random.default_rng(7)
    obs = rng.uniform(0, 3, size=(S, L, OBS)).astype(np.float32)
    q = rng.exponential(size=(S, L, A)).astype(np.float32)
    masks = rng.random((S, L, A)) < 0.6 if masked else None
    if masks is not None:
        masks[..., 0] = True  # at least one action allowed, as on the line
    return obs, q, masks


@pytest.mark.parametrize("masked", [False, True], ids=["unmasked", "masked"])
def test_the_host_policy_acts_as_the_jitted_one(masked):
    per_seed, specs, stacked = stacked_policies()
    assert host.supported(*specs.values())
    obs, q, masks = inputs(masked)
    on_host = host.HostPolicy(specs, stacked)
    jitted = JittedPolicy(compiled(tuple(sorted(specs.items()))), stacked)
    actions, values, log_probs = on_host.act(obs, q, masks)
    j_actions, j_values, j_log_probs = jitted.act(obs, q, masks)
    np.testing.assert_array_equal(actions, j_actions)
    np.testing.assert_allclose(values, j_values, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(log_probs, j_log_probs, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(on_host.values(obs), jitted.values(obs), rtol=1e-6, atol=1e-6)
    assert actions.shape == values.shape == log_probs.shape == (S, L)
    # and what each seed's own torch networks give (SB3's forward_critic, value_net; the logits)
    for s in range(S):
        with torch.no_grad():
            x = torch.from_numpy(obs[s])
            value = per_seed[s]["value_net"](per_seed[s]["value_latent"](x))[:, 0].numpy()
            raw = per_seed[s]["action_net"](per_seed[s]["policy_net"](x))
            if masks is not None:
                raw = torch.where(torch.from_numpy(masks[s]), raw, torch.tensor(-1e8))
            log_prob = torch.distributions.Categorical(logits=raw).log_prob(torch.from_numpy(actions[s])).numpy()
        np.testing.assert_allclose(values[s], value, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(log_probs[s], log_prob, rtol=1e-5, atol=1e-5)
        if masks is not None:
            assert masks[s][np.arange(L), actions[s]].all()


def test_the_host_q_network_is_greedy_as_the_torch_one():
    torch.manual_seed(3)
    per_seed = [
        {"q_net": nn.Sequential(nn.Linear(OBS, 64), nn.ReLU(), nn.Linear(64, 64), nn.ReLU(), nn.Linear(64, A))}
        for _ in range(S)
    ]
    spec = params.specs_of(per_seed)["q_net"]
    stacked = params.stack([params.torch_tree(n) for n in per_seed])
    obs, _, _ = inputs(False)
    greedy = host.HostQNetwork(spec, stacked["q_net"]).greedy(obs)
    for s in range(S):
        with torch.no_grad():
            expected = per_seed[s]["q_net"](torch.from_numpy(obs[s])).argmax(dim=1).numpy()
        np.testing.assert_array_equal(greedy[s], expected)


def test_a_layer_the_host_does_not_evaluate_is_left_to_the_jitted_path():
    spec = params.spec_of(nn.Sequential(nn.Linear(2, 2), nn.ELU()))
    assert not host.supported(spec)
    with pytest.raises(ValueError, match="'elu' is not evaluated on the host: allowed linear, tanh, relu, identity"):
        host.forward(spec, [(np.ones((1, 2, 2), np.float32), np.zeros((1, 1, 2), np.float32))], np.ones((1, 1, 2)))
