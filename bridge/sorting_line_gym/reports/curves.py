"""Learning curves over runs, from the benchmark's cell records (format 2: an RL cell's ``curve``,
which ``studies.curves`` records: every ``every`` steps, the policy's mean reward on the first
``episodes`` held-out seeds from ``seed``).

- :func:`curve_bands`: one series of runs as the steps every run has, the mean over runs and its
  95 % interval over whole runs (``stats.mean_interval`` on a runs x 1 array per step: a resample
  draws runs); the engine check's curves and the benchmark's.
- :func:`benchmark_curves`: the benchmark report's panels, per line (setup x variant) with RL
  cells that have a curve: one series per RL algorithm and training configuration (engine, lines,
  lines mapping), labelled ``ppo``, ``ppo, 8 lines``, ``ppo (batched)``, so that runs of different
  trainings never share a mean; and as references rba-hold's and the oracle's mean reward on the
  curves' own seeds, so that a curve's last point and its references are scored on the same episodes.

Pure analysis, no I/O; the figure is ``plots.learning_curves_figure``'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..line.vocabulary import SETUPS, VARIANTS
from ..training.hyperparams import ALGOS, DEFAULT_MAPPING
from . import stats

Line = tuple[str, str]  # (setup, variant)
#: Who the references of a panel are: the best baseline and the clairvoyant optimum.
REFERENCES = ("rba-hold", "oracle")


def curve_bands(records: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """The learning curve over runs: steps every run has, mean over runs and its 95 % interval
    (whole runs drawn); None when no run has a curve."""
    curves = [{p["step"]: p["reward_mean"] for p in r["curve"]["points"]} for r in records if r.get("curve")]
    if not curves:
        return None
    steps = sorted(set.intersection(*(set(c) for c in curves)))
    values = np.array([[c[s] for s in steps] for c in curves], dtype=float)  # runs x steps
    bands = [stats.mean_interval(values[:, [i]]) for i in range(len(steps))]
    return {
        "steps": steps,
        "runs": len(curves),
        "mean": [b.point for b in bands],
        "low": [b.low for b in bands],
        "high": [b.high for b in bands],
    }


def configuration(cell: dict[str, Any]) -> tuple[str, int, str, str]:
    """What a series holds the runs of: (agent, lines, mapping, engine), as ``benchmark_cells.Cell``
    records them (an SB3 cell names no engine; a format-1 cell no mapping)."""
    return cell["agent"], cell.get("n_envs", 1), cell.get("mapping", DEFAULT_MAPPING), cell.get("engine", "sb3")


def series_label(agent: str, n_envs: int, mapping: str, engine: str) -> str:
    """``ppo``, ``ppo, 8 lines``, ``ppo, 8 lines, same-line-rollout`` (a mapping not the default), with
    `` (batched)`` for the batched engine's cells."""
    label = agent
    if n_envs > 1:
        label += f", {n_envs} lines" + (f", {mapping}" if mapping != DEFAULT_MAPPING else "")
    return label + (f" ({engine})" if engine != "sb3" else "")


def _order(config: tuple[str, int, str, str]) -> tuple:
    agent, n_envs, mapping, engine = config
    return ALGOS.index(agent), engine != "sb3", engine, n_envs, mapping


def benchmark_curves(
    records: Sequence[dict[str, Any]], oracles: dict[Line, dict[str, Any]] | None = None
) -> dict[Line, dict[str, Any]]:
    """Per line with RL cells that have a curve, in the order of the setups and variants:
    ``series``, one per configuration in the order of ``ALGOS`` (the SB3 cells first, then by lines),
    each its ``configuration`` fields, ``label`` and ``curve_bands``; ``seeds``, the curves'
    ``{"first", "episodes"}`` (None where the curves of the line were scored on different seeds);
    ``references``, rba-hold's and the oracle's (``oracles``, per line) mean reward on those seeds,
    where a record has every one of them. Empty when no cell has a curve."""
    groups: dict[Line, dict[tuple, list[dict[str, Any]]]] = {}
    for r in records:
        c = r["cell"]
        if c["agent"] in ALGOS and r.get("curve"):
            groups.setdefault((c["setup"], c["variant"]), {}).setdefault(configuration(c), []).append(r)
    panels = {}
    for line in sorted(groups, key=lambda line: (list(SETUPS).index(line[0]), VARIANTS.index(line[1]))):
        series = []
        for config in sorted(groups[line], key=_order):
            fields = dict(zip(("agent", "n_envs", "mapping", "engine"), config, strict=True))
            series.append({**fields, "label": series_label(*config), **curve_bands(groups[line][config])})
        seeds = {(r["curve"]["seed"], r["curve"]["episodes"]) for rs in groups[line].values() for r in rs}
        first, episodes = seeds.pop() if len(seeds) == 1 else (None, None)
        panels[line] = {
            "series": series,
            "seeds": {"first": first, "episodes": episodes} if first is not None else None,
            "references": _references(line, records, oracles or {}, first, episodes),
        }
    return panels


def _references(
    line: Line, records: Sequence[dict[str, Any]], oracles: dict[Line, dict[str, Any]], first, episodes
) -> dict[str, float]:
    """rba-hold's (its first record on ``line``) and the oracle's mean reward on seeds ``first`` ..
    ``first + episodes - 1``, those that have all of them."""
    if first is None:
        return {}
    episodes_of = {"oracle": oracles[line]["per_episode"]} if line in oracles else {}
    for r in records:
        c = r["cell"]
        if (c["setup"], c["variant"]) == line and c["agent"] == "rba-hold" and "heldout" in r:
            episodes_of.setdefault("rba-hold", r["heldout"]["per_episode"])
    found = {}
    for who in REFERENCES:
        rewards = {int(e["seed"]): float(e["reward"]) for e in episodes_of.get(who, ())}
        wanted = range(first, first + episodes)
        if all(s in rewards for s in wanted):
            found[who] = float(np.mean([rewards[s] for s in wanted]))
    return found
