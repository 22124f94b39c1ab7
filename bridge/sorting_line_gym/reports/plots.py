"""Figures of the benchmark report (the episode dashboard is ``render``'s).

- :func:`benchmark_figure`: the paper's Figure 7, mean episode reward per setup and agent, with
  our spread as error bars and the paper's Table 1 values as markers.
- :func:`analysis_figure`: the paper's Figure 3 for the basic line, drawn from the rows of
  ``sorting_line table`` (the library's expected-reward analysis, the one the rule-based agent
  decides with, made in-process) and the library's step reward:
  accuracy against occupancy per speed; the accuracy heat map with the area under the threshold
  in black; reward against accuracy per speed; the expected-reward heat map with the best speed
  per occupancy marked.

- :func:`strip_figure`: strip plots, each row one cell's runs (a dot per run) beside its interval,
  so a reader sees how the runs spread, not only the summary; :func:`runs_figure` draws the
  benchmark's (per line and agent, and the --n-envs check), the transfer study draws its own.
- :func:`curve_figure`: learning curves, the mean over runs with a band, several series one over
  the other per panel, with reference values as horizontal lines (the engine check's SB3 and
  batched curves); :func:`learning_curves_figure` draws the benchmark's (``curves.benchmark_curves``).

Each writes ``<stem>.png`` and ``<stem>.svg`` and returns their paths. Figures are drawn on their
own ``Figure`` and Agg canvas (as ``render`` does), never through pyplot: importing this module
leaves the caller's matplotlib backend and open windows alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

import sorting_line_gym._native as _native

from ..line.vocabulary import (
    EPISODE_STEPS,
    EVAL_SEEDS,
    SETUPS,
    SPEEDS,
    THRESHOLD,
    VARIANTS,
    check_variant,
    reward,
    speed_index_of,
)

AGENT_COLORS = {
    "random": "#9e9e9e",
    "rba": "#1f77b4",
    "rba-hold": "#17becf",
    "dqn": "#ff7f0e",
    "ppo": "#2ca02c",
    "a2c": "#d62728",
}


def _figure(**kwargs) -> Figure:
    """A figure on an Agg canvas of its own (files only; never a window)."""
    fig = Figure(layout="constrained", **kwargs)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, stem: Path) -> list[Path]:
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    fig.savefig(paths[0], dpi=120)
    fig.savefig(paths[1])
    return paths


def benchmark_figure(rows: dict[tuple[str, str, str], dict[str, Any]], stem: Path) -> list[Path]:
    """Grouped bars: one group per setup and variant, one bar per agent that has results."""
    from .paper import TABLE_1

    agents = [a for a in AGENT_COLORS if any(k[2] == a for k in rows)]
    groups = [(s, v) for s in SETUPS for v in VARIANTS if any((s, v, a) in rows for a in agents)]
    fig = _figure(figsize=(13, 5.2))
    ax = fig.subplots()
    width = 0.8 / max(1, len(agents))
    x = np.arange(len(groups))
    for i, agent in enumerate(agents):
        offset = (i - (len(agents) - 1) / 2) * width
        means = [rows[(s, v, agent)]["reward_mean"] if (s, v, agent) in rows else np.nan for s, v in groups]
        stds = [rows[(s, v, agent)]["reward_std"] if (s, v, agent) in rows else 0.0 for s, v in groups]
        ax.bar(
            x + offset,
            means,
            width,
            yerr=stds,
            capsize=2,
            label=agent,
            color=AGENT_COLORS[agent],
            error_kw={"elinewidth": 0.8},
        )
        paper = [TABLE_1.get((s, v, agent), (None, None, np.nan))[2] for s, v in groups]
        if not all(np.isnan(paper)):
            ax.scatter(x + offset, paper, marker="_", s=120, color="black", zorder=3, linewidths=2)
    ax.scatter([], [], marker="_", s=120, color="black", linewidths=2, label="paper (Table 1)")
    ax.set_xticks(x, [f"{s} {'adv' if v == 'advanced' else 'basic'}" for s, v in groups])
    ax.set_ylabel(f"episode reward ({EPISODE_STEPS} steps, seeds {EVAL_SEEDS})")
    ax.set_title("Mean episode reward per setup and agent, through ROS 2 (bars: ours, +- std; marks: the paper)")
    ax.axhline(0, color="black", linewidth=0.6)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(ncol=len(agents) + 1, loc="upper center", bbox_to_anchor=(0.5, -0.08), frameon=False)
    return _save(fig, stem)


def read_table(variant: str = "basic") -> list[dict[str, str]]:
    """The rows of ``sorting_line table --variant VARIANT``, made in-process by the library
    (``_native.table``): column name to the text the CLI prints."""
    return _native.table(check_variant(variant))


def reward_of(accuracy: np.ndarray, speed: float) -> np.ndarray:
    """The step reward without a speed change at belt speed ``speed``, the library's
    (src/sim/reward.rs); a speed that is not one of the ten raises ValueError."""
    index = speed_index_of(speed)
    if index is None:
        raise ValueError(f"speed = {speed!r} is not a belt speed: allowed {', '.join(map(str, SPEEDS))}")
    return reward(accuracy, index)


def _dynamics_grid() -> tuple[np.ndarray, list[float], np.ndarray, np.ndarray]:
    """The basic line's table (category 0, mode 0) as grids over (speed, occupancy): (occupancies,
    speeds, expected accuracy, expected reward)."""
    rows = [r for r in read_table("basic") if r["category"] == "0" and r["mode"] == "0"]
    occupancies = sorted({float(r["occupancy"]) for r in rows})
    speeds = sorted({float(r["speed"]) for r in rows})
    acc = np.full((len(speeds), len(occupancies)), np.nan)
    reward = np.full_like(acc, np.nan)
    oi = {o: i for i, o in enumerate(occupancies)}
    si = {s: i for i, s in enumerate(speeds)}
    for r in rows:
        i, j = si[float(r["speed"])], oi[float(r["occupancy"])]
        acc[i, j] = float(r["expected_accuracy"])
        reward[i, j] = float(r["expected_reward"])
    return np.array(occupancies), speeds, acc, reward


def analysis_figure(stem: Path) -> list[Path]:
    occ, speeds, acc, reward = _dynamics_grid()
    cmap = matplotlib.colormaps["viridis"]
    extent = (occ[0], occ[-1], speeds[0] - 0.05, speeds[-1] + 0.05)

    fig = _figure(figsize=(13, 9.5))
    axes = fig.subplots(2, 2)
    ax = axes[0, 0]
    for i, s in enumerate(speeds):
        ax.plot(occ, acc[i], color=cmap(i / (len(speeds) - 1)), label=f"{s:.1f}")
    ax.axhline(THRESHOLD, color="black", linestyle="--", linewidth=1, label="threshold")
    ax.set(xlabel="belt occupancy", ylabel="expected accuracy", title="Accuracy vs occupancy, per belt speed")
    ax.legend(title="speed", ncol=2, fontsize=8)
    ax.grid(alpha=0.3)

    ax = axes[0, 1]
    masked = np.ma.masked_where(acc < THRESHOLD, acc)
    ax.imshow(np.ones_like(acc), cmap=ListedColormap(["black"]), aspect="auto", origin="lower", extent=extent)
    im = ax.imshow(masked, cmap="viridis", aspect="auto", origin="lower", vmin=THRESHOLD, vmax=1.0, extent=extent)
    fig.colorbar(im, ax=ax, label="expected accuracy")
    ax.set(
        xlabel="belt occupancy",
        ylabel="belt speed",
        title=f"Expected accuracy (black: below the threshold {THRESHOLD})",
    )

    ax = axes[1, 0]
    a = np.linspace(THRESHOLD, 1.0, 61)
    for i, s in enumerate(speeds):
        ax.plot(a, reward_of(a, s), color=cmap(i / (len(speeds) - 1)), label=f"{s:.1f}")
    ax.set(xlabel="accuracy", ylabel="step reward", title="Reward vs accuracy, per belt speed (above the threshold)")
    ax.legend(title="speed", ncol=2, fontsize=8)
    ax.grid(alpha=0.3)

    ax = axes[1, 1]
    im = ax.imshow(reward, cmap="magma", aspect="auto", origin="lower", extent=extent)
    best = [speeds[int(np.nanargmax(reward[:, j]))] for j in range(len(occ))]
    ax.plot(occ, best, color="cyan", linewidth=1.5, drawstyle="steps-mid", label="best speed (rba)")
    fig.colorbar(im, ax=ax, label="expected step reward")
    ax.set(xlabel="belt occupancy", ylabel="belt speed", title="Expected reward per speed and occupancy")
    ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"The basic line's dynamics (sorting_line table; threshold {THRESHOLD})")
    return _save(fig, stem)


def _line_label(setup: str, variant: str) -> str:
    return f"{setup} {'adv' if variant == 'advanced' else 'basic'}"


def interval_figure(rows: dict[tuple[str, str, str], dict[str, Any]], stem: Path) -> list[Path]:
    """One panel per line: each agent's held-out IQM with its 95 % interval (a bar for the
    interval, a dot for the IQM), the mean as a cross, and the oracle's mean as a dashed line."""
    lines = [
        (s, v)
        for s in SETUPS
        for v in VARIANTS
        if any((s, v, a) in rows and "heldout" in rows[(s, v, a)] for a in AGENT_COLORS)
    ]
    if not lines:
        return []
    agents = [a for a in AGENT_COLORS if any((s, v, a) in rows for s, v in lines)]
    columns = min(4, len(lines))
    fig = _figure(figsize=(3.6 * columns, 2.9 * ((len(lines) + columns - 1) // columns)))
    axes = np.atleast_1d(fig.subplots((len(lines) + columns - 1) // columns, columns, squeeze=False)).ravel()
    for ax, (setup, variant) in zip(axes, lines, strict=False):
        for i, agent in enumerate(agents):
            row = rows.get((setup, variant, agent))
            if row is None or "heldout" not in row:
                continue
            h = row["heldout"]
            iqm = h["iqm"]
            ax.plot(
                [iqm["low"], iqm["high"]],
                [i, i],
                color=AGENT_COLORS[agent],
                linewidth=7,
                alpha=0.55,
                solid_capstyle="butt",
            )
            ax.plot(iqm["point"], i, "o", color=AGENT_COLORS[agent], markersize=4)
            ax.plot(h["mean"]["point"], i, "x", color="black", markersize=4)
        oracle = rows.get((setup, variant, "oracle"))
        if oracle is not None:
            ax.axvline(oracle["heldout"]["mean"]["point"], color="black", linestyle="--", linewidth=1)
        ax.set_yticks(range(len(agents)), agents)
        ax.set_ylim(-0.7, len(agents) - 0.3)
        ax.invert_yaxis()
        ax.set_title(_line_label(setup, variant))
        ax.grid(axis="x", alpha=0.3)
    for ax in axes[len(lines) :]:
        ax.set_visible(False)
    fig.supxlabel("held-out episode reward: IQM (dot), 95% CI (bar), mean (x), oracle (dashed)", fontsize=9)
    return _save(fig, stem)


def aggregate_figure(
    aggregate: dict[str, dict[str, Any]], normalized: dict[str, dict[tuple[str, str], np.ndarray]], stem: Path
) -> list[Path]:
    """Left: each agent's IQM and mean over the lines of the normalized score (random 0, oracle 1)
    with their 95 % intervals. Right: performance profiles, the fraction of runs x lines whose
    normalized score exceeds tau."""
    from . import stats

    agents = [a for a in AGENT_COLORS if a in aggregate]
    fig = _figure(figsize=(12, 4.2))
    left, right = fig.subplots(1, 2, width_ratios=[1, 1.3])
    for i, agent in enumerate(agents):
        for j, (name, marker) in enumerate((("iqm", "o"), ("mean", "s"))):
            d = aggregate[agent][name]
            y = i + (j - 0.5) * 0.3
            left.plot(
                [d["low"], d["high"]], [y, y], color=AGENT_COLORS[agent], linewidth=6, alpha=0.55, solid_capstyle="butt"
            )
            left.plot(
                d["point"], y, marker, color=AGENT_COLORS[agent], markersize=4, label=name.upper() if i == 0 else None
            )
    left.set_yticks(range(len(agents)), agents)
    left.invert_yaxis()
    left.axvline(1.0, color="black", linestyle="--", linewidth=1)
    left.set(
        xlabel="normalized score (random 0, oracle 1)", title="Aggregate over the lines: IQM (o) and mean (s), 95% CI"
    )
    left.grid(axis="x", alpha=0.3)
    taus = np.linspace(-0.1, 1.05, 231)
    for agent in agents:
        scores = np.concatenate(list(normalized[agent].values()))
        right.plot(taus, stats.performance_profile(scores, taus), color=AGENT_COLORS[agent], label=agent)
    right.set(
        xlabel="normalized score tau", ylabel="fraction of runs x lines with score > tau", title="Performance profiles"
    )
    right.grid(alpha=0.3)
    right.legend(fontsize=8)
    return _save(fig, stem)


@dataclass(frozen=True)
class Strip:
    """One row of a strip plot: one value per run of a cell, and the cell's interval (None: none)."""

    label: str
    runs: Sequence[float]
    interval: dict[str, float] | None = None
    color: str = "#444444"


@dataclass(frozen=True)
class StripPanel:
    """A panel of strips, with reference values (label, value) drawn as vertical lines."""

    title: str
    strips: Sequence[Strip]
    references: Sequence[tuple[str, float]] = ()


def _draw_strips(ax, panel: StripPanel) -> None:
    for i, strip in enumerate(panel.strips):
        if strip.interval is not None:
            lo, hi = strip.interval["low"], strip.interval["high"]
            ax.plot([lo, hi], [i, i], color=strip.color, linewidth=8, alpha=0.3, solid_capstyle="butt")
            ax.plot(strip.interval["point"], i, "|", color=strip.color, markersize=12, markeredgewidth=2)
        runs = np.asarray(strip.runs, dtype=float)
        # Spread the dots over the row by rank (no random jitter: a redrawn report is the same).
        offsets = np.linspace(-0.22, 0.22, len(runs)) if len(runs) > 1 else np.zeros(len(runs))
        order = np.argsort(runs, kind="stable")
        marker = "D" if len(runs) == 1 else "o"
        ax.scatter(runs[order], i + offsets, s=16, marker=marker, color=strip.color, edgecolors="black", lw=0.4)
    for (label, value), style in zip(panel.references, ("--", ":", "-."), strict=False):
        ax.axvline(value, color="black", linestyle=style, linewidth=1, label=f"{label} {value:.2f}")
    if panel.references:
        ax.legend(fontsize=6, loc="best")
    ax.set_yticks(range(len(panel.strips)), [s.label for s in panel.strips], fontsize=8)
    ax.set_ylim(-0.7, len(panel.strips) - 0.3)
    ax.invert_yaxis()
    ax.set_title(panel.title, fontsize=9)
    ax.grid(axis="x", alpha=0.3)


def strip_figure(panels: Sequence[StripPanel], stem: Path, xlabel: str, columns: int = 4) -> list[Path]:
    """One panel per entry of ``panels``, up to ``columns`` a row: each strip's runs as dots (a
    diamond for a single run) over its interval (bar) and point (tick); nothing when no panels."""
    panels = [p for p in panels if p.strips]
    if not panels:
        return []
    columns = min(columns, len(panels))
    rows = (len(panels) + columns - 1) // columns
    height = max(len(p.strips) for p in panels)
    fig = _figure(figsize=(max(6.5, 3.8 * columns), (0.9 + 0.32 * height) * rows + 0.5))
    axes = np.atleast_1d(fig.subplots(rows, columns, squeeze=False)).ravel()
    for ax, panel in zip(axes, panels, strict=False):
        _draw_strips(ax, panel)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    fig.supxlabel(xlabel, fontsize=9)
    return _save(fig, stem)


def runs_figure(
    rows: dict[tuple[str, str, str], dict[str, Any]], checks: Sequence[dict[str, Any]], stem: Path
) -> list[Path]:
    """The benchmark's runs: per line, each agent's runs (held-out mean per training seed) over its
    IQM interval, the oracle's mean as a line; then per --n-envs check, one line's runs against N
    lines'."""
    panels = []
    for setup in SETUPS:
        for variant in VARIANTS:
            held = {
                a: rows[(setup, variant, a)]["heldout"]
                for a in AGENT_COLORS
                if "heldout" in rows.get((setup, variant, a), {})
            }
            strips = [Strip(a, h["per_seed"], h["iqm"], AGENT_COLORS[a]) for a, h in held.items()]
            oracle = rows.get((setup, variant, "oracle"))
            refs = [("oracle", oracle["heldout"]["mean"]["point"])] if oracle else []
            panels.append(StripPanel(_line_label(setup, variant), strips, refs))
    for c in checks:
        color = AGENT_COLORS[c["agent"]]
        strips = [
            Strip("1 line", c["per_run"][0], c["iqm_1"], color),
            Strip(f"{c['n_envs']} lines", c["per_run"][1], c["iqm_n"], color),
        ]
        title = f"{_line_label(c['setup'], c['variant'])}, {c['agent']}: --n-envs ({c['mapping']})"
        panels.append(StripPanel(title, strips))
    return strip_figure(
        panels,
        stem,
        "held-out episode reward: a dot per run (its mean over the seeds), tick: IQM, bar: its 95% CI over runs",
    )


@dataclass(frozen=True)
class CurveSeries:
    """One learning curve: the mean over runs per step and its band (low, high), in one color."""

    label: str
    steps: Sequence[int]
    mean: Sequence[float]
    low: Sequence[float]
    high: Sequence[float]
    color: str = "#444444"
    linestyle: str = "-"


@dataclass(frozen=True)
class CurvePanel:
    """A panel of learning curves drawn one over the other, with reference values (label, value)
    drawn as horizontal lines."""

    title: str
    series: Sequence[CurveSeries]
    references: Sequence[tuple[str, float]] = ()


def curve_figure(panels: Sequence[CurvePanel], stem: Path, xlabel: str, ylabel: str, columns: int = 3) -> list[Path]:
    """One panel per entry of ``panels``, up to ``columns`` a row: each series' mean as a line with
    its band shaded, the series one over the other; nothing when no panel has a series."""
    panels = [p for p in panels if p.series]
    if not panels:
        return []
    columns = min(columns, len(panels))
    rows = (len(panels) + columns - 1) // columns
    fig = _figure(figsize=(4.2 * columns, 3.0 * rows + 0.4))
    axes = np.atleast_1d(fig.subplots(rows, columns, squeeze=False)).ravel()
    for ax, panel in zip(axes, panels, strict=False):
        for s in panel.series:
            ax.fill_between(s.steps, s.low, s.high, color=s.color, alpha=0.25, linewidth=0)
            ax.plot(s.steps, s.mean, color=s.color, linestyle=s.linestyle, linewidth=1.4, marker=".", markersize=3,
                    label=s.label)  # fmt: skip
        for (label, value), style in zip(panel.references, ("--", ":", "-."), strict=False):
            ax.axhline(value, color="black", linestyle=style, linewidth=0.9, label=f"{label} {value:.2f}")
        ax.set_title(panel.title, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    fig.supxlabel(xlabel, fontsize=9)
    fig.supylabel(ylabel, fontsize=9)
    return _save(fig, stem)


def learning_curves_figure(curves: dict[tuple[str, str], dict[str, Any]], stem: Path) -> list[Path]:
    """The benchmark's learning curves (``curves.benchmark_curves``): a panel per line, a series per
    RL algorithm (its color) and training configuration (a line style per further one of the same
    algorithm), rba-hold's and the oracle's mean on the same seeds as lines; nothing without curves."""
    styles = ("-", "--", "-.", ":")
    panels = []
    for (setup, variant), panel in curves.items():
        series, seen = [], dict[str, int]()
        for s in panel["series"]:
            style = styles[seen.setdefault(s["agent"], 0) % len(styles)]
            seen[s["agent"]] += 1
            label = f"{s['label']} ({s['runs']} run{'s' if s['runs'] != 1 else ''})"
            series.append(
                CurveSeries(label, s["steps"], s["mean"], s["low"], s["high"], AGENT_COLORS[s["agent"]], style)
            )
        seeds = panel["seeds"]
        span = f": seeds {seeds['first']}..{seeds['first'] + seeds['episodes'] - 1}" if seeds else ""
        panels.append(CurvePanel(_line_label(setup, variant) + span, series, list(panel["references"].items())))
    return curve_figure(panels, stem, "training steps", "mean reward (band: 95% CI over runs)")
