"""S independent networks as one batched computation: the weights of S copies of one torch
``nn.Sequential`` (Linear layers and elementwise activations, as SB3's ``create_mlp`` and
``MlpExtractor`` build them) stacked over a leading seed axis, so that the forward pass of all S
networks is one ``torch.baddbmm`` per layer instead of S small matmuls.

Why this is exact per seed: a batched matmul multiplies seed s's inputs by seed s's weights only,
so a loss that is a sum of per-seed losses gives each seed the gradient its own network would get;
Adam and RMSprop are elementwise, so one optimizer over the stacked tensors steps every seed as
its own optimizer would (all seeds share the step count and learning rate, which holds because
they step in lock-step on one schedule). What is not elementwise, the global gradient-norm clip,
is done per seed by :func:`clip_grad_norm_per_seed`.

The interface (stable; the on-policy and DQN learners both build on it):

- :class:`StackedLinear`: ``weight`` (S, out, in), ``bias`` (S, out). Slice ``[s]`` has exactly the
  shape of ``nn.Linear``'s weight and bias, so weights and optimizer state move to and from SB3's
  per-seed modules by indexing, without transposes.
- :class:`StackedSequential`: S copies of one ``nn.Sequential`` of Linear layers and elementwise
  activations; ``StackedSequential(nets)`` copies the S networks' weights in, ``write_to(nets)``
  copies them back out, ``load_from(nets)`` in again. Input (S, B, in) -> output (S, B, out).
- :func:`parameter_pairs`: each stacked parameter with the S per-seed parameters it holds, in
  ``parameters()`` order (which is ``nn.Sequential``'s order, weight before bias).
- :func:`clip_grad_norm_per_seed`: ``torch.nn.utils.clip_grad_norm_`` computed over one seed's
  slices of all the given parameters, for each seed.
- :func:`stacked_optimizer`: an optimizer of the same class and settings as a per-seed one (SB3's
  Adam eps 1e-5, A2C's RMSprop alpha 0.99 eps 1e-5, ...) over stacked parameters;
  :func:`optimizer_state_from_seeds` / :func:`optimizer_state_to_seeds` move its state (moments,
  step count, learning rate) from and to S per-seed optimizers, so that a model saved per seed
  continues training in SB3 as if SB3 had trained it, and an SB3 model continues here.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import torch
from torch import nn

#: Activations that act elementwise, so that applying them to (S, B, F) is applying them per seed.
ELEMENTWISE = (nn.Tanh, nn.ReLU, nn.LeakyReLU, nn.ELU, nn.SiLU, nn.GELU, nn.Sigmoid, nn.Softplus, nn.Identity)


class StackedLinear(nn.Module):
    """S ``nn.Linear`` layers of one shape as one: ``weight`` (S, out, in), ``bias`` (S, out)."""

    def __init__(self, linears: Sequence[nn.Linear]):
        super().__init__()
        check_same_shapes(linears, "Linear layers")
        if any(lin.bias is None for lin in linears):
            raise ValueError("StackedLinear: a Linear layer without a bias is not supported (SB3's MLPs have biases)")
        with torch.no_grad():
            self.weight = nn.Parameter(torch.stack([lin.weight.detach() for lin in linears]).clone())
            self.bias = nn.Parameter(torch.stack([lin.bias.detach() for lin in linears]).clone())  # type: ignore[union-attr]

    @property
    def n_seeds(self) -> int:
        return self.weight.shape[0]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # F.linear(x, W, b) = b + x @ W.T (torch/nn/modules/linear.py), per seed: one batched matmul.
        return torch.baddbmm(self.bias.unsqueeze(1), x, self.weight.transpose(1, 2))


class StackedSequential(nn.Module):
    """S copies of one ``nn.Sequential`` of Linear layers and elementwise activations (see the
    module docstring). An empty Sequential (SB3's ``net_arch=[]``) is the identity."""

    def __init__(self, nets: Sequence[nn.Sequential]):
        super().__init__()
        if not nets:
            raise ValueError("StackedSequential needs at least one network (one per seed)")
        kinds = [[type(m) for m in net] for net in nets]
        if any(k != kinds[0] for k in kinds):
            raise ValueError(f"StackedSequential: the networks differ in their layers: {kinds[0]} vs others")
        layers: list[nn.Module] = []
        for i, module in enumerate(nets[0]):
            if isinstance(module, nn.Linear):
                layers.append(StackedLinear([net[i] for net in nets]))  # type: ignore[misc]
            elif isinstance(module, ELEMENTWISE):
                layers.append(module)  # no parameters: one instance serves all seeds
            else:
                allowed = ", ".join(c.__name__ for c in (nn.Linear, *ELEMENTWISE))
                raise ValueError(f"StackedSequential: layer {i} is a {type(module).__name__}; allowed: {allowed}")
        self.layers = nn.ModuleList(layers)
        self.n_seeds = len(nets)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers:
            x = layer(x)
        return x

    def write_to(self, nets: Sequence[nn.Module]) -> None:
        """Copies seed s's weights into ``nets[s]`` (an ``nn.Sequential`` of the same layers)."""
        copy_to_seeds(self, nets)

    def load_from(self, nets: Sequence[nn.Module]) -> None:
        """Copies ``nets[s]``'s weights into seed s."""
        copy_from_seeds(self, nets)


def check_same_shapes(modules: Sequence[nn.Module], what: str) -> None:
    if not modules:
        raise ValueError(f"no {what} to stack (one per seed is needed)")
    shapes = [[tuple(p.shape) for p in m.parameters()] for m in modules]
    if any(s != shapes[0] for s in shapes):
        raise ValueError(
            f"the {what} to stack differ in shape: {shapes[0]} vs {next(s for s in shapes if s != shapes[0])}"
        )


def parameter_pairs(stacked: nn.Module, nets: Sequence[nn.Module]) -> list[tuple[nn.Parameter, list[nn.Parameter]]]:
    """Each parameter of ``stacked`` with the S parameters of ``nets`` it holds (slice s is
    ``nets[s]``'s), matched in ``parameters()`` order and checked by shape."""
    mine = list(stacked.parameters())
    theirs = [list(net.parameters()) for net in nets]
    if any(len(t) != len(mine) for t in theirs) or len(nets) != (mine[0].shape[0] if mine else len(nets)):
        raise ValueError(
            f"{len(nets)} networks of {[len(t) for t in theirs]} parameters do not match the stacked network "
            f"({len(mine)} parameters of {mine[0].shape[0] if mine else '?'} seeds)"
        )
    pairs = []
    for k, p in enumerate(mine):
        per_seed = [t[k] for t in theirs]
        if any(q.shape != p.shape[1:] for q in per_seed):
            raise ValueError(f"parameter {k}: stacked shape {tuple(p.shape)} does not hold {tuple(per_seed[0].shape)}")
        pairs.append((p, per_seed))
    return pairs


@torch.no_grad()
def copy_to_seeds(stacked: nn.Module, nets: Sequence[nn.Module]) -> None:
    for p, per_seed in parameter_pairs(stacked, nets):
        for s, q in enumerate(per_seed):
            q.copy_(p[s])


@torch.no_grad()
def copy_from_seeds(stacked: nn.Module, nets: Sequence[nn.Module]) -> None:
    for p, per_seed in parameter_pairs(stacked, nets):
        p.copy_(torch.stack([q.detach() for q in per_seed]))


@torch.no_grad()
def clip_grad_norm_per_seed(parameters: Iterable[nn.Parameter], max_norm: float) -> torch.Tensor:
    """``torch.nn.utils.clip_grad_norm_(seed's parameters, max_norm)`` for each seed at once (SB3
    calls it on ``policy.parameters()`` after each backward): the 2-norm over all of one seed's
    gradient slices, and the seed's gradients scaled by ``min(1, max_norm / (norm + 1e-6))``.
    Returns the S norms before clipping."""
    grads = [p.grad for p in parameters if p.grad is not None]
    if not grads:
        raise ValueError("clip_grad_norm_per_seed: no parameter has a gradient")
    # torch/nn/utils/clip_grad.py: total = ||(||g_1||, ..., ||g_n||)||, per seed here.
    norms = torch.stack([torch.linalg.vector_norm(g.flatten(1), dim=1) for g in grads], dim=1)
    total = torch.linalg.vector_norm(norms, dim=1)
    coef = torch.clamp(max_norm / (total + 1e-6), max=1.0)
    for g in grads:
        g.mul_(coef.view(-1, *([1] * (g.dim() - 1))))
    return total


def stacked_optimizer(like: torch.optim.Optimizer, parameters: Iterable[nn.Parameter]) -> torch.optim.Optimizer:
    """An optimizer of ``like``'s class and settings (its ``defaults``: lr, eps, alpha, betas, ...)
    over ``parameters``, which must be elementwise (Adam, AdamW, RMSprop, SGD: checked)."""
    allowed = (torch.optim.Adam, torch.optim.AdamW, torch.optim.RMSprop, torch.optim.SGD)
    if type(like) not in allowed:
        raise ValueError(
            f"optimizer {type(like).__name__} is not supported by the batched trainer: allowed "
            f"{', '.join(c.__name__ for c in allowed)} (elementwise, so stacking the seeds is exact)"
        )
    if len(like.param_groups) != 1:
        raise ValueError(f"an optimizer with {len(like.param_groups)} parameter groups is not supported: allowed 1")
    settings = {k: v for k, v in like.defaults.items() if k != "params"}
    settings["lr"] = like.param_groups[0]["lr"]
    return type(like)(list(parameters), **settings)


def optimizer_state_from_seeds(
    stacked: torch.optim.Optimizer,
    pairs: Sequence[tuple[nn.Parameter, Sequence[nn.Parameter]]],
    seeds: Sequence[torch.optim.Optimizer],
) -> None:
    """The per-seed optimizers' state (moments by slice; the step count, which must agree) and
    learning rate into ``stacked``. Seeds without state (never stepped) leave it empty."""
    stacked.param_groups[0]["lr"] = seeds[0].param_groups[0]["lr"]
    for p, per_seed in pairs:
        states = [opt.state.get(q, {}) for opt, q in zip(seeds, per_seed, strict=True)]
        if not any(states):
            stacked.state.pop(p, None)
            continue
        keys = sorted(states[0])
        if any(sorted(st) != keys for st in states):
            raise ValueError("the models' optimizers differ in their state (some have stepped, some not)")
        merged = {}
        for key in keys:
            values = [st[key] for st in states]
            if torch.is_tensor(values[0]) and values[0].shape == per_seed[0].shape:
                merged[key] = torch.stack([v.detach() for v in values]).clone()
            else:  # the step count: one per stacked tensor, so the seeds must have stepped equally often
                if any(float(v) != float(values[0]) for v in values):
                    raise ValueError(
                        f"the models' optimizers have stepped different numbers of times ({key}: "
                        f"{sorted({float(v) for v in values})}): allowed models that trained the same number of updates"
                    )
                merged[key] = values[0].clone() if torch.is_tensor(values[0]) else values[0]
        stacked.state[p] = merged


def optimizer_state_to_seeds(
    stacked: torch.optim.Optimizer,
    pairs: Sequence[tuple[nn.Parameter, Sequence[nn.Parameter]]],
    seeds: Sequence[torch.optim.Optimizer],
) -> None:
    """``stacked``'s state and learning rate into the per-seed optimizers (slice s to seed s)."""
    for opt in seeds:
        opt.param_groups[0]["lr"] = stacked.param_groups[0]["lr"]
    for p, per_seed in pairs:
        state = stacked.state.get(p)
        for s, (opt, q) in enumerate(zip(seeds, per_seed, strict=True)):
            if not state:
                opt.state.pop(q, None)
                continue
            opt.state[q] = {key: seed_slice(v, s, p.shape) for key, v in state.items()}


def seed_slice(value: object, s: int, stacked_shape: torch.Size) -> object:
    """Seed s's part of one optimizer state entry: its slice of a stacked tensor, else a copy (the step)."""
    if torch.is_tensor(value):
        return value[s].clone() if value.shape == stacked_shape else value.clone()
    return value
