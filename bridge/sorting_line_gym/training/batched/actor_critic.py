"""SB3's ``ActorCriticPolicy`` (the MlpPolicy of PPO and A2C) and sb3-contrib's
``MaskableActorCriticPolicy`` (MaskablePPO's) for S seeds at once, on discrete actions.

The networks are SB3's, stacked (``stacked.StackedSequential``): ``mlp_extractor.policy_net`` and
``mlp_extractor.value_net`` on the flattened observation (the shared ``FlattenExtractor``), then
``action_net`` (logits) and ``value_net``. The distribution is torch's ``Categorical`` as SB3's
``CategoricalDistribution`` builds it, or sb3-contrib's ``MaskableCategorical`` with masks; each
function names what it mirrors. Observations are (S, B, obs_dim), results (S, B, ...).

Sampling draws from one ``torch.Generator`` per seed: a seed's actions never depend on another
seed's. With a generator in the state SB3's global generator has for that seed, the draws are
SB3's (``torch.multinomial(probs, 1, True)`` is what ``Categorical.sample`` calls; :func:`sample`
draws the same).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from .stacked import StackedLinear, StackedSequential

#: The logit sb3-contrib gives a masked action (sb3_contrib/common/maskable/distributions.py, HUGE_NEG).
HUGE_NEG = -1e8


def per_seed_modules(policy: nn.Module) -> nn.ModuleList:
    """The modules of one SB3 policy that hold its parameters, in :class:`StackedActorCritic`'s order."""
    return nn.ModuleList(
        [policy.mlp_extractor.policy_net, policy.mlp_extractor.value_net, policy.action_net, policy.value_net]
    )


def check_policy(policy: nn.Module) -> None:
    """Refuses, by name, a policy this module does not mirror."""
    from stable_baselines3.common.distributions import CategoricalDistribution
    from stable_baselines3.common.torch_layers import FlattenExtractor

    masked = type(policy.action_dist).__name__ == "MaskableCategoricalDistribution"
    if not (isinstance(policy.action_dist, CategoricalDistribution) or masked):
        raise ValueError(
            f"action distribution {type(policy.action_dist).__name__}: the batched trainer has the categorical "
            "one of Discrete actions (the sorting line's)"
        )
    if not isinstance(policy.features_extractor, FlattenExtractor) or not policy.share_features_extractor:
        raise ValueError(
            f"features_extractor_class = {type(policy.features_extractor).__name__}, share_features_extractor = "
            f"{policy.share_features_extractor}: the batched trainer has FlattenExtractor, shared (the MlpPolicy's)"
        )
    if len(policy.observation_space.shape) != 1:
        raise ValueError(f"observation space {policy.observation_space}: the batched trainer has 1-D Box observations")
    mine = sum(p.numel() for p in per_seed_modules(policy).parameters())
    if mine != sum(p.numel() for p in policy.parameters()):
        raise ValueError("the policy has parameters outside its MLP, action and value nets: not supported")


class StackedActorCritic(nn.Module):
    """S actor-critic policies of one architecture as one module (see the module docstring)."""

    def __init__(self, policies: Sequence[nn.Module]):
        super().__init__()
        for policy in policies:
            check_policy(policy)
        self.policy_net = StackedSequential([p.mlp_extractor.policy_net for p in policies])
        self.value_latent = StackedSequential([p.mlp_extractor.value_net for p in policies])
        self.action_net = StackedLinear([p.action_net for p in policies])
        self.value_net = StackedLinear([p.value_net for p in policies])
        self.n_seeds = len(policies)

    def seed_modules(self, policies: Sequence[nn.Module]) -> list[nn.ModuleList]:
        """Per seed, the SB3 modules whose parameters this module's hold (for ``stacked.parameter_pairs``)."""
        return [per_seed_modules(p) for p in policies]

    def logits(self, obs: torch.Tensor) -> torch.Tensor:
        # ActorCriticPolicy.get_distribution: mlp_extractor.forward_actor, then action_net.
        return self.action_net(self.policy_net(obs))

    def predict_values(self, obs: torch.Tensor) -> torch.Tensor:
        """(S, B) values: ActorCriticPolicy.predict_values (forward_critic, then value_net)."""
        return self.value_net(self.value_latent(obs)).squeeze(-1)

    def evaluate_actions(
        self, obs: torch.Tensor, actions: torch.Tensor, masks: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(values, log_prob, entropy), each (S, B): ActorCriticPolicy.evaluate_actions, and
        MaskableActorCriticPolicy.evaluate_actions with ``masks`` (S, B, A) bool."""
        logits = normalized_logits(self.logits(obs), masks)
        return self.predict_values(obs), log_prob(logits, actions), entropy(logits, masks)

    @torch.no_grad()
    def act(
        self, obs: torch.Tensor, generators: Sequence[torch.Generator], masks: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(actions, values, log_probs), each (S, B): ActorCriticPolicy.forward (deterministic=False),
        seed s sampling from ``generators[s]``."""
        logits = normalized_logits(self.logits(obs), masks)
        probs = torch.softmax(logits, dim=-1)  # Categorical.probs: logits_to_probs = softmax
        actions = sample(probs, generators)
        return actions, self.predict_values(obs), log_prob(logits, actions)

    @torch.no_grad()
    def predict(self, obs: torch.Tensor, masks: torch.Tensor | None = None) -> torch.Tensor:
        """(S, B) actions of ``predict(deterministic=True)``: CategoricalDistribution.mode, argmax of probs."""
        return torch.argmax(torch.softmax(normalized_logits(self.logits(obs), masks), dim=-1), dim=-1)


def sample(probs: torch.Tensor, generators: Sequence[torch.Generator]) -> torch.Tensor:
    """(S, B) actions drawn from ``probs`` (S, B, A), seed s from ``generators[s]``: what
    ``torch.multinomial(probs[s], 1, True, generator)`` (Categorical.sample) draws, bit for bit,
    without its per-call checks (a third of a rollout step's time at S = 16). For one sample,
    multinomial is the exponential race of aten/src/ATen/native/Distributions.cpp: q ~ Exp(1) of
    ``probs``' shape, from the generator, and argmax(probs / q)."""
    q = torch.empty_like(probs)
    for s, generator in enumerate(generators):
        q[s].exponential_(1, generator=generator)
    return torch.argmax(probs / q, dim=-1)


def normalized_logits(raw: torch.Tensor, masks: torch.Tensor | None) -> torch.Tensor:
    """The ``logits`` of the distribution SB3 builds from the action net's output: torch's
    ``Categorical(logits=raw)`` normalizes them (raw - logsumexp); sb3-contrib's
    ``MaskableCategorical.apply_masking`` then puts HUGE_NEG where masked and normalizes again."""
    logits = raw - raw.logsumexp(dim=-1, keepdim=True)
    if masks is None:
        return logits
    masked = torch.where(masks, logits, torch.tensor(HUGE_NEG, dtype=logits.dtype))
    return masked - masked.logsumexp(dim=-1, keepdim=True)


def log_prob(logits: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    # torch Categorical.log_prob: the normalized logit of the action.
    return logits.gather(-1, actions.long().unsqueeze(-1)).squeeze(-1)


def entropy(logits: torch.Tensor, masks: torch.Tensor | None) -> torch.Tensor:
    probs = torch.softmax(logits, dim=-1)
    if masks is None:
        # torch Categorical.entropy: logits clamped at the dtype's lowest value, -(p log p).sum.
        clamped = torch.clamp(logits, min=torch.finfo(logits.dtype).min)
        return -(clamped * probs).sum(-1)
    # MaskableCategorical.entropy: masked actions contribute 0.
    return -torch.where(masks, logits * probs, torch.tensor(0.0, dtype=logits.dtype)).sum(-1)
