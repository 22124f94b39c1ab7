"""A2C's update for S seeds at once: ``A2C.train`` (stable_baselines3/a2c/a2c.py) on a filled
rollout buffer: one gradient step on the whole rollout, no minibatches, with the policy's
optimizer (SB3's default for A2C: RMSprop, alpha 0.99, eps 1e-5, weight decay 0, built by SB3
and copied by ``stacked.stacked_optimizer``).

SB3's ``rollout_buffer.get(batch_size=None)`` shuffles the rollout before yielding it whole; the
means of the loss do not depend on the order, so the samples are taken in buffer order (the sums
may differ from SB3's in the last float bit, far inside the tests' 1e-5).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from .actor_critic import StackedActorCritic
from .rollout import FlatRollout
from .stacked import clip_grad_norm_per_seed


@dataclass(frozen=True)
class A2CSettings:
    normalize_advantage: bool
    ent_coef: float
    vf_coef: float
    max_grad_norm: float


def a2c_loss(policy: StackedActorCritic, data: FlatRollout, s: A2CSettings) -> torch.Tensor:
    """The S losses (S,) of A2C.train."""
    values, log_prob, entropy = policy.evaluate_actions(data.observations, data.actions, data.action_masks)
    advantages = data.advantages
    if s.normalize_advantage:
        advantages = (advantages - advantages.mean(dim=1, keepdim=True)) / (advantages.std(dim=1, keepdim=True) + 1e-8)
    # Policy gradient loss; value loss using the TD(gae_lambda) target; entropy loss
    policy_loss = -(advantages * log_prob).mean(dim=1)
    value_loss = F.mse_loss(data.returns, values, reduction="none").mean(dim=1)
    entropy_loss = -entropy.mean(dim=1)
    return policy_loss + s.ent_coef * entropy_loss + s.vf_coef * value_loss


def a2c_update(
    policy: StackedActorCritic, optimizer: torch.optim.Optimizer, data: FlatRollout, settings: A2CSettings
) -> int:
    """One A2C.train: loss, backward, each seed's gradient clipped by its own norm, one step."""
    loss = a2c_loss(policy, data, settings)
    optimizer.zero_grad()
    loss.sum().backward()
    clip_grad_norm_per_seed(policy.parameters(), settings.max_grad_norm)
    optimizer.step()
    return 1
