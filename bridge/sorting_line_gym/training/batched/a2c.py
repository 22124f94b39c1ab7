"""A2C's update for S seeds at once: ``A2C.train`` (stable_baselines3/a2c/a2c.py) on a filled
rollout buffer: one gradient step on the whole rollout, no minibatches, with the policy's
optimizer (SB3's default for A2C: RMSprop, alpha 0.99, eps 1e-5, weight decay 0, mirrored by
``optim``). The loss is written once, for one seed (:func:`a2c_loss`); the update is one compiled
JAX computation, vmapped over seeds (each seed's gradient, clip and step its own).

SB3's ``rollout_buffer.get(batch_size=None)`` shuffles the rollout before yielding it whole; the
means of the loss do not depend on the order, so the samples are taken in buffer order (the sums
may differ from SB3's in the last float bit, far inside the tests' 1e-5).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import optim
from .actor_critic import evaluate_actions
from .params import Spec
from .rollout import FlatRollout
from .seed_axis import over_seeds


@dataclass(frozen=True)
class A2CSettings:
    normalize_advantage: bool
    ent_coef: float
    vf_coef: float
    max_grad_norm: float


def a2c_loss(specs: dict[str, Spec], normalize: bool, p: Any, data: dict[str, Any], hp: dict[str, Any]) -> jax.Array:
    """One seed's loss of A2C.train."""
    # actions = rollout_data.actions.long().flatten(); values = values.flatten()
    values, log_prob, entropy = evaluate_actions(specs, p, data["observations"], data["actions"],
                                                 data.get("action_masks"))  # fmt: skip
    advantages = data["advantages"]
    if normalize:
        advantages = (advantages - advantages.mean()) / (jnp.std(advantages, ddof=1) + np.float32(1e-8))
    # Policy gradient loss
    policy_loss = -(advantages * log_prob).mean()
    # Value loss using the TD(gae_lambda) target: F.mse_loss(rollout_data.returns, values)
    value_loss = jnp.mean((data["returns"] - values) ** 2)
    # Entropy loss favors exploration: -th.mean(entropy)
    entropy_loss = -jnp.mean(entropy)
    return policy_loss + hp["ent_coef"] * entropy_loss + hp["vf_coef"] * value_loss


@functools.lru_cache(maxsize=32)
def compiled_update(specs: tuple[tuple[str, Spec], ...], opt: optim.Settings, normalize: bool):
    """The jitted update of S seeds: (params, state, data, coef (S,), hp) -> (params, state)."""
    spec = dict(specs)

    def one_seed(p, state, data, coef, hp):
        # Optimization step: zero_grad, loss.backward(), clip_grad_norm_(policy.parameters()), step()
        grads = jax.grad(a2c_loss, argnums=2)(spec, normalize, p, data, hp)
        grads, _ = optim.clip_grad_norm(grads, hp["max_grad_norm"])
        return optim.step(opt, p, grads, state, coef)

    return over_seeds(one_seed, (0, 0, 0, 0, None))


def a2c_update(
    specs: dict[str, Spec],
    opt: optim.Settings,
    params: Any,
    state: dict[str, Any],
    coef: dict[str, np.ndarray],
    data: FlatRollout,
    settings: A2CSettings,
) -> tuple[Any, dict[str, Any]]:
    """One A2C.train for every seed; ``coef``: the optimizer's scalars of this one step (S, 1)."""
    fields = data.arrays("observations", "actions", "advantages", "returns")
    hp = {
        "ent_coef": np.float32(settings.ent_coef),
        "vf_coef": np.float32(settings.vf_coef),
        "max_grad_norm": np.float32(settings.max_grad_norm),
    }
    update = compiled_update(tuple(sorted(specs.items())), dataclasses.replace(opt, lr=0.0),
                             settings.normalize_advantage)  # fmt: skip
    return update(params, state, fields, {key: c[:, 0] for key, c in coef.items()}, hp)
