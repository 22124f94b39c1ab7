"""`sorting-line-benchmark`: the paper's Table 1 and Figure 7, reproduced through ROS 2.

    sorting-line-benchmark                                   # everything: 8 lines x 6 agents, 5 training seeds
    sorting-line-benchmark --setups B D --agents rba rba-hold ppo --train-seeds 42 43 44 --n-envs 8
    sorting-line-benchmark --agents random rba rba-hold      # baselines only, about a minute

For every setup (A-D) and variant (basic, advanced) it evaluates the baselines (random, rba,
rba-hold) and, for each training seed, trains DQN, PPO and A2C with the paper's hyperparameters
(``sorting-line-train``; with ``--n-envs N`` on N lines of one node, the hyperparameters mapped by
``--lines-mapping``, one of ``training.hyperparams.MAPPINGS``) and evaluates the model. Every agent
is evaluated twice with ``sorting-line-eval``'s protocol (50 steps, deterministic): on the paper's
10 seeds 42..51, and
on ``--heldout-episodes`` (100) held-out seeds from ``--heldout-seed`` (10000), which no training
starts from (training seed s starts its N lines from seeds s..s+N-1 and draws the later
episodes' seeds at random from [0, 2^63)). Every line is a real node process stepped over DDS.
Beside each agent: ``sorting_line oracle`` on the same seeds (the clairvoyant optimum per seed)
and the gap to it.

Statistics (``reports.benchmark_summary`` with ``reports.stats``, rliable's method on scipy): per
cell the mean, the IQM over training seeds x held-out episodes with its 95 % bootstrap interval
over whole runs (a training seed's scores on all held-out seeds drawn together), the probability
that each RL agent beats rba-hold per line (same bootstrap), and per agent the IQM over the 8 lines
of the score normalized between the random agent (0) and the oracle (1), its runs drawn within
each line. Where cells of one agent on one line exist on one line and on N lines (in
the same ``--out``; ``--check-n-envs`` trains the one-line cells of DQN, PPO and A2C on B advanced
and D basic), the report checks that they agree, per line and per algorithm (a verdict needs at
least 5 training seeds a side), with each side's gradient steps per transition.

Each finished cell is saved at once in ``<out>/cells/`` (models in ``<out>/models/``), so an
interrupted run picks up where it stopped: a rerun skips cells already done with the same budget.
``--jobs N`` runs N cells at once (each its own node and process); ``--ray ADDRESS`` runs each cell
(or batch) as a task of that Ray cluster instead (``ray_cells``), the store and resume staying here.
Each RL cell records its learning curve: every ``--curve-every`` steps (5000; 0: none) the
policy's mean on the first ``--curve-episodes`` (20) held-out seeds, scored as the final
evaluation (``curves``); the cells' format is ``benchmark_cells``'.

``--engine batched`` trains the RL cells that differ only by training seed (same line, algorithm,
lines and budget) together, in one run of the batched trainer (``sorting-line-train --engine
batched``: native lines by default, with ``--backend ros`` one node's seeds x n-envs lines), then
evaluates and saves each seed's cell as ``--engine sb3`` (the default) does; the cells are named
``..._batched_seed<S>`` and their records name the engine, so the two engines' cells never mix,
and a batch that was cut leaves its evaluated cells saved: a
rerun trains the missing seeds, as one smaller batch. When the cells are in, it
writes ``<out>/table.md`` and ``table.json`` (our figures beside the paper's Table 1 and the
reference implementation's), ``figure7.png``/``.svg`` (mean reward per setup and agent),
``figure3.png``/``.svg`` (the reward analysis behind the rule-based agent), ``intervals`` (IQM
and interval per line and agent), ``runs`` (each cell's runs, a dot per training seed, beside its
interval; and the --n-envs check's), ``curves`` (learning curves: per line the mean over runs of
each RL algorithm and training configuration, with its 95 % interval over runs as a band and
rba-hold's and the oracle's mean on the same seeds as lines; from every RL cell of this budget
saved in ``<out>``, another engine's or lines' cells labelled as such; none without curves; the
numbers in ``table.json``'s ``learning_curves``), ``aggregate`` (aggregate IQM and performance
profiles) and the seed-42 dashboard of every agent in ``<out>/dashboards/``, and ``results.csv``:
every run's reward and normalized score on every held-out seed (``reports.results_csv``).
``--report-only`` redraws from saved cells; ``--compare MY_RESULTS`` puts a user's agent beside
the table (``benchmark_compare``). Ctrl-C or SIGTERM stops it within seconds, workers and their
nodes included (exit 130); the cells that finished are kept.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from ..agents.learned_policy import TRAIN_HINT, missing_training_stack
from ..envs.native import BACKENDS
from ..line.vocabulary import (
    EPISODE_STEPS,
    EVAL_EPISODES,
    EVAL_FIRST_SEED,
    EVAL_SEEDS,
    NODE_LINES,
    SETUPS,
    THRESHOLD,
    VARIANTS,
)
from ..reports import results_csv
from ..reports.benchmark_summary import (
    AGENTS,
    HELDOUT_EPISODES,
    HELDOUT_SEED,
    Heldout,
    aggregates,
    agreement,
    agreement_by_algorithm,
    improvements,
    normalized_per_seed_runs,
    normalized_runs,
    oracle_rows,
    summarize,
)
from ..reports.benchmark_tables import statistics_markdown, table_markdown
from ..reports.curves import benchmark_curves
from ..training.hyperparams import ALGOS, DEFAULT_MAPPING, MAPPINGS
from . import benchmark_compare, cell_pool
from .benchmark_cells import (  # noqa: F401 (re-exported: the benchmark's cells as callers know them)
    CELL_FORMAT,
    ENGINES,
    Cell,
    CellFormatError,
    batches,
    load_cell,
    plan,
    saved_records,
    with_saved_curves,
)
from .cell_store import write_atomic
from .curves import DEFAULT_EPISODES, DEFAULT_EVERY, CurveSettings

#: Five training seeds per RL cell, for interval estimates over runs; the paper's 42 first.
DEFAULT_SEEDS = (42, 43, 44, 45, 46)
#: Where --check-n-envs compares one line with N: ((setups), (variants)), agent.
AGREEMENT_CELLS = tuple(((("B",), ("advanced",)), a) for a in ALGOS) + tuple(((("D",), ("basic",)), a) for a in ALGOS)


def run_cell(
    cell: Cell,
    out: Path,
    timesteps: int,
    heldout: Heldout,
    progress: bool,
    backend: str = "ros",
    curve: CurveSettings | None = None,
) -> dict[str, Any]:
    """Trains (RL) and evaluates one cell on ``backend``; writes and returns its record. Runs in a
    worker. Both backends give the same record but for wall times (a cell store may mix them); the
    native backend draws no dashboard. ``curve``: the RL cell's learning curve (``curves``)."""
    from ..training import hyperparams
    from ..training.train import train
    from .curves import sb3_callback

    start = time.perf_counter()
    record: dict[str, Any] = {"cell": cell.fields(), "timesteps": timesteps if cell.agent in ALGOS else None}
    spec = cell.agent
    if cell.agent in ALGOS:
        params = hyperparams.load(
            cell.agent,
            cell.variant,
            overrides=[f"n_timesteps={timesteps}", f"n_envs={cell.n_envs}"],
            mapping=cell.mapping,
        )
        models = out / f"models{cell.lines}"
        recorder = sb3_callback(cell.agent, cell.setup, cell.variant, curve) if curve and curve.on else None
        run = train(
            cell.agent,
            cell.setup,
            cell.variant,
            seed=cell.train_seed,
            out=models,
            params=params,
            tensorboard=out / "tensorboard",
            progress=progress,
            backend=backend,
            callbacks=[recorder] if recorder is not None else [],
        )
        record["training"] = asdict(run)
        if recorder is not None:
            record["curve"] = recorder.curve.record()
        spec = f"{cell.agent}:{run.model_path}"
    return _evaluated(cell, spec, record, out, heldout, backend, start)


def _evaluated(
    cell: Cell, spec: str, record: dict[str, Any], out: Path, heldout: Heldout, backend: str, start: float
) -> dict[str, Any]:
    """``record`` with the evaluations of agent ``spec`` (the paper's seeds, the held-out ones) and
    the wall time since ``start``, written as the cell's file."""
    from .evaluate import evaluate

    dashboard = out / "dashboards" / f"{cell.name}.png" if backend == "ros" else None  # episode 1, seed 42
    if dashboard is not None:
        dashboard.parent.mkdir(parents=True, exist_ok=True)
    record["evaluation"] = asdict(evaluate(spec, cell.setup, cell.variant, dashboard=dashboard, backend=backend))
    record["heldout"] = asdict(
        evaluate(spec, cell.setup, cell.variant, seed=heldout.seed, episodes=heldout.episodes, backend=backend)
    )
    record["wall_s"] = time.perf_counter() - start
    record["format"] = CELL_FORMAT
    write_atomic(out / "cells" / f"{cell.name}.json", record)  # whole or absent, even if the run is killed
    return record


def run_batch(
    cells: list[Cell],
    out: Path,
    timesteps: int,
    heldout: Heldout,
    progress: bool,
    backend: str = "native",
    curve: CurveSettings | None = None,
) -> list[dict[str, Any]]:
    """Trains the RL ``cells``, which differ only by training seed, at once with the batched
    trainer (its progress bar counts the steps of a seed and shows the steps/s of all), then
    evaluates and writes each seed's cell as ``run_cell`` does, one after the other: a batch cut
    during the evaluations leaves the cells done so far saved. A cell's ``wall_s`` is its share of
    the training and its own evaluations; its curve's, its share of the curves'. Runs in a worker."""
    from ..training import hyperparams
    from ..training.train_batched import train_batched
    from .curves import BatchedCurves

    first = cells[0]
    shared = (first.setup, first.variant, first.agent, first.n_envs, first.mapping, first.engine)
    if first.agent not in ALGOS or any((c.setup, c.variant, c.agent, c.n_envs, c.mapping, c.engine) != shared
                                       for c in cells):  # fmt: skip
        raise ValueError(f"cells {[c.name for c in cells]}: allowed RL cells that differ only by training seed")
    start = time.perf_counter()
    params = hyperparams.load(
        first.agent, first.variant, overrides=[f"n_timesteps={timesteps}", f"n_envs={first.n_envs}"],
        mapping=first.mapping,
    )  # fmt: skip
    seeds = [c.train_seed for c in cells]
    models = out / f"models{first.lines}_{first.engine}"  # beside, not over, the SB3 cells' models
    curves = BatchedCurves(first.setup, first.variant, len(seeds), timesteps, curve) if curve and curve.on else None
    runs = train_batched(first.agent, first.setup, first.variant, seeds=seeds, out=models, params=params,
                         progress=progress, on_update=curves, backend=backend)  # fmt: skip
    share = (time.perf_counter() - start) / len(cells)
    records = []
    for i, (cell, run) in enumerate(zip(cells, runs, strict=True)):
        record = {"cell": cell.fields(), "timesteps": timesteps, "engine": cell.engine, "training": asdict(run)}
        if curves is not None:
            record["curve"] = curves.curves[i].record()
        spec = f"{cell.agent}:{run.model_path}"
        records.append(_evaluated(cell, spec, record, out, heldout, backend, time.perf_counter() - share))
    return records


def run_unit(
    cells: list[Cell], out: Path, timesteps: int, heldout: Heldout, progress: bool, backend: str,
    curve: CurveSettings | None = None,
):  # fmt: skip
    """The records of one of ``batches``: a batch of RL cells, or one cell. Runs in a worker."""
    if cells[0].agent in ALGOS and cells[0].engine == "batched":
        return run_batch(cells, out, timesteps, heldout, progress, backend, curve)
    return [run_cell(cells[0], out, timesteps, heldout, progress, backend, curve)]


def oracle(setup: str, variant: str, seed: int, episodes: int, cache: Path) -> dict[str, Any]:
    """``sorting_line oracle --json`` for these seeds (the clairvoyant optimum per seed), kept in
    ``cache`` (it is deterministic). Solved by the library in this process (``_native.oracle_eval``,
    the same JSON)."""
    import sorting_line_gym._native as _native

    path = cache / f"{setup}_{variant}_seed{seed}_x{episodes}.json"
    if path.is_file():
        return json.loads(path.read_text())
    settings = dict(SETUPS[setup], variant=variant, threshold=THRESHOLD, max_steps=EPISODE_STEPS)
    record = _native.oracle_eval(settings, episodes, seed)
    for e in record["per_episode"]:
        e.pop("actions", None)  # the report needs the rewards; `sorting_line oracle --actions` gives them again
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record) + "\n")
    return record


def write_report(
    out: Path,
    records: list[dict[str, Any]],
    timesteps: int,
    agents=AGENTS,
    heldout: Heldout | None = None,
    engine: str = "sb3",
) -> list[Path]:
    """Table 1 (``table.md``, ``table.json``) and the figures from the cells' ``records``, with the
    oracle on the same seeds (held-out: by default the benchmark's); the --n-envs check compares
    the saved cells of ``engine``; the learning curves draw every saved RL cell of this budget
    (``with_saved_curves``)."""
    from ..reports import plots  # matplotlib, only for a report

    heldout = heldout or Heldout()

    lines = sorted({(r["cell"]["setup"], r["cell"]["variant"]) for r in records})
    oracles = {line: oracle(*line, heldout.seed, heldout.episodes, out / "oracle") for line in lines}
    paper_oracles = {line: oracle(*line, EVAL_FIRST_SEED, EVAL_EPISODES, out / "oracle") for line in lines}
    rows = summarize(records, oracles)
    rows.update(oracle_rows(oracles, paper_oracles))
    poi = improvements(records)
    normalized = normalized_runs(records, oracles)
    aggregate = aggregates(normalized)
    saved = saved_records(out)
    checks = agreement([r for r in saved if r.get("engine", "sb3") == engine], timesteps)
    curves = benchmark_curves(with_saved_curves(records, saved, timesteps, heldout), oracles)
    table = out / "table.md"
    table.write_text(
        f"# Benchmark: Table 1 through ROS 2\n\n{table_markdown(rows, timesteps, agents, heldout)}"
        f"\n{statistics_markdown(poi, aggregate, checks)}"
    )
    (out / "table.json").write_text(
        json.dumps(
            {
                "rows": [{"setup": s, "variant": v, "agent": a, **row} for (s, v, a), row in sorted(rows.items())],
                "probability_of_improvement_over_rba_hold": [
                    {"setup": s, "variant": v, "agent": a, **p} for (s, v, a), p in sorted(poi.items())
                ],
                "aggregate_normalized": aggregate,
                "aggregate_normalized_per_seed": aggregates(normalized_per_seed_runs(rows)),
                "n_envs_agreement": checks,
                "n_envs_agreement_by_algorithm": agreement_by_algorithm(checks),
                "learning_curves": [{"setup": s, "variant": v, **panel} for (s, v), panel in curves.items()],
            },
            indent=2,
        )
        + "\n"
    )
    written = [table, out / "table.json", results_csv.write(out / "results.csv", results_csv.rows_of(records, oracles))]
    written += plots.benchmark_figure({k: r for k, r in rows.items() if k[2] != "oracle"}, out / "figure7")
    written += plots.interval_figure(rows, out / "intervals")
    written += plots.runs_figure(rows, checks, out / "runs")
    written += plots.learning_curves_figure(curves, out / "curves")
    if aggregate:
        written += plots.aggregate_figure(aggregate, normalized, out / "aggregate")
    written += plots.analysis_figure(out / "figure3")
    return written


# ------------------------------------------------------------------------------------------
# Command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sorting-line-benchmark", description="The paper's Table 1 and Figure 7 through ROS 2; resumable."
    )
    p.add_argument(
        "--out", type=Path, default=Path("results/benchmark"), help="results directory (default results/benchmark)"
    )
    p.add_argument(
        "--setups", nargs="+", default=list(SETUPS), choices=list(SETUPS), help="setups to run (default all)"
    )
    p.add_argument(
        "--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS, help="variants to run (default both)"
    )
    p.add_argument("--agents", nargs="+", default=list(AGENTS), choices=AGENTS, help="agents to run (default all)")
    p.add_argument(
        "--train-seeds",
        nargs="+",
        type=int,
        default=list(DEFAULT_SEEDS),
        help=f"training seeds of the RL agents (default {' '.join(map(str, DEFAULT_SEEDS))})",
    )
    p.add_argument(
        "--timesteps", type=int, default=100_000, help="training budget per RL agent (default %(default)s, the paper's)"
    )
    p.add_argument(
        "--n-envs",
        type=int,
        default=1,
        help="lines of one node per training, a power of two "
        "(default 1, as the paper; hyperparameters mapped, see hyperparams)",
    )
    p.add_argument(
        "--heldout-seed",
        type=int,
        default=HELDOUT_SEED,
        help=f"first held-out evaluation seed (default {HELDOUT_SEED})",
    )
    p.add_argument(
        "--heldout-episodes",
        type=int,
        default=HELDOUT_EPISODES,
        help=f"held-out evaluation episodes (default {HELDOUT_EPISODES})",
    )
    p.add_argument(
        "--jobs", type=int, default=1, help="cells run at once, each in its own process and node (default 1)"
    )
    _add_curve_options(p)
    _add_check_options(p)
    p.add_argument("--report-only", action="store_true", help="only redraw the table and figures from saved cells")
    benchmark_compare.add_option(p)
    _add_engine_options(p)
    return p


def _add_engine_options(p: argparse.ArgumentParser) -> None:
    """Where the lines run and who trains on them."""
    p.add_argument(
        "--backend",
        default=None,
        choices=BACKENDS,
        help="ros: each cell on nodes over ROS 2; native: the line in-process (same records) "
        "(default ros; native with --engine batched)",
    )
    p.add_argument(
        "--engine",
        default="sb3",
        choices=ENGINES,
        help="who trains the RL cells: sb3, cell by cell (default), or batched: the training seeds of a line at "
        "once (sorting-line-train --engine batched; on one node's lines with --backend ros), each seed still a "
        "cell of its own",
    )
    p.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run each cell (with --engine batched: each batch) as a task of the Ray cluster at ADDRESS "
        "(HOST:PORT, ray://HOST[:PORT] or auto, as ray.init takes it), one CPU each, as many at once as it has; "
        "the cells, models and resume stay here in --out; not with --jobs (docs/benchmark.md)",
    )


def _add_curve_options(p: argparse.ArgumentParser) -> None:
    """The RL cells' learning curves (studies/curves.py)."""
    p.add_argument(
        "--curve-every",
        type=int,
        default=DEFAULT_EVERY,
        help=f"a learning-curve point every K training steps, in each RL cell (default {DEFAULT_EVERY}; 0: none)",
    )
    p.add_argument(
        "--curve-episodes",
        type=int,
        help=f"a curve point's episodes: the first M held-out seeds (default {DEFAULT_EPISODES}, or all of them "
        "when --heldout-episodes is fewer)",
    )


def _add_check_options(p: argparse.ArgumentParser) -> None:
    """The options of the one-line against N-line check."""
    p.add_argument(
        "--check-n-envs",
        action="store_true",
        help="with --n-envs N > 1: also train the selected RL agents on B advanced and D basic (where selected) on "
        "one line, per training seed, for the check that one line and N lines agree, per algorithm (run last)",
    )
    p.add_argument(
        "--lines-mapping",
        choices=MAPPINGS,
        default=DEFAULT_MAPPING,
        help=f"with --n-envs N > 1: how the one-line hyperparameters go to N lines (default {DEFAULT_MAPPING}; "
        "see training/hyperparams.py)",
    )


def heldout_of(args) -> Heldout:
    return Heldout(args.heldout_seed, args.heldout_episodes)


def curve_of(args) -> CurveSettings:
    """The learning curves the command line asks for, on the first held-out seeds."""
    episodes = min(DEFAULT_EPISODES, args.heldout_episodes) if args.curve_episodes is None else args.curve_episodes
    return CurveSettings(args.curve_every, episodes, args.heldout_seed)


def run_all(todo: list[Cell], args, finished, bar) -> None:
    """Runs the cells, ``args.jobs`` at a time; ``finished(cell, record or exception)`` for each."""
    if args.engine == "batched":
        _run_batches(todo, args, finished, bar)
        return
    _run_units(todo, run_cell, args, finished, bar, lambda cells: ", ".join(c.name for c in cells))


def _run_batches(todo: list[Cell], args, finished, bar) -> None:
    """``run_all`` with ``--engine batched``: ``batches(todo)``, ``args.jobs`` at a time."""

    def unit_finished(cells: list[Cell], outcome) -> None:
        for i, cell in enumerate(cells):
            finished(cell, outcome if isinstance(outcome, Exception) else outcome[i])

    def names(units: list[list[Cell]]) -> str:
        return ", ".join(f"{u[0].name} ({len(u)} seeds)" if len(u) > 1 else u[0].name for u in units)

    _run_units(batches(todo), run_unit, args, unit_finished, bar, names)


def _run_units(units: list, runner, args, finished, bar, names) -> None:
    """``runner(unit, ...)`` for each unit (a cell, or a batch of cells), ``args.jobs`` at a time;
    ``finished(unit, outcome or exception)`` for each; ``names(units)`` labels the bar."""
    if args.ray is not None:
        _run_on_cluster(units, runner, args, finished, bar, names)
        return
    if args.jobs == 1:
        # In this process, with SB3's (or the batched trainer's) progress bar for each training.
        for unit in units:
            bar.set_postfix_str(names([unit]))
            try:
                outcome = runner(unit, args.out, args.timesteps, heldout_of(args), True, args.backend, curve_of(args))
            except Exception as e:  # noqa: BLE001 - report every failed unit, keep the others
                outcome = e
            finished(unit, outcome)
        return
    # Only this bar, with the units running (each worker is a fresh interpreter with its own node).
    cell_pool.run_parallel(
        units,
        lambda unit: (runner, unit, args.out, args.timesteps, heldout_of(args), False, args.backend, curve_of(args)),
        args.jobs,
        finished,
        lambda running: bar.set_postfix_str(names(running)),
    )


def _run_on_cluster(units: list, runner, args, finished, bar, names) -> None:
    """``_run_units`` with ``--ray``: each unit a task of the cluster, in a scratch directory of its
    host; its models come back into ``--out`` and its records are saved here, as they would be there."""
    from . import ray_cells

    def saved(unit, outcome) -> None:
        if not isinstance(outcome, Exception):
            for record in outcome if isinstance(outcome, list) else [outcome]:
                write_atomic(args.out / "cells" / f"{Cell(**record['cell']).name}.json", record)
        finished(unit, outcome)

    ray_cells.run_on_cluster(
        units,
        lambda unit: (runner, unit, args.out, args.timesteps, heldout_of(args), False, args.backend, curve_of(args)),
        args.out,
        saved,
        lambda running: bar.set_postfix_str(names(running)),
    )


def _invalid(args) -> str | None:
    """What is wrong with the command line's values, if anything."""
    for flag, value in (
        ("--timesteps", args.timesteps),
        ("--n-envs", args.n_envs),
        ("--jobs", args.jobs),
        ("--heldout-episodes", args.heldout_episodes),
    ):
        if value < 1:
            return f"{flag} = {value} is not valid: allowed 1 or more"
    if args.n_envs & (args.n_envs - 1) or args.n_envs > 2048:
        return f"--n-envs = {args.n_envs} is not valid: allowed a power of two, 1 .. 2048"
    if args.heldout_seed < 0:
        return f"--heldout-seed = {args.heldout_seed} is not valid: allowed 0 or more"
    if args.curve_every < 0:
        return f"--curve-every = {args.curve_every} is not valid: allowed 0 (no curves) or more"
    if args.curve_episodes is not None and not 1 <= args.curve_episodes <= args.heldout_episodes:
        return (
            f"--curve-episodes = {args.curve_episodes} is not valid: allowed 1 .. --heldout-episodes "
            f"({args.heldout_episodes}): a curve is scored on the first held-out seeds"
        )
    if args.engine == "batched" and args.backend == "ros" and len(args.train_seeds) * args.n_envs > NODE_LINES:
        # A batch trains on one node of seeds x n_envs lines (training/batched/lines.py).
        return (
            f"--engine batched --backend ros with {len(args.train_seeds)} --train-seeds x --n-envs {args.n_envs} = "
            f"{len(args.train_seeds) * args.n_envs} lines is not valid: a batch trains on one node of at most "
            f"{NODE_LINES} lines; allowed seeds x n-envs <= {NODE_LINES} (or --backend native)"
        )
    if args.ray is not None and args.jobs != 1:
        return (
            f"--jobs {args.jobs} with --ray is not valid: on a cluster as many cells run at once as it has CPUs; "
            "allowed --ray without --jobs (or --jobs without --ray, on this machine)"
        )
    return None


def _unwritable(args) -> str | None:
    """Why ``--out`` cannot take the cells, if it cannot: found before any cell runs, as a cell that
    cannot be saved would be found out only after its minutes of work."""
    try:
        (args.out / "cells").mkdir(parents=True, exist_ok=True)
    except OSError as e:
        return f"--out {args.out} cannot be written: {e.strerror} ({e.filename})"
    return None


def _unjoinable(args) -> str | None:
    """Why the Ray cluster of ``--ray`` cannot be joined, if it cannot (None without ``--ray``):
    found before any cell runs, naming the address."""
    if args.ray is None:
        return None
    from .ray_cells import ClusterError, connect

    try:
        connect(args.ray)
    except ClusterError as e:
        return str(e)
    return None


def _cells_of(args) -> list[Cell]:
    """The cells the command line asks for, the one-line cells of --check-n-envs last."""
    cells = plan(
        args.setups, args.variants, args.agents, args.train_seeds, args.n_envs, args.lines_mapping, args.engine
    )
    if args.check_n_envs and args.n_envs > 1:
        cells += [
            c
            for line, agent in AGREEMENT_CELLS
            for c in plan(*line, [agent], args.train_seeds, 1, engine=args.engine)
            if c.agent in args.agents and c.setup in args.setups and c.variant in args.variants
        ]
    return cells


def run_with_bar(todo: list[Cell], cells: list[Cell], done: dict, failures: list, args) -> bool:
    """Runs ``todo`` under a progress bar, adding to ``done`` and ``failures``; False if interrupted."""
    from tqdm import tqdm

    signal.signal(signal.SIGTERM, cell_pool.interrupt)
    bar = tqdm(total=len(cells), initial=len(done), unit="cell", desc="benchmark", file=sys.stderr, dynamic_ncols=True)

    def finished(cell: Cell, outcome) -> None:
        if isinstance(outcome, Exception):
            failures.append((cell, outcome))
            bar.write(f"{cell.name}: FAILED: {outcome}")
        else:
            done[cell] = outcome
            r = outcome["evaluation"]
            h = outcome["heldout"]
            bar.write(
                f"{cell.name}: seeds {EVAL_SEEDS} {r['reward_mean']:.2f} +- {r['reward_std']:.2f}"
                f", held-out {h['reward_mean']:.2f}"
                f" +- {h['reward_std']:.2f} ({outcome['wall_s']:.0f} s)"
            )
        bar.update(1)

    try:
        run_all(todo, args, finished, bar)
    except KeyboardInterrupt:
        return False
    finally:
        bar.close()
    return True


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.backend is None:
        args.backend = "native" if args.engine == "batched" else "ros"
    problem = _invalid(args)
    if problem:
        print(f"sorting-line-benchmark: {problem}", file=sys.stderr)
        return 2
    heldout = heldout_of(args)
    cells = _cells_of(args)
    try:
        done = {c: r for c in cells if (r := load_cell(c, args.out, args.timesteps, heldout)) is not None}
    except CellFormatError as e:
        print(f"sorting-line-benchmark: {e}", file=sys.stderr)
        return 2
    todo = [] if args.report_only else [c for c in cells if c not in done]
    missing = missing_training_stack() if any(c.agent in ALGOS for c in todo) else []
    if missing:
        print(
            f"sorting-line-benchmark: the RL agents ({', '.join(a for a in args.agents if a in ALGOS)}) need "
            f"{' and '.join(missing)}, the training stack: {TRAIN_HINT}; without it, --agents random rba rba-hold",
            file=sys.stderr,
        )
        return 2
    problem = _unwritable(args) or (_unjoinable(args) if todo else None)  # after the checks above: they write nothing
    if problem:
        print(f"sorting-line-benchmark: {problem}", file=sys.stderr)
        return 2
    at_once = f"{args.jobs} at a time" if args.engine == "sb3" else f"{args.jobs} batch(es) at a time, batched"
    if args.ray is not None:
        at_once = f"on the Ray cluster at {args.ray}" + (", batched" if args.engine == "batched" else "")
    print(
        f"benchmark: {len(cells)} cells, {len(done)} already done, {len(todo)} to run, {at_once} -> {args.out}",
        file=sys.stderr,
    )
    failures = []
    if todo and not run_with_bar(todo, cells, done, failures, args):
        print(
            f"sorting-line-benchmark: interrupted; {len(done)} of {len(cells)} cells are saved in {args.out}: "
            "the same command goes on from there",
            file=sys.stderr,
        )
        return 130
    # The table is of the run's --n-envs; the one-line cells of --check-n-envs go to the agreement check.
    records = [done[c] for c in cells if c in done and (c.agent not in ALGOS or c.n_envs == args.n_envs)]
    if not records:
        print("sorting-line-benchmark: no finished cells to report", file=sys.stderr)
        return 1
    if code := benchmark_compare.report(
        args, records, lambda: write_report(args.out, records, args.timesteps, args.agents, heldout, args.engine)
    ):
        return code
    if failures:
        print(
            f"sorting-line-benchmark: {len(failures)} cell(s) failed: {', '.join(c.name for c, _ in failures)}",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
