"""S SB3 torch networks as stacked JAX arrays, and the per-seed forward pass of one of them: the
base of the batched learners' JAX arithmetic (``optim`` steps these arrays, the losses call
:func:`forward` on one seed's slice under ``jax.vmap``).

Interface (stable; the on-policy learners and DQN both build on it):

- A **tree** is a dict of named networks, each a list of layers ``{"w": (out, in), "b": (out,)}``,
  one per ``nn.Linear`` in the network's order: :func:`torch_tree` gives it for one seed's torch
  modules (holding the live ``nn.Parameter``s), :func:`stack` turns S such trees into one tree of
  float32 JAX arrays with a leading seed axis, **in the engine's layout**: ``w`` (S, in, out), slice
  ``[s]`` seed s's weight transposed (W.T, what ``x @ W.T`` reads), ``b`` (S, out). The same
  functions move optimizer moments (trees of the same structure, elementwise, so the layout does
  not change their values) in and out; :func:`torch_layout` gives a stacked tree's arrays back in
  torch's layout and :func:`write_back` copies them into the S torch trees in place (the SB3
  models then hold the weights). Why W.T: XLA's CPU backend sums ``x @ W.T`` as torch does (see
  :func:`forward`) only on a contiguous W.T, and a transposed copy of W per use cost as much as
  the matmul itself (docs/results/performance.md).
- A **spec** is a network's shape of computation, hashable (a static argument of ``jax.jit``): one
  entry per module of the ``nn.Sequential`` (or the single ``nn.Linear`` head), ``("linear",)`` or
  an elementwise activation with its settings, e.g. ``("tanh",)``, ``("leaky_relu", 0.01)``.
  :func:`spec_of` reads it from a torch module and refuses, naming it, a module it cannot mirror;
  :func:`specs_of` does so for a dict of networks and checks that all seeds share it.
- :func:`forward(spec, layers, x) <forward>`: one seed's network on ``x`` (..., in) -> (..., out),
  torch's ``F.linear`` (x @ W.T + b, W.T as stored) and the activations' own formulas, to be vmapped
  over seeds.

Why JAX: the networks are tiny (64 units), so eager torch spends its time in per-op overhead;
``jit`` fuses a whole update into one XLA computation and ``vmap`` batches the seeds in it, each
seed computed from its own slice only (no reduction crosses the seed axis), so a seed's result is
its own network's. Float32 throughout, as SB3's; ``tanh`` is torch's rounding of it
(``torch_math``: XLA's own float32 tanh is up to 4.5 ulp off, enough to move an update past 1e-5
of SB3's).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import torch
from torch import nn

from . import torch_math

#: One module of a network: ("linear",) or an activation's name and settings.
Op = tuple[Any, ...]
Spec = tuple[Op, ...]
#: Named networks, each a list of {"w", "b"} layers (torch parameters, numpy or JAX arrays).
Tree = dict[str, list[dict[str, Any]]]


def _activation(module: nn.Module) -> Op | None:
    """The spec entry of an elementwise activation (its settings that change the result), else None."""
    if isinstance(module, nn.Tanh):
        return ("tanh",)
    if isinstance(module, nn.ReLU):
        return ("relu",)
    if isinstance(module, nn.LeakyReLU):
        return ("leaky_relu", float(module.negative_slope))
    if isinstance(module, nn.ELU):
        return ("elu", float(module.alpha))
    if isinstance(module, nn.SiLU):
        return ("silu",)
    if isinstance(module, nn.GELU):
        return ("gelu", module.approximate)
    if isinstance(module, nn.Sigmoid):
        return ("sigmoid",)
    if isinstance(module, nn.Identity):
        return ("identity",)
    return None


ALLOWED = "Linear (with bias), Tanh, ReLU, LeakyReLU, ELU, SiLU, GELU, Sigmoid, Identity"


def spec_of(module: nn.Module) -> Spec:
    """The spec of an ``nn.Sequential`` of Linear layers and activations, or of one ``nn.Linear``."""
    modules = list(module) if isinstance(module, nn.Sequential) else [module]
    ops: list[Op] = []
    for i, m in enumerate(modules):
        if isinstance(m, nn.Linear):
            if m.bias is None:
                raise ValueError(f"layer {i}: a Linear layer without a bias is not supported (SB3's MLPs have biases)")
            ops.append(("linear",))
            continue
        op = _activation(m)
        if op is None:
            raise ValueError(f"layer {i} is a {type(m).__name__}: the batched trainer mirrors {ALLOWED}")
        ops.append(op)
    return tuple(ops)


def specs_of(per_seed: Sequence[Mapping[str, nn.Module]]) -> dict[str, Spec]:
    """Each named network's spec, which every seed must share (one computation serves all)."""
    if not per_seed:
        raise ValueError("no networks to stack (one set per seed is needed)")
    specs = {name: spec_of(m) for name, m in per_seed[0].items()}
    for s, nets in enumerate(per_seed[1:], start=1):
        theirs = {name: spec_of(m) for name, m in nets.items()}
        if theirs != specs:
            raise ValueError(f"seed {s}'s networks {theirs} differ from seed 0's {specs}: allowed one architecture")
    return specs


def torch_tree(nets: Mapping[str, nn.Module]) -> Tree:
    """One seed's networks as a tree of their live parameters (:func:`spec_of` checks them)."""
    tree: Tree = {}
    for name, net in nets.items():
        spec_of(net)
        modules = list(net) if isinstance(net, nn.Sequential) else [net]
        tree[name] = [{"w": m.weight, "b": m.bias} for m in modules if isinstance(m, nn.Linear)]
    return tree


def _to_numpy(t: Any) -> np.ndarray:
    return t.detach().cpu().numpy() if torch.is_tensor(t) else np.asarray(t)


def _is_weight(path: tuple[Any, ...]) -> bool:
    """Whether a leaf of a tree is a Linear layer's weight (its key ``"w"``)."""
    return bool(path) and getattr(path[-1], "key", None) == "w"


def stack(trees: Sequence[Any]) -> Any:
    """S trees of torch tensors (or arrays) of one structure -> one tree of float32 JAX arrays with
    a leading seed axis, weights in the engine's layout (slice s = trees[s], ``w`` transposed);
    shapes are checked to agree."""
    if not trees:
        raise ValueError("no trees to stack (one per seed is needed)")
    leaves = [jax.tree_util.tree_flatten_with_path(t, is_leaf=torch.is_tensor) for t in trees]
    structure = jax.tree_util.tree_structure(trees[0], is_leaf=torch.is_tensor)
    for s, t in enumerate(trees[1:], start=1):
        theirs = jax.tree_util.tree_structure(t, is_leaf=torch.is_tensor)
        if theirs != structure:
            raise ValueError(f"seed {s}'s networks differ in structure from seed 0's: {theirs} vs {structure}")
    stacked = []
    for k, (path, _) in enumerate(leaves[0][0]):
        arrays = [_to_numpy(ls[0][k][1]) for ls in leaves]
        if any(a.shape != arrays[0].shape for a in arrays):
            raise ValueError(f"the networks to stack differ in shape: {[a.shape for a in arrays]}")
        array = np.stack(arrays).astype(np.float32)
        stacked.append(jnp.asarray(np.ascontiguousarray(array.transpose(0, 2, 1)) if _is_weight(path) else array))
    return jax.tree_util.tree_unflatten(structure, stacked)


def torch_layout(stacked: Any) -> list[np.ndarray]:
    """The leaves of a stacked tree as numpy arrays in torch's layout (``w`` (S, out, in)), in the
    tree's leaf order: what :func:`write_back` and the optimizer's state copy into torch."""
    leaves = jax.tree_util.tree_flatten_with_path(stacked)[0]
    return [np.asarray(a).transpose(0, 2, 1) if _is_weight(path) else np.asarray(a) for path, a in leaves]


@torch.no_grad()
def write_back(stacked: Any, trees: Sequence[Any]) -> None:
    """Copies slice s of every array of ``stacked`` into ``trees[s]``'s torch tensor, in place."""
    arrays = torch_layout(stacked)  # one device copy per array
    for s, tree in enumerate(trees):
        targets = jax.tree_util.tree_leaves(tree, is_leaf=torch.is_tensor)
        if len(targets) != len(arrays):
            raise ValueError(f"seed {s}: {len(targets)} tensors to write, {len(arrays)} stacked arrays")
        for array, target in zip(arrays, targets, strict=True):
            part = array[s]
            if tuple(part.shape) != tuple(target.shape):
                raise ValueError(
                    f"seed {s}: a stacked slice of shape {part.shape} for a tensor of {tuple(target.shape)}"
                )
            target.copy_(torch.from_numpy(np.array(part)))  # a writable copy


def activate(op: Op, x: jax.Array) -> jax.Array:
    """An activation as torch computes it (torch/nn/modules/activation.py)."""
    kind = op[0]
    if kind == "tanh":
        return torch_math.tanh(x)
    if kind == "relu":
        return jax.nn.relu(x)
    if kind == "leaky_relu":
        return jnp.where(x > 0, x, x * op[1])
    if kind == "elu":
        return jnp.where(x > 0, x, op[1] * jnp.expm1(x))
    if kind == "silu":
        return jax.nn.silu(x)
    if kind == "gelu":
        return jax.nn.gelu(x, approximate=op[1] == "tanh")
    if kind == "sigmoid":
        return jax.nn.sigmoid(x)
    if kind == "identity":
        return x
    raise ValueError(f"activation {kind!r} is not mirrored: allowed {ALLOWED}")


def forward(spec: Spec, layers: Sequence[Mapping[str, jax.Array]], x: jax.Array) -> jax.Array:
    """One seed's network: x (..., in) -> (..., out). An empty spec (SB3's ``net_arch=[]``) is the identity."""
    k = 0
    for op in spec:
        if op[0] == "linear":
            # F.linear(x, W, b) = x @ W.T + b (torch/nn/modules/linear.py), W.T stored as it is read
            # (the module docstring). On a contiguous W.T, XLA's CPU kernel sums as torch does for
            # these shapes (sequential over the inputs, fused multiply-adds); with W.T folded into
            # the dot, for an output width that is no multiple of its vector width (DQN's 30
            # actions) it sums in another order, and Adam makes those last bits grow over a
            # training; a seed's result also no longer depends on which seeds share its batch.
            x = x @ layers[k]["w"] + layers[k]["b"]
            k += 1
        else:
            x = activate(op, x)
    return x
