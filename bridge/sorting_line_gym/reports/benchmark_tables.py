"""The benchmark's report as markdown: Table 1 beside the paper's and the reference's figures
(:func:`table_markdown`), then the statistics over runs (:func:`statistics_markdown`)."""

from __future__ import annotations

from typing import Any

from ..line.vocabulary import EPISODE_STEPS, EVAL_EPISODES, EVAL_SEEDS, SETUPS, VARIANTS
from ..training.hyperparams import ALGOS
from .benchmark_summary import (
    AGENTS,
    AGREEMENT_RUNS,
    TABLE_ORDER,
    Heldout,
    Key,
    aggregates,
    agreement_by_algorithm,
    normalized_per_seed_runs,
)

TABLE_HEADER = [
    f"| index | setup | env | agent | runs | seeds {EVAL_SEEDS}: reward | held-out: mean |"
    " held-out: IQM [95% CI] | gap to oracle |"
    " speed % | purity % | speed changes | paper: reward | reference impl.: reward |",
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
]


def _interval(d: dict[str, float]) -> str:
    return f"{d['point']:.2f} [{d['low']:.2f}, {d['high']:.2f}]"


def _env(variant: str) -> str:
    return "Adv" if variant == "advanced" else "Basic"


def _our_cells(row: dict[str, Any] | None, agent: str, best: float) -> list[str]:
    """Our columns of one row (runs .. speed changes); "not run" when the agent has no results."""
    if row is None:
        return ["", "not run", "", "", "", "", "", ""]
    mean = f"{row['reward_mean']:.2f}"
    bold = row["reward_mean"] == best and agent != "oracle"
    ours = (f"**{mean}**" if bold else mean) + f" +- {row['reward_std']:.2f}"
    h = row.get("heldout")
    if h:
        iqm = "exact: " + f"{h['iqm']['point']:.2f}" if agent == "oracle" else _interval(h["iqm"])
        heldout = [f"{h['mean']['point']:.2f}", iqm, f"{h['gap_mean']:.2f}"]
    else:
        heldout = ["", "", ""]
    return [
        "" if agent == "oracle" else str(row["seeds"]),
        ours,
        *heldout,
        f"{100 * row['speed_mean']:.0f}",
        f"{100 * row['purity_mean']:.1f}",
        f"{row['speed_changes_mean']:.1f}",
    ]


def _table_note(timesteps: int, heldout: Heldout) -> str:
    return (
        f"\nRuns: training seeds (RL) or 1 (the deterministic baselines). Seeds {EVAL_SEEDS}: the paper's protocol"
        f" ({EVAL_EPISODES} episodes of {EPISODE_STEPS} steps, deterministic policy), mean +- population std over the"
        " episodes, or for RL with several"
        f" runs the mean over runs +- the std across them. Held-out: {heldout.episodes} seeds from {heldout.seed}; mean"
        " and IQM over runs x episodes, the IQM's 95% bootstrap interval resamples whole runs (a run's scores on"
        " all held-out seeds together; one run: exact); each run's held-out mean is drawn in `runs.png`; gap to"
        " oracle = mean over runs x seeds of `sorting_line oracle` - agent. RL"
        f" agents trained for {timesteps} steps with the paper's hyperparameters. The paper's Table 1 has no random,"
        " rba-hold or oracle rows, and its RBA figures are not what the reference implementation's code gives on the"
        f" same protocol (last column). Bold: our best agent on seeds {EVAL_SEEDS}."
    )


def table_markdown(
    rows: dict[Key, dict[str, Any]], timesteps: int, agents=AGENTS, heldout: Heldout | None = None
) -> str:
    """Our figures beside the paper's and the reference's, for ``agents`` (and the oracle) on every
    line that has results ("not run" marks a requested agent whose cells are missing); ``heldout``
    by default the benchmark's."""
    heldout = heldout or Heldout()
    from .paper import REFERENCE, TABLE_1, TABLE_1_INDEX

    lines = list(TABLE_HEADER)
    ran = {(s, v) for s, v, a in rows if a != "oracle"}
    for setup in SETUPS:
        for variant in VARIANTS:
            if (setup, variant) not in ran:
                continue
            shown = [a for a in TABLE_ORDER if a in agents] + ["oracle"]
            best = max(rows[(setup, variant, a)]["reward_mean"] for a in shown[:-1] if (setup, variant, a) in rows)
            for agent in shown:
                key = (setup, variant, agent)
                row, paper, ref = rows.get(key), TABLE_1.get(key), REFERENCE.get(key)
                if row is None and paper is None:
                    continue
                cells = [TABLE_1_INDEX.get(key, ""), setup, _env(variant), agent, *_our_cells(row, agent, best)]
                cells += [f"{paper[2]:.2f}" if paper else "", f"{ref[0]:.2f} +- {ref[1]:.2f}" if ref else ""]
                lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n" + _table_note(timesteps, heldout) + "\n" + normalized_markdown(rows, agents)


def normalized_markdown(rows: dict[Key, dict[str, Any]], agents=AGENTS) -> str:
    """Table 1's held-out scores normalized per seed (``benchmark_summary.normalized_summary``),
    per line and agent; empty when no line has a random cell."""
    out = [
        "",
        "## Table 1, normalized per held-out seed: (R - R_random) / (R_oracle - R_random)",
        "",
        "| setup | env | agent | runs | seeds | normalized: mean [95% CI] | normalized: IQM [95% CI] |",
        "|---|---|---|---|---|---|---|",
    ]
    left_out: dict[str, list[int]] = {}
    for setup in SETUPS:
        for variant in VARIANTS:
            for agent in [a for a in TABLE_ORDER if a in agents]:
                n = rows.get((setup, variant, agent), {}).get("heldout", {}).get("normalized")
                if n is None:
                    continue
                left_out[f"{setup} {_env(variant)}"] = n["left_out_seeds"]
                scores = [_interval(n["mean"]), _interval(n["iqm"])] if n["seeds"] else ["no seed has a scale"] * 2
                cells = [setup, _env(variant), agent, str(rows[(setup, variant, agent)]["seeds"]), str(n["seeds"])]
                out.append("| " + " | ".join(cells + scores) + " |")
    if not left_out:
        return ""
    dropped = "; ".join(f"{line}: {', '.join(map(str, seeds))}" for line, seeds in left_out.items() if seeds)
    out += [
        "",
        "Per held-out seed, R = the agent's reward, R_random = the random agent's on that seed (0), R_oracle ="
        " `sorting_line oracle`'s (1, the clairvoyant optimum); mean and IQM over runs x seeds, interval: whole runs"
        " resampled, as Table 1's. A seed where the oracle does no better than the random agent (R_oracle - R_random"
        " <= 1e-9) has no scale and is left out for every agent of its line"
        f" ({'left out: ' + dropped if dropped else 'none here'}). Lines without a random cell have no row.",
        "",
    ]
    return "\n".join(out + _normalized_aggregate_markdown(aggregates(normalized_per_seed_runs(rows)), agents))


def _normalized_aggregate_markdown(aggregate: dict[str, dict[str, Any]], agents) -> list[str]:
    out = [
        "### Over the lines, normalized per seed",
        "",
        "| agent | lines | IQM [95% CI] | mean [95% CI] |",
        "|---|---|---|---|",
    ]
    for agent in [a for a in TABLE_ORDER if a in agents and a in aggregate]:
        a = aggregate[agent]
        out.append(f"| {agent} | {a['lines']} | {_interval(a['iqm'])} | {_interval(a['mean'])} |")
    return out + [
        "",
        "Per run and line: its mean over the seeds of the score normalized per seed; IQM and mean over runs x lines,"
        " interval: whole runs resampled within each line, as the aggregate below (which normalizes a run's mean"
        " reward by the line's mean rewards of random and the oracle instead).",
        "",
    ]


def _improvement_markdown(poi) -> list[str]:
    algos = [a for a in ALGOS if any(k[2] == a for k in poi)]
    out = [
        "## Probability of improvement over rba-hold (held-out seeds, 95% CI)",
        "",
        "| setup | env | " + " | ".join(f"P({a} > rba-hold)" for a in algos) + " |",
        "|---|---|" + "---|" * len(algos),
    ]
    for setup in SETUPS:
        for variant in VARIANTS:
            if any((setup, variant, a) in poi for a in algos):
                cells = [_interval(poi[(setup, variant, a)]) if (setup, variant, a) in poi else "" for a in algos]
                out.append(f"| {setup} | {_env(variant)} | " + " | ".join(cells) + " |")
    return out + [
        "",
        "P(X > Y): the chance that a run of X beats rba-hold on a held-out seed, averaged over the seeds (ties half);"
        " 0.5 = no difference. Interval: whole runs of the agent resampled (rba-hold is one deterministic run).",
        "",
    ]


def _aggregate_markdown(aggregate) -> list[str]:
    out = [
        "## Aggregate over the lines: score normalized between random (0) and the oracle (1)",
        "",
        "| agent | lines | IQM [95% CI] | mean [95% CI] |",
        "|---|---|---|---|",
    ]
    for agent in TABLE_ORDER:
        if agent in aggregate:
            a = aggregate[agent]
            out.append(f"| {agent} | {a['lines']} | {_interval(a['iqm'])} | {_interval(a['mean'])} |")
    return out + [
        "",
        "Per run and line: (held-out mean reward - random's) / (oracle's - random's); IQM over runs x lines,"
        " interval: whole runs resampled within each line (the bootstrap stratified by line).",
        "",
    ]


def _agreement_markdown(checks: list[dict[str, Any]]) -> list[str]:
    out = [
        "## One line against N lines of one node (--n-envs)",
        "",
        "| setup | env | agent | lines | mapping | runs | IQM, 1 line [95% CI] | IQM, N lines [95% CI] "
        "| P(N lines > 1 line) | agree | gradient steps per 1000 transitions (1 / N lines) "
        "| training s (1 / N lines) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in checks:
        g = c["gradient_steps_per_transition"]
        out.append(
            f"| {c['setup']} | {_env(c['variant'])} | {c['agent']} | {c['n_envs']} | "
            f"{c['mapping']} | {c['runs'][0]} / {c['runs'][1]} | {_interval(c['iqm_1'])} | {_interval(c['iqm_n'])} | "
            f"{_interval(c['poi_n_over_1'])} | {'yes' if c['agree'] else 'NO'} | "
            f"{1000 * g[0]:.0f} / {1000 * g[1]:.0f} | "
            f"{c['train_wall_s'][0]:.0f} / {c['train_wall_s'][1]:.0f} |"
        )
    out += [
        "",
        "Agree: the two IQM intervals overlap (each over whole runs; the runs are drawn in `runs.png`)."
        " Mapping: how the one-line hyperparameters go to N lines"
        " (`training/hyperparams.py`).",
        "",
        "### Per algorithm",
        "",
        "| agent | lines | mapping | checked on | agree on | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for row in agreement_by_algorithm(checks):
        out.append(
            f"| {row['agent']} | {row['n_envs']} | {row['mapping']} | {', '.join(row['lines'])} | "
            f"{row['agreeing']} of {len(row['lines'])} | {row['verdict']} |"
        )
    out += ["", f"Verdicts need at least {AGREEMENT_RUNS} runs (training seeds) a side on each checked line.", ""]
    return out


def statistics_markdown(poi, aggregate, checks) -> str:
    """Probability of improvement, aggregate IQM and the --n-envs agreement check as markdown."""
    out = []
    if poi:
        out += _improvement_markdown(poi)
    if aggregate:
        out += _aggregate_markdown(aggregate)
    if checks:
        out += _agreement_markdown(checks)
    return "\n".join(out)
