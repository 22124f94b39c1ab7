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
  figure is a lower bound when not all runs reached it); IQM over runs with its interval;
- the continual-RL metrics (``continual``), each per run with the IQM over runs and its interval
  over whole runs:

  - *jumpstart*: the score right after the change, i.e. the frozen snapshot's evaluation on the
    changed line (the continued agent is that snapshot at the change), for continued and frozen;
    from scratch has no evaluation at its start, so none;
  - *AUC*: the area under the normalised training curve after the change, the mean over the
    after-change episodes of ``(reward - random) / (oracle - random)``, with random's and the
    oracle's means after the change from the scenario's baselines cell (``normalisation``; none
    where that cell has not both, e.g. one of the study's first version, which recorded no random:
    the table says why); for continued (its curve after the change) and from scratch (its whole
    curve);
  - *steps to rba-hold*: training steps after the change (from scratch: from its start) until the
    10-episode moving mean of the training rewards first reaches rba-hold's mean after the change;
    a run that never does counts as its budget, so the figure is then a lower bound (as for the
    steps to recover);
  - *forward transfer*: ``(AUC - AUC_scratch) / (1 - AUC_scratch)`` per continued run, against the
    mean AUC of the from-scratch runs (held fixed: the interval resamples the continued runs);
    none when that mean is 1 or more (from-scratch runs at the oracle's mean or above: no scale);
  - *crossover*: the training steps after the change at which the from-scratch run's cumulative
    training reward first exceeds the continued run's of the same training seed; a pair where it
    never does counts as the budget (a lower bound).

  - *score before the change* and *forgetting* (``forgetting``): every trained agent and the
    snapshot at the change are evaluated on the line before the change too (the same held-out
    seeds); the score there normalised by random's and the oracle's means on that line, and the
    forgetting, ``(snapshot - agent) / (oracle - random)`` per seed against the snapshot of the
    same training seed (the agent deployed when the line changed): IQM over runs x seeds, the
    interval over whole runs, as the final score. Frozen's forgetting is 0 by construction (it is
    that snapshot) and is not computed; cells saved before these evaluations existed have none
    (the study trains them again: ``transfer_cells.outdated``).

  The strategies (``STRATEGIES``): (a) continued, (b) frozen, (c) from scratch, (d)
  shrink-and-perturb, the continued agent shrunk and perturbed at the change
  (``transfer_cells.shrink_perturb``), and (e) a new agent cloned from the exact oracle's
  episodes before it trains (``transfer_cells.clone_oracle``); (d) has the metrics of (a), its
  jumpstart its own perturbed snapshot's; (e) those of (c), and a jumpstart: the cloned agent's
  score before its RL training.

No ROS and no Stable-Baselines3 here: the report redraws from the cell files alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import stats

WINDOW = 10


@dataclass(frozen=True)
class Strategy:
    """A strategy of the study: the cell kind and record key of its evaluation episodes and of its
    training curve (None: it trains no further), and how the tables and figures name and colour it."""

    kind: str
    evaluation: str
    curve: str | None
    label: str
    colour: str
    #: The record key of its agent's evaluation right after the change (jumpstart), or None.
    at_change: str | None = None
    #: The record key of its agent's evaluation on the line before the change (forgetting).
    before: str | None = None


#: The strategies, in the order of every table and figure. The continued agent at the change is
#: the frozen snapshot: one jumpstart for both.
STRATEGIES = {
    "continued": Strategy("transfer", "continued_eval", "continued_curve", "(a) continued", "tab:blue",
                          "frozen_eval", "continued_before_eval"),
    "frozen": Strategy("transfer", "frozen_eval", None, "(b) frozen", "tab:gray", "frozen_eval", "frozen_before_eval"),
    "scratch": Strategy("scratch", "scratch_eval", "scratch_curve", "(c) from scratch", "tab:orange",
                        None, "scratch_before_eval"),
    "perturbed": Strategy("perturbed", "perturbed_eval", "perturbed_curve", "(d) shrink-and-perturb", "tab:purple",
                          "perturbed_at_change_eval", "perturbed_before_eval"),
    "cloned": Strategy("cloned", "cloned_eval", "cloned_curve", "(e) new, cloned from the oracle", "tab:brown",
                       "cloned_at_change_eval", "cloned_before_eval"),
}  # fmt: skip
#: Forgetting is measured against the agent deployed at the change: the transfer cell's snapshot.
FORGETTING_REFERENCE = "frozen"
COMPARISONS = (
    ("continued", "scratch"),
    ("continued", "frozen"),
    ("scratch", "frozen"),
    ("perturbed", "continued"),
    ("perturbed", "scratch"),
    ("cloned", "scratch"),
)
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
    st = STRATEGIES[strategy]
    return np.array([r[st.evaluation] for r in runs_of(records, scenario, algo, st.kind)], dtype=float)


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


def curves_after(records: list[dict], scenario: str, algo: str, key: dict[str, Any]) -> dict[str, dict[int, list]]:
    """Per strategy that trains, each run's (training seed's) training curve after the change:
    continued from episode ``before`` on, from scratch whole."""
    found = {}
    for strategy, st in STRATEGIES.items():
        if st.curve is not None:
            runs = runs_of(records, scenario, algo, st.kind)
            found[strategy] = {r["cell"]["seed"]: r[st.curve][_change_at(st, key) :] for r in runs}
    return found


def _change_at(st: Strategy, key: dict[str, Any]) -> int:
    """The episode of ``st``'s training curve at which the line has changed: ``before`` for an agent
    trained through the change, 0 for one trained on the changed line."""
    return key["before"] if st.kind in ("transfer", "perturbed") else 0


def recovery(records: list[dict], scenario: str, algo: str, key: dict[str, Any]) -> dict[str, Any] | None:
    """Steps to recover of continued (after the change) and from scratch, against one target."""
    scratch = scores(records, scenario, algo, "scratch")
    transfer = runs_of(records, scenario, algo, "transfer")
    if scratch.size == 0 or not transfer:
        return None
    target = recovery_target(float(stats.iqm(scratch)))
    budget = key["after"] * key["episode_steps"]
    found: dict[str, Any] = {"target": target, "budget_steps": budget}
    for strategy, runs in curves_after(records, scenario, algo, key).items():
        if runs:
            steps = [recovery_steps(c, target, key["episode_steps"], key["window"]) for c in runs.values()]
            found[strategy] = _counted(steps, budget)
    return found


def _counted(steps: list[int | None], budget: int) -> dict[str, Any]:
    """Steps per run (None: never within ``budget``) with their IQM over runs, a run that never got
    there counted as ``budget`` (the figure is then a lower bound)."""
    counted = np.array([[s if s is not None else budget] for s in steps], dtype=float)
    return {
        "per_run": steps,
        "reached": sum(s is not None for s in steps),
        "runs": len(steps),
        "iqm": stats.iqm_interval(counted).as_dict(),
    }


def _over_runs(values: list[float]) -> dict[str, Any]:
    """One value per run with their IQM and its interval over runs."""
    return {"per_run": values, "runs": len(values), "iqm": stats.iqm_interval(np.array(values)[:, None]).as_dict()}


def normalisation(record: dict[str, Any], side: str = "after") -> dict[str, Any]:
    """The scale of a scenario's normalised scores from its baselines cell: ``low`` and ``high``,
    random's and the oracle's means on the line after the change (``side`` "before": before it);
    or, where the cell has not both or the oracle is not above random, ``missing``: why there is none."""
    line = record[side]
    absent = [agent for agent in ("random", "oracle") if agent not in line]
    if absent:
        why = record.get(f"oracle_{side}_missing") if absent == ["oracle"] else None
        return {"missing": f"the baselines cell has no {' and no '.join(absent)} {side} the change"
                + (f" ({why})" if why else "")}  # fmt: skip
    low, high = float(np.mean(line["random"])), float(np.mean(line["oracle"]))
    if not high > low:
        return {"missing": f"the oracle's mean {side} the change ({high:.2f}) is not above random's ({low:.2f})"}
    return {"low": low, "high": high}


def auc(curve, low: float, high: float) -> float:
    """The area under the normalised curve of episode rewards ``curve``, per episode: the mean of
    ``(reward - low) / (high - low)`` (1: ``high`` from the first episode on)."""
    return float(np.mean(stats.normalized(np.asarray(curve, dtype=float), low, high)))


def forward_transfer(auc_run: float, auc_scratch: float) -> float | None:
    """``(AUC - AUC_scratch) / (1 - AUC_scratch)``; None when ``AUC_scratch`` >= 1."""
    return (auc_run - auc_scratch) / (1 - auc_scratch) if auc_scratch < 1 else None


def crossover_steps(scratch_curve, continued_curve, episode_steps: int) -> int | None:
    """Steps after the change at the end of the first episode where the cumulative reward of
    ``scratch_curve`` exceeds that of ``continued_curve`` (both from the change on), or None."""
    n = min(len(scratch_curve), len(continued_curve))
    ahead = np.cumsum(np.asarray(scratch_curve[:n], dtype=float)) > np.cumsum(
        np.asarray(continued_curve[:n], dtype=float)
    )
    return (int(np.argmax(ahead)) + 1) * episode_steps if ahead.any() else None


def _over_runs_and_seeds(values: np.ndarray) -> dict[str, Any]:
    """Runs x evaluation seeds with each run's mean and the IQM over all of them, its interval over
    whole runs (as the final score's)."""
    return {"per_run": values.mean(axis=1).tolist(), "runs": values.shape[0],
            "iqm": stats.iqm_interval(values).as_dict()}  # fmt: skip


#: Why frozen's forgetting is not computed: its agent is the reference itself.
FROZEN_FORGETTING = "0 by construction: the frozen agent is the snapshot at the change, the reference"


def forgetting(
    records: list[dict], scenario: str, algo: str, scale: dict[str, Any] | None
) -> dict[str, dict[str, Any]]:
    """Per strategy, its forgetting and its score on the line before the change (``before``), both
    normalised by ``scale`` (random's and the oracle's means before the change, ``normalisation``):
    ``score_before_change``, the IQM over runs x seeds of ``(score - random) / (oracle - random)``;
    ``forgetting``, of ``(reference - score) / (oracle - random)`` per seed, the reference the
    snapshot at the change of the same training seed (the agent deployed when the line changed), so
    that 0 is nothing forgotten and 1 the oracle's margin over random lost. Intervals over whole
    runs. Frozen's forgetting is 0 by construction, not computed (``forgetting_note``). None of it
    where ``scale`` is missing or the cells have no evaluations on the line before the change
    (``forgetting_missing`` says why)."""
    found: dict[str, dict[str, Any]] = {s: {} for s in STRATEGIES}
    found[FORGETTING_REFERENCE]["forgetting_note"] = FROZEN_FORGETTING
    ref_st = STRATEGIES[FORGETTING_REFERENCE]
    reference = {r["cell"]["seed"]: r.get(ref_st.before) for r in runs_of(records, scenario, algo, ref_st.kind)}
    for strategy, st in STRATEGIES.items():
        runs = runs_of(records, scenario, algo, st.kind)
        if not runs or st.before is None:
            continue
        why = None
        if scale is None or "missing" in scale:
            why = "no baselines cell" if scale is None else scale["missing"]
        elif any(st.before not in r for r in runs):
            why = "cells saved before forgetting was measured (no evaluations on the line before the change)"
        if why is not None or scale is None:
            found[strategy]["forgetting_missing"] = why
            continue
        low, high = scale["low"], scale["high"]
        own = np.array([r[st.before] for r in runs], dtype=float)
        found[strategy]["score_before_change"] = _over_runs_and_seeds(stats.normalized(own, low, high))
        if strategy == FORGETTING_REFERENCE:
            continue
        seeds = [r["cell"]["seed"] for r in runs]
        if any(reference.get(seed) is None for seed in seeds):
            found[strategy]["forgetting_missing"] = (
                f"no snapshot at the change of seeds {[s for s in seeds if reference.get(s) is None]} "
                "evaluated on the line before it"
            )
            continue
        drop = (np.array([reference[seed] for seed in seeds], dtype=float) - own) / (high - low)
        found[strategy]["forgetting"] = {**_over_runs_and_seeds(drop), "seeds": seeds}
    return found


def continual(
    records: list[dict],
    scenario: str,
    algo: str,
    key: dict[str, Any],
    scale: dict[str, Any] | None,
    rba_hold: float | None,
    scale_before: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The continual-RL metrics of one scenario and algorithm (module docstring), per strategy, and
    the crossover between from scratch and continued; ``scale_before``: the normalisation of the
    line before the change (``forgetting``)."""
    budget = key["after"] * key["episode_steps"]
    curves = curves_after(records, scenario, algo, key)
    found: dict[str, Any] = {s: {} for s in STRATEGIES}
    for strategy, st in STRATEGIES.items():
        cells = runs_of(records, scenario, algo, st.kind)
        if st.at_change is not None and cells and all(st.at_change in r for r in cells):
            at_change = np.array([r[st.at_change] for r in cells], dtype=float)
            found[strategy]["jumpstart"] = _over_runs_and_seeds(at_change)
    for strategy, runs in curves.items():
        if not runs:
            continue
        if scale is not None and "missing" not in scale:
            found[strategy]["auc"] = _over_runs([auc(c, scale["low"], scale["high"]) for c in runs.values()])
        if rba_hold is not None:
            steps = [recovery_steps(c, rba_hold, key["episode_steps"], key["window"]) for c in runs.values()]
            found[strategy]["steps_to_rba_hold"] = {**_counted(steps, budget), "target": rba_hold}
    for strategy in ("continued", "perturbed", "cloned"):
        if "auc" not in found[strategy] or "auc" not in found["scratch"]:
            continue
        base = float(np.mean(found["scratch"]["auc"]["per_run"]))
        transfers = [t for a in found[strategy]["auc"]["per_run"] if (t := forward_transfer(a, base)) is not None]
        if len(transfers) == len(found[strategy]["auc"]["per_run"]):
            found[strategy]["forward_transfer"] = {**_over_runs(transfers), "auc_scratch": base}
        else:
            found[strategy]["forward_transfer_missing"] = f"the from-scratch runs' mean AUC is {base:.3f}, not below 1"
    for strategy, metrics in forgetting(records, scenario, algo, scale_before).items():
        found[strategy].update(metrics)
    pairs = sorted(set(curves.get("continued", {})) & set(curves.get("scratch", {})))
    if pairs:
        steps = [crossover_steps(curves["scratch"][s], curves["continued"][s], key["episode_steps"]) for s in pairs]
        found["scratch"]["crossover"] = {**_counted(steps, budget), "seeds": pairs}
    return found


def baseline_summary(record: dict[str, Any]) -> dict[str, Any]:
    """Means of the deterministic baselines (one run each: exact on these seeds)."""
    summary: dict[str, Any] = {
        side: {agent: float(np.mean(v)) for agent, v in record[side].items()} for side in ("before", "after")
    }
    summary["oracle_after_missing"] = record.get("oracle_after_missing")
    return summary


def algo_summary(
    records: list[dict],
    scenario: str,
    algo: str,
    key: dict[str, Any],
    rba_hold,
    scale: dict[str, Any] | None = None,
    scale_before: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A scenario's and algorithm's strategies, comparisons, steps to recover and continual-RL
    metrics; ``rba_hold``: its episodes after the change (1 x seeds), ``scale`` and ``scale_before``:
    ``normalisation`` after and before the change."""
    strategies, improvements = {}, {}
    for strategy in STRATEGIES:
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
    target = float(rba_hold.mean()) if rba_hold is not None else None
    return {
        "strategies": strategies,
        "improvement": improvements,
        "recovery": recovery(records, scenario, algo, key),
        "continual": continual(records, scenario, algo, key, scale, target, scale_before),
    }


def summarize(records: list[dict], key: dict[str, Any], scenarios, algos) -> dict[str, Any]:
    """Everything the tables and the plot show, per scenario (and algorithm)."""
    found = {}
    for scenario in scenarios:
        base = [r for r in records if r["cell"]["scenario"] == scenario and r["cell"]["kind"] == "baselines"]
        rba_hold = np.array([base[0]["after"]["rba-hold"]]) if base else None
        scale = normalisation(base[0]) if base else None
        scale_before = normalisation(base[0], "before") if base else None
        found[scenario] = {
            "baselines": baseline_summary(base[0]) if base else None,
            "normalisation": scale,
            "normalisation_before": scale_before,
            "algos": {a: algo_summary(records, scenario, a, key, rba_hold, scale, scale_before) for a in algos},
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
        f"{b['after']['oracle']:.2f}" if "oracle" in b["after"] else "n/a (below)",
    ]


def _score_table(summary: dict[str, Any], key: dict[str, Any]) -> list[str]:
    lines = [
        f"## Final score after the change: IQM [95 % CI] over runs x {key['evaluations']} held-out seeds "
        f"(from {key['eval_seed']})",
        "",
        "| scenario | algorithm | runs | "
        + " | ".join(st.label for st in STRATEGIES.values())
        + " | rba-hold before / after | rba before / after | oracle after |",
        "|---|---|---|" + "---|" * len(STRATEGIES) + "---|---|---|",
    ]
    for scenario, s in summary.items():
        base = _baseline_cells(s["baselines"])
        for algo, a in s["algos"].items():
            st = a["strategies"]
            runs = "/".join(str(st[x]["runs"]) if x in st else "0" for x in STRATEGIES)
            scores = [_interval(st.get(x, {}).get("iqm")) for x in STRATEGIES]
            lines.append(f"| {scenario} | {algo} | {runs} | " + " | ".join(scores + base) + " |")
    missing = {sc: s["baselines"]["oracle_after_missing"] for sc, s in summary.items()
               if s["baselines"] and s["baselines"].get("oracle_after_missing")}  # fmt: skip
    lines += ["", *(f"No oracle after the change in {sc}: {why}." for sc, why in missing.items())] if missing else []
    return lines


def _improvement_table(summary: dict[str, Any]) -> list[str]:
    pairs = [f"{x} > {y}" for x, y in COMPARISONS] + [f"{x} > rba-hold" for x in STRATEGIES]
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
    training = [name for name, st in STRATEGIES.items() if st.curve is not None]
    titles = [STRATEGIES[n].label + (", after the change" if STRATEGIES[n].kind != "scratch" else "") for n in training]
    lines = [
        f"## Steps to recover: to {RECOVERY_SHARE:.0%} of the from-scratch final score, IQM [95 % CI] over runs",
        "",
        "| scenario | algorithm | target reward | " + " | ".join(titles) + " |",
        "|---|---|---|" + "---|" * len(training),
    ]
    for scenario, s in summary.items():
        for algo, a in s["algos"].items():
            r = a["recovery"]
            cells = [f"{r['target']:.2f}", *(_steps(r.get(n)) for n in training)] if r else ["-"] * (1 + len(training))
            lines.append(f"| {scenario} | {algo} | " + " | ".join(cells) + " |")
    return lines


#: The continual-RL tables' columns: (title, the metric in ``continual``'s strategy, digits).
CONTINUAL_COLUMNS = (
    ("jumpstart", "jumpstart", 2),
    ("AUC after the change", "auc", 3),
    ("steps to rba-hold", "steps_to_rba_hold", 0),
    ("forward transfer", "forward_transfer", 3),
    ("new agent's cumulative reward passes the continued one's at", "crossover", 0),
    ("score before the change", "score_before_change", 3),
    ("forgetting", "forgetting", 3),
)


def _normalised_between(scale: dict[str, Any] | None, what: str = "AUC", where: str = "after the change") -> str:
    """How ``what`` is normalised (``scale``: ``normalisation`` of the line ``where``), or why it is not."""
    if scale is None:
        return f"no baselines cell: no {what}"
    if "missing" in scale:
        return f"no {what}: {scale['missing']}"
    return f"{what} normalised between random and the oracle {where} ({scale['low']:.2f} and {scale['high']:.2f})"


def _continual_cell(metric: dict[str, Any] | None, digits: int, note: str | None = None) -> str:
    if note is not None:
        return "0 (by construction)"
    if not metric:
        return "-"
    if "reached" in metric:
        return f"{_interval(metric['iqm'], digits)} ({metric['reached']}/{metric['runs']})"
    return _interval(metric["iqm"], digits)


def _continual_tables(summary: dict[str, Any], key: dict[str, Any]) -> list[str]:
    lines = [
        "## Continual-RL metrics: IQM [95 % CI] over runs",
        "",
        "Jumpstart: the score right after the change (the frozen snapshot's, evaluated on the changed line). "
        "AUC: the mean normalised training reward after the change, (reward - random) / (oracle - random) "
        "(1: the oracle's mean throughout). "
        f"Steps to rba-hold: until the {key['window']}-episode moving mean of the training rewards reaches "
        "rba-hold's mean "
        "after the change ((k/n): k of n runs did; the others count as the budget, a lower bound). "
        "Forward transfer: (AUC - AUC_scratch) / (1 - AUC_scratch), against the mean AUC of the from-scratch runs. "
        "Crossover: steps after the change at which the from-scratch run's cumulative training reward first "
        "exceeds the continued run's of the same seed ((k/n) as above). "
        "Score before the change: the agent's score on the line before the change after its training, "
        "(score - random) / (oracle - random) there. Forgetting: (the snapshot at the change's score - the agent's) / "
        "(oracle - random), both on the line before the change, per seed against the snapshot of the same training "
        "seed (0: nothing forgotten; frozen: 0 by construction, it is that snapshot).",
    ]
    header = "| strategy | runs | final score | " + " | ".join(c[0] for c in CONTINUAL_COLUMNS) + " |"
    for scenario, s in summary.items():
        for algo, a in s["algos"].items():
            lines += ["", f"### {scenario}, {algo}: {_normalised_between(s.get('normalisation'))}; "
                      f"{_normalised_between(s.get('normalisation_before'), 'forgetting', 'before it')}", "", header,
                      "|---|---|---|" + "---|" * len(CONTINUAL_COLUMNS)]  # fmt: skip
            for strategy in STRATEGIES:
                st, metrics = a["strategies"].get(strategy), a.get("continual", {}).get(strategy, {})
                cells = [
                    _continual_cell(metrics.get(name), digits, metrics.get("forgetting_note") if name == "forgetting"
                                    else None)
                    for _, name, digits in CONTINUAL_COLUMNS
                ]  # fmt: skip
                final = _interval(st["iqm"]) if st else "-"
                lines.append(f"| {strategy} | {st['runs'] if st else 0} | {final} | " + " | ".join(cells) + " |")
            missing = {
                n: m["forgetting_missing"] for n, m in a.get("continual", {}).items() if "forgetting_missing" in m
            }
            lines += ["", *(f"No forgetting for {n}: {why}." for n, why in missing.items())] if missing else []
    return lines


def markdown(summary: dict[str, Any], key: dict[str, Any]) -> str:
    """The tables: final scores, probabilities of improvement, steps to recover, and the
    continual-RL metrics per scenario and algorithm."""
    lines = _score_table(summary, key) + [""] + _improvement_table(summary) + [""] + _recovery_table(summary)
    lines += [""] + _continual_tables(summary, key)
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
    before, window = key["before"], key["window"]
    for strategy in (st for st in STRATEGIES.values() if st.curve is not None):
        runs = runs_of(records, scenario, algo, strategy.kind)
        if not runs:
            continue
        curves = np.array([moving(r[strategy.curve], window) for r in runs])
        x = np.arange(curves.shape[1]) - _change_at(strategy, key)
        seeds = f"mean of {len(runs)} seeds, band min-max" if len(runs) > 1 else "1 seed"
        ax.plot(x, curves.mean(axis=0), color=strategy.colour, label=f"{strategy.label}: {seeds}")
        ax.fill_between(x, curves.min(axis=0), curves.max(axis=0), color=strategy.colour, alpha=0.2, lw=0)
    s = summary[scenario]
    frozen = s["algos"][algo]["strategies"].get("frozen")
    if frozen:
        ax.axhline(
            frozen["iqm"]["point"],
            color=STRATEGIES["frozen"].colour,
            ls="--",
            label=f"{STRATEGIES['frozen'].label}, IQM: {frozen['iqm']['point']:.1f}",
        )
    for agent, style in (("rba-hold", ":"), ("oracle", "-.")):
        if s["baselines"] and agent in s["baselines"]["after"]:
            value = s["baselines"]["after"][agent]
            ax.axhline(value, color="tab:green", ls=style, label=f"{agent} after the change: {value:.1f}")
    ax.axvline(0, color="black", lw=0.8)
    ax.set_title(f"{scenario}, {algo}: change after {before} episodes", fontsize=9)
    ax.set_xlabel(f"episodes relative to the change ({key['episode_steps']} steps each)")
    ax.set_ylabel(f"episode reward ({window}-episode moving mean)")
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

    panels = []
    for scenario, s in summary.items():
        after = (s["baselines"] or {}).get("after", {})
        refs = [(agent, after[agent]) for agent in ("rba-hold", "oracle") if agent in after]
        for algo, a in s["algos"].items():
            strips = [
                Strip(STRATEGIES[name].label, st["per_run"], st["iqm"], STRATEGIES[name].colour)
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
