"""The rollout's forward pass on the host, in numpy: the networks of S seeds evaluated on one step's
observations (S, L, obs_dim), for the learners' action choice (``ActorCriticPolicy.forward`` of PPO,
A2C and MaskablePPO; ``QNetwork._predict`` of DQN).

Why not JAX here: a rollout step evaluates one row per seed, where XLA's CPU dot costs many times
numpy's, so a jitted forward took more than half of an A2C training (the figures are in
docs/results/performance.md). The updates stay in JAX (gradients over many rows).

The arithmetic is ``params.forward``'s and ``torch_math``'s, operation for operation: ``x @ W.T + b``
per seed, tanh, exp and log computed in float64 and rounded once to float32 (what torch's kernels
give), logsumexp and softmax by torch's steps. numpy and XLA may round a sum of products in another
order, so a host value can differ from the jitted one in the last bit (as both differ from torch's
one-row kernel): far inside the step-for-step tests' 1e-5, which run through this path.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .actor_critic import HUGE_NEG
from .params import Spec

#: The layers this module evaluates; a network with another activation takes the jitted path.
HOST_OPS = ("linear", "tanh", "relu", "identity")

Layers = list[tuple[np.ndarray, np.ndarray]]


def supported(*specs: Spec) -> bool:
    """Whether every network of ``specs`` is made of layers this module evaluates."""
    return all(op[0] in HOST_OPS for spec in specs for op in spec)


def layers_of(stacked: Sequence[Mapping[str, Any]]) -> Layers:
    """One stacked network's layers as numpy: (W.T (S, in, out), as params stores it, b (S, 1, out)),
    views of the JAX arrays (on the CPU ``np.asarray`` copies nothing; it waits for the update that
    made them)."""
    return [(np.asarray(layer["w"]), np.asarray(layer["b"])[:, None]) for layer in stacked]


def _rounded(f, x: np.ndarray) -> np.ndarray:
    return f(x.astype(np.float64)).astype(np.float32)


def forward(spec: Spec, layers: Layers, x: np.ndarray) -> np.ndarray:
    """S seeds' network (params.forward per seed): x (S, B, in) -> (S, B, out)."""
    k = 0
    for op in spec:
        if op[0] == "linear":
            # F.linear(x, W, b) = x @ W.T + b per seed: a stacked matmul
            w, b = layers[k]
            x, k = np.matmul(x, w) + b, k + 1
        elif op[0] == "tanh":
            x = _rounded(np.tanh, x)  # torch_math.tanh
        elif op[0] == "relu":
            x = np.maximum(x, np.float32(0))
        elif op[0] != "identity":
            raise ValueError(f"layer {op[0]!r} is not evaluated on the host: allowed {', '.join(HOST_OPS)}")
    return x


def logsumexp(x: np.ndarray) -> np.ndarray:
    """torch_math.logsumexp: m = amax (0 where infinite); log(sum(exp(x - m))) + m."""
    m = np.max(x, axis=-1, keepdims=True)
    m = np.where(np.isinf(m), np.float32(0), m)
    return _rounded(np.log, np.sum(_rounded(np.exp, x - m), axis=-1, keepdims=True)) + m


def softmax(x: np.ndarray) -> np.ndarray:
    """torch_math.softmax: exp(x - max), times 1 / their sum."""
    e = _rounded(np.exp, x - np.max(x, axis=-1, keepdims=True))
    return e * (np.float32(1) / np.sum(e, axis=-1, keepdims=True))


class HostPolicy:
    """S seeds' actor-critic policy (actor_critic's networks) on the host, for one set of weights."""

    def __init__(self, specs: Mapping[str, Spec], stacked: Mapping[str, Any]):
        self.specs = specs
        self.layers = {name: layers_of(stacked[name]) for name in specs}

    def _net(self, name: str, x: np.ndarray) -> np.ndarray:
        return forward(self.specs[name], self.layers[name], x)

    def act(
        self, obs: np.ndarray, q: np.ndarray, masks: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """actor_critic.act for S seeds: (actions, values, log_probs), each (S, L), from observations
        (S, L, obs_dim), exponential draws ``q`` (S, L, A) and masks (S, L, A) bool or None."""
        obs = np.asarray(obs, dtype=np.float32)
        raw = self._net("action_net", self._net("policy_net", obs))
        # normalized_logits: Categorical(logits=raw) normalizes; MaskableCategorical masks, again
        logits = raw - logsumexp(raw)
        if masks is not None:
            masked = np.where(masks, logits, HUGE_NEG)
            logits = masked - logsumexp(masked)
        # sample: torch.multinomial's exponential race, argmax(probs / q)
        actions = np.argmax(softmax(logits) / q, axis=-1)
        values = self.values(obs)
        log_probs = np.take_along_axis(logits, actions[..., None], axis=-1)[..., 0]
        return actions, values, log_probs

    def values(self, obs: np.ndarray) -> np.ndarray:
        """actor_critic.predict_values for S seeds: (S, B) from (S, B, obs_dim)."""
        obs = np.asarray(obs, dtype=np.float32)
        return self._net("value_net", self._net("value_latent", obs))[..., 0]


class HostQNetwork:
    """S seeds' Q-networks on the host, for one set of weights."""

    def __init__(self, spec: Spec, stacked: Sequence[Mapping[str, Any]]):
        self.spec, self.layers = spec, layers_of(stacked)

    def greedy(self, obs: np.ndarray) -> np.ndarray:
        """QNetwork._predict: the argmax of the Q-values (the first of equal ones, torch's rule and
        numpy's), (S, N) from (S, N, obs_dim)."""
        return np.argmax(forward(self.spec, self.layers, np.asarray(obs, dtype=np.float32)), axis=-1)
