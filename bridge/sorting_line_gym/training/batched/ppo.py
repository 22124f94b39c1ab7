"""PPO's update for S seeds at once: ``PPO.train`` (stable_baselines3/ppo/ppo.py) on a filled
rollout buffer, and with action masks ``MaskablePPO.train`` (sb3_contrib/ppo_mask/ppo_mask.py).

The loss is written once, for one seed (:func:`ppo_loss`), line for line as SB3's; a whole update
(every epoch, every minibatch, each seed's gradient, its own clip and its own optimizer step) is
one compiled JAX computation (:func:`compiled_update`): ``vmap`` over seeds of a ``lax.scan`` over
the epochs and, inside, over the minibatches, so that nothing of one seed reaches another and the
Python loop of SB3 (15,600 minibatch steps per 100k steps) runs as one call per update. Each seed
shuffles its rollout with its own numpy generator, exactly as SB3 draws (:func:`minibatch_orders`).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import optim, torch_math
from .actor_critic import evaluate_actions
from .params import Spec
from .rollout import FlatRollout
from .seed_axis import over_seeds


@dataclass(frozen=True)
class PPOSettings:
    """What one PPO update uses, with the schedules (clip ranges) evaluated at the update's progress."""

    n_epochs: int
    batch_size: int
    clip_range: float
    clip_range_vf: float | None
    normalize_advantage: bool
    ent_coef: float
    vf_coef: float
    max_grad_norm: float
    #: MaskablePPO normalizes a one-sample minibatch too (its train() lacks PPO's ``len > 1`` test).
    maskable: bool = False


def minibatch_orders(rngs: Sequence[np.random.RandomState], n_epochs: int, size: int) -> np.ndarray:
    """(S, n_epochs, size): per epoch, each seed's permutation of its ``size`` samples.
    RolloutBuffer.get draws ``np.random.permutation(buffer_size * n_envs)`` once per call, and
    PPO.train calls it once an epoch; here from the seed's own generator, epoch after epoch."""
    return np.stack([np.stack([rng.permutation(size) for rng in rngs]) for _ in range(n_epochs)], axis=1)


def ppo_loss(
    specs: dict[str, Spec], normalize: bool, clip_vf: bool, p: Any, mb: dict[str, Any], hp: dict[str, Any]
) -> jax.Array:
    """One seed's loss on one minibatch ``mb`` (PPO.train's inner loop). ``normalize``: whether
    this minibatch's advantages are normalized (decided by the caller from its size, as SB3)."""
    # actions = rollout_data.actions.long().flatten(); values = values.flatten()
    values, log_prob, entropy = evaluate_actions(specs, p, mb["observations"], mb["actions"], mb.get("action_masks"))
    advantages = mb["advantages"]
    # Normalize advantage (per minibatch; torch's std is the unbiased one)
    if normalize:
        advantages = (advantages - advantages.mean()) / (jnp.std(advantages, ddof=1) + np.float32(1e-8))
    # ratio between old and new policy, should be one at the first iteration
    ratio = torch_math.exp(log_prob - mb["log_probs"])
    # clipped surrogate loss
    policy_loss_1 = advantages * ratio
    policy_loss_2 = advantages * jnp.clip(ratio, hp["clip_low"], hp["clip_high"])
    policy_loss = -jnp.minimum(policy_loss_1, policy_loss_2).mean()
    if not clip_vf:
        # No clipping
        values_pred = values
    else:
        # Clip the difference between old and new value; NOTE: this depends on the reward scaling
        values_pred = mb["values"] + jnp.clip(values - mb["values"], -hp["clip_range_vf"], hp["clip_range_vf"])
    # Value loss using the TD(gae_lambda) target: F.mse_loss(rollout_data.returns, values_pred)
    value_loss = jnp.mean((mb["returns"] - values_pred) ** 2)
    # Entropy loss favors exploration: -th.mean(entropy)
    entropy_loss = -jnp.mean(entropy)
    return policy_loss + hp["ent_coef"] * entropy_loss + hp["vf_coef"] * value_loss


def hyperparameters(s: PPOSettings) -> dict[str, np.float32]:
    """The float settings as the float32 scalars torch's ops turn SB3's Python floats into
    (``th.clamp(ratio, 1 - clip_range, 1 + clip_range)``: the bounds in float64, then float32)."""
    return {
        "clip_low": np.float32(1 - s.clip_range),
        "clip_high": np.float32(1 + s.clip_range),
        "clip_range_vf": np.float32(0.0 if s.clip_range_vf is None else s.clip_range_vf),
        "ent_coef": np.float32(s.ent_coef),
        "vf_coef": np.float32(s.vf_coef),
        "max_grad_norm": np.float32(s.max_grad_norm),
    }


def minibatch_step(
    specs: dict[str, Spec], opt: optim.Settings, normalize: bool, clip_vf: bool, data: dict[str, Any], hp: dict
):
    """One seed's gradient step on the minibatch ``idx``: SB3's optimizer.zero_grad(),
    loss.backward(), clip_grad_norm_(policy.parameters(), max_grad_norm), optimizer.step()."""

    def step(carry, xs):
        p, state = carry
        idx, coef = xs
        mb = {k: jnp.take(v, idx, axis=0) for k, v in data.items()}  # RolloutBuffer._get_samples(batch_inds)
        grads = jax.grad(ppo_loss, argnums=3)(specs, normalize, clip_vf, p, mb, hp)
        grads, _ = optim.clip_grad_norm(grads, hp["max_grad_norm"])
        return optim.step(opt, p, grads, state, coef), None

    return step


@functools.lru_cache(maxsize=32)
def compiled_update(
    specs: tuple[tuple[str, Spec], ...],
    opt: optim.Settings,
    normalize: tuple[bool, bool],
    clip_vf: bool,
    n_rest: int,
):
    """The jitted update of S seeds: (params, state, data, full (S, E, K, B), rest (S, E, R),
    coef_full (S, E, K), coef_rest (S, E), hp) -> (params, state). K full minibatches of B and,
    when B does not divide the rollout, a last one of R = n_rest samples, each epoch (SB3's
    RolloutBuffer.get: consecutive slices of the permutation, the last one possibly shorter)."""
    spec = dict(specs)

    def one_seed(p, state, data, full, rest, coef_full, coef_rest, hp):
        full_step = minibatch_step(spec, opt, normalize[0], clip_vf, data, hp)
        rest_step = minibatch_step(spec, opt, normalize[1], clip_vf, data, hp)

        def epoch(carry, xs):
            idx_full, idx_rest, c_full, c_rest = xs
            carry, _ = jax.lax.scan(full_step, carry, (idx_full, c_full))
            if n_rest:
                carry, _ = rest_step(carry, (idx_rest, c_rest))
            return carry, None

        (p, state), _ = jax.lax.scan(epoch, (p, state), (full, rest, coef_full, coef_rest))
        return p, state

    return over_seeds(one_seed, (0, 0, 0, 0, 0, 0, 0, None))


def ppo_update(
    specs: dict[str, Spec],
    opt: optim.Settings,
    params: Any,
    state: dict[str, Any],
    coef: dict[str, np.ndarray],
    data: FlatRollout,
    settings: PPOSettings,
    orders: np.ndarray,
) -> tuple[Any, dict[str, Any]]:
    """PPO.train's epochs and minibatches (``orders``: :func:`minibatch_orders`), all seeds at once;
    ``coef``: the optimizer's scalars of the update's steps (``optim.coefficients``, (S, steps)),
    whose learning rate the caller set (``_update_learning_rate``). Returns (params, state)."""
    n_seeds, n_epochs, size = orders.shape
    b = settings.batch_size
    k, r = size // b, size % b
    per_epoch = k + (r > 0)
    # PPO.train: `if self.normalize_advantage and len(advantages) > 1` (MaskablePPO: without the size test)
    normalize = (settings.normalize_advantage and (b > 1 or settings.maskable),
                 settings.normalize_advantage and (r > 1 or settings.maskable))  # fmt: skip
    fields = data.arrays("observations", "actions", "values", "log_probs", "advantages", "returns")
    steps = {key: c.reshape(n_seeds, n_epochs, per_epoch) for key, c in coef.items()}
    full = orders[:, :, : k * b].reshape(n_seeds, n_epochs, k, b).astype(np.int32)
    rest = orders[:, :, k * b :].astype(np.int32)
    # the learning rate is in ``coef``: one compiled update serves every lr (the cache key leaves it out)
    key = (tuple(sorted(specs.items())), dataclasses.replace(opt, lr=0.0))
    update = compiled_update(*key, normalize, settings.clip_range_vf is not None, r)
    return update(
        params,
        state,
        fields,
        full,
        rest,
        {key: c[:, :, :k] for key, c in steps.items()},
        {key: c[:, :, k] if r else c[:, :, 0] for key, c in steps.items()},
        hyperparameters(settings),
    )
