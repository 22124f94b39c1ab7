"""`sorting-line-benchmark`: the paper's Table 1 and Figure 7, reproduced through ROS 2.

    sorting-line-benchmark                                   # everything: 8 lines x 6 agents
    sorting-line-benchmark --setups B D --agents rba rba-hold ppo --train-seeds 42 43 44
    sorting-line-benchmark --agents random rba rba-hold      # baselines only, about a minute

For every setup (A-D) and variant (basic, advanced) it evaluates the baselines (random, rba,
rba-hold) and, for each training seed, trains DQN, PPO and A2C with the paper's hyperparameters
(``sorting-line-train``) and evaluates the model; evaluation is ``sorting-line-eval``'s protocol
(seeds 42..51, 50 steps, deterministic). Every line is a real node process stepped over DDS.

Each finished cell is saved at once in ``<out>/cells/`` (models in ``<out>/models/``), so an
interrupted run picks up where it stopped: a rerun skips cells already done with the same budget.
``--jobs N`` runs N cells at once (each its own node and process). When the cells are in, it
writes ``<out>/table.md`` and ``table.json`` (our figures beside the paper's Table 1 and the
reference implementation's), ``figure7.png``/``.svg`` (mean reward per setup and agent),
``figure3.png``/``.svg`` (the reward analysis behind the rule-based agent) and the seed-42
dashboard of every agent in ``<out>/dashboards/``. ``--report-only`` redraws from saved cells.
Ctrl-C or SIGTERM stops it within seconds, workers and their nodes included (exit 130); the
cells that finished are kept.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import signal
import statistics
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Optional

from ..line.vocabulary import SETUPS, VARIANTS
from ..training.hyperparams import ALGOS

BASELINES = ("random", "rba", "rba-hold")
AGENTS = BASELINES + ALGOS
#: Row order of the table: the paper's within a line (RBA, DQN, PPO, A2C), our extras first.
TABLE_ORDER = ("random", "rba", "rba-hold", "dqn", "ppo", "a2c")
DEFAULT_SEEDS = (42,)


@dataclass(frozen=True)
class Cell:
    """One evaluation of the benchmark: an agent on a line (and its training seed, for RL)."""

    setup: str
    variant: str
    agent: str
    train_seed: Optional[int] = None

    @property
    def name(self) -> str:
        seed = f"_seed{self.train_seed}" if self.train_seed is not None else ""
        return f"{self.setup}_{self.variant}_{self.agent}{seed}"


def plan(setups, variants, agents, train_seeds) -> list[Cell]:
    """Baselines first (quick), then RL cells by training seed and algorithm, in the order given,
    so a partial run has whole rows: one algorithm on every line before the next."""
    cells = [Cell(s, v, a) for s in setups for v in variants for a in agents if a in BASELINES]
    cells += [Cell(s, v, a, seed) for seed in train_seeds for a in agents if a in ALGOS for s in setups for v in variants]
    return cells


def run_cell(cell: Cell, out: Path, timesteps: int, n_envs: int, progress: bool) -> dict[str, Any]:
    """Trains (RL) and evaluates one cell; writes and returns its record. Runs in a worker."""
    from ..training import hyperparams
    from .evaluate import evaluate
    from ..training.train import train

    start = time.perf_counter()
    record: dict[str, Any] = {"cell": asdict(cell), "timesteps": timesteps if cell.agent in ALGOS else None}
    spec = cell.agent
    if cell.agent in ALGOS:
        params = hyperparams.load(cell.agent, cell.variant, overrides=[f"n_timesteps={timesteps}", f"n_envs={n_envs}"])
        run = train(
            cell.agent, cell.setup, cell.variant, seed=cell.train_seed, out=out / "models", params=params,
            tensorboard=out / "tensorboard", progress=progress,
        )
        record["training"] = asdict(run)
        spec = f"{cell.agent}:{run.model_path}"
    dashboard = out / "dashboards" / f"{cell.name}.png"  # the first evaluation episode, seed 42
    dashboard.parent.mkdir(parents=True, exist_ok=True)
    record["evaluation"] = asdict(evaluate(spec, cell.setup, cell.variant, dashboard=dashboard))
    record["wall_s"] = time.perf_counter() - start
    path = out / "cells" / f"{cell.name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(record, indent=2) + "\n")
    tmp.replace(path)  # a cell file is whole or absent, even if the run is killed while writing
    return record


def load_cell(cell: Cell, out: Path, timesteps: int) -> Optional[dict[str, Any]]:
    """The saved record of ``cell`` if it was run with the same budget."""
    path = out / "cells" / f"{cell.name}.json"
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text())
    except json.JSONDecodeError:
        return None
    if cell.agent in ALGOS and record.get("timesteps") != timesteps:
        return None
    return record


# ------------------------------------------------------------------------------------------
# Aggregation


def summarize(records: list[dict[str, Any]]) -> dict[tuple[str, str, str], dict[str, Any]]:
    """Per (setup, variant, agent): reward mean and std. Baselines: over the 10 evaluation
    episodes. RL: the mean over training seeds of each model's mean, with the std across training
    seeds (and the per-episode std when there is a single seed)."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in records:
        c = r["cell"]
        groups.setdefault((c["setup"], c["variant"], c["agent"]), []).append(r)
    rows = {}
    for key, rs in groups.items():
        evals = [r["evaluation"] for r in rs]
        means = [e["reward_mean"] for e in evals]
        seeds = len(rs)
        rows[key] = {
            "reward_mean": statistics.fmean(means),
            "reward_std": statistics.pstdev(means) if seeds > 1 else evals[0]["reward_std"],
            "std_over": "training seeds" if seeds > 1 else "episodes",
            "seeds": seeds,
            "per_seed": means,
            "speed_mean": statistics.fmean(e["speed_mean"] for e in evals),
            "purity_mean": statistics.fmean(e["purity_mean"] for e in evals),
            "speed_changes_mean": statistics.fmean(e["speed_changes_mean"] for e in evals),
            "train_wall_s": statistics.fmean(r["training"]["wall_s"] for r in rs) if "training" in rs[0] else None,
        }
    return rows


def table_markdown(rows: dict[tuple[str, str, str], dict[str, Any]], timesteps: int, agents=AGENTS) -> str:
    """Our figures beside the paper's and the reference's, for ``agents`` on every line that has
    results ("not run" marks a requested agent whose cells are missing)."""
    from .paper import REFERENCE, TABLE_1, TABLE_1_INDEX

    lines = [
        "| index | setup | env | agent | ours: reward | ours: speed % | ours: purity % | speed changes | paper: reward | paper: speed % | paper: purity % | reference impl.: reward |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ran = {(s, v) for s, v, _ in rows}
    for setup in SETUPS:
        for variant in VARIANTS:
            if (setup, variant) not in ran:
                continue
            shown = [a for a in TABLE_ORDER if a in agents]
            best = max(rows[(setup, variant, a)]["reward_mean"] for a in shown if (setup, variant, a) in rows)
            for agent in shown:
                key = (setup, variant, agent)
                row = rows.get(key)
                paper = TABLE_1.get(key)
                ref = REFERENCE.get(key)
                if row is None and paper is None:
                    continue
                if row is None:
                    ours = "not run"
                else:
                    mean = f"{row['reward_mean']:.2f}"
                    ours = (
                        (f"**{mean}**" if row["reward_mean"] == best else mean)
                        + f" +- {row['reward_std']:.2f}"
                        + (f" ({row['seeds']} seeds)" if row["seeds"] > 1 else "")
                    )
                lines.append(
                    "| "
                    + " | ".join(
                        [
                            TABLE_1_INDEX.get(key, ""),
                            setup,
                            "Adv" if variant == "advanced" else "Basic",
                            agent,
                            ours,
                            f"{100 * row['speed_mean']:.0f}" if row else "",
                            f"{100 * row['purity_mean']:.1f}" if row else "",
                            f"{row['speed_changes_mean']:.1f}" if row else "",
                            f"{paper[2]:.2f}" if paper else "",
                            f"{paper[0]:g}" if paper else "",
                            f"{paper[1]:g}" if paper else "",
                            f"{ref[0]:.2f} +- {ref[1]:.2f}" if ref else "",
                        ]
                    )
                    + " |"
                )
    note = (
        f"\nEpisode reward over seeds 42..51 (50 steps, deterministic policy): mean +- population std over the 10 episodes,"
        f" or, for RL agents trained with more than one seed, the mean over training seeds +- the std across them."
        f" RL agents trained for {timesteps} steps with the paper's hyperparameters. The paper's Table 1 has no random or"
        f" rba-hold rows, and its RBA figures are not what the reference implementation's code gives on the same protocol"
        f" (last column). Bold: our best agent on the line."
    )
    return "\n".join(lines) + "\n" + note + "\n"


def write_report(out: Path, records: list[dict[str, Any]], timesteps: int, agents=AGENTS) -> list[Path]:
    from .plots import analysis_figure, benchmark_figure

    rows = summarize(records)
    table = out / "table.md"
    table.write_text(f"# Benchmark: Table 1 through ROS 2\n\n{table_markdown(rows, timesteps, agents)}")
    (out / "table.json").write_text(
        json.dumps([{"setup": s, "variant": v, "agent": a, **row} for (s, v, a), row in sorted(rows.items())], indent=2) + "\n"
    )
    written = [table, out / "table.json"]
    written += benchmark_figure(rows, out / "figure7")
    written += analysis_figure(out / "figure3")
    return written


# ------------------------------------------------------------------------------------------
# Command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sorting-line-benchmark", description="The paper's Table 1 and Figure 7 through ROS 2; resumable.")
    p.add_argument("--out", type=Path, default=Path("results/benchmark"), help="results directory (default results/benchmark)")
    p.add_argument("--setups", nargs="+", default=list(SETUPS), choices=list(SETUPS))
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    p.add_argument("--agents", nargs="+", default=list(AGENTS), choices=AGENTS)
    p.add_argument("--train-seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS), help="training seeds of the RL agents (default 42)")
    p.add_argument("--timesteps", type=int, default=100_000, help="training budget per RL agent (default 100000, the paper's)")
    p.add_argument("--n-envs", type=int, default=1, help="lines per training (default 1, as the paper)")
    p.add_argument("--jobs", type=int, default=1, help="cells run at once, each in its own process and node (default 1)")
    p.add_argument("--report-only", action="store_true", help="only redraw the table and figures from saved cells")
    return p


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _die_with_the_benchmark() -> None:
    """Worker initializer: the kernel kills this worker when the benchmark process dies, however
    it dies (a worker in an rclpy wait ignores SIGTERM, and a killed benchmark runs no handler)."""
    import ctypes

    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Kills the pool's workers at once (their nodes get SIGTERM through their parent-death
    signal): a worker would otherwise finish its cell, a training of several minutes, and rclpy's
    own SIGTERM handler keeps it from dying of the signal."""
    for child in multiprocessing.active_children():
        child.kill()
    pool.shutdown(wait=False, cancel_futures=True)


def run_all(todo: list[Cell], args, finished, bar) -> None:
    """Runs the cells, ``args.jobs`` at a time; ``finished(cell, record or exception)`` for each."""
    if args.jobs == 1:
        # In this process, with SB3's progress bar for each training.
        for cell in todo:
            bar.set_postfix_str(cell.name)
            try:
                outcome = run_cell(cell, args.out, args.timesteps, args.n_envs, True)
            except Exception as e:  # noqa: BLE001 - report every failed cell, keep the others
                outcome = e
            finished(cell, outcome)
        return
    # rclpy is not fork-safe: workers start fresh interpreters. Only this bar, with the cells running.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context, initializer=_die_with_the_benchmark) as pool:
        try:
            pending = {}
            queue = list(todo)
            while queue or pending:
                while queue and len(pending) < args.jobs:
                    cell = queue.pop(0)
                    pending[pool.submit(run_cell, cell, args.out, args.timesteps, args.n_envs, False)] = cell
                    bar.set_postfix_str(", ".join(c.name for c in pending.values()))
                complete, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in complete:
                    cell = pending.pop(future)
                    try:
                        outcome = future.result()
                    except Exception as e:  # noqa: BLE001
                        outcome = e
                    finished(cell, outcome)
        except KeyboardInterrupt:
            _stop_workers(pool)  # before the with-block's shutdown, which would wait for the cells
            raise


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    args = build_parser().parse_args(argv)
    for flag, value in (("--timesteps", args.timesteps), ("--n-envs", args.n_envs), ("--jobs", args.jobs)):
        if value < 1:
            print(f"sorting-line-benchmark: {flag} = {value} is not valid: allowed 1 or more", file=sys.stderr)
            return 2
    cells = plan(args.setups, args.variants, args.agents, args.train_seeds)
    done = {c: r for c in cells if (r := load_cell(c, args.out, args.timesteps)) is not None}
    todo = [c for c in cells if c not in done]
    if args.report_only:
        todo = []
    print(f"benchmark: {len(cells)} cells, {len(done)} already done, {len(todo)} to run, {args.jobs} at a time -> {args.out}", file=sys.stderr)
    failures = []
    if todo:
        signal.signal(signal.SIGTERM, _interrupt)
        bar = tqdm(total=len(cells), initial=len(done), unit="cell", desc="benchmark", file=sys.stderr, dynamic_ncols=True)

        def finished(cell: Cell, outcome) -> None:
            if isinstance(outcome, Exception):
                failures.append((cell, outcome))
                bar.write(f"{cell.name}: FAILED: {outcome}")
            else:
                done[cell] = outcome
                r = outcome["evaluation"]
                bar.write(f"{cell.name}: {r['reward_mean']:.2f} +- {r['reward_std']:.2f} ({outcome['wall_s']:.0f} s)")
            bar.update(1)

        try:
            run_all(todo, args, finished, bar)
        except KeyboardInterrupt:
            bar.close()
            print(f"sorting-line-benchmark: interrupted; {len(done)} of {len(cells)} cells are saved in {args.out}: "
                  "the same command goes on from there", file=sys.stderr)
            return 130
        bar.close()
    records = [done[c] for c in cells if c in done]
    if not records:
        print("sorting-line-benchmark: no finished cells to report", file=sys.stderr)
        return 1
    for path in write_report(args.out, records, args.timesteps, args.agents):
        print(f"written: {path}", file=sys.stderr)
    print((args.out / "table.md").read_text())
    if failures:
        print(f"sorting-line-benchmark: {len(failures)} cell(s) failed: {', '.join(c.name for c, _ in failures)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
