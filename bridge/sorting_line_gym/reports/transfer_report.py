"""The transfer study's report (`sorting-line-transfer`): statistics, tables and the plot, from
the saved cells (see ``studies.transfer_cells`` for what a cell holds).

Statistics are the benchmark's (``reports.stats``, rliable's method): a *run* is a training seed,
the *tasks* are the held-out evaluation seeds. Per scenario and algorithm:

- each strategy's final score after the change: IQM over runs x evaluation seeds with its 95 %
  bootstrap interval over whole runs (a run's scores on all evaluation seeds drawn together), and
  each run's mean (``per_run``), which :func:`runs_plot` draws beside the interval;
- the probability of improvement between strategies, and of each strategy over rba-hold, with
  its interval (each strategy's runs drawn whole, the two sides independently);
- steps to recover: training steps after the change (for "from scratch": from its start) until
  the 10-episode moving mean of the training rewards first reaches 90 % of the from-scratch final
  score (its IQM over runs x seeds); a run that never does counts as its whole budget (so the
  figure is a lower bound when not all runs reached it); IQM over runs with its interval.

No ROS and no Stable-Baselines3 here: the report redraws from the cell files alone.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from . import stats

WINDOW = 10
#: (cell kind, record key) of each strategy's evaluation episodes.
EVALUATIONS = {
    "continued": ("transfer", "continued_eval"),
    "frozen": ("transfer", "frozen_eval"),
    "scratch": ("scratch", "scratch_eval"),
}
COMPARISONS = (("continued", "scratch"), ("continued", "frozen"), ("scratch", "frozen"))
RECOVERY_SHARE = 0.9


def runs_of(records: list[dict], scenario: str, algo: str, kind: str) -> list[dict]:
    found = [
        r
        for r in records
        if r["cell"]["scenario"] == scenario and r["cell"]["algo"] == algo and r["cell"]["kind"] == kind
    ]
    return sorted(found, key=lambda r: r["cell"]["seed"])


def scores(records: list[dict], scenario: str, algo: str, strategy: str) -> np.ndarray:
    """Runs x evaluation seeds of one strategy (empty when no cell is in)."""
    kind, key = EVALUATIONS[strategy]
    return np.array([r[key] for r in runs_of(records, scenario, algo, kind)], dtype=float)


def recovery_target(final: float) -> float:
    """90 % of the from-scratch final score, on the side of it towards zero when it is negative
    (so that "reaching" it still means getting within 10 % of it)."""
    return RECOVERY_SHARE * final if final >= 0 else (2 - RECOVERY_SHARE) * final


def moving(curve, window: int = WINDOW) -> np.ndarray:
    c = np.asarray(curve, dtype=float)
    return np.array([c[max(0, k - window + 1) : k + 1].mean() for k in range(len(c))])


def recovery_steps(curve, target: float, episode_steps: int, window: int = WINDOW) -> int | None:
    """Steps until the ``window``-episode moving mean of ``curve`` (episode rewards) first reaches
    ``target`` (a full window first), or None."""
    means = moving(curve, window)
    for k in range(window - 1, len(means)):
        if means[k] >= target:
            return (k + 1) * episode_steps
    return None


def recovery(records: list[dict], scenario: str, algo: str, key: dict[str, Any]) -> dict[str, Any] | None:
    """Steps to recover of continued (after the change) and from scratch, against one target."""
    scratch = scores(records, scenario, algo, "scratch")
    transfer = runs_of(records, scenario, algo, "transfer")
    if scratch.size == 0 or not transfer:
        return None
    target = recovery_target(float(stats.iqm(scratch)))
    budget = key["after"] * key["episode_steps"]
    curves = {
        "continued": [r["continued_curve"][key["before"] :] for r in transfer],
        "scratch": [r["scratch_curve"] for r in runs_of(records, scenario, algo, "scratch")],
    }
    found: dict[str, Any] = {"target": target, "budget_steps": budget}
    for strategy, runs in curves.items():
        steps = [recovery_steps(c, target, key["episode_steps"], key["window"]) for c in runs]
        counted = np.array([[s if s is not None else budget] for s in steps], dtype=float)
        found[strategy] = {
            "per_run": steps,
            "reached": sum(s is not None for s in steps),
            "runs": len(steps),
            "iqm": stats.iqm_interval(counted).as_dict(),
        }
    return found


def baseline_summary(record: dict[str, Any]) -> dict[str, Any]:
    """Means of the deterministic baselines (one run each: exact on these seeds)."""
    summary: dict[str, Any] = {
        side: {agent: float(np.mean(v)) for agent, v in record[side].items()} for side in ("before", "after")
    }
    summary["oracle_after_missing"] = record.get("oracle_after_missing")
    return summary


def algo_summary(records: list[dict], scenario: str, algo: str, key: dict[str, Any], rba_hold) -> dict[str, Any]:
    strategies, improvements = {}, {}
    for strategy in EVALUATIONS:
        s = scores(records, scenario, algo, strategy)
        if s.size:
            strategies[strategy] = {
                "runs": s.shape[0],
                "per_run": s.mean(axis=1).tolist(),
                "iqm": stats.iqm_interval(s).as_dict(),
                "mean": stats.mean_interval(s).as_dict(),
            }
            if rba_hold is not None:
                improvements[f"{strategy} > rba-hold"] = stats.probability_of_improvement_interval(
                    s, rba_hold
                ).as_dict()
    for x, y in COMPARISONS:
        sx, sy = scores(records, scenario, algo, x), scores(records, scenario, algo, y)
        if sx.size and sy.size:
            improvements[f"{x} > {y}"] = stats.probability_of_improvement_interval(sx, sy).as_dict()
    return {"strategies": strategies, "improvement": improvements, "recovery": recovery(records, scenario, algo, key)}


def summarize(records: list[dict], key: dict[str, Any], scenarios, algos) -> dict[str, Any]:
    """Everything the tables and the plot show, per scenario (and algorithm)."""
    found = {}
    for scenario in scenarios:
        base = [r for r in records if r["cell"]["scenario"] == scenario and r["cell"]["kind"] == "baselines"]
        rba_hold = np.array([base[0]["after"]["rba-hold"]]) if base else None
        found[scenario] = {
            "baselines": baseline_summary(base[0]) if base else None,
            "algos": {a: algo_summary(records, scenario, a, key, rba_hold) for a in algos},
        }
    return found


def _interval(d: dict[str, float] | None, digits: int = 2) -> str:
    if not d:
        return "-"
    return f"{d['point']:.{digits}f} [{d['low']:.{digits}f}, {d['high']:.{digits}f}]"


def _steps(r: dict[str, Any] | None) -> str:
    if not r:
        return "-"
    return f"{_interval(r['iqm'], 0)} ({r['reached']}/{r['runs']} reached)"


def _baseline_cells(b: dict[str, Any] | None) -> list[str]:
    if b is None:
        return ["-", "-", "-"]
    return [
        f"{b['before']['rba-hold']:.2f} / {b['after']['rba-hold']:.2f}",
        f"{b['before']['rba']:.2f} / {b['after']['rba']:.2f}",
        f"{b['after']['oracle']:.2f}" if "oracle" in b["after"] else "n/a (not a fixed setup)",
    ]


def _score_table(summary: dict[str, Any], key: dict[str, Any]) -> list[str]:
    lines = [
        f"## Final score after the change: IQM [95 % CI] over runs x {key['evaluations']} held-out seeds "
        f"(from {key['eval_seed']})",
        "",
        "| scenario | algorithm | runs | (a) continued | (b) frozen | (c) from scratch | rba-hold before / after "
        "| rba before / after | oracle after |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for scenario, s in summary.items():
        base = _baseline_cells(s["baselines"])
        for algo, a in s["algos"].items():
            st = a["strategies"]
            runs = "/".join(str(st[x]["runs"]) if x in st else "0" for x in EVALUATIONS)
            scores = [_interval(st.get(x, {}).get("iqm")) for x in EVALUATIONS]
            lines.append(f"| {scenario} | {algo} | {runs} | " + " | ".join(scores + base) + " |")
    return lines


def _improvement_table(summary: dict[str, Any]) -> list[str]:
    pairs = [f"{x} > {y}" for x, y in COMPARISONS] + [f"{x} > rba-hold" for x in EVALUATIONS]
    lines = [
        "## Probability of improvement P(X > Y) [95 % CI]",
        "",
        "| scenario | algorithm | " + " | ".join(pairs) + " |",
        "|---|---|" + "---|" * len(pairs),
    ]
    for scenario, s in summary.items():
        for algo, a in s["algos"].items():
            lines.append(
                f"| {scenario} | {algo} | " + " | ".join(_interval(a["improvement"].get(p)) for p in pairs) + " |"
            )
    return lines


def _recovery_table(summary: dict[str, Any]) -> list[str]:
    lines = [
        f"## Steps to recover: to {RECOVERY_SHARE:.0%} of the from-scratch final score, IQM [95 % CI] over runs",
        "",
        "| scenario | algorithm | target reward | (a) continued, after the change | (c) from scratch |",
        "|---|---|---|---|---|",
    ]
    for scenario, s in summary.items():
        for algo, a in s["algos"].items():
            r = a["recovery"]
            lines.append(
                f"| {scenario} | {algo} | {r['target']:.2f} | {_steps(r['continued'])} | {_steps(r['scratch'])} |"
                if r
                else f"| {scenario} | {algo} | - | - | - |"
            )
    return lines


def markdown(summary: dict[str, Any], key: dict[str, Any]) -> str:
    """The three tables: final scores, probabilities of improvement, steps to recover."""
    lines = _score_table(summary, key) + [""] + _improvement_table(summary) + [""] + _recovery_table(summary)
    lines += [
        "",
        "Runs: training seeds. A run that does not reach the target within its budget counts as the whole "
        "budget, so such an IQM is a lower bound. Baselines are deterministic: one run, exact on these seeds.",
        "Hyperparameters (SB3's defaults otherwise): "
        + "; ".join(f"{algo} {params}" for algo, params in key.get("hyperparameters", {}).items())
        + ".",
    ]
    return "\n".join(lines) + "\n"


def _panel(ax, records: list[dict], summary: dict[str, Any], scenario: str, algo: str, key: dict[str, Any]) -> None:
    before = key["before"]
    transfer = runs_of(records, scenario, algo, "transfer")
    scratch = runs_of(records, scenario, algo, "scratch")
    for runs, curve_key, offset, colour, label in (
        (transfer, "continued_curve", before, "tab:blue", "(a) continued"),
        (scratch, "scratch_curve", 0, "tab:orange", "(c) from scratch"),
    ):
        if not runs:
            continue
        curves = np.array([moving(r[curve_key]) for r in runs])
        x = np.arange(curves.shape[1]) - offset
        seeds = f"mean of {len(runs)} seeds, band min-max" if len(runs) > 1 else "1 seed"
        ax.plot(x, curves.mean(axis=0), color=colour, label=f"{label}: {seeds}")
        ax.fill_between(x, curves.min(axis=0), curves.max(axis=0), color=colour, alpha=0.2, lw=0)
    s = summary[scenario]
    frozen = s["algos"][algo]["strategies"].get("frozen")
    if frozen:
        ax.axhline(
            frozen["iqm"]["point"], color="tab:gray", ls="--", label=f"(b) frozen, IQM: {frozen['iqm']['point']:.1f}"
        )
    for agent, style in (("rba-hold", ":"), ("oracle", "-.")):
        if s["baselines"] and agent in s["baselines"]["after"]:
            value = s["baselines"]["after"][agent]
            ax.axhline(value, color="tab:green", ls=style, label=f"{agent} after the change: {value:.1f}")
    ax.axvline(0, color="black", lw=0.8)
    ax.set_title(f"{scenario}, {algo}: change after {before} episodes", fontsize=9)
    ax.set_xlabel("episodes relative to the change (50 steps each)")
    ax.set_ylabel(f"episode reward ({WINDOW}-episode moving mean)")
    ax.legend(fontsize=6, loc="lower right")


def plot(records: list[dict], summary: dict[str, Any], key: dict[str, Any], stem: Path) -> list[Path]:
    """Training curves around the change (mean over seeds, band: min..max), one panel per scenario
    (columns) and algorithm (rows); ``stem``.png and .svg."""
    from matplotlib.figure import Figure

    scenarios = list(summary)
    algos = list(next(iter(summary.values()))["algos"]) if summary else []
    fig = Figure(figsize=(6 * max(1, len(scenarios)), 4 * max(1, len(algos))))
    axes = np.array(fig.subplots(max(1, len(algos)), max(1, len(scenarios)), squeeze=False))
    for i, algo in enumerate(algos):
        for j, scenario in enumerate(scenarios):
            _panel(axes[i, j], records, summary, scenario, algo, key)
    fig.tight_layout()
    written = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    fig.savefig(written[0], dpi=110)
    fig.savefig(written[1])
    return written


def runs_plot(summary: dict[str, Any], stem: Path) -> list[Path]:
    """Each strategy's runs (a dot per training seed: its mean over the evaluation seeds) over its
    IQM interval, one panel per scenario and algorithm, rba-hold and the oracle after the change
    as lines; ``stem``.png and .svg (nothing when no strategy has runs)."""
    from .plots import Strip, StripPanel, strip_figure

    colours = {"continued": "tab:blue", "frozen": "tab:gray", "scratch": "tab:orange"}
    labels = {"continued": "(a) continued", "frozen": "(b) frozen", "scratch": "(c) from scratch"}
    panels = []
    for scenario, s in summary.items():
        after = (s["baselines"] or {}).get("after", {})
        refs = [(agent, after[agent]) for agent in ("rba-hold", "oracle") if agent in after]
        for algo, a in s["algos"].items():
            strips = [
                Strip(labels[name], st["per_run"], st["iqm"], colours[name])
                for name, st in a["strategies"].items()
                if "per_run" in st
            ]
            panels.append(StripPanel(f"{scenario}, {algo}: final score after the change", strips, refs))
    return strip_figure(
        panels,
        stem,
        "reward after the change: a dot per run (its mean over the seeds), tick: IQM, bar: its 95% CI over runs",
        columns=2,
    )
