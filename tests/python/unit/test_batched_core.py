"""The batched trainer's JAX core (training/batched/params.py, optim.py) against the per-seed torch
modules and optimizers it mirrors: the stacked forward pass, torch's clip_grad_norm_ and two
optimizer steps (SB3's Adam eps 1e-5, A2C's RMSprop alpha 0.99 eps 1e-5) give every seed what its
own torch network and optimizer give, and the optimizer state moves to and from torch's by slice.
No node, no DDS; a few seconds (most of it JAX's compilation).
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
jax = pytest.importorskip("jax")
from torch import nn  # noqa: E402

from sorting_line_gym.training.batched import optim, params  # noqa: E402

S = 4
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def nets(seed: int) -> dict[str, nn.Module]:
    torch.manual_seed(seed)
    body = nn.Sequential(nn.Linear(3, 8), nn.Tanh(), nn.Linear(8, 8), nn.ReLU(), nn.Linear(8, 6), nn.LeakyReLU(0.1))
    return {"body": body, "head": nn.Linear(6, 5)}


def torch_forward(n: dict[str, nn.Module], x: torch.Tensor) -> torch.Tensor:
    return n["head"](n["body"](x))


def test_stacked_forward_and_write_back_equal_the_seeds_networks():
    per_seed = [nets(s) for s in range(S)]
    specs = params.specs_of(per_seed)
    trees = [params.torch_tree(n) for n in per_seed]
    stacked = params.stack(trees)
    # the engine's layout: each weight stored transposed, (S, in, out)
    assert stacked["body"][0]["w"].shape == (S, 3, 8) and stacked["head"][0]["b"].shape == (S, 5)
    np.testing.assert_array_equal(np.asarray(stacked["body"][0]["w"][1]), per_seed[1]["body"][0].weight.detach().T)

    def forward(p, x):
        return params.forward(specs["head"], p["head"], params.forward(specs["body"], p["body"], x))

    x = np.random.default_rng(0).normal(size=(S, 7, 3)).astype(np.float32)
    out = np.asarray(jax.jit(jax.vmap(forward))(stacked, x))
    for s in range(S):
        with torch.no_grad():
            np.testing.assert_allclose(out[s], torch_forward(per_seed[s], torch.from_numpy(x[s])), rtol=1e-6, atol=1e-6)
    moved = jax.tree_util.tree_map(lambda a: a + 1.0, stacked)
    params.write_back(moved, trees)
    for s in range(S):
        np.testing.assert_array_equal(
            per_seed[s]["body"][2].weight.detach().numpy(), np.asarray(moved["body"][1]["w"][s]).T
        )


def test_what_cannot_be_mirrored_is_refused():
    with pytest.raises(ValueError, match="layer 1 is a Dropout"):
        params.spec_of(nn.Sequential(nn.Linear(2, 2), nn.Dropout()))
    with pytest.raises(ValueError, match="differ in shape"):
        params.stack([params.torch_tree({"a": nn.Linear(2, 2)}), params.torch_tree({"a": nn.Linear(2, 3)})])
    with pytest.raises(ValueError, match="optimizer LBFGS is not supported"):
        optim.settings_of(torch.optim.LBFGS(nn.Linear(2, 2).parameters()))
    with pytest.raises(ValueError, match=r"RMSprop\(centered=True\) is not supported"):
        optim.settings_of(torch.optim.RMSprop(nn.Linear(2, 2).parameters(), centered=True))


@pytest.mark.parametrize("kind", ["adam", "rmsprop"])
def test_clipped_steps_equal_each_seeds_torch_optimizer(kind):
    """Loss, backward, SB3's clip_grad_norm_ (0.5), the optimizer step, three times with a learning
    rate per seed: every seed's weights and optimizer state equal its own torch's; the state moves
    out to fresh torch optimizers and back by slice."""
    make = {
        "adam": lambda ps, lr: torch.optim.Adam(ps, lr=lr, eps=1e-5),
        "rmsprop": lambda ps, lr: torch.optim.RMSprop(ps, lr=lr, alpha=0.99, eps=1e-5, weight_decay=0),
    }[kind]
    rates = [7e-4, 1e-3, 3e-4, 5e-3]
    per_seed = [nets(s) for s in range(S)]
    opts = [make([p for m in n.values() for p in m.parameters()], lr) for n, lr in zip(per_seed, rates, strict=True)]
    specs, trees = params.specs_of(per_seed), [params.torch_tree(n) for n in per_seed]
    settings = optim.settings_of(opts[0])
    p = params.stack(trees)
    state, count = optim.state_from_torch(settings, opts, trees)
    assert count == 0 and float(np.abs(np.asarray(state[optim.STATE_KEYS[kind][0]]["head"][0]["w"])).max()) == 0

    def loss(q, x, y):
        out = params.forward(specs["head"], q["head"], params.forward(specs["body"], q["body"], x))
        return ((out - y) ** 2).mean()

    def update(q, st, x, y, coef):
        grads, norm = optim.clip_grad_norm(jax.grad(loss)(q, x, y), 0.5)
        q, st = optim.step(settings, q, grads, st, coef)
        return q, st, norm

    jitted = jax.jit(jax.vmap(update))
    rng = np.random.default_rng(1)
    coef = optim.coefficients(settings, rates, count, 3, S)
    for k in range(3):
        x, y = rng.normal(size=(S, 16, 3)).astype(np.float32), (rng.normal(size=(S, 16, 5)) * 10).astype(np.float32)
        for s in range(S):
            opts[s].zero_grad()
            ((torch_forward(per_seed[s], torch.from_numpy(x[s])) - torch.from_numpy(y[s])) ** 2).mean().backward()
            torch.nn.utils.clip_grad_norm_(opts[s].param_groups[0]["params"], 0.5)
            opts[s].step()
        p, state, norms = jitted(p, state, x, y, {key: c[:, k] for key, c in coef.items()})
        assert (np.asarray(norms) > 0.5).all()  # the clip acts
    for s in range(S):
        theirs_all = jax.tree_util.tree_leaves(trees[s], is_leaf=torch.is_tensor)
        for mine, theirs in zip(params.torch_layout(p), theirs_all, strict=True):
            np.testing.assert_allclose(np.asarray(mine[s]), theirs.detach().numpy(), rtol=1e-5, atol=1e-6)
    copies = [nets(10 + s) for s in range(S)]
    copy_trees = [params.torch_tree(n) for n in copies]
    copy_opts = [make([q for m in n.values() for q in m.parameters()], 0.1) for n in copies]
    optim.state_to_torch(settings, state, 3, rates, copy_opts, copy_trees)
    for s in range(S):
        assert copy_opts[s].param_groups[0]["lr"] == rates[s]
        ours = jax.tree_util.tree_leaves(copy_trees[s], is_leaf=torch.is_tensor)
        theirs = jax.tree_util.tree_leaves(trees[s], is_leaf=torch.is_tensor)
        for q, r in zip(ours, theirs, strict=True):
            got, ref = copy_opts[s].state[q], opts[s].state[r]
            assert list(got) == list(ref) and float(got["step"]) == float(ref["step"]) == 3
            for key in optim.STATE_KEYS[kind]:
                torch.testing.assert_close(got[key], ref[key], rtol=1e-5, atol=1e-7)
    back, count = optim.state_from_torch(settings, opts, trees)
    assert count == 3
    for a, b in zip(jax.tree_util.tree_leaves(back), jax.tree_util.tree_leaves(state), strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-7)
