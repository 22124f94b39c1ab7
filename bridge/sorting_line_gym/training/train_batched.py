"""`sorting-line-train --engine batched --seeds 42 43 ...`: the batched trainer (training/batched)
behind the training command: all the seeds of one algorithm trained at once, each written as
``--engine sb3`` writes one (``<algo>_<setup>_<variant>_seed<S>.zip``, an SB3 model file, and its
``.json`` training record).

The lines are native by default; ``--backend ros`` trains on S x L lines of one `sorting_line
node` started for the run (``--lines S*L``, stopped with it), as ``--engine sb3 --backend ros``
starts its node: each step is then one round trip to the node, which sets the pace. A node serves
at most 64 lines, so S x L beyond that fails before anything starts.

The hyperparameters are the same (``hyperparams.load``: the paper's, ``--hp``, ``n_envs`` lines
per seed); what the batched trainer does not implement fails before anything starts (its checks).
The progress bar counts each seed's steps and shows the steps per second of all seeds together.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..line.flags import call_with_flags
from ..line.vocabulary import check_setup
from . import hyperparams
from .run_record import TrainingRun, model_stem, write_record


def trainer(
    algo: str,
    setup: str,
    variant: str,
    seeds: Sequence[int],
    own: dict[str, Any],
    kwargs: dict[str, Any],
    lines: dict[str, Any] | None = None,
):
    """The batched trainer of ``algo`` (DQN's or the on-policy one) for ``seeds``; ``lines``: where
    its lines run (``backend``, ``namespace``: ``batched.lines.BatchedLines``; default native)."""
    lines = lines or {}
    if algo == "dqn":
        from .batched.dqn import BatchedDQN

        return BatchedDQN(
            seeds, setup=setup, variant=variant, n_envs=own["n_envs"], episode_steps=own["episode_steps"],
            **lines, **kwargs,
        )  # fmt: skip
    from .batched.on_policy import OnPolicyTrainer

    return OnPolicyTrainer(
        algo,
        seeds,
        setup=setup,
        variant=variant,
        params=kwargs,
        lines_per_seed=own["n_envs"],
        episode_steps=own["episode_steps"],
        **lines,
    )


def progress_bar(total: int, n_seeds: int):
    """A tqdm bar of one seed's steps and a callback for the trainers' ``learn`` that updates it."""
    from tqdm import tqdm

    bar = tqdm(total=total, unit="step", desc=f"{n_seeds} seeds", dynamic_ncols=True)
    started = time.perf_counter()

    def update(engine) -> None:
        bar.update(max(0, min(engine.num_timesteps, total) - bar.n))
        rate = engine.num_timesteps * n_seeds / max(time.perf_counter() - started, 1e-9)
        bar.set_postfix_str(f"{rate:,.0f} steps/s over all seeds", refresh=False)

    return bar, update


def _both(first: Callable[[Any], None] | None, second: Callable[[Any], None] | None):
    """One progress callback calling ``first`` then ``second`` (either may be None; None if both are)."""
    if first is None or second is None:
        return first or second

    def both(engine) -> None:
        first(engine)
        second(engine)

    return both


def train_batched(
    algo: str,
    setup: str,
    variant: str,
    *,
    seeds: Sequence[int] = (42,),
    out: str | Path = "models",
    params: dict[str, Any] | None = None,
    progress: bool = True,
    torch_threads: int = 1,
    on_update: Callable[[Any], None] | None = None,
    backend: str = "native",
    namespace: str | Sequence[str] | None = None,
) -> list[TrainingRun]:
    """Trains ``algo`` for all ``seeds`` at once, saves each seed's model and record, returns the records
    (``wall_s``: the batch's); ``on_update(engine)`` before the first step and after each update. The lines
    are native, or with ``backend="ros"`` a node's: one started for the run, or the one(s) at ``namespace``."""
    import torch

    check_setup(setup)
    params = params if params is not None else hyperparams.load(algo, variant)
    own, kwargs = hyperparams.split(params)
    torch.set_num_threads(torch_threads)
    (out := Path(out)).mkdir(parents=True, exist_ok=True)
    engine = trainer(algo, setup, variant, seeds, own, kwargs, {"backend": backend, "namespace": namespace})
    try:
        bar, update = progress_bar(own["n_timesteps"], len(engine.seeds)) if progress else (None, None)
        start = time.perf_counter()
        if on_update is not None:  # a study's learning curves: step 0, then after each update
            on_update(engine)
        engine.learn(own["n_timesteps"], _both(update, on_update))
        wall = time.perf_counter() - start
        if bar is not None:
            bar.close()
        if algo == "dqn":  # BatchedDQN.save names the files as model_stem does
            paths = engine.save(out)
        else:
            paths = engine.save([out / f"{model_stem(algo, setup, variant, s)}.zip" for s in engine.seeds])
        episodes = [int(n) for n in engine.lines.episode_counts]
    finally:
        engine.close()
    return write_records(algo, setup, variant, own, kwargs, engine.seeds, paths, episodes, wall, torch_threads)


def write_records(
    algo: str, setup: str, variant: str, own: dict[str, Any], kwargs: dict[str, Any], seeds: Sequence[int],
    paths: Sequence[Path], episodes: Sequence[int], wall: float, torch_threads: int,
) -> list[TrainingRun]:  # fmt: skip
    """Each seed's TrainingRun, written beside its model as ``<model>.json``; ``wall``: the batch's."""
    rate, engine = own["n_timesteps"] * len(seeds) / wall, f"batched ({len(seeds)} seeds at once)"
    shared = dict(wall=wall, steps_per_s=rate, torch_threads=torch_threads, engine=engine)
    return [
        write_record(algo, setup, variant, own, kwargs, seed, path, episodes=episodes[s], **shared)
        for s, (seed, path) in enumerate(zip(seeds, paths, strict=True))
    ]


def refused_flags(args: argparse.Namespace) -> str | None:
    """Why the flags cannot go to the batched trainer, or None: what it lacks is refused, not ignored."""
    if args.tensorboard not in (None, "none"):
        return f"--tensorboard {args.tensorboard}: the batched engine writes no TensorBoard logs (--engine sb3 does)"
    if args.verbose:
        return "-v: SB3's console log is --engine sb3's; the batched engine shows a progress bar"
    return None


def main_batched(args: argparse.Namespace, params: dict[str, Any]) -> int:
    """``sorting-line-train --engine batched``: exit 0, or 2 for flags or hyperparameters it refuses."""
    refused = refused_flags(args)
    if refused:
        print(f"sorting-line-train: {refused}", file=sys.stderr)
        return 2
    args.backend = args.backend or "native"  # the batched engine's default (--engine sb3's is ros)
    print(
        f"training {args.algo.upper()} on setup {args.setup} {args.variant}, seeds {args.seeds} at once "
        f"on {args.backend} lines: {params}",
        file=sys.stderr,
    )
    try:
        runs = call_with_flags(train_batched, args, args.algo, args.setup, args.variant, params=params,
                               progress=not args.no_progress)  # fmt: skip
    except ValueError as e:  # what the trainer refuses, before it trains
        print(f"sorting-line-train: {e}", file=sys.stderr)
        return 2
    run = runs[0]
    print(
        f"trained {len(runs)} seeds x {run.n_timesteps} steps in {run.wall_s:.1f} s ({run.steps_per_s:.0f} steps/s "
        f"over all seeds); models {', '.join(r.model_path for r in runs)}"
    )
    return 0
