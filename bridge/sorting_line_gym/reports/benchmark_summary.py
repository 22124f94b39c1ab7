"""The benchmark's results as numbers: per line and agent the mean over runs and the held-out
IQM with its interval (``summarize``), the oracle's row, the probability that an RL agent beats
rba-hold, the score normalized between the random agent and the oracle and its aggregate over the
lines, and where one line and N lines were both trained, whether they agree. The score is also
normalized per held-out seed (``references``, ``normalized_summary``): (R - R_random) /
(R_oracle - R_random) on each seed, the random agent's and the exact oracle's rewards on it.

Pure analysis of the records ``studies.benchmark`` saves (one JSON per cell): no ROS, no training.
The statistics are ``stats``'; the tables ``benchmark_tables``, the figures ``plots``.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..training.hyperparams import ALGOS, DEFAULT_MAPPING, gradient_steps_per_transition
from . import stats

BASELINES = ("random", "rba", "rba-hold")
AGENTS = BASELINES + ALGOS
#: Row order of the table: the paper's within a line (RBA, DQN, PPO, A2C), our extras first.
TABLE_ORDER = ("random", "rba", "rba-hold", "dqn", "ppo", "a2c")
#: The held-out evaluation: seeds far from every training start (s .. s + n_envs - 1).
HELDOUT_SEED = 10_000
HELDOUT_EPISODES = 100
#: Runs (training seeds) per side that an agreement verdict needs.
AGREEMENT_RUNS = 5


@dataclass(frozen=True)
class Heldout:
    """The held-out evaluation seeds: ``episodes`` seeds from ``seed``."""

    seed: int = HELDOUT_SEED
    episodes: int = HELDOUT_EPISODES


Key = tuple  # (setup, variant, agent)


def _group(records: list[dict[str, Any]]) -> dict[Key, list[dict[str, Any]]]:
    groups: dict[Key, list[dict[str, Any]]] = {}
    for r in records:
        c = r["cell"]
        groups.setdefault((c["setup"], c["variant"], c["agent"]), []).append(r)
    for rs in groups.values():
        rs.sort(key=lambda r: r["cell"]["train_seed"] or 0)
    return groups


def by_cell(records: list[dict[str, Any]]) -> dict[Key, list[dict[str, Any]]]:
    """The records by (setup, variant, agent), each cell's runs in the order of their training seeds."""
    return _group(records)


def episode_rewards(records: list[dict[str, Any]], which: str = "heldout") -> np.ndarray:
    """Runs x evaluation seeds: each record's (training seed's) per-episode rewards."""
    return np.array([[e["reward"] for e in r[which]["per_episode"]] for r in records])


@dataclass(frozen=True)
class References:
    """A line's references for the score normalized per held-out seed: on each seed (``seeds``),
    the random agent's reward (0) and the exact oracle's (1)."""

    seeds: tuple[int, ...]
    random: np.ndarray
    oracle: np.ndarray

    def normalize(self, seeds, scores) -> tuple[np.ndarray, list[int]]:
        """``(R - R_random) / (R_oracle - R_random)`` per seed of ``scores`` (runs x ``seeds``, which
        must be this line's seeds in order), over the seeds that have a scale, and the seeds left
        out (where the oracle does no better than the random agent: ``stats.normalized_per_task``)."""
        if tuple(int(s) for s in seeds) != self.seeds:
            raise ValueError(f"scores on seeds {_seed_span(seeds)}, allowed the references' {_seed_span(self.seeds)}")
        values, kept = stats.normalized_per_task(scores, self.random, self.oracle)
        return values, [s for s, k in zip(self.seeds, kept, strict=True) if not k]


def _seed_span(seeds) -> str:
    """Seeds as ``first..last`` when they are consecutive, else listed."""
    seeds = [int(s) for s in seeds]
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}..{seeds[-1]} ({len(seeds)} seeds)"
    return ", ".join(map(str, seeds)) or "none"


def episode_seeds(record: dict[str, Any], which: str = "heldout") -> list[int]:
    """The evaluation seeds of a record, in its episodes' order."""
    return [int(e["seed"]) for e in record[which]["per_episode"]]


def references(
    records: list[dict[str, Any]], oracles: dict[tuple[str, str], dict[str, Any]]
) -> dict[tuple[str, str], References]:
    """Per line with a random cell and an oracle: the random agent's and the oracle's reward on each
    held-out seed (the random agent is one deterministic run). Refuses a random cell and an
    oracle on different seeds."""
    found = {}
    for (setup, variant, agent), rs in _group([r for r in records if "heldout" in r]).items():
        if agent != "random" or (setup, variant) not in oracles:
            continue
        seeds = episode_seeds(rs[0])
        oracle = oracles[(setup, variant)]["per_episode"]
        if [int(e["seed"]) for e in oracle] != seeds:
            raise ValueError(
                f"{setup} {variant}: the oracle is on seeds {_seed_span(e['seed'] for e in oracle)}, "
                f"the random cell on {_seed_span(seeds)}: allowed the same seeds"
            )
        found[(setup, variant)] = References(
            tuple(seeds), episode_rewards(rs[:1])[0], np.array([e["reward"] for e in oracle], dtype=float)
        )
    return found


def normalized_summary(refs: References, seeds, scores) -> dict[str, Any]:
    """The normalized score of one cell (runs x held-out seeds): mean and IQM over runs x seeds with
    their intervals over whole runs, as the rewards', each run's mean (``per_run``), and the seeds
    left out."""
    values, left_out = refs.normalize(seeds, scores)
    summary: dict[str, Any] = {"seeds": values.shape[1], "left_out_seeds": left_out}
    if values.shape[1]:
        summary |= {
            "mean": stats.mean_interval(values).as_dict(),
            "iqm": stats.iqm_interval(values).as_dict(),
            "per_run": values.mean(axis=1).tolist(),
        }
    return summary


def summarize(
    records: list[dict[str, Any]], oracles: dict[tuple[str, str], dict[str, Any]]
) -> dict[Key, dict[str, Any]]:
    """Per (setup, variant, agent). On the paper's seeds 42..51: the mean over training seeds of
    each model's mean, with the std across training seeds (the per-episode std for one run). On
    the held-out seeds: mean and IQM over runs x episodes with their bootstrap intervals over
    whole runs, each run's mean (``per_seed``: one per training seed), the gap to the oracle of
    the same seeds, and (where the line has a random cell) the score normalized per seed
    (``normalized``: :func:`normalized_summary`)."""
    rows = {}
    refs = references(records, oracles)
    for key, rs in _group(records).items():
        evals = [r["evaluation"] for r in rs]
        means = [e["reward_mean"] for e in evals]
        seeds = len(rs)
        row = {
            "reward_mean": statistics.fmean(means),
            "reward_std": statistics.pstdev(means) if seeds > 1 else evals[0]["reward_std"],
            "std_over": "training seeds" if seeds > 1 else "episodes",
            "seeds": seeds,
            "per_seed": means,
            "speed_mean": statistics.fmean(e["speed_mean"] for e in evals),
            "purity_mean": statistics.fmean(e["purity_mean"] for e in evals),
            "speed_changes_mean": statistics.fmean(e["speed_changes_mean"] for e in evals),
            "train_wall_s": statistics.fmean(r["training"]["wall_s"] for r in rs) if "training" in rs[0] else None,
            "n_envs": rs[0]["cell"].get("n_envs", 1),
        }
        if all("heldout" in r for r in rs):
            scores = episode_rewards(rs)
            oracle_rewards = np.array([e["reward"] for e in oracles[key[:2]]["per_episode"]])
            row["heldout"] = {
                "first_seed": rs[0]["heldout"]["seed"],
                "episodes": scores.shape[1],
                "per_seed": scores.mean(axis=1).tolist(),
                "mean": stats.mean_interval(scores).as_dict(),
                "iqm": stats.iqm_interval(scores).as_dict(),
                "oracle_mean": float(oracle_rewards.mean()),
                "gap_mean": float((oracle_rewards[None, :] - scores).mean()),
            }
            if key[:2] in refs:
                row["heldout"]["normalized"] = normalized_summary(refs[key[:2]], episode_seeds(rs[0]), scores)
        rows[key] = row
    return rows


def oracle_rows(
    oracles: dict[tuple[str, str], dict[str, Any]], paper_oracles: dict[tuple[str, str], dict[str, Any]]
) -> dict[Key, dict[str, Any]]:
    """The oracle as a row of the table (it has no runs: the optimum is one number per seed)."""
    rows = {}
    for line, heldout in oracles.items():
        paper = paper_oracles[line]
        rewards = np.array([e["reward"] for e in heldout["per_episode"]])
        rows[line + ("oracle",)] = {
            "reward_mean": paper["reward_mean"],
            "reward_std": paper["reward_std"],
            "seeds": 1,
            "speed_mean": paper["speed_mean"],
            "purity_mean": paper["purity_mean"],
            "speed_changes_mean": paper["speed_changes_mean"],
            "heldout": {
                "mean": {"point": float(rewards.mean())},
                "iqm": {"point": float(stats.iqm(rewards))},
                "oracle_mean": float(rewards.mean()),
                "gap_mean": 0.0,
            },
        }
    return rows


def improvements(
    records: list[dict[str, Any]], versus: str = "rba-hold"
) -> dict[tuple[str, str, str], dict[str, float]]:
    """Per line and RL agent: P(agent > ``versus``) on the held-out seeds, with its interval."""
    groups = _group([r for r in records if "heldout" in r])
    found = {}
    for (setup, variant, agent), rs in groups.items():
        if agent in ALGOS and (setup, variant, versus) in groups:
            interval = stats.probability_of_improvement_interval(
                episode_rewards(rs), episode_rewards(groups[(setup, variant, versus)])
            )
            found[(setup, variant, agent)] = interval.as_dict()
    return found


def normalized_runs(
    records: list[dict[str, Any]], oracles: dict[tuple[str, str], dict[str, Any]]
) -> dict[str, dict[tuple[str, str], np.ndarray]]:
    """Per agent and line: each run's held-out mean reward normalized between the random agent's
    mean (0) and the oracle's (1) on the same seeds. Lines without a random cell are left out."""
    groups = _group([r for r in records if "heldout" in r])
    per_agent: dict[str, dict[tuple[str, str], np.ndarray]] = {}
    for (setup, variant, agent), rs in groups.items():
        if (setup, variant, "random") not in groups or (setup, variant) not in oracles:
            continue
        worst = float(episode_rewards(groups[(setup, variant, "random")]).mean())
        best = float(np.mean([e["reward"] for e in oracles[(setup, variant)]["per_episode"]]))
        per_agent.setdefault(agent, {})[(setup, variant)] = stats.normalized(
            episode_rewards(rs).mean(axis=1), worst, best
        )
    return per_agent


def aggregates(normalized: dict[str, dict[tuple[str, str], np.ndarray]]) -> dict[str, dict[str, Any]]:
    """Per agent: IQM and mean over runs x lines of the normalized score, the interval over whole
    runs stratified by line (each line's runs drawn from that line's)."""
    found = {}
    for agent, lines in normalized.items():
        strata = list(lines.values())
        found[agent] = {
            "lines": len(strata),
            "iqm": stats.iqm_interval_over_lines(strata).as_dict(),
            "mean": stats.mean_interval_over_lines(strata).as_dict(),
        }
    return found


def normalized_per_seed_runs(rows: dict[Key, dict[str, Any]]) -> dict[str, dict[tuple[str, str], np.ndarray]]:
    """Per agent and line: each run's mean of the score normalized per seed (``summarize``'s
    ``heldout.normalized.per_run``), the input of :func:`aggregates` as :func:`normalized_runs` is."""
    per_agent: dict[str, dict[tuple[str, str], np.ndarray]] = {}
    for (setup, variant, agent), row in rows.items():
        normalized = row.get("heldout", {}).get("normalized") or {}
        if normalized.get("per_run"):
            per_agent.setdefault(agent, {})[(setup, variant)] = np.array(normalized["per_run"])
    return per_agent


def _updates_per_transition(agent: str, records: list[dict[str, Any]]) -> float:
    r = records[0]["training"]
    return gradient_steps_per_transition(agent, {**r["hyperparams"], "n_envs": r["n_envs"]})


def agreement(records: list[dict[str, Any]], timesteps: int) -> list[dict[str, Any]]:
    """Where one agent on one line was trained on one line and on N lines (same budget, per
    mapping): their IQM intervals, P(N lines > 1 line) and each side's runs (held-out mean per
    run); they agree when the IQM intervals overlap."""
    by_lines: dict[tuple[str, str, str], dict[tuple[int, str], list[dict[str, Any]]]] = {}
    for r in records:
        c = r["cell"]
        if c["agent"] in ALGOS and "heldout" in r and r.get("timesteps") == timesteps:
            lines = (c.get("n_envs", 1), c.get("mapping", DEFAULT_MAPPING))
            by_lines.setdefault((c["setup"], c["variant"], c["agent"]), {}).setdefault(lines, []).append(r)
    checks = []
    for (setup, variant, agent), groups in sorted(by_lines.items()):
        ones = [rs for (n, _), rs in groups.items() if n == 1]
        if not ones:
            continue
        one = episode_rewards(ones[0])
        for (n, mapping), rs in sorted(groups.items()):
            if n == 1:
                continue
            many = episode_rewards(rs)
            iqm_one, iqm_many = stats.iqm_interval(one), stats.iqm_interval(many)
            checks.append(
                {
                    "setup": setup,
                    "variant": variant,
                    "agent": agent,
                    "n_envs": n,
                    "mapping": mapping,
                    "runs": [one.shape[0], many.shape[0]],
                    "iqm_1": iqm_one.as_dict(),
                    "iqm_n": iqm_many.as_dict(),
                    "poi_n_over_1": stats.probability_of_improvement_interval(many, one).as_dict(),
                    "per_run": [one.mean(axis=1).tolist(), many.mean(axis=1).tolist()],
                    "agree": iqm_one.overlaps(iqm_many),
                    "gradient_steps_per_transition": [
                        _updates_per_transition(agent, ones[0]),
                        _updates_per_transition(agent, rs),
                    ],
                    "train_wall_s": [
                        statistics.fmean(r["training"]["wall_s"] for r in ones[0]),
                        statistics.fmean(r["training"]["wall_s"] for r in rs),
                    ],
                }
            )
    return checks


def agreement_by_algorithm(checks: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per agent, number of lines and mapping: on how many of the checked lines one line and N lines
    agree, and the verdict: "agrees" (on every checked line), "does not agree" (on some line not),
    each with at least ``AGREEMENT_RUNS`` runs a side, else "too few runs"."""
    groups: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for c in checks:
        groups.setdefault((c["agent"], c["n_envs"], c["mapping"]), []).append(c)
    rows = []
    for (agent, n, mapping), cs in sorted(groups.items(), key=lambda kv: (ALGOS.index(kv[0][0]), kv[0][1:])):
        agreeing = sum(c["agree"] for c in cs)
        if any(min(c["runs"]) < AGREEMENT_RUNS for c in cs):
            verdict = f"too few runs (fewer than {AGREEMENT_RUNS} a side)"
        else:
            verdict = "agrees" if agreeing == len(cs) else "does not agree"
        lines = [f"{c['setup']} {c['variant']}" for c in cs]
        rows.append(
            {"agent": agent, "n_envs": n, "mapping": mapping, "lines": lines, "agreeing": agreeing, "verdict": verdict}
        )
    return rows
