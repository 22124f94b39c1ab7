"""The float32 functions of SB3's losses as torch rounds them, in JAX: ``tanh``, ``exp``, ``log``,
``logsumexp`` and ``softmax``, so that the batched trainer's update stays within 1e-5 of SB3's.

Why: torch's CPU kernels of these (Sleef's, to 1 ulp) give the correctly rounded float32 value
almost always; XLA's float32 ones are fast approximations (its tanh up to 4.5 ulp off, exp and log
differ from torch's in 10% of values). An update of 320 Adam steps amplifies last-bit differences:
with XLA's own functions a PPO update came 2.3e-5 (tanh) and 1.1e-5 (exp, log) away from SB3's,
over the tests' bar of 1e-5. Here each is computed in float64 and rounded once to float32, which is
what torch's value is, and the composite ones follow torch's kernels step by step
(aten/src/ATen/native/ReduceOps.cpp logsumexp; SoftMaxKernel.cpp softmax). Their derivatives are
torch's too (``tanh_backward``: grad * (1 - y * y) on the float32 output).

This needs JAX's 64-bit types, switched on for the process on import (``jax_enable_x64``): the
batched trainer creates every array with an explicit dtype (float32, int32), so no other value
changes type; code of its own in the process should do the same.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)


def _unfused(product: jax.Array) -> jax.Array:
    """The product rounded on its own (XLA would fuse it into a multiply-add; see optim.unfused)."""
    return jax.lax.optimization_barrier(product)


def _rounded(f):
    return lambda x: f(x.astype(jnp.float64)).astype(x.dtype)


@jax.custom_vjp
def tanh(x: jax.Array) -> jax.Array:
    return _rounded(jnp.tanh)(x)


def _tanh_fwd(x):
    y = tanh(x)
    return y, y


def _tanh_bwd(y, g):
    # tanh_backward (aten/src/ATen/native/cpu/BinaryOpsKernel.cpp): grad * (1 - output * output)
    return (g * (1 - _unfused(y * y)),)  # y * y rounded, as torch's, not fused into the subtraction


tanh.defvjp(_tanh_fwd, _tanh_bwd)


@jax.custom_vjp
def exp(x: jax.Array) -> jax.Array:
    return _rounded(jnp.exp)(x)


def _exp_fwd(x):
    y = exp(x)
    return y, y


def _exp_bwd(y, g):
    # derivatives.yaml, exp: grad * result
    return (g * y,)


exp.defvjp(_exp_fwd, _exp_bwd)


def log(x: jax.Array) -> jax.Array:
    """Rounded once from float64 (not differentiated: it appears only inside :func:`logsumexp`)."""
    return _rounded(jnp.log)(x)


@jax.custom_vjp
def logsumexp(x: jax.Array) -> jax.Array:
    """torch.logsumexp(x, dim=-1, keepdim=True): m = amax (0 where infinite); log(sum(exp(x - m))) + m."""
    m = jnp.max(x, axis=-1, keepdims=True)
    m = jnp.where(jnp.isinf(m), jnp.zeros_like(m), m)
    return log(jnp.sum(exp(x - m), axis=-1, keepdims=True)) + m


def _logsumexp_fwd(x):
    y = logsumexp(x)
    return y, (x, y)


def _logsumexp_bwd(res, g):
    # logsumexp_backward (FunctionsManual.cpp): grad * (self - result).exp()
    x, y = res
    return (g * exp(x - y),)


logsumexp.defvjp(_logsumexp_fwd, _logsumexp_bwd)


@jax.custom_vjp
def softmax(x: jax.Array) -> jax.Array:
    """torch.softmax(x, dim=-1) (vec_softmax_lastdim): exp(x - max), times 1 / their sum."""
    e = exp(x - jnp.max(x, axis=-1, keepdims=True))
    return e * (1 / jnp.sum(e, axis=-1, keepdims=True))


def _softmax_fwd(x):
    y = softmax(x)
    return y, y


def _softmax_bwd(y, g):
    # _softmax_backward_data (vec_softmax_backward): output * (grad - sum(grad * output))
    return (y * (g - jnp.sum(g * y, axis=-1, keepdims=True)),)


softmax.defvjp(_softmax_fwd, _softmax_bwd)
