"""One seed's computation compiled once and run for S seeds, so that a seed's bits do not depend
on how many seeds share its batch: the one way the batched learners compile per-seed JAX code.

Why not ``jax.jit(jax.vmap(f))``: XLA compiles that for the S seeds it is given, and its CPU code
for a batch of S differs with S (how dots and reductions are tiled and vectorized). A seed's
result then moved in its last bits with the batch around it: one DQN gradient step of seed 42 gave
the same bits at S = 8, 16 and 32 and other bits at S = 1, 2 and 4, and A2C's 3,000 steps of seed 42
differed by up to 2.7e-7 between S = 1 and S = 32. So ``--seeds 42`` and ``--seeds 42 .. 73`` trained
seed 42 differently, against "same seed, same trajectory".

:func:`over_seeds` instead compiles ``vmap(f)`` for a fixed chunk of :data:`CHUNK` seeds and maps the
chunks one after the other in a compiled loop (``lax.map``); S seeds are padded to whole chunks
with copies of the first seed, whose results are dropped. Every seed is then computed by the same
compiled code in every batch (tests/python/unit/test_batched_seed_axis.py holds seed 11's weights
to the bit alone, beside 2 and beside 8 seeds, for PPO, A2C and DQN).

Why a chunk of 2: the chunk's code is also what the step-for-step tests hold to SB3, and not every
size of it sums as torch does. DQN's 600-step training (test_batched_dqn.py) ends 2.0e-5 from SB3's
weights, past the tests' 1e-5, when its seeds are computed in vmaps of 4, 8 or 16 seeds, and
within it in vmaps of 1 or 2; plain ``jit(vmap)`` of 8 seeds failed the same way. So the tests
of 2 or 3 seeds cover the code that runs at any S. The price is speed at large S (XLA's kernels for
2 seeds are smaller than for 64): docs/results/performance.md has the figures.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

#: Seeds per compiled chunk (module docstring: why 2).
CHUNK = 2


def over_seeds(fn: Callable[..., Any], in_axes: Sequence[int | None], chunk: int | None = None) -> Callable[..., Any]:
    """``jax.jit(jax.vmap(fn, in_axes))`` (arguments with axis 0 have a leading seed axis, those
    with None are shared by all seeds; the results have a leading seed axis), computed chunk by
    chunk so that each seed's results are the same whatever the number of seeds."""
    if any(axis not in (0, None) for axis in in_axes):
        raise ValueError(f"in_axes {tuple(in_axes)}: allowed 0 (per seed) or None (shared) for each argument")
    chunk = chunk or CHUNK
    per_chunk = jax.vmap(fn, in_axes=tuple(in_axes))

    def run(*args: Any) -> Any:
        seeded = [a for a, axis in zip(args, in_axes, strict=True) if axis == 0]
        n_seeds = jax.tree_util.tree_leaves(seeded)[0].shape[0]
        n_chunks = -(-n_seeds // chunk)
        # seed s's row, then copies of seed 0 up to whole chunks
        rows = np.where(np.arange(n_chunks * chunk) < n_seeds, np.arange(n_chunks * chunk), 0)

        def chunked(x: jax.Array) -> jax.Array:
            if n_chunks * chunk != n_seeds:
                x = jnp.take(x, rows, axis=0)
            return x.reshape(n_chunks, chunk, *x.shape[1:])

        def one_chunk(xs: list[Any]) -> Any:
            it = iter(xs)
            return per_chunk(*(next(it) if axis == 0 else a for a, axis in zip(args, in_axes, strict=True)))

        out = jax.lax.map(one_chunk, jax.tree_util.tree_map(chunked, seeded))
        return jax.tree_util.tree_map(lambda y: y.reshape(n_chunks * chunk, *y.shape[2:])[:n_seeds], out)

    return jax.jit(run)
