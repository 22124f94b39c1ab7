"""The batched trainer's stacked networks (training/batched/stacked.py) against the per-seed torch
modules they stack: forward pass, gradients, the per-seed gradient-norm clip and one optimizer
step equal what S separate SB3-built networks and optimizers give. No node, no DDS; about a second.
"""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")
from torch import nn  # noqa: E402

from sorting_line_gym.training.batched import stacked  # noqa: E402

S = 4


def mlp(seed: int) -> nn.Sequential:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Linear(3, 8), nn.Tanh(), nn.Linear(8, 8), nn.ReLU(), nn.Linear(8, 5))


def test_forward_and_write_back_equal_the_seeds_networks():
    nets = [mlp(s) for s in range(S)]
    net = stacked.StackedSequential(nets)
    x = torch.randn(S, 7, 3)
    out = net(x)
    for s in range(S):
        torch.testing.assert_close(out[s], nets[s](x[s]), rtol=1e-6, atol=1e-6)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(1.0)
    net.write_to(nets)
    for s in range(S):
        torch.testing.assert_close(net(x)[s], nets[s](x[s]), rtol=1e-6, atol=1e-6)
    fresh = [mlp(10 + s) for s in range(S)]
    net.load_from(fresh)
    torch.testing.assert_close(net(x)[2], fresh[2](x[2]), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("optimizer", ["adam", "rmsprop"])
def test_a_clipped_step_equals_each_seeds_own(optimizer):
    """Loss, backward, SB3's clip_grad_norm_ (0.5) and the optimizer step (SB3's Adam eps 1e-5, A2C's
    RMSprop alpha 0.99 eps 1e-5), twice: every seed's weights and optimizer state equal its own."""
    nets = [mlp(s) for s in range(S)]
    make = {
        "adam": lambda ps: torch.optim.Adam(ps, lr=7e-4, eps=1e-5),
        "rmsprop": lambda ps: torch.optim.RMSprop(ps, lr=7e-4, alpha=0.99, eps=1e-5, weight_decay=0),
    }[optimizer]
    opts = [make(n.parameters()) for n in nets]
    net = stacked.StackedSequential(nets)
    opt = stacked.stacked_optimizer(opts[0], net.parameters())
    x, target = torch.randn(S, 16, 3), torch.randn(S, 16, 5) * 10  # large: the clip acts
    for _ in range(2):
        for s in range(S):
            opts[s].zero_grad()
            ((nets[s](x[s]) - target[s]) ** 2).mean().backward()
            torch.nn.utils.clip_grad_norm_(nets[s].parameters(), 0.5)
            opts[s].step()
        opt.zero_grad()
        ((net(x) - target) ** 2).mean(dim=(1, 2)).sum().backward()
        norms = stacked.clip_grad_norm_per_seed(net.parameters(), 0.5)
        assert (norms > 0.5).all()
        opt.step()
    pairs = stacked.parameter_pairs(net, nets)
    for p, per_seed in pairs:
        for s, q in enumerate(per_seed):
            torch.testing.assert_close(p[s], q, rtol=1e-5, atol=1e-6)
    copies = [make(mlp(s).parameters()) for s in range(S)]
    copy_pairs = [(p, [list(c.param_groups[0]["params"])[k] for c in copies]) for k, (p, _) in enumerate(pairs)]
    stacked.optimizer_state_to_seeds(opt, copy_pairs, copies)
    for (_, mine), (_, theirs) in zip(pairs, copy_pairs, strict=True):
        for s in range(S):
            ref, got = opts[s].state[mine[s]], copies[s].state[theirs[s]]
            assert sorted(ref) == sorted(got)
            for key in ref:
                torch.testing.assert_close(torch.as_tensor(got[key]), torch.as_tensor(ref[key]), rtol=1e-5, atol=1e-7)
    again = stacked.stacked_optimizer(opts[0], net.parameters())
    stacked.optimizer_state_from_seeds(again, pairs, opts)
    for p, _ in pairs:
        for key, value in again.state[p].items():
            torch.testing.assert_close(torch.as_tensor(value), torch.as_tensor(opt.state[p][key]), rtol=1e-5, atol=1e-7)


def test_what_cannot_be_stacked_is_refused():
    with pytest.raises(ValueError, match="layer 1 is a Dropout"):
        stacked.StackedSequential([nn.Sequential(nn.Linear(2, 2), nn.Dropout())])
    with pytest.raises(ValueError, match="differ in shape"):
        stacked.StackedSequential([nn.Sequential(nn.Linear(2, 2)), nn.Sequential(nn.Linear(2, 3))])
    with pytest.raises(ValueError, match="LBFGS is not supported"):
        stacked.stacked_optimizer(torch.optim.LBFGS(mlp(0).parameters()), mlp(1).parameters())
