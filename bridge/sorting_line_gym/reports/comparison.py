"""A user's agent beside Table 1 (`sorting-line-benchmark --compare MY_RESULTS`), with Table 1's own
statistics: per line, their agent's mean and IQM over runs x held-out seeds with intervals over
whole runs, its score normalized per seed by the table's random and oracle rows, and P(theirs >
each of ours) with its interval over whole runs of both (``stats``' functions, unchanged).

Both sides are rows of ``results_csv`` (the table's ``results.csv`` and the user's file in the
same columns). :func:`mismatch` says what in the user's rows does not fit the table, before
anything is computed or drawn: a line the table does not have, held-out seeds other than the
table's, fewer than ``MIN_RUNS`` runs (an interval over runs needs two). Pure; no ROS, no training.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..training.hyperparams import ALGOS
from . import stats
from .benchmark_summary import BASELINES, TABLE_ORDER, References, normalized_summary
from .plots import AGENT_COLORS, Strip, StripPanel, strip_figure
from .results_csv import ResultRow

#: Runs an agent needs for an interval over runs.
MIN_RUNS = 2
#: Our agents, in Table 1's order (the oracle is a reference, not a competitor).
OURS = tuple(a for a in TABLE_ORDER if a in BASELINES + ALGOS)
#: How many seeds an error lists before "...".
_SHOWN = 5
YOURS_COLOR = "#000000"


@dataclass(frozen=True)
class Runs:
    """One agent on one line: its runs (rows: training seeds) x held-out seeds (ascending)."""

    train_seeds: tuple[int | None, ...]
    seeds: tuple[int, ...]
    rewards: np.ndarray


def _grouped(rows: list[ResultRow]) -> dict[tuple[str, str, str], dict[int | None, dict[int, float]]]:
    """(setup, variant, agent) -> training seed -> held-out seed -> reward."""
    found: dict[tuple[str, str, str], dict[int | None, dict[int, float]]] = {}
    for r in rows:
        found.setdefault((r.setup, r.variant, r.agent), {}).setdefault(r.train_seed, {})[r.heldout_seed] = r.reward
    return found


def runs_of(rows: list[ResultRow]) -> dict[tuple[str, str, str], Runs]:
    """Per (setup, variant, agent): its runs, which must all be on the same held-out seeds."""
    found = {}
    for key, by_run in _grouped(rows).items():
        train_seeds = tuple(sorted(by_run, key=lambda s: -1 if s is None else s))
        seeds = tuple(sorted(by_run[train_seeds[0]]))
        if any(tuple(sorted(by_run[t])) != seeds for t in train_seeds):
            raise ValueError(f"{key}: the runs are not on the same held-out seeds")
        found[key] = Runs(train_seeds, seeds, np.array([[by_run[t][s] for s in seeds] for t in train_seeds]))
    return found


def _span(seeds) -> str:
    seeds = sorted(seeds)
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}..{seeds[-1]}"
    shown = ", ".join(map(str, seeds[:_SHOWN]))
    return shown + (f", ... ({len(seeds)} seeds)" if len(seeds) > _SHOWN else "")


def mismatch(theirs: list[ResultRow], ours: list[ResultRow]) -> str | None:
    """What in ``theirs`` does not fit the table ``ours``, if anything (the first problem found):
    a line the table does not have, a run on other held-out seeds than the table's on that line,
    an agent with fewer than ``MIN_RUNS`` runs on a line."""
    table: dict[tuple[str, str], set[int]] = {}
    for (setup, variant, _), by_run in _grouped(ours).items():
        table.setdefault((setup, variant), set(next(iter(by_run.values()))))
    for (setup, variant, agent), by_run in sorted(_grouped(theirs).items(), key=lambda kv: str(kv[0])):
        name = f"agent {agent!r} on {setup} {variant}"
        if (setup, variant) not in table:
            lines = ", ".join(f"{s} {v}" for s, v in sorted(table)) or "none"
            return f"{name}: the table has no cells on {setup} {variant}: allowed the table's lines ({lines})"
        expected = table[(setup, variant)]
        for train_seed, rewards in sorted(by_run.items(), key=lambda kv: -1 if kv[0] is None else kv[0]):
            if set(rewards) != expected:
                missing, extra = sorted(expected - set(rewards)), sorted(set(rewards) - expected)
                return (
                    f"{name}, train_seed {train_seed}: held-out seeds {_span(rewards)}, but the table's are "
                    f"{_span(expected)}: allowed exactly those, each once"
                    + (f" (missing: {_span(missing)})" if missing else "")
                    + (f" (not in the table: {_span(extra)})" if extra else "")
                )
        if len(by_run) < MIN_RUNS:
            seeds = ", ".join(str(s) for s in by_run)
            return (
                f"{name} has {len(by_run)} run (train_seed {seeds}): an interval over runs needs at least "
                f"{MIN_RUNS}; allowed {MIN_RUNS} or more training seeds"
            )
    return None


def _references(ours: dict[tuple[str, str, str], Runs], line: tuple[str, str]) -> References | None:
    """The table's random and oracle rewards on each seed of ``line``, where it has both."""
    random, oracle = ours.get((*line, "random")), ours.get((*line, "oracle"))
    if random is None or oracle is None:
        return None
    return References(random.seeds, random.rewards[0], oracle.rewards[0])


def _summary(runs: Runs, refs: References | None) -> dict[str, Any]:
    """Table 1's statistics of one agent on one line (``benchmark_summary.summarize``'s held-out ones)."""
    summary: dict[str, Any] = {
        "runs": len(runs.train_seeds),
        "train_seeds": list(runs.train_seeds),
        "seeds": len(runs.seeds),
        "per_run": runs.rewards.mean(axis=1).tolist(),
        "mean": stats.mean_interval(runs.rewards).as_dict(),
        "iqm": stats.iqm_interval(runs.rewards).as_dict(),
    }
    if refs is not None:
        summary["normalized"] = normalized_summary(refs, runs.seeds, runs.rewards)
    return summary


def compare(theirs: list[ResultRow], ours: list[ResultRow]) -> dict[str, Any]:
    """Per line of ``theirs``: our agents' statistics (``ours``), and each of their agents' with
    P(theirs > each of ours). ``ValueError`` if :func:`mismatch` finds a problem."""
    problem = mismatch(theirs, ours)
    if problem:
        raise ValueError(problem)
    mine, table = runs_of(theirs), runs_of(ours)
    lines: dict[tuple[str, str], dict[str, Any]] = {}
    for (setup, variant, agent), runs in sorted(mine.items()):
        line = (setup, variant)
        refs = _references(table, line)
        if line not in lines:
            ours_here = [a for a in OURS if (*line, a) in table]
            oracle = table.get((*line, "oracle"))
            lines[line] = {
                "setup": setup,
                "variant": variant,
                "ours": {a: _summary(table[(*line, a)], refs) for a in ours_here},
                "oracle_mean": float(oracle.rewards.mean()) if oracle is not None else None,
                "yours": {},
            }
        summary = _summary(runs, refs)
        summary["probability_of_improvement"] = {
            a: stats.probability_of_improvement_interval(runs.rewards, table[(*line, a)].rewards).as_dict()
            for a in lines[line]["ours"]
        }
        lines[line]["yours"][agent] = summary
    return {"lines": list(lines.values())}


def _interval(d: dict[str, float] | None) -> str:
    return "" if d is None else f"{d['point']:.2f} [{d['low']:.2f}, {d['high']:.2f}]"


def _env(variant: str) -> str:
    return "Adv" if variant == "advanced" else "Basic"


def markdown(result: dict[str, Any], source: str) -> str:
    """The comparison as markdown: the scores of ours and theirs per line, then P(theirs > ours)."""
    out = [
        f"# Your agent beside Table 1 ({source})",
        "",
        "| setup | env | agent | runs | held-out: mean [95% CI] | held-out: IQM [95% CI] | normalized: IQM [95% CI] |",
        "|---|---|---|---|---|---|---|",
    ]
    for line in result["lines"]:
        named = [(a, s) for a, s in line["ours"].items()] + [(f"**yours: {a}**", s) for a, s in line["yours"].items()]
        for name, s in named:
            normalized = s.get("normalized", {}).get("iqm")
            cells = [line["setup"], _env(line["variant"]), name, str(s["runs"]), _interval(s["mean"])]
            out.append("| " + " | ".join([*cells, _interval(s["iqm"]), _interval(normalized)]) + " |")
    out += ["", "## P(yours > ours) on the held-out seeds (95% CI)", ""]
    versus = [a for a in OURS if any(a in line["ours"] for line in result["lines"])]
    out += ["| setup | env | yours | " + " | ".join(f"P(> {a})" for a in versus) + " |"]
    out += ["|---|---|---|" + "---|" * len(versus)]
    for line in result["lines"]:
        for agent, s in line["yours"].items():
            p = s["probability_of_improvement"]
            cells = [line["setup"], _env(line["variant"]), agent, *(_interval(p.get(a)) for a in versus)]
            out.append("| " + " | ".join(cells) + " |")
    out += [
        "",
        "Your rows are scored as Table 1's: mean and IQM over runs x held-out seeds, intervals resampling whole runs"
        " (2,000 resamples); normalized per seed by the table's random (0) and oracle (1) rewards on that seed"
        " (empty without a random cell on the line); P(X > Y): the chance that a run of yours beats a run of ours on a"
        " seed, averaged over the seeds (ties half), both sides' runs resampled whole; 0.5 = no difference.",
        "",
    ]
    return "\n".join(out)


def figure(result: dict[str, Any], stem: Path) -> list[Path]:
    """Strip plots per line: every run of ours and of theirs (its held-out mean) over its IQM
    interval, the oracle's mean as a line; beside it, where the line has a random cell, the same
    runs normalized per seed (random 0, oracle 1)."""
    panels = []
    for line in result["lines"]:
        named = [(a, s, AGENT_COLORS.get(a, "#444444")) for a, s in line["ours"].items()]
        named += [(f"yours: {a}", s, YOURS_COLOR) for a, s in line["yours"].items()]
        title = f"{line['setup']} {line['variant']}"
        refs = [("oracle", line["oracle_mean"])] if line["oracle_mean"] is not None else []
        strips = [Strip(a, s["per_run"], s["iqm"], c) for a, s, c in named]
        panels.append(StripPanel(f"{title}: held-out reward", strips, refs))
        normalized = [(a, s["normalized"], c) for a, s, c in named if s.get("normalized", {}).get("seeds")]
        if normalized:
            strips = [Strip(a, n["per_run"], n["iqm"], c) for a, n, c in normalized]
            panels.append(StripPanel(f"{title}: normalized per seed", strips, [("random", 0.0), ("oracle", 1.0)]))
    return strip_figure(
        panels,
        stem,
        "dot: a run's mean over the held-out seeds; tick: IQM; bar: its 95% CI over runs",
        columns=2,
    )
