"""PPO's update for S seeds at once: ``PPO.train`` (stable_baselines3/ppo/ppo.py) on a filled
rollout buffer, and with action masks ``MaskablePPO.train`` (sb3_contrib/ppo_mask/ppo_mask.py).

Every seed's loss is SB3's loss of that seed's minibatch; the S losses are summed for one backward
pass (no parameter is shared, so seed s's gradient is the gradient of its own loss), then each
seed's gradient is clipped by its own norm and one optimizer over the stacked weights steps them
all (elementwise: ``stacked``). Each seed shuffles its rollout with its own generator.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from .actor_critic import StackedActorCritic
from .rollout import FlatRollout
from .stacked import clip_grad_norm_per_seed


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


def minibatch_orders(rngs: Sequence[np.random.RandomState], n_epochs: int, size: int) -> list[np.ndarray]:
    """Per epoch, each seed's permutation of its ``size`` samples: RolloutBuffer.get draws
    ``np.random.permutation(buffer_size * n_envs)`` once per call, and PPO.train calls it once an
    epoch; here from the seed's own generator. (n_epochs arrays of shape (S, size).)"""
    return [np.stack([rng.permutation(size) for rng in rngs]) for _ in range(n_epochs)]


def ppo_loss(policy: StackedActorCritic, batch: FlatRollout, s: PPOSettings) -> torch.Tensor:
    """The S losses (S,) of PPO.train's inner loop on one minibatch per seed."""
    # actions = rollout_data.actions.long().flatten(); values.flatten()
    values, log_prob, entropy = policy.evaluate_actions(batch.observations, batch.actions, batch.action_masks)
    advantages = batch.advantages
    # Normalize advantage (per seed, per minibatch; torch's std is the unbiased one, as SB3's).
    if s.normalize_advantage and (advantages.shape[1] > 1 or s.maskable):
        advantages = (advantages - advantages.mean(dim=1, keepdim=True)) / (advantages.std(dim=1, keepdim=True) + 1e-8)
    # ratio between old and new policy; clipped surrogate loss
    ratio = torch.exp(log_prob - batch.log_probs)
    policy_loss_1 = advantages * ratio
    policy_loss_2 = advantages * torch.clamp(ratio, 1 - s.clip_range, 1 + s.clip_range)
    policy_loss = -torch.min(policy_loss_1, policy_loss_2).mean(dim=1)
    if s.clip_range_vf is None:
        values_pred = values
    else:  # clip the difference between old and new value
        values_pred = batch.values + torch.clamp(values - batch.values, -s.clip_range_vf, s.clip_range_vf)
    # F.mse_loss(rollout_data.returns, values_pred), per seed
    value_loss = F.mse_loss(batch.returns, values_pred, reduction="none").mean(dim=1)
    entropy_loss = -entropy.mean(dim=1)
    return policy_loss + s.ent_coef * entropy_loss + s.vf_coef * value_loss


def ppo_update(
    policy: StackedActorCritic,
    optimizer: torch.optim.Optimizer,
    data: FlatRollout,
    settings: PPOSettings,
    orders: Sequence[np.ndarray],
) -> int:
    """PPO.train's epochs and minibatches (``orders``: :func:`minibatch_orders`), all seeds in
    lock-step; the optimizer's learning rate is set by the caller (``_update_learning_rate``).
    Returns the gradient steps taken."""
    steps = 0
    for order in orders:
        indices = torch.from_numpy(order)
        # RolloutBuffer.get: consecutive slices of the permutation, the last one possibly shorter.
        for start in range(0, data.size, settings.batch_size):
            loss = ppo_loss(policy, data.select(indices[:, start : start + settings.batch_size]), settings)
            optimizer.zero_grad()
            loss.sum().backward()
            clip_grad_norm_per_seed(policy.parameters(), settings.max_grad_norm)
            optimizer.step()
            steps += 1
    return steps
