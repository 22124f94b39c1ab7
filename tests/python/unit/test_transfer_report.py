"""The transfer report's continual-RL metrics (reports/transfer_report.py ``continual``) on records
made up here, whose curves give known answers: jumpstart, the area under the normalised curve after
the change (between random and the oracle; none, saying why, without them), steps to rba-hold (a run
that never gets there counted as its budget, a lower bound), forward transfer against the
from-scratch runs' mean AUC (none when that mean is not below 1), the crossover of the cumulative
training rewards, forgetting against the snapshot at the change between random and the oracle
before it (frozen's 0 by construction; none, saying why, for cells without the evaluations), the
shrink-and-perturb strategy's metrics, and their table. No node, no training.
"""

from __future__ import annotations

import pytest

from sorting_line_gym.reports import transfer_report as tr

KEY = {"before": 10, "after": 20, "episode_steps": 50, "window": 10, "evaluations": 4, "eval_seed": 10_000}
BUDGET = 20 * 50


def record(kind: str, seed: int | None = None, **values) -> dict:
    algo = None if kind == "baselines" else "ppo"
    return {"cell": {"scenario": "sensor", "kind": kind, "algo": algo, "seed": seed}, **values}


def records(after: dict[str, list[float]], scratch1=None) -> list[dict]:
    """Two seeds. Continued after the change: 5 throughout (seed 1), 2 throughout (seed 2); from
    scratch: 0 for 8 episodes then 10 (seed 1), 1 throughout (seed 2)."""
    return [
        record("transfer", 1, continued_curve=[9.0] * 10 + [5.0] * 20, continued_eval=[6.0] * 4, frozen_eval=[1.0] * 4),
        record("transfer", 2, continued_curve=[9.0] * 10 + [2.0] * 20, continued_eval=[4.0] * 4, frozen_eval=[3.0] * 4),
        record("scratch", 1, scratch_curve=scratch1 or [0.0] * 8 + [10.0] * 12, scratch_eval=[9.0] * 4),
        record("scratch", 2, scratch_curve=[1.0] * 20, scratch_eval=[1.0] * 4),
        record("baselines", before={"rba": [1.0] * 4, "rba-hold": [2.0] * 4}, after=after),
    ]


BOTH_RBAS = {"rba": [3.0] * 4, "rba-hold": [5.0] * 4}
RANDOM_AND_ORACLE = {**BOTH_RBAS, "random": [0.0] * 4, "oracle": [10.0] * 4}


def continual(after, **kwargs) -> tuple[dict, dict]:
    summary = tr.summarize(records(after, **kwargs), KEY, ["sensor"], ["ppo"])["sensor"]
    return summary, summary["algos"]["ppo"]["continual"]


def test_the_metrics_of_known_curves_between_random_and_the_oracle():
    summary, found = continual(RANDOM_AND_ORACLE)
    assert summary["normalisation"] == {"low": 0.0, "high": 10.0}
    # Jumpstart: the frozen snapshot's scores (1 and 3 per run), for continued and frozen alike.
    for strategy in ("continued", "frozen"):
        assert found[strategy]["jumpstart"]["per_run"] == [1.0, 3.0]
        assert found[strategy]["jumpstart"]["iqm"]["point"] == pytest.approx(2.0)
    assert "jumpstart" not in found["scratch"] and "auc" not in found["frozen"]
    # AUC: the mean of reward / 10 after the change.
    assert found["continued"]["auc"]["per_run"] == pytest.approx([0.5, 0.2])
    assert found["scratch"]["auc"]["per_run"] == pytest.approx([0.6, 0.1])
    assert found["continued"]["auc"]["iqm"]["point"] == pytest.approx(0.35)
    auc = found["continued"]["auc"]["iqm"]
    assert auc["low"] == pytest.approx(0.2) and auc["high"] == pytest.approx(0.5)  # two runs, resampled whole
    # Steps to rba-hold (5): continued seed 1 at its first full window, seed 2 never; from scratch
    # seed 1 when its window holds five 10s (episode 13), seed 2 never.
    steps = found["continued"]["steps_to_rba_hold"]
    assert steps["per_run"] == [500, None] and steps["reached"] == 1 and steps["target"] == 5.0
    assert steps["iqm"]["point"] == pytest.approx((500 + BUDGET) / 2)  # the one that never did counts as the budget
    assert found["scratch"]["steps_to_rba_hold"]["per_run"] == [650, None]
    # Forward transfer against the from-scratch mean AUC 0.35.
    ft = found["continued"]["forward_transfer"]
    assert ft["auc_scratch"] == pytest.approx(0.35)
    assert ft["per_run"] == pytest.approx([0.15 / 0.65, -0.15 / 0.65])
    # Crossover: seed 1's cumulative rewards 10 (k - 7) against 5 (k + 1) after episode k: first
    # above at k = 16 (90 > 85; at 15 they tie); seed 2's never (1 against 2 per episode).
    cross = found["scratch"]["crossover"]
    assert cross["per_run"] == [17 * 50, None] and cross["reached"] == 1 and cross["seeds"] == [1, 2]
    assert cross["iqm"]["point"] == pytest.approx((850 + BUDGET) / 2)


@pytest.mark.parametrize(
    "after,why",
    [
        (BOTH_RBAS, "the baselines cell has no random and no oracle after the change"),
        ({**BOTH_RBAS, "oracle": [10.0] * 4}, "the baselines cell has no random after the change"),
        ({**BOTH_RBAS, "random": [0.0] * 4}, "the baselines cell has no oracle after the change"),
        ({**BOTH_RBAS, "random": [4.0] * 4, "oracle": [4.0] * 4}, "(4.00) is not above random's (4.00)"),
    ],
)
def test_without_random_and_the_oracle_after_the_change_there_is_no_auc_and_the_table_says_why(after, why):
    """One normalisation only (the issue's, the benchmark's): a baselines cell of the study's first
    version, which has no random, gets no AUC and no forward transfer rather than another scale."""
    summary, found = continual(after)
    assert why in summary["normalisation"]["missing"] and "low" not in summary["normalisation"]
    assert all("auc" not in found[s] and "forward_transfer" not in found[s] for s in found)
    assert found["continued"]["steps_to_rba_hold"]["per_run"] == [500, None]  # the rest stays
    text = tr.markdown(tr.summarize(records(after), KEY, ["sensor"], ["ppo"]), KEY)
    assert f"### sensor, ppo: no AUC: {summary['normalisation']['missing']}" in text


def test_forward_transfer_is_left_out_when_the_from_scratch_auc_is_not_below_1():
    _, found = continual(RANDOM_AND_ORACLE, scratch1=[20.0] * 20)  # AUCs 2.0 and 0.1
    assert "forward_transfer" not in found["continued"]
    assert "mean AUC is 1.050, not below 1" in found["continued"]["forward_transfer_missing"]


def test_the_pure_metrics():
    assert tr.auc([0.0, 10.0], -10.0, 10.0) == pytest.approx(0.75)
    with pytest.raises(ValueError, match="best > worst"):
        tr.auc([1.0], 5.0, 5.0)
    assert tr.forward_transfer(0.8, 0.5) == pytest.approx(0.6) and tr.forward_transfer(0.8, 1.0) is None
    assert tr.crossover_steps([3.0, 3.0], [1.0, 9.0], 50) == 50  # ahead from the first episode
    assert tr.crossover_steps([1.0, 1.0], [1.0, 1.0], 50) is None  # a tie is not a pass


def test_the_table_names_the_normalisation_and_says_why_forgetting_is_missing():
    """Records without evaluations on the line before the change (cells saved before forgetting was
    measured) and a baselines cell without random before it: no forgetting, and the table says why."""
    summary = tr.summarize(records(RANDOM_AND_ORACLE), KEY, ["sensor"], ["ppo"])
    text = tr.markdown(summary, KEY)
    assert "### sensor, ppo: AUC normalised between random and the oracle after the change (0.00 and 10.00)" in text
    assert "no forgetting: the baselines cell has no random and no oracle before the change" in text
    rows = {line.split(" | ")[0]: line for line in text.splitlines() if line.startswith(("| continued", "| scratch"))}
    # strategy, runs, final, jumpstart, AUC, steps to rba-hold, forward transfer, crossover, score before, forgetting
    assert rows["| continued"].startswith(
        "| continued | 2 | 5.00 [4.00, 6.00] | 2.00 [1.00, 3.00] | 0.350 [0.200, 0.500] |"
    )
    assert "750 [500, 1000] (1/2)" in rows["| continued"] and rows["| continued"].endswith("| - | - |")
    assert rows["| scratch"].endswith("| 925 [850, 1000] (1/2) | - | - |")
    assert "No forgetting for continued: the baselines cell has no random and no oracle before the change." in text
    frozen = next(line for line in text.splitlines() if line.startswith("| frozen"))
    assert frozen.endswith("| 0 (by construction) |")  # not computed: it is the reference itself


# ----------------------------------------------------------------------------------------------
# Forgetting and shrink-and-perturb

BEFORE_SCALE = {"rba": [1.0] * 4, "rba-hold": [2.0] * 4, "random": [0.0] * 4, "oracle": [20.0] * 4}


def records_before(before=BEFORE_SCALE, scratch_before=True) -> list[dict]:
    """``records`` with every evaluation on the line before the change, between random 0 and the
    oracle 20 there, and the perturbed cells. Snapshots at the change score 10 (seed 1) and 8
    (seed 2) before it; after training continued 6 and 8, from scratch 2 and 4, shrink-and-perturb
    10 and 4 (known forgetting: 0.2 and 0, 0.4 and 0.2, 0 and 0.2)."""
    found = records(RANDOM_AND_ORACLE)
    own = {("transfer", 1): [6.0] * 4, ("transfer", 2): [8.0] * 4, ("scratch", 1): [2.0] * 4,
           ("scratch", 2): [4.0] * 4}  # fmt: skip
    for r in found:
        kind, seed = r["cell"]["kind"], r["cell"]["seed"]
        if kind == "transfer":
            r["continued_before_eval"] = own[kind, seed]
            r["frozen_before_eval"] = [10.0] * 4 if seed == 1 else [8.0] * 4
        elif kind == "scratch" and scratch_before:
            r["scratch_before_eval"] = own[kind, seed]
        elif kind == "baselines":
            r["before"] = before
    for seed, before_score in ((1, [10.0] * 4), (2, [4.0] * 4)):
        found.append(
            record(
                "perturbed",
                seed,
                perturbed_curve=[9.0] * 10 + [float(7 * seed - 4)] * 20,  # 3 then 10 after the change
                perturbed_eval=[7.0] * 4,
                perturbed_at_change_eval=[0.5 * seed] * 4,
                perturbed_before_eval=before_score,
            )
        )
    return found


def test_forgetting_of_known_scores_against_the_snapshot_between_random_and_the_oracle_before_the_change():
    summary = tr.summarize(records_before(), KEY, ["sensor"], ["ppo"])["sensor"]
    assert summary["normalisation_before"] == {"low": 0.0, "high": 20.0}
    found = summary["algos"]["ppo"]["continual"]
    # (snapshot - agent) / (oracle - random) before the change, per seed of the same training seed.
    expected = {"continued": [0.2, 0.0], "scratch": [0.4, 0.2], "perturbed": [0.0, 0.2]}
    for strategy, per_run in expected.items():
        f = found[strategy]["forgetting"]
        assert f["per_run"] == pytest.approx(per_run) and f["runs"] == 2 and f["seeds"] == [1, 2], strategy
        # IQM over runs x seeds of two runs of 4 equal seeds: the mean; resampling whole runs, the two runs' values.
        assert f["iqm"]["point"] == pytest.approx(sum(per_run) / 2), strategy
        assert (f["iqm"]["low"], f["iqm"]["high"]) == pytest.approx((min(per_run), max(per_run))), strategy
    # Frozen is the reference: 0 by construction, not computed; its own score before the change is.
    assert "forgetting" not in found["frozen"] and "by construction" in found["frozen"]["forgetting_note"]
    assert found["frozen"]["score_before_change"]["per_run"] == pytest.approx([0.5, 0.4])
    assert found["continued"]["score_before_change"]["per_run"] == pytest.approx([0.3, 0.4])
    text = tr.markdown(tr.summarize(records_before(), KEY, ["sensor"], ["ppo"]), KEY)
    assert "forgetting normalised between random and the oracle before it (0.00 and 20.00)" in text
    row = next(line for line in text.splitlines() if line.startswith("| scratch"))
    assert row.endswith("| 0.150 [0.100, 0.200] | 0.300 [0.200, 0.400] |")
    assert "No forgetting for" not in text


def test_forgetting_is_left_out_saying_why_for_cells_without_the_evaluations_before_the_change():
    found = tr.summarize(records_before(scratch_before=False), KEY, ["sensor"], ["ppo"])["sensor"]["algos"]["ppo"]
    scratch = found["continual"]["scratch"]
    assert "forgetting" not in scratch and "saved before forgetting was measured" in scratch["forgetting_missing"]
    assert "forgetting" in found["continual"]["continued"]  # the others keep theirs
    oracle_below = {**BEFORE_SCALE, "oracle": [0.0] * 4}
    found = tr.summarize(records_before(oracle_below), KEY, ["sensor"], ["ppo"])["sensor"]["algos"]["ppo"]
    assert "is not above random's" in found["continual"]["continued"]["forgetting_missing"]


def test_shrink_and_perturb_is_a_strategy_with_the_metrics_of_continued():
    summary = tr.summarize(records_before(), KEY, ["sensor"], ["ppo"])["sensor"]
    ppo = summary["algos"]["ppo"]
    assert list(tr.STRATEGIES) == ["continued", "frozen", "scratch", "perturbed", "cloned"]
    assert ppo["strategies"]["perturbed"]["iqm"]["point"] == pytest.approx(7.0)
    found = ppo["continual"]["perturbed"]
    # Its jumpstart is its own perturbed snapshot's, not the frozen one's.
    assert found["jumpstart"]["per_run"] == pytest.approx([0.5, 1.0])
    assert found["auc"]["per_run"] == pytest.approx([0.3, 1.0])  # rewards 3 and 10 after the change, of 10
    ft = found["forward_transfer"]
    assert ft["per_run"] == pytest.approx([(0.3 - 0.35) / 0.65, (1.0 - 0.35) / 0.65])
    assert found["steps_to_rba_hold"]["per_run"] == [None, 500]
    assert ppo["recovery"]["perturbed"]["per_run"] == [None, 500]  # 90 % of from scratch's IQM (5.0)
    assert ppo["improvement"]["perturbed > continued"]["point"] == 1.0  # 7 against 6 and 4
    text = tr.markdown(tr.summarize(records_before(), KEY, ["sensor"], ["ppo"]), KEY)
    assert "| (d) shrink-and-perturb |" in text and "| sensor | ppo | 2/2/2/2/0 |" in text
    assert "(d) shrink-and-perturb, after the change" in text
    row = next(line for line in text.splitlines() if line.startswith("| perturbed"))
    assert row.startswith("| perturbed | 2 | 7.00 [7.00, 7.00] | 0.75 [0.50, 1.00] | 0.650 [0.300, 1.000] |")


def test_the_new_agent_cloned_from_the_oracle_has_the_metrics_of_from_scratch_and_a_jumpstart():
    """Cloned from the oracle: its jumpstart is the cloned agent before its RL training; its curve
    starts at the change, as from scratch's; forward transfer and forgetting as the others'."""
    found = records_before()
    for seed, curve, before in ((1, [10.0] * 20, [9.0] * 4), (2, [5.0] * 20, [8.0] * 4)):
        found.append(record("cloned", seed, cloned_curve=curve, cloned_eval=[9.0 + seed] * 4,
                            cloned_at_change_eval=[8.0] * 4, cloned_before_eval=before))  # fmt: skip
    ppo = tr.summarize(found, KEY, ["sensor"], ["ppo"])["sensor"]["algos"]["ppo"]
    cloned = ppo["continual"]["cloned"]
    assert cloned["jumpstart"]["per_run"] == [8.0, 8.0]
    assert cloned["auc"]["per_run"] == pytest.approx([1.0, 0.5])  # from its first episode: no part before a change
    assert cloned["forward_transfer"]["per_run"] == pytest.approx([0.65 / 0.65, 0.15 / 0.65])
    assert cloned["forgetting"]["per_run"] == pytest.approx([0.05, 0.0])  # (10 - 9) / 20, (8 - 8) / 20
    assert cloned["steps_to_rba_hold"]["per_run"] == [500, 500]
    assert ppo["improvement"]["cloned > scratch"]["point"] == 1.0  # 10 and 11 against 9 and 1
    assert ppo["strategies"]["cloned"]["per_run"] == [10.0, 11.0]
    text = tr.markdown(tr.summarize(found, KEY, ["sensor"], ["ppo"]), KEY)
    assert "| (e) new, cloned from the oracle |" in text and "| sensor | ppo | 2/2/2/2/2 |" in text
