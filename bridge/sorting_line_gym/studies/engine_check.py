"""`sorting-line-engine-check`: is the batched engine equal to SB3, statistically? (issue 54, item 4)

    sorting-line-engine-check --out results/engine-check --jobs 2             # both engines, then the report
    sorting-line-engine-check --out results/engine-check --engines sb3 --jobs 2   # one engine's cells only
    sorting-line-engine-check --out results/engine-check --report-only        # the report from saved cells

Trains the benchmark's RL cells (``sorting-line-benchmark``'s own code: its plan, cells, cell
records, resume and workers) with each engine, into ``<out>/sb3`` and ``<out>/batched``: PPO, DQN
and A2C on B advanced and D basic, training seeds 42..51, 100k steps on one line each (the paper's
protocol and hyperparameters), on native lines, each run scored on 100 held-out seeds (from 10000)
and its learning curve recorded every 5000 steps on the first 20 of them. Then writes, in
``<out>``, per algorithm x line each engine's mean over runs with its 95 % interval, the 95 %
interval of the difference of the means by a bootstrap of whole runs (each engine's runs drawn
independently) and the verdict against +-1.5 (``reports.engine_check``): ``engine_check.md``,
``.json``, ``.csv``, ``engine_check_runs.png`` (every run: a strip plot) and
``engine_check_curves.png`` (the two engines' learning curves one over the other). Every option
can be narrowed for a quick check (tests/python/test_engine_check.py runs a reduced one).

Resumable as the benchmark is: a rerun keeps the finished cells. ``<out>/study.json`` holds the
options that change results (budget, held-out seeds, curves); a directory of another
configuration, or one holding something else (a benchmark's cells), is refused before any
training, as are an unknown algorithm or line, and fewer than 3 training seeds (no interval).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..agents.learned_policy import TRAIN_HINT, missing_training_stack
from ..line.vocabulary import SETUPS, VARIANTS
from ..reports.benchmark_summary import HELDOUT_EPISODES, HELDOUT_SEED
from ..reports.engine_check import MARGIN, MIN_RUNS, write_report
from ..training.hyperparams import ALGOS
from . import benchmark
from .cell_store import CellStore, ConfigurationMismatch
from .curves import DEFAULT_EPISODES, DEFAULT_EVERY

#: The issue's check: its algorithms, lines and at least 10 training seeds per engine.
DEFAULT_ALGOS = ("ppo", "dqn", "a2c")
DEFAULT_LINES = ("B:advanced", "D:basic")
DEFAULT_SEEDS = tuple(range(42, 52))
STUDY = "engine-check"


def parse_line(text: str) -> tuple[str, str]:
    """``SETUP:VARIANT`` (e.g. ``B:advanced``) as (setup, variant); a ValueError naming what is allowed."""
    setup, _, variant = text.partition(":")
    if setup not in SETUPS or variant not in VARIANTS:
        raise ValueError(
            f"line {text!r} is not valid: allowed SETUP:VARIANT with SETUP one of {', '.join(SETUPS)} and VARIANT "
            f"one of {', '.join(VARIANTS)} (e.g. B:advanced)"
        )
    return setup, variant


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sorting-line-engine-check",
        description="The batched engine against SB3: the benchmark's RL cells with both engines, "
        "the difference of the means with its interval over runs, the learning curves; resumable.",
    )
    p.add_argument("--out", type=Path, default=Path("results/engine-check"), help="results directory")
    p.add_argument("--engines", nargs="+", default=list(benchmark.ENGINES), choices=benchmark.ENGINES,
                   help="the engines to train (default both; the report compares whatever is saved)")  # fmt: skip
    p.add_argument("--algos", nargs="+", default=list(DEFAULT_ALGOS), choices=ALGOS,
                   help=f"default {' '.join(DEFAULT_ALGOS)}")  # fmt: skip
    p.add_argument("--lines", nargs="+", default=list(DEFAULT_LINES), metavar="SETUP:VARIANT",
                   help=f"default {' '.join(DEFAULT_LINES)}")  # fmt: skip
    p.add_argument("--train-seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS),
                   help=f"training seeds per engine (default {DEFAULT_SEEDS[0]} .. {DEFAULT_SEEDS[-1]};"
                        f" at least {MIN_RUNS})")  # fmt: skip
    p.add_argument("--timesteps", type=int, default=100_000, help="training steps per run (default %(default)s)")
    p.add_argument("--heldout-seed", type=int, default=HELDOUT_SEED, help=f"first held-out seed ({HELDOUT_SEED})")
    p.add_argument("--heldout-episodes", type=int, default=HELDOUT_EPISODES,
                   help=f"held-out seeds a run is scored on (default {HELDOUT_EPISODES})")  # fmt: skip
    p.add_argument("--curve-every", type=int, default=DEFAULT_EVERY,
                   help=f"a learning-curve point every K steps (default {DEFAULT_EVERY}; 0: none)")  # fmt: skip
    p.add_argument("--curve-episodes", type=int, default=DEFAULT_EPISODES,
                   help=f"a curve point's held-out seeds (default the first {DEFAULT_EPISODES})")  # fmt: skip
    p.add_argument("--margin", type=float, default=MARGIN, help=f"agreement margin in reward (default {MARGIN})")
    p.add_argument("--jobs", type=int, default=1,
                   help="cells (batched: batches) at once, each in a worker process (default 1)")  # fmt: skip
    p.add_argument("--report-only", action="store_true", help="only write the report from the saved cells")
    return p


def invalid(args) -> str | None:
    """What is wrong with the command line, if anything (before anything is trained or written)."""
    try:
        args.lines = list(dict.fromkeys(parse_line(t) for t in args.lines))
    except ValueError as e:
        return str(e)
    seeds = args.train_seeds
    if len(set(seeds)) != len(seeds) or min(seeds) < 0:
        return f"--train-seeds {' '.join(map(str, seeds))} is not valid: allowed distinct seeds, 0 or more"
    if len(seeds) < MIN_RUNS:
        return (
            f"--train-seeds: {len(seeds)} seed(s) give no interval over runs: allowed {MIN_RUNS} or more "
            f"(the issue's check: 10)"
        )
    if not args.margin > 0:
        return f"--margin = {args.margin} is not valid: allowed a reward above 0"
    return None


def benchmark_args(args, engine: str) -> argparse.Namespace:
    """The benchmark's own options for ``engine``'s cells (checked by its own rules)."""
    argv = [
        "--out", str(args.out / engine), "--engine", engine, "--backend", "native",
        "--timesteps", str(args.timesteps), "--heldout-seed", str(args.heldout_seed),
        "--heldout-episodes", str(args.heldout_episodes), "--curve-every", str(args.curve_every),
        "--curve-episodes", str(args.curve_episodes), "--jobs", str(args.jobs),
    ]  # fmt: skip
    return benchmark.build_parser().parse_args(argv)


def cells_of(args, engine: str) -> list[benchmark.Cell]:
    """The RL cells of ``engine``, line by line, seed by seed (the benchmark's plan)."""
    return [c for s, v in args.lines for c in benchmark.plan((s,), (v,), args.algos, args.train_seeds, engine=engine)]


def study_key(args) -> dict[str, Any]:
    """What changes the results (algorithms, lines and seeds may grow: more cells, same study)."""
    return {
        "study": STUDY,
        "timesteps": args.timesteps,
        "heldout_seed": args.heldout_seed,
        "heldout_episodes": args.heldout_episodes,
        "curve_every": args.curve_every,
        "curve_episodes": args.curve_episodes,
    }


def open_store(args) -> CellStore:
    """The study's directory, refused (ValueError) if it holds another study or anything else."""
    study = args.out / "study.json"
    if args.out.is_dir() and any(args.out.iterdir()) and not study.is_file():
        raise ValueError(
            f"--out {args.out} holds files but no engine check ({study} is missing): use an empty or new directory"
        )
    store = CellStore(args.out, study_key(args))  # a ConfigurationMismatch names what differs
    if store.study["key"].get("study") != STUDY:
        raise ValueError(f"--out {args.out} holds another study ({store.study['key'].get('study')!r})")
    return store


def _prepare(args) -> tuple[dict[str, tuple], str | None]:
    """Per engine (its benchmark options, cells, finished cells), or what is wrong."""
    units = {}
    for engine in dict.fromkeys(args.engines):
        bargs = benchmark_args(args, engine)
        problem = benchmark._invalid(bargs)
        if problem:
            return {}, problem
        heldout, cells = benchmark.heldout_of(bargs), cells_of(args, engine)
        done = {c: r for c in cells if (r := benchmark.load_cell(c, bargs.out, args.timesteps, heldout)) is not None}
        units[engine] = (bargs, cells, done)
    return units, None


def _train(units: dict[str, tuple], args) -> int | None:
    """Runs each engine's missing cells; 130 if interrupted, None when done."""
    for engine, (bargs, cells, done) in units.items():
        todo = [c for c in cells if c not in done]
        print(f"engine check, {engine}: {len(cells)} cells, {len(done)} already done, {len(todo)} to run, "
              f"{args.jobs} at a time -> {bargs.out}", file=sys.stderr)  # fmt: skip
        failures: list = []
        if todo and not benchmark.run_with_bar(todo, cells, done, failures, bargs):
            print(f"sorting-line-engine-check: interrupted; the finished cells are saved in {args.out}: the same "
                  "command goes on from there", file=sys.stderr)  # fmt: skip
            return 130
        for cell, error in failures:
            print(f"sorting-line-engine-check: {cell.name} failed: {error}", file=sys.stderr)
    return None


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    problem = invalid(args)
    units: dict[str, tuple] = {}
    if problem is None:
        try:
            units, problem = _prepare(args)
            store = open_store(args)
        except (ValueError, ConfigurationMismatch) as e:  # CellFormatError is a ValueError
            problem = str(e)
    if problem is None and not args.report_only and (missing := missing_training_stack()):
        problem = f"needs {' and '.join(missing)}, the training stack: {TRAIN_HINT}"
    if problem is not None:
        print(f"sorting-line-engine-check: {problem}", file=sys.stderr)
        return 2
    if not args.report_only:
        store.begin(sys.argv if argv is None else ["sorting-line-engine-check", *argv])
        stopped = _train(units, args)
        if stopped is not None:
            return stopped
    by_engine = {}
    for engine in benchmark.ENGINES:
        bargs = benchmark_args(args, engine)
        heldout = benchmark.heldout_of(bargs)
        found = [benchmark.load_cell(c, bargs.out, args.timesteps, heldout) for c in cells_of(args, engine)]
        by_engine[engine] = [r for r in found if r is not None]
    written = write_report(args.out, by_engine, args.algos, args.lines, margin=args.margin,
                           timesteps=args.timesteps, heldout_episodes=args.heldout_episodes)  # fmt: skip
    for path in written:
        print(f"written: {path}", file=sys.stderr)
    print((args.out / "engine_check.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
