"""Torch's Adam and RMSprop, and torch's ``clip_grad_norm_``, as pure JAX functions of one seed's
parameters (to be vmapped over seeds with ``params``' stacked trees), with the optimizer state
moved from and to S torch optimizers: a saved SB3 model continues training in SB3 as if SB3 had
trained it, and an SB3 model continues here.

Interface (stable; the on-policy learners and DQN both build on it):

- :func:`settings_of(optimizer) <settings_of>` -> :class:`Settings` (kind ``"adam"`` or
  ``"rmsprop"``, lr, eps, betas / alpha, weight_decay): the torch optimizer's own settings (SB3's
  Adam eps 1e-5; A2C's RMSprop alpha 0.99 eps 1e-5); anything else is refused, naming it.
- :func:`init(settings, params) <init>` -> state: a dict of moment trees keyed by torch's state
  names (Adam ``exp_avg``, ``exp_avg_sq``; RMSprop ``square_avg``), zeros shaped as ``params``.
- :func:`coefficients(settings, lr, first_step, n, n_seeds) <coefficients>` -> dict of float32
  arrays (n_seeds, n): the per-step scalars of steps ``first_step + 1 .. first_step + n`` (torch
  counts a step before it takes it), computed as torch computes them, in Python floats (float64),
  before they meet the float32 tensors. ``lr`` is one float shared by all seeds or one per seed.
  Vmap over seeds, then ``lax.scan`` over the n steps.
- :func:`step(settings, params, grads, state, coef) <step>` -> (params, state): one seed's step,
  ``coef`` that seed's scalars of that step (one column of :func:`coefficients`).
- :func:`clip_grad_norm(grads, max_norm) <clip_grad_norm>` -> (grads, total norm): torch's
  ``clip_grad_norm_`` on one seed's gradients (SB3 clips after every backward).
- :func:`state_from_torch(settings, optimizers, trees) <state_from_torch>` -> (stacked state, step
  count) and :func:`state_to_torch(settings, state, step, lr, optimizers, trees) <state_to_torch>`:
  the moments by slice (``trees[s]`` is seed s's ``params.torch_tree``) and the step count, which
  all seeds share (they step in lock-step); a never-stepped optimizer has no state, as torch's.

Exact per seed: the formulas are torch/optim/adam.py's ``_single_tensor_adam`` and rmsprop.py's
``_single_tensor_rmsprop`` (what torch runs on CPU), op for op in their order, so that a seed's
weights equal its own torch optimizer's to float32 rounding.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import torch

from .params import stack, torch_layout

#: torch's state entries besides ``step``, per optimizer kind (the order torch creates them in).
STATE_KEYS = {"adam": ("exp_avg", "exp_avg_sq"), "rmsprop": ("square_avg",)}


@dataclass(frozen=True)
class Settings:
    """One optimizer's settings (its torch ``defaults`` and the param group's lr)."""

    kind: str
    lr: float
    eps: float
    weight_decay: float = 0.0
    beta1: float = 0.9
    beta2: float = 0.999
    alpha: float = 0.99


def settings_of(optimizer: torch.optim.Optimizer) -> Settings:
    """The settings of a torch Adam or RMSprop, refusing (naming it) any option not mirrored here."""
    kind = {torch.optim.Adam: "adam", torch.optim.RMSprop: "rmsprop"}.get(type(optimizer))  # type: ignore[call-overload]
    if kind is None:
        raise ValueError(
            f"optimizer {type(optimizer).__name__} is not supported by the batched trainer: allowed Adam, RMSprop "
            "(torch's, as SB3 builds them)"
        )
    if len(optimizer.param_groups) != 1:
        raise ValueError(
            f"an optimizer with {len(optimizer.param_groups)} parameter groups is not supported: allowed 1"
        )
    group = optimizer.param_groups[0]
    unsupported = {
        "amsgrad": False,
        "maximize": False,
        "decoupled_weight_decay": False,
        "momentum": 0,
        "centered": False,
    }
    for key, allowed in unsupported.items():
        if key in group and group[key] != allowed:
            raise ValueError(f"{type(optimizer).__name__}({key}={group[key]!r}) is not supported: allowed {allowed!r}")
    lr = group["lr"]
    if torch.is_tensor(lr):
        lr = lr.item()
    if kind == "adam":
        beta1, beta2 = group["betas"]
        return Settings(
            "adam", float(lr), float(group["eps"]), float(group["weight_decay"]), float(beta1), float(beta2)
        )
    return Settings(
        "rmsprop", float(lr), float(group["eps"]), float(group["weight_decay"]), alpha=float(group["alpha"])
    )


def unfused(product: Any) -> Any:
    """``product`` rounded on its own before it is added: XLA's CPU backend otherwise contracts
    ``a * b + c`` into one fused multiply-add (rounded once) where torch rounds the product, then
    the sum; a last-bit difference per step that hundreds of steps amplify past 1e-5 (DQN's
    600-step training test against SB3)."""
    return jax.lax.optimization_barrier(product)


def init(settings: Settings, params: Any) -> dict[str, Any]:
    """Zero moments shaped as ``params`` (torch's state when it first steps: ``zeros_like``)."""
    return {key: jax.tree_util.tree_map(jnp.zeros_like, params) for key in STATE_KEYS[settings.kind]}


def coefficients(
    settings: Settings, lr: float | Sequence[float], first_step: int, n: int, n_seeds: int
) -> dict[str, np.ndarray]:
    """The scalars of the n steps after ``first_step``, (n_seeds, n) float32 each (module docstring)."""
    rates = np.broadcast_to(np.asarray(lr, dtype=np.float64), (n_seeds,))
    if settings.kind == "rmsprop":
        # _single_tensor_rmsprop: param.addcdiv_(grad, avg, value=-lr)
        return {"neg_lr": np.repeat(-rates[:, None], n, axis=1).astype(np.float32)}
    steps = np.arange(first_step + 1, first_step + n + 1, dtype=np.float64)
    # _single_tensor_adam (not capturable): step = _get_value(step_t) (a Python float), then
    # bias_correction1 = 1 - beta1**step; bias_correction2 = 1 - beta2**step; step_size = lr / bias_correction1;
    # bias_correction2_sqrt = bias_correction2**0.5, all in float64 until they meet the tensors.
    bias_correction1 = 1 - settings.beta1**steps
    bias_correction2_sqrt = (1 - settings.beta2**steps) ** 0.5
    step_size = rates[:, None] / bias_correction1[None, :]
    return {
        "neg_step_size": (-step_size).astype(np.float32),
        "bias_correction2_sqrt": np.repeat(bias_correction2_sqrt[None, :], n_seeds, axis=0).astype(np.float32),
    }


def step(settings: Settings, params: Any, grads: Any, state: dict[str, Any], coef: dict[str, Any]):
    """One seed's optimizer step: (new params, new state)."""
    if settings.weight_decay != 0:
        # grad = grad.add(param, alpha=weight_decay)
        grads = jax.tree_util.tree_map(lambda g, p: g + unfused(settings.weight_decay * p), grads, params)
    if settings.kind == "rmsprop":
        return _rmsprop(settings, params, grads, state, coef)
    return _adam(settings, params, grads, state, coef)


def _adam(settings: Settings, params: Any, grads: Any, state: dict[str, Any], coef: dict[str, Any]):
    one_minus_beta1 = np.float32(1 - settings.beta1)
    beta2, one_minus_beta2 = np.float32(settings.beta2), np.float32(1 - settings.beta2)
    eps = np.float32(settings.eps)
    tree_map = jax.tree_util.tree_map
    # exp_avg.lerp_(grad, 1 - beta1): torch's lerp for a weight below 0.5 is self + weight * (end - self)
    exp_avg = tree_map(lambda m, g: m + unfused(one_minus_beta1 * (g - m)), state["exp_avg"], grads)
    # exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1 - beta2): addcmul is self + value * t1 * t2
    exp_avg_sq = tree_map(
        lambda v, g: unfused(v * beta2) + unfused(one_minus_beta2 * g * g), state["exp_avg_sq"], grads
    )

    def update(p, m, v):
        # denom = (exp_avg_sq.sqrt() / bias_correction2_sqrt).add_(eps)
        denom = jnp.sqrt(v) / coef["bias_correction2_sqrt"] + eps
        # param.addcdiv_(exp_avg, denom, value=-step_size): addcdiv is self + value * t1 / t2
        return p + coef["neg_step_size"] * m / denom

    return tree_map(update, params, exp_avg, exp_avg_sq), {"exp_avg": exp_avg, "exp_avg_sq": exp_avg_sq}


def _rmsprop(settings: Settings, params: Any, grads: Any, state: dict[str, Any], coef: dict[str, Any]):
    alpha, one_minus_alpha, eps = np.float32(settings.alpha), np.float32(1 - settings.alpha), np.float32(settings.eps)
    tree_map = jax.tree_util.tree_map
    # square_avg.mul_(alpha).addcmul_(grad, grad, value=1 - alpha)
    square_avg = tree_map(
        lambda v, g: unfused(v * alpha) + unfused(one_minus_alpha * g * g), state["square_avg"], grads
    )

    def update(p, g, v):
        # avg = square_avg.sqrt(); avg = avg.add_(eps); param.addcdiv_(grad, avg, value=-lr)
        return p + coef["neg_lr"] * g / (jnp.sqrt(v) + eps)

    return tree_map(update, params, grads, square_avg), {"square_avg": square_avg}


def clip_grad_norm(grads: Any, max_norm: float) -> tuple[Any, jax.Array]:
    """torch.nn.utils.clip_grad_norm_(parameters, max_norm) on one seed's gradients: the 2-norm of
    the tensors' 2-norms, and every gradient times clamp(max_norm / (total + 1e-6), max=1)."""
    leaves = jax.tree_util.tree_leaves(grads)
    # _get_total_norm: vector_norm(stack([vector_norm(g) for g in grads]))
    total = jnp.linalg.norm(jnp.stack([jnp.linalg.norm(g.ravel()) for g in leaves]))
    # _clip_grads_with_norm_: clip_coef = max_norm / (total_norm + 1e-6); clamp(clip_coef, max=1.0)
    coef = jnp.minimum(jnp.asarray(max_norm, jnp.float32) / (total + np.float32(1e-6)), np.float32(1.0))
    return jax.tree_util.tree_map(lambda g: g * coef, grads), total


def _check_parameters(optimizer: torch.optim.Optimizer, tree: Any, s: int) -> list[torch.Tensor]:
    """Seed s's tensors of ``tree``, which must be exactly the optimizer's parameters."""
    leaves = jax.tree_util.tree_leaves(tree, is_leaf=torch.is_tensor)
    if {id(p) for p in optimizer.param_groups[0]["params"]} != {id(q) for q in leaves}:
        raise ValueError(f"seed {s}: the optimizer's parameters are not the networks' (parameters outside them?)")
    return leaves


def state_from_torch(
    settings: Settings, optimizers: Sequence[torch.optim.Optimizer], trees: Sequence[Any]
) -> tuple[dict[str, Any], int]:
    """The S torch optimizers' moments, stacked by slice into trees shaped as ``trees[0]``, and the
    step count they share. Optimizers that never stepped give zeros and step 0 (torch's first step
    starts from zeros too)."""
    keys = STATE_KEYS[settings.kind]
    counts: set[float] = set()
    per_seed: list[dict[str, Any]] = []
    for s, (opt, tree) in enumerate(zip(optimizers, trees, strict=True)):
        leaves = _check_parameters(opt, tree, s)
        states = [opt.state.get(q, {}) for q in leaves]
        if not any(states):
            counts.add(0.0)
            per_seed.append({k: jax.tree_util.tree_map(torch.zeros_like, tree, is_leaf=torch.is_tensor) for k in keys})
            continue
        missing = sorted({k for st in states for k in (*keys, "step") if k not in st})
        if missing:
            raise ValueError(f"seed {s}: the optimizer's state lacks {missing} for some parameters")
        counts.update(float(st["step"]) for st in states)
        structure = jax.tree_util.tree_structure(tree, is_leaf=torch.is_tensor)
        per_seed.append({k: jax.tree_util.tree_unflatten(structure, [st[k].detach() for st in states]) for k in keys})
    if len(counts) != 1:
        raise ValueError(
            f"the models' optimizers have stepped different numbers of times ({sorted(counts)}): allowed models "
            "that trained the same number of updates"
        )
    return {k: stack([seed[k] for seed in per_seed]) for k in keys}, int(counts.pop())


@torch.no_grad()
def state_to_torch(
    settings: Settings,
    state: dict[str, Any],
    step_count: int,
    lr: float | Sequence[float],
    optimizers: Sequence[torch.optim.Optimizer],
    trees: Sequence[Any],
) -> None:
    """Seed s's slice of the moments, the step count and the learning rate into ``optimizers[s]``
    (its state as torch's own steps would have left it; none before the first step)."""
    rates = np.broadcast_to(np.asarray(lr, dtype=np.float64), (len(optimizers),))
    keys = STATE_KEYS[settings.kind]
    moments = {k: torch_layout(state[k]) for k in keys}
    for s, (opt, tree) in enumerate(zip(optimizers, trees, strict=True)):
        leaves = _check_parameters(opt, tree, s)
        opt.param_groups[0]["lr"] = float(rates[s])
        for i, q in enumerate(leaves):
            if step_count == 0:
                opt.state.pop(q, None)
                continue
            # torch keeps the step as a float32 scalar tensor (_get_scalar_dtype) when not capturable/fused
            entry: dict[str, Any] = {"step": torch.tensor(float(step_count), dtype=torch.float32)}
            for k in keys:
                entry[k] = torch.from_numpy(np.array(moments[k][i][s])).to(q.dtype)
            opt.state[q] = entry
