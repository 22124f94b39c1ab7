"""A batched seed's run does not depend on the seeds around it (training/batched/seed_axis.py):
seed 11 trained alone, beside one, two and eight other seeds (one chunk padded, one whole chunk,
two and five chunks) ends with the same weights to the bit, for PPO, A2C and DQN (with
``jax.jit(jax.vmap(...))`` in place of ``over_seeds`` all three fail); and ``over_seeds`` itself
gives each seed, padded chunk or not, what it gives that seed alone.

Native lines in this process: no node, no DDS. About 30 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from support.training_stack import MISSING

if MISSING:
    pytest.skip(f"needs the training stack (setup.sh --train); missing {', '.join(MISSING)}", allow_module_level=True)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from sorting_line_gym.training.batched.dqn import BatchedDQN  # noqa: E402
from sorting_line_gym.training.batched.on_policy import OnPolicyTrainer  # noqa: E402
from sorting_line_gym.training.batched.seed_axis import CHUNK, over_seeds  # noqa: E402

pytestmark = pytest.mark.usefixtures("one_torch_thread")

#: Seed 11 alone and among others, in batches of whole and of padded chunks.
BATCHES = ([11], [4, 11], [3, 4, 11], [3, 4, 5, 6, 7, 8, 9, 10, 11])
PPO = dict(n_steps=40, batch_size=24, n_epochs=3, gamma=0.85, learning_rate=7e-4, ent_coef=0.03)
A2C = dict(gamma=0.9, learning_rate=5e-4, ent_coef=0.06)
DQN = dict(gamma=0.95, learning_starts=40, train_freq=2, gradient_steps=2, target_update_interval=60,
           exploration_fraction=0.4, buffer_size=300, batch_size=16, learning_rate=1e-3)  # fmt: skip


def test_the_batches_hold_whole_and_padded_chunks():
    assert {len(b) % CHUNK == 0 for b in BATCHES} == {True, False} and len(BATCHES[-1]) > 2 * CHUNK


def test_each_seed_gets_the_bits_it_gets_alone():
    """A gradient of a small network with reductions over rows and a shared argument, per seed."""

    def grad_of_one(w, x, scale):
        return jax.grad(lambda w: jnp.sum(jnp.tanh(x @ w) ** 2) * scale)(w)

    f = over_seeds(grad_of_one, (0, 0, None))
    rng = np.random.default_rng(0)
    w, x = rng.normal(size=(20, 7, 64)).astype(np.float32), rng.normal(size=(20, 32, 7)).astype(np.float32)
    scale = np.float32(0.3)
    alone = [np.asarray(f(w[s : s + 1], x[s : s + 1], scale))[0] for s in range(20)]
    for n in (2, 3, CHUNK, CHUNK + 1, 20):
        together = np.asarray(f(w[:n], x[:n], scale))
        assert together.shape == (n, 7, 64)
        for s in range(n):
            np.testing.assert_array_equal(together[s], alone[s], err_msg=f"seed {s} of {n}")


def test_a_bad_axis_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"in_axes \(0, 1\): allowed 0 \(per seed\) or None \(shared\)"):
        over_seeds(lambda a, b: a, (0, 1))


def seed_11_weights(make, total: int, weights) -> list[list[np.ndarray]]:
    """Seed 11's final weights (``weights(engine)``: stacked arrays) trained in each of :data:`BATCHES`."""
    out = []
    for seeds in BATCHES:
        engine = make(seeds)
        try:
            engine.learn(total)
            out.append([np.asarray(w)[seeds.index(11)] for w in weights(engine)])
        finally:
            engine.close()
    return out


@pytest.mark.parametrize("algo, params, total", [("ppo", PPO, 80), ("a2c", A2C, 40)], ids=["ppo", "a2c"])
def test_an_on_policy_seed_trains_to_the_same_bits_in_any_batch(algo, params, total):
    def make(seeds):
        return OnPolicyTrainer(algo, seeds, setup="B", variant="advanced", params=params, lines_per_seed=1,
                               episode_steps=15)  # fmt: skip

    first, *others = seed_11_weights(make, total, lambda tr: [p for p, _ in tr.weights()])
    for batch, weights in zip(BATCHES[1:], others, strict=True):
        for ours, alone in zip(weights, first, strict=True):
            np.testing.assert_array_equal(ours, alone, err_msg=f"seed 11 among {batch}")


def test_a_dqn_seed_trains_to_the_same_bits_in_any_batch():
    def make(seeds):
        return BatchedDQN(seeds, setup="B", variant="advanced", n_envs=2, episode_steps=50, **DQN)

    first, *others = seed_11_weights(make, 400, lambda e: jax.tree.leaves((e.q_net, e.q_net_target)))
    for batch, weights in zip(BATCHES[1:], others, strict=True):
        for ours, alone in zip(weights, first, strict=True):
            np.testing.assert_array_equal(ours, alone, err_msg=f"seed 11 among {batch}")
