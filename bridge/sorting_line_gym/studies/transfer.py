"""`sorting-line-transfer`: the transfer study of the evolving line (the paper's future work),
through ROS: MaskablePPO and A2C on `SortingLineEvolving-v0`, resumable cell by cell.

    sorting-line-transfer --full                 # the paper's scale: 2000 + 2000 episodes, 5 seeds, PPO and A2C
    sorting-line-transfer --smoke --out /tmp/t   # the same pipeline at CI size
    sorting-line-transfer --seeds 1 2 3 --before 300 --after 300 --algos ppo --evaluations 20

For each scenario, algorithm and training seed: (a) **continued**, an agent trained `--before`
episodes before the change and `--after` more after it, unchanged (the schedule changes the line:
the agent is not told); (b) **frozen**, its snapshot at the change, evaluated on the changed line
without further learning; (c) **from scratch**, a new agent trained `--after` episodes on the changed
line; (d) **shrink-and-perturb**, (a)'s agent shrunk and perturbed at the change (Ash & Adams 2020)
and trained on; (e) **new, cloned from the oracle**, (c) fitted first to the exact oracle's
episodes; each also evaluated on the line before the change (forgetting); against rba,
rba-hold and random (`sorting_line eval`, offline) and the oracle. Scenarios
(`--scenarios`, default `upgrade drift`): ``transfer_cells.SCENARIOS``, the ready schedules of the
same names in `evolutions/` (docs/evolving.md says what each changes), with the change moved to
episode `--before` + 1; a `--out` written by the study's first version takes only its two.
What a cell runs: ``transfer_cells``; the statistics: ``reports.transfer_report``.

Each finished cell is saved at once in `<out>/cells/` (whole or not at all); a rerun of the same
command skips the finished cells and goes on, and a run with other result-changing options
(`--before`, `--after`, `--evaluations`, `--ppo-settings` and the other hyperparameters, the
schedules) into the same `--out` is refused. `--max-cells N` stops after N cells (to split a study
into sittings); Ctrl-C keeps the finished cells. A progress bar (plain lines when stderr is not a
terminal) projects the end time. `--ray ADDRESS` runs each cell (or batch) as a task of that Ray
cluster (``ray_cells``; the schedules go with it, its models come back), the store staying here.
`--engine batched` trains the cells of one scenario, kind and algorithm (their seeds differ) at once
with the batched trainer, on native lines (its default backend; `--backend ros` is refused), and
saves each seed's cell as `--engine sb3` (the default) does, with the engine in its record and in
the store's key, so the two engines' cells never mix; a rerun trains only the missing seeds.
Writes `transfer.json` (the statistics), `transfer.md` (the tables), `transfer.png`/`.svg` (training
curves around the change) and `transfer_runs.png`/`.svg` (each strategy's runs beside its interval).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path

from ..agents.learned_policy import TRAIN_HINT, missing_training_stack
from ..envs.native import BACKENDS
from ..reports import transfer_report
from . import cell_pool
from . import transfer_cells as tc
from .cell_store import CellProgress, CellStore, ConfigurationMismatch, write_atomic

#: --full: the paper's scale (2000 episodes = 100,000 steps, the paper's training budget).
FULL = {"before": 2000, "after": 2000, "seeds": [1, 2, 3, 4, 5], "evaluations": 100}
#: --smoke: every step of the pipeline, in about a minute per cell kind.
SMOKE = {"before": 10, "after": 10, "seeds": [1, 2], "evaluations": 3}
DEFAULTS = {"before": 200, "after": 200, "seeds": [1, 2, 3], "evaluations": 20}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sorting-line-transfer", description=__doc__.split("\n\n")[0])
    preset = p.add_mutually_exclusive_group()
    preset.add_argument("--full", action="store_true", help=f"the paper's scale: {FULL} (options given override it)")
    preset.add_argument("--smoke", action="store_true", help=f"CI size: {SMOKE} (options given override it)")
    p.add_argument(
        "--scenarios",
        nargs="+",
        choices=tc.SCENARIOS,
        default=list(tc.FIRST_SCENARIOS),
        help=f"default: {' '.join(tc.FIRST_SCENARIOS)}",
    )
    p.add_argument("--algos", nargs="+", choices=tc.ALGOS, default=list(tc.ALGOS), help="default: ppo a2c")
    p.add_argument(
        "--ppo-settings",
        choices=tc.PPO_SETTINGS,
        default="study",
        help="PPO's hyperparameters: study (SB3's defaults on 10-episode rollouts; default) or paper "
        "(the paper's gamma, learning rate and entropy coefficient on the same rollouts)",
    )
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        default=None,
        help="ros: each cell's line a node over ROS 2; native: the line in-process (same cells) "
        "(default ros; native with --engine batched)",
    )
    p.add_argument(
        "--engine",
        choices=tc.ENGINES,
        default="sb3",
        help="who trains the agents: sb3, cell by cell (default), or batched: the seeds of a scenario, kind and "
        "algorithm at once (training/batched; native lines), each seed still a cell of its own",
    )
    p.add_argument("--seeds", type=int, nargs="+", help=f"training seeds (default {DEFAULTS['seeds']})")
    p.add_argument("--before", type=int, help=f"episodes before the change (default {DEFAULTS['before']})")
    p.add_argument("--after", type=int, help=f"episodes after it, and from scratch (default {DEFAULTS['after']})")
    p.add_argument(
        "--evaluations",
        type=int,
        help=f"held-out evaluation episodes, seeds {tc.EVAL_SEED}... (default {DEFAULTS['evaluations']})",
    )
    p.add_argument(
        "--out", type=Path, default=Path("results/transfer"), help="results directory (default results/transfer)"
    )
    p.add_argument(
        "--jobs", type=int, default=1, help="cells run at once, each in its own process and node (default 1)"
    )
    p.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run each cell (with --engine batched: each batch) as a task of the Ray cluster at ADDRESS "
        "(HOST:PORT, ray://HOST[:PORT] or auto), one CPU each; the cells, models and resume stay here in --out; "
        "not with --jobs (docs/benchmark.md)",
    )
    p.add_argument("--max-cells", type=int, help="stop after running this many cells (the rest on the next run)")
    p.add_argument("--report-only", action="store_true", help="train nothing: the report of the cells saved in --out")
    return p


def options(argv: list[str] | None):
    """The parsed options with the preset's values filled in; exits 2 naming a bad value."""
    parser = build_parser()
    args = parser.parse_args(argv)
    preset = FULL if args.full else SMOKE if args.smoke else DEFAULTS
    for name, value in preset.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if args.before < tc.WINDOW or args.before % tc.WINDOW:
        parser.error(
            f"--before = {args.before} is not valid: allowed a multiple of {tc.WINDOW}, at least {tc.WINDOW} "
            "(PPO's rollout is 10 episodes: the snapshot must be taken at the change)"
        )
    if args.after < tc.WINDOW or args.after % tc.WINDOW:
        parser.error(f"--after = {args.after} is not valid: allowed a multiple of {tc.WINDOW}, at least {tc.WINDOW}")
    if len(set(args.seeds)) != len(args.seeds) or min(args.seeds) < 0:
        parser.error(
            f"--seeds {' '.join(map(str, args.seeds))} is not valid: allowed distinct training seeds, each 0 or more"
        )
    if args.evaluations < 1:
        parser.error(f"--evaluations = {args.evaluations} is not valid: allowed 1 or more")
    if args.jobs < 1:
        parser.error(f"--jobs = {args.jobs} is not valid: allowed 1 or more")
    if args.ray is not None and args.jobs != 1:
        parser.error(
            f"--jobs {args.jobs} with --ray is not valid: on a cluster as many cells run at once as it has CPUs; "
            "allowed --ray without --jobs (or --jobs without --ray, on this machine)"
        )
    if args.max_cells is not None and args.max_cells < 1:
        parser.error(f"--max-cells = {args.max_cells} is not valid: allowed 1 or more")
    if args.backend is None:
        args.backend = "native" if args.engine == "batched" else "ros"
    if args.engine == "batched" and args.backend != "native":
        parser.error(
            f"--engine batched --backend {args.backend} is not valid: the batched trainer trains on native lines; "
            "allowed --backend native with --engine batched (or --engine sb3 for ROS)"
        )
    args.settings = tc.Settings(args.before, args.after, args.evaluations, args.ppo_settings, args.backend)
    return args


def kind_of(name: str) -> str:
    """A cell's kind for the projection: baselines, or an algorithm's transfer or scratch cells."""
    parts = name.split("_")
    return "baselines" if parts[-1] == "baselines" else f"{parts[1]}_{parts[2]}"


def run_cells(todo: list[tc.Cell], store: CellStore, args, done: dict[str, dict]) -> int:
    """Runs ``todo`` (the first ``--max-cells`` of them), ``--jobs`` at a time, saving each as it
    finishes; 0, 1 if a cell failed (the others go on), 130 if interrupted. The projection is of
    the whole study."""
    times = {n: r["seconds"] for n, r in done.items()}
    parallel, at_once = args.jobs, f"{args.jobs} at a time"
    if args.ray is not None:
        from .ray_cells import capacity

        parallel, at_once = capacity(), f"on the Ray cluster at {args.ray} ({capacity()} CPUs now)"
    progress = CellProgress([c.name for c in todo], times, kind_of, "transfer", parallel=parallel)
    limit = f" ({args.max_cells} of them now: --max-cells)" if args.max_cells is not None else ""
    progress.line(
        f"transfer: {len(todo) + len(done)} cells, {len(done)} already done, {len(todo)} to run{limit}, "
        f"{at_once} -> {args.out}"
    )
    failed = []

    def finished(cell: tc.Cell, outcome) -> None:
        if isinstance(outcome, Exception):
            failed.append(cell.name)
            progress.line(f"{cell.name}: FAILED: {outcome!r}")
            return
        done[cell.name] = store.save(cell.name, outcome)
        progress.done(cell.name, outcome["seconds"])

    def running(cells: list[tc.Cell]) -> None:
        progress.bar.set_description_str(", ".join(c.name for c in cells))

    try:
        batch = todo[: args.max_cells]
        if args.ray is not None:
            _run_on_cluster(batch, args, finished, running)
        elif args.engine == "batched":
            _run_batches(batch, args, finished, running, progress)
        elif args.jobs == 1:
            for cell in batch:
                running([cell])
                finished(cell, _outcome(cell, args))
        else:
            cell_pool.run_parallel(
                batch, lambda c: (tc.run_cell, c, args.settings, args.out), args.jobs, finished, running
            )
    except KeyboardInterrupt:
        progress.line(f"interrupted: {len(done)} cells are saved in {args.out}; the same command goes on from there")
        return 130
    finally:
        progress.close()
    return 1 if failed else 0


def _run_on_cluster(todo: list[tc.Cell], args, finished, running) -> None:
    """``run_cells`` with ``--ray``: each cell (with ``--engine batched``, each of ``tc.batches``) a
    task of the cluster, with the scenarios' schedules; the records are saved here as they come."""
    from . import ray_cells

    schedules = {p.relative_to(args.out).as_posix(): p.read_bytes() for p in (args.out / "schedules").glob("*")}
    if args.engine != "batched":
        call = lambda c: (tc.run_cell, c, args.settings, args.out)  # noqa: E731
        ray_cells.run_on_cluster(todo, call, args.out, finished, running, schedules)
        return

    def unit_finished(cells: list[tc.Cell], outcome) -> None:
        for i, cell in enumerate(cells):
            finished(cell, outcome if isinstance(outcome, Exception) else outcome[i])

    ray_cells.run_on_cluster(
        tc.batches(todo),
        lambda unit: (_unit, unit, args.settings, args.out),
        args.out,
        unit_finished,
        lambda units: running([c for u in units for c in u]),
        schedules,
    )


def _run_batches(todo: list[tc.Cell], args, finished, running, progress: CellProgress) -> None:
    """``run_cells`` with ``--engine batched``: ``tc.batches(todo)``, ``--jobs`` at a time; in this
    process each cell is saved as soon as it is evaluated."""

    def unit_finished(cells: list[tc.Cell], outcome) -> None:
        if isinstance(outcome, Exception):
            for cell in cells:
                if cell.name not in saved:
                    finished(cell, outcome)
            return
        for cell, record in zip(cells, outcome, strict=True):
            if cell.name not in saved:
                finished(cell, record)
        batch = outcome[-1].get("batch")
        if batch:
            progress.line(f"batch of {len(batch['seeds'])} seeds: {batch['steps_per_s']:,.0f} steps/s over all seeds")

    saved: set[str] = set()

    def one(cell: tc.Cell, record) -> None:
        saved.add(cell.name)
        finished(cell, record)

    units = tc.batches(todo)
    if args.jobs == 1:
        for unit in units:
            running(unit)
            try:
                if unit[0].kind == "baselines":
                    outcome = [tc.run_cell(unit[0], args.settings, args.out)]
                else:
                    outcome = tc.run_batch(unit, args.settings, args.out, progress.tty, one)
            except Exception as e:  # noqa: BLE001 - report every failed batch, keep the others
                outcome = e
            unit_finished(unit, outcome)
        return
    cell_pool.run_parallel(units, lambda unit: (_unit, unit, args.settings, args.out), args.jobs, unit_finished,
                           lambda units: running([c for u in units for c in u]))  # fmt: skip


def _unit(cells: list[tc.Cell], settings: tc.Settings, out: Path) -> list[dict]:
    """The records of one of ``tc.batches`` (in a worker)."""
    if cells[0].kind == "baselines":
        return [tc.run_cell(cells[0], settings, out)]
    return tc.run_batch(cells, settings, out)


def _outcome(cell: tc.Cell, args):
    """The record of ``cell`` run in this process, or the exception it raised."""
    try:
        return tc.run_cell(cell, args.settings, args.out)
    except Exception as e:  # noqa: BLE001 - report every failed cell, keep the others
        return e


def report(args, key: dict, done: dict[str, dict]) -> str:
    records = list(done.values())
    summary = transfer_report.summarize(records, key, args.scenarios, args.algos)
    write_atomic(args.out / "transfer.json", {"key": key, "summary": summary})
    text = transfer_report.markdown(summary, key)
    (args.out / "transfer.md").write_text(text)
    transfer_report.plot(records, summary, key, args.out / "transfer")
    transfer_report.runs_plot(summary, args.out / "transfer_runs")
    return text


def study_key(args) -> dict:
    """The key of the study's cells: the options that change results, with the schedules of every
    scenario, or of the first two where ``--out`` holds a store of the first version
    (``tc.key_scenarios``, which raises ``tc.OlderStore`` if it is asked for the others there)."""
    study = args.out / "study.json"
    saved = json.loads(study.read_text()).get("key") if study.is_file() else None
    key = args.settings.key(scenarios=tc.key_scenarios(saved, args.scenarios, str(args.out)))
    if args.engine != "sb3":  # an SB3 store's key stays as it was before there were two engines
        key["engine"] = args.engine
    return key


def main(argv: list[str] | None = None) -> int:
    args = options(argv)
    # Its cells train agents, and its configuration's key holds their SB3 hyperparameters.
    if missing := missing_training_stack():
        print(
            f"sorting-line-transfer: needs {' and '.join(missing)}, the training stack: {TRAIN_HINT}", file=sys.stderr
        )
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    earlier = args.out / "transfer.json"
    if earlier.is_file() and "runs" in json.loads(earlier.read_text()):
        print(
            f"sorting-line-transfer: {earlier} holds the runs of the earlier sorting-line-transfer (before cells): "
            "use another --out, so that they are kept",
            file=sys.stderr,
        )
        return 2
    try:
        key = study_key(args)
        store = CellStore(args.out, key)
    except ConfigurationMismatch as e:  # tc.OlderStore too
        print(f"sorting-line-transfer: {e}", file=sys.stderr)
        return 2
    cells = tc.plan(args.scenarios, args.algos, args.seeds)
    done = {c.name: r for c in cells if (r := store.load(c.name)) is not None}
    for name in [] if args.report_only else [n for n, r in done.items() if tc.outdated(r)]:
        print(f"sorting-line-transfer: {name}: {tc.outdated(done.pop(name))}", file=sys.stderr)
    todo = [] if args.report_only else [c for c in cells if c.name not in done]
    status = 0
    if todo:
        if args.ray is not None:
            from .ray_cells import ClusterError, connect

            try:
                connect(args.ray)
            except ClusterError as e:
                print(f"sorting-line-transfer: {e}", file=sys.stderr)
                return 2
        store.begin(sys.argv if argv is None else ["sorting-line-transfer", *argv])
        for scenario in args.scenarios:
            tc.schedules(scenario, args.before, args.out)
        signal.signal(signal.SIGTERM, cell_pool.interrupt)
        status = run_cells(todo, store, args, done)
    if not done:
        print("sorting-line-transfer: no finished cells to report", file=sys.stderr)
        return 1
    print(report(args, key, done))
    left = len([c for c in cells if c.name not in done])
    print(
        f"sorting-line-transfer: {len(done)} of {len(cells)} cells done"
        + (f"; {left} left: the same command goes on" if left else "")
        + f"; wrote {args.out}/transfer.{{json,md,png,svg}}",
        file=sys.stderr,
    )
    return status


if __name__ == "__main__":
    sys.exit(main())
