"""DQN's arithmetic for S seeds at once, in JAX: the Q-network's greedy action, SB3's DQN loss, its
gradient steps (clip and Adam) and the target network's update, each written once for one seed
and vmapped over the seed axis, jitted as one XLA computation per call.

- :meth:`QLearning.act`: ``QNetwork._predict`` (argmax of the Q-values) of every seed on its own
  observations, (S, N, obs_dim) -> (S, N).
- :meth:`QLearning.train`: ``G`` gradient steps of every seed (``DQN.train``'s loop body, G times,
  on the G replay batches drawn beforehand by the seed's own generator), one ``lax.scan`` over the
  steps inside the vmap over the seeds: one call for all of a ``train(gradient_steps)``.
- :meth:`QLearning.polyak`: ``polyak_update(q_net, q_net_target, tau)`` of every seed.

The weights are ``params`` trees (``{"q_net": [{"w", "b"}, ...]}``, a leading seed axis), the
optimizer state and per-step scalars ``optim``'s (torch's Adam, formula for formula). No reduction
crosses the seed axis: seed s's loss, gradient, norm and moments are computed from its own slices
only, so each seed's step is the one its own SB3 model would take.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import host, optim
from .optim import unfused
from .params import Spec, forward
from .replay import ReplaySamples
from .seed_axis import over_seeds


def smooth_l1(x: jax.Array, y: jax.Array) -> jax.Array:
    """F.smooth_l1_loss(x, y) with beta 1 and reduction "mean" (aten's smooth_l1_loss: z = |x - y|,
    0.5 * z * z / beta where z < beta, else z - 0.5 * beta)."""
    z = jnp.abs(x - y)
    return jnp.mean(jnp.where(z < 1.0, 0.5 * z * z, z - 0.5))


def dqn_loss(spec: Spec, gamma: float, q_net: Any, q_net_target: Any, batch: ReplaySamples) -> jax.Array:
    """One seed's loss of DQN.train (stable_baselines3/dqn/dqn.py), line for line."""
    # with th.no_grad(): next_q_values = self.q_net_target(replay_data.next_observations)
    next_q_values = jax.lax.stop_gradient(forward(spec, q_net_target["q_net"], batch.next_observations))
    # next_q_values, _ = next_q_values.max(dim=1): follow the greedy policy
    next_q_values = next_q_values.max(axis=1)
    # target_q_values = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q_values (1-step TD)
    target_q_values = batch.rewards + unfused((1 - batch.dones) * np.float32(gamma) * next_q_values)
    # current_q_values = th.gather(self.q_net(replay_data.observations), dim=1, index=replay_data.actions.long()),
    # as a select and a sum of one value and zeros (exact; its gradient a select too, no scatter)
    q_values = forward(spec, q_net["q_net"], batch.observations)
    taken = batch.actions[:, None] == jnp.arange(q_values.shape[1])
    current_q_values = jnp.where(taken, q_values, np.float32(0)).sum(axis=1)
    # loss = F.smooth_l1_loss(current_q_values, target_q_values): Huber, less sensitive to outliers
    return smooth_l1(current_q_values, target_q_values)


class QLearning:
    """The jitted functions of one DQN setting (network spec, optimizer settings, gamma, the clip),
    for any number of seeds (the leading axis of the arrays they are given)."""

    def __init__(self, spec: Spec, settings: optim.Settings, gamma: float, max_grad_norm: float):
        self.spec, self.settings = spec, settings
        self.gamma, self.max_grad_norm = float(gamma), float(max_grad_norm)

        def greedy(q_net: Any, obs: jax.Array) -> jax.Array:
            # QNetwork._predict: q_values.argmax(dim=1) (the first of equal values, as torch's)
            return jnp.argmax(forward(spec, q_net["q_net"], obs), axis=-1)

        def gradient_step(carry, step):
            q_net, state, q_net_target = carry
            batch, coef = step
            # loss.backward() (the target's values carry no gradient: computed under no_grad)
            loss, grads = jax.value_and_grad(lambda q: dqn_loss(spec, self.gamma, q, q_net_target, batch))(q_net)
            # th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm): the target's
            # parameters have no gradient, so the norm is the q_net's alone
            grads, _ = optim.clip_grad_norm(grads, self.max_grad_norm)
            # self.policy.optimizer.step()
            q_net, state = optim.step(settings, q_net, grads, state, coef)
            return (q_net, state, q_net_target), loss

        def steps(q_net, state, q_net_target, batches, coefs):
            # DQN.train: for _ in range(gradient_steps), on the batches sampled in that order
            (q_net, state, _), losses = jax.lax.scan(gradient_step, (q_net, state, q_net_target), (batches, coefs))
            return q_net, state, losses

        def polyak(q_net: Any, q_net_target: Any, keep: jax.Array, tau: jax.Array) -> Any:
            # polyak_update (stable_baselines3/common/utils.py): th.mul_(target, 1 - tau);
            # th.add_(target, param, alpha=tau) (1 - tau computed in Python floats, as there)
            return jax.tree_util.tree_map(lambda p, t: unfused(t * keep) + unfused(tau * p), q_net, q_net_target)

        self._act = over_seeds(greedy, (0, 0))
        # The rollout's forward (S observations of one step) on the host where it can be: a jitted
        # call of one row per seed costs more than the arithmetic (host.py).
        self._on_host = host.supported(spec)
        self._host: tuple[Any, host.HostQNetwork] | None = None
        self._train = over_seeds(steps, (0, 0, 0, 0, 0))
        self._polyak = over_seeds(polyak, (0, 0, None, None))

    def act(self, q_net: Any, observations: np.ndarray) -> np.ndarray:
        """Greedy actions (S, N) of observations (S, N, obs_dim)."""
        if not self._on_host:
            return np.asarray(self._act(q_net, observations))
        if self._host is None or self._host[0] is not q_net:
            self._host = (q_net, host.HostQNetwork(self.spec, q_net["q_net"]))  # once per set of weights
        return self._host[1].greedy(observations)

    def train(
        self, q_net: Any, state: Any, q_net_target: Any, batches: ReplaySamples, coefs: Mapping[str, np.ndarray]
    ) -> tuple[Any, Any, jax.Array]:
        """G gradient steps of every seed: ``batches`` with axes (S, G, B, ...), ``coefs`` the
        optimizer's per-step scalars (S, G) (``optim.coefficients``). Returns the new weights and
        optimizer state and the losses (S, G)."""
        return self._train(q_net, state, q_net_target, batches, dict(coefs))

    def polyak(self, q_net: Any, q_net_target: Any, tau: float) -> Any:
        """The target network moved towards q_net by tau (tau 1: a copy)."""
        return self._polyak(q_net, q_net_target, np.float32(1 - tau), np.float32(tau))
