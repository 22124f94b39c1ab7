"""The engine check's statistics (issue 54, "equal to SB3, statistically"): per algorithm and line,
each engine's mean held-out score over its runs with a 95 % interval, the 95 % interval of the
difference of the means (batched - sb3) by a bootstrap of whole runs, each engine's runs drawn
independently of the other's (two strata: the engines' runs are different trainings), and the
verdict against a margin (+-1.5 reward, about one run-to-run standard deviation).

Verdicts, from the difference's interval [low, high] and the margin m:

- ``within +-m``: the whole interval lies inside [-m, m]: the engines agree to m;
- ``differ``: the whole interval lies outside [-m, m] (beyond m on one side);
- otherwise ``undecided: ~N seeds per engine``: the interval straddles a bound. An interval's width
  shrinks as 1 / sqrt(runs), so with the difference staying where it is, the half-width that fits
  within the margin, m - |point|, asks for about runs * (half-width / (m - |point|))^2 seeds per
  engine (no figure when |point| >= m: more seeds would show a difference, not an agreement).

Also each run's held-out mean (the strip plot's dots) and the learning curves (per step, the mean
over runs and its 95 % interval over runs: ``curves.curve_bands``) of both engines. Pure analysis
of the benchmark's cell records (``studies.benchmark``); the figures are ``plots``'.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import stats
from .curves import curve_bands

#: The issue's margin: about one run-to-run standard deviation of a cell's held-out mean.
MARGIN = 1.5
#: Runs per engine below which a bootstrap interval over runs says nothing.
MIN_RUNS = 3
ENGINE_COLORS = {"sb3": "#1f77b4", "batched": "#ff7f0e"}

Line = tuple[str, str]  # (setup, variant)


def runs_of(records: Sequence[dict[str, Any]], algo: str, line: Line) -> list[dict[str, Any]]:
    """The records of ``algo`` on ``line``, by training seed."""
    rs = [
        r for r in records if r["cell"]["agent"] == algo and (r["cell"]["setup"], r["cell"]["variant"]) == tuple(line)
    ]
    return sorted(rs, key=lambda r: r["cell"]["train_seed"])


def scores(records: Sequence[dict[str, Any]]) -> np.ndarray:
    """runs x held-out seeds: each run's summed reward on each held-out seed."""
    return np.array([[e["reward"] for e in r["heldout"]["per_episode"]] for r in records], dtype=float)


def _difference(batch: list[np.ndarray]) -> np.ndarray:
    """Mean of the second stratum (batched) - mean of the first (sb3), per resample."""
    return batch[1].mean(axis=(1, 2)) - batch[0].mean(axis=(1, 2))


def difference_interval(sb3: np.ndarray, batched: np.ndarray) -> stats.Interval:
    """batched - sb3 mean score, with the 95 % interval: whole runs drawn, each engine's own."""
    return stats.run_bootstrap([sb3, batched], _difference)


def verdict(diff: stats.Interval, runs: int, margin: float = MARGIN) -> str:
    """The module docstring's verdict for the difference ``diff`` over ``runs`` runs per engine."""
    if -margin <= diff.low and diff.high <= margin:
        return f"within +-{margin:g}"
    if diff.low > margin or diff.high < -margin:
        return f"differ (beyond +-{margin:g})"
    half = (diff.high - diff.low) / 2
    room = margin - abs(diff.point)
    if room <= 0:
        return f"undecided: the difference lies at or beyond +-{margin:g}"
    return f"undecided: ~{math.ceil(runs * (half / room) ** 2)} seeds per engine"


def compare(
    by_engine: dict[str, Sequence[dict[str, Any]]], algo: str, line: Line, margin: float = MARGIN
) -> dict[str, Any]:
    """One row of the table: per engine its runs, mean and interval; the difference and verdict
    when both engines have at least MIN_RUNS runs."""
    row: dict[str, Any] = {"algo": algo, "setup": line[0], "variant": line[1]}
    arrays = {}
    for engine, records in by_engine.items():
        rs = runs_of(records, algo, line)
        if not rs:
            continue
        arrays[engine] = scores(rs)
        row[engine] = {
            "runs": len(rs),
            "seeds": [r["cell"]["train_seed"] for r in rs],
            "per_run": arrays[engine].mean(axis=1).tolist(),
            "mean": stats.mean_interval(arrays[engine]).as_dict(),
            "std_over_runs": float(np.std(arrays[engine].mean(axis=1), ddof=1)) if len(rs) > 1 else None,
            "train_wall_s": float(np.mean([r["training"]["wall_s"] for r in rs])),
        }
    if all(e in arrays and arrays[e].shape[0] >= MIN_RUNS for e in ("sb3", "batched")):
        diff = difference_interval(arrays["sb3"], arrays["batched"])
        row["difference"] = diff.as_dict()
        row["verdict"] = verdict(diff, min(arrays["sb3"].shape[0], arrays["batched"].shape[0]), margin)
    else:
        have = {e: arrays[e].shape[0] if e in arrays else 0 for e in ("sb3", "batched")}
        row["verdict"] = f"not yet: runs sb3 {have['sb3']}, batched {have['batched']} (needs {MIN_RUNS} each)"
    return row


def table_markdown(rows: Sequence[dict[str, Any]], margin: float, timesteps: int, heldout_episodes: int) -> str:
    """The table as markdown, one row per algorithm x line."""

    def side(row, engine):
        s = row.get(engine)
        if s is None:
            return "-", "0"
        m = s["mean"]
        return f"{m['point']:.2f} [{m['low']:.2f}, {m['high']:.2f}]", str(s["runs"])

    lines = [
        "| algo | line | sb3: runs | sb3: mean [95% CI] | batched: runs | batched: mean [95% CI] "
        "| batched - sb3 [95% CI] | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        (sb3, n_sb3), (bat, n_bat) = side(row, "sb3"), side(row, "batched")
        d = row.get("difference")
        diff = f"{d['point']:+.2f} [{d['low']:+.2f}, {d['high']:+.2f}]" if d else "-"
        line = f"{row['setup']} {row['variant']}"
        lines.append(f"| {row['algo']} | {line} | {n_sb3} | {sb3} | {n_bat} | {bat} | {diff} | {row['verdict']} |")
    note = (
        f"\nMean over runs of each run's mean summed reward on {heldout_episodes} held-out seeds, after "
        f"{timesteps} training steps; intervals: 95 % percentile bootstrap over whole runs (a run's scores on "
        "every held-out seed drawn together), the difference's with each engine's runs drawn independently. "
        f"Verdict against +-{margin:g} (reports/engine_check.py says how).\n"
    )
    return "\n".join(lines) + "\n" + note


def write_report(
    out: Path,
    by_engine: dict[str, Sequence[dict[str, Any]]],
    algos: Sequence[str],
    lines: Sequence[Line],
    *,
    margin: float = MARGIN,
    timesteps: int,
    heldout_episodes: int,
) -> list[Path]:
    """``engine_check.md``, ``.json``, ``.csv``, ``engine_check_runs.png`` (strip plot: every run)
    and ``engine_check_curves.png`` (both engines' curves, one over the other) in ``out``."""
    from .plots import CurvePanel, CurveSeries, Strip, StripPanel, curve_figure, strip_figure

    rows = [compare(by_engine, a, tuple(line), margin) for line in lines for a in algos]
    out.mkdir(parents=True, exist_ok=True)
    md, js, cv = out / "engine_check.md", out / "engine_check.json", out / "engine_check.csv"
    md.write_text(f"# Engine check: batched against SB3\n\n{table_markdown(rows, margin, timesteps, heldout_episodes)}")
    curves = {
        f"{a} {s} {v}": {e: curve_bands(runs_of(rs, a, (s, v))) for e, rs in by_engine.items()}
        for (s, v) in lines
        for a in algos
    }
    js.write_text(json.dumps({"margin": margin, "timesteps": timesteps, "rows": rows, "curves": curves}, indent=1))
    with cv.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["algo", "setup", "variant", "engine", "runs", "mean", "low", "high",
                    "diff", "diff_low", "diff_high", "verdict"])  # fmt: skip
        for row in rows:
            d = row.get("difference") or {}
            for e in ("sb3", "batched"):
                s = row.get(e)
                if s is None:
                    continue
                m = s["mean"]
                w.writerow([row["algo"], row["setup"], row["variant"], e, s["runs"], m["point"], m["low"], m["high"],
                            d.get("point"), d.get("low"), d.get("high"), row["verdict"]])  # fmt: skip
    panels = []
    for row in rows:
        strips = [Strip(e, row[e]["per_run"], row[e]["mean"], ENGINE_COLORS[e]) for e in ("sb3", "batched") if e in row]
        panels.append(StripPanel(f"{row['algo']} {row['setup']} {row['variant']}: {row['verdict']}", strips))
    written = [md, js, cv]
    xlabel = "held-out reward: a dot per run (its mean over the seeds), tick: mean over runs, bar: its 95% CI"
    written += strip_figure(panels, out / "engine_check_runs", xlabel, columns=3)
    curve_panels = [
        CurvePanel(
            title,
            [
                CurveSeries(f"{e} ({b['runs']} runs)", b["steps"], b["mean"], b["low"], b["high"], ENGINE_COLORS[e])
                for e, b in per_engine.items()
                if b is not None
            ],
        )
        for title, per_engine in curves.items()
    ]
    written += curve_figure(curve_panels, out / "engine_check_curves", "training steps", "mean held-out reward")
    return written
