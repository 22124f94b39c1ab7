"""SB3's ``ActorCriticPolicy`` (the MlpPolicy of PPO and A2C) and sb3-contrib's
``MaskableActorCriticPolicy`` (MaskablePPO's) on discrete actions, as pure JAX functions of one
seed's parameters (``params``' trees; the learners vmap them over seeds).

The networks are SB3's (:func:`networks`): ``mlp_extractor.policy_net`` and
``mlp_extractor.value_net`` on the flattened observation (the shared ``FlattenExtractor``), then
``action_net`` (logits) and ``value_net``. The distribution is torch's ``Categorical`` as SB3's
``CategoricalDistribution`` builds it, or sb3-contrib's ``MaskableCategorical`` with masks; each
function names what it mirrors, with torch's rounding of logsumexp and softmax (``torch_math``).
``specs`` is ``params.specs_of``'s dict for these networks.

Sampling: :func:`sample` takes the exponential draws ``q`` as an argument. The trainer draws them
from one ``torch.Generator`` per seed (``exponential_noise``), so a seed's actions never depend on
another seed's, and with a generator in the state SB3's global generator has for that seed, the
actions are SB3's: ``Categorical.sample`` calls ``torch.multinomial(probs, 1, True)``, which for
one sample is the exponential race of aten/src/ATen/native/Distributions.cpp, q ~ Exp(1) of
``probs``' shape drawn from the generator and argmax(probs / q).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import torch
from torch import nn

from . import torch_math
from .params import Spec, forward
from .seed_axis import over_seeds

#: The logit sb3-contrib gives a masked action (sb3_contrib/common/maskable/distributions.py, HUGE_NEG).
HUGE_NEG = np.float32(-1e8)


def networks(policy: nn.Module) -> dict[str, nn.Module]:
    """The modules of one SB3 policy that hold its parameters, by the names the trees use."""
    return {
        "policy_net": policy.mlp_extractor.policy_net,
        "value_latent": policy.mlp_extractor.value_net,
        "action_net": policy.action_net,
        "value_net": policy.value_net,
    }


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
    mine = sum(p.numel() for m in networks(policy).values() for p in m.parameters())
    if mine != sum(p.numel() for p in policy.parameters()):
        raise ValueError("the policy has parameters outside its MLP, action and value nets: not supported")


def raw_logits(specs: dict[str, Spec], p: dict[str, Any], obs: jax.Array) -> jax.Array:
    # ActorCriticPolicy.get_distribution: mlp_extractor.forward_actor, then action_net.
    return forward(specs["action_net"], p["action_net"], forward(specs["policy_net"], p["policy_net"], obs))


def predict_values(specs: dict[str, Spec], p: dict[str, Any], obs: jax.Array) -> jax.Array:
    """(B,) values: ActorCriticPolicy.predict_values (forward_critic, then value_net)."""
    return forward(specs["value_net"], p["value_net"], forward(specs["value_latent"], p["value_latent"], obs))[..., 0]


def normalized_logits(raw: jax.Array, masks: jax.Array | None) -> jax.Array:
    """The ``logits`` of the distribution SB3 builds from the action net's output: torch's
    ``Categorical(logits=raw)`` normalizes them (raw - logsumexp); sb3-contrib's
    ``MaskableCategorical.apply_masking`` then puts HUGE_NEG where masked and normalizes again."""
    logits = raw - torch_math.logsumexp(raw)
    if masks is None:
        return logits
    masked = jnp.where(masks, logits, HUGE_NEG)
    return masked - torch_math.logsumexp(masked)


def log_prob(logits: jax.Array, actions: jax.Array) -> jax.Array:
    # torch Categorical.log_prob: the normalized logit of the action.
    return jnp.take_along_axis(logits, actions[..., None].astype(jnp.int32), axis=-1)[..., 0]


def entropy(logits: jax.Array, masks: jax.Array | None) -> jax.Array:
    probs = torch_math.softmax(logits)  # Categorical.probs: logits_to_probs = softmax
    if masks is None:
        # torch Categorical.entropy: logits clamped at the dtype's lowest value, -(p log p).sum.
        clamped = jnp.maximum(logits, jnp.finfo(logits.dtype).min)
        return -(clamped * probs).sum(-1)
    # MaskableCategorical.entropy: masked actions contribute 0.
    return -jnp.where(masks, logits * probs, np.float32(0.0)).sum(-1)


def evaluate_actions(
    specs: dict[str, Spec], p: dict[str, Any], obs: jax.Array, actions: jax.Array, masks: jax.Array | None = None
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(values, log_prob, entropy), each (B,): ActorCriticPolicy.evaluate_actions, and
    MaskableActorCriticPolicy.evaluate_actions with ``masks`` (B, A) bool."""
    logits = normalized_logits(raw_logits(specs, p, obs), masks)
    return predict_values(specs, p, obs), log_prob(logits, actions), entropy(logits, masks)


def sample(logits: jax.Array, q: jax.Array) -> jax.Array:
    """The actions ``torch.multinomial(probs, 1, True)`` draws given its exponential draws ``q``
    (module docstring): argmax(probs / q)."""
    probs = torch_math.softmax(logits)  # Categorical.probs
    return jnp.argmax(probs / q, axis=-1)


def act(
    specs: dict[str, Spec], p: dict[str, Any], obs: jax.Array, q: jax.Array, masks: jax.Array | None = None
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(actions, values, log_probs), each (B,): ActorCriticPolicy.forward (deterministic=False)
    with the exponential draws ``q`` (B, A) of its sampling."""
    logits = normalized_logits(raw_logits(specs, p, obs), masks)
    actions = sample(logits, q)
    return actions, predict_values(specs, p, obs), log_prob(logits, actions)


def predict(specs: dict[str, Spec], p: dict[str, Any], obs: jax.Array, masks: jax.Array | None = None) -> jax.Array:
    """(B,) actions of ``predict(deterministic=True)``: CategoricalDistribution.mode, argmax of probs."""
    return jnp.argmax(torch_math.softmax(normalized_logits(raw_logits(specs, p, obs), masks)), axis=-1)


@functools.lru_cache(maxsize=32)
def compiled(specs: tuple[tuple[str, Spec], ...]) -> dict[str, Any]:
    """:func:`act`, :func:`predict_values` and :func:`predict` of S seeds at once, jitted: each
    takes the stacked params and (S, B, ...) arrays (``masks`` None or (S, B, A) bool), one call
    for all S x B. Cached by architecture, so that trainers of one architecture share the compiled code."""
    spec = dict(specs)
    return {
        "act": over_seeds(lambda p, obs, q, masks: act(spec, p, obs, q, masks), (0, 0, 0, 0)),
        "values": over_seeds(lambda p, obs: predict_values(spec, p, obs), (0, 0)),
        "predict": over_seeds(lambda p, obs, masks: predict(spec, p, obs, masks), (0, 0, 0)),
    }


class JittedPolicy:
    """:func:`compiled`'s ``act`` and ``values`` of one set of stacked weights, numpy out: the
    interface of ``host.HostPolicy``, for the networks that path does not evaluate."""

    def __init__(self, functions: dict[str, Any], stacked: Any):
        self.functions, self.stacked = functions, stacked

    def act(self, obs: np.ndarray, q: np.ndarray, masks: np.ndarray | None = None):
        return tuple(np.asarray(a) for a in self.functions["act"](self.stacked, obs, q, masks))

    def values(self, obs: np.ndarray) -> np.ndarray:
        return np.asarray(self.functions["values"](self.stacked, obs))


def exponential_noise(generators: Sequence[torch.Generator], shape: tuple[int, ...]) -> np.ndarray:
    """(S, *shape) Exp(1) draws, seed s's from ``generators[s]`` in torch's order: the draws of
    ``shape[0]`` consecutive samplings of ``shape[1:]`` each (one draw of (k, L, A) is, value for
    value, k draws of (L, A): the generator is consumed in element order)."""
    out = np.empty((len(generators), *shape), dtype=np.float32)
    for s, generator in enumerate(generators):
        out[s] = torch.empty(shape).exponential_(1, generator=generator).numpy()
    return out
