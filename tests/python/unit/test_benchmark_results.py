"""Table 1's score normalized per held-out seed, ``results.csv`` and ``--compare`` on records whose
answers are known (reports.benchmark_summary, reports.results_csv, reports.comparison): no node,
no training. The last test runs `sorting-line-benchmark` itself on the native backend (baselines
only, a few seconds of evaluation) and compares a CSV made from the table's own rows.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sorting_line_gym.reports import benchmark_summary, comparison, results_csv, stats

FIRST = 10_000


def record(agent: str, rewards, train_seed: int | None = None, line=("B", "advanced"), first=FIRST) -> dict:
    """A cell's record as the benchmark saves it, with these held-out rewards (seeds first, ...)."""
    rewards = [float(x) for x in rewards]
    evaluation = {"reward_mean": float(np.mean(rewards)), "reward_std": 0.0, "speed_mean": 0.5}
    evaluation |= {"purity_mean": 0.9, "speed_changes_mean": 1.0}
    episodes = [{"seed": first + i, "reward": x} for i, x in enumerate(rewards)]
    cell = {"setup": line[0], "variant": line[1], "agent": agent, "train_seed": train_seed}
    held = {"seed": first, "episodes": len(rewards), "per_episode": episodes}
    return {"cell": cell, "evaluation": evaluation, "heldout": held}


def oracle(rewards, first=FIRST) -> dict:
    return {"per_episode": [{"seed": first + i, "reward": float(x)} for i, x in enumerate(rewards)]}


#: Four held-out seeds: the oracle's and the random agent's rewards; on the last the oracle does no
#: better than random (no scale: the seed is left out).
ORACLE = [10.0, 20.0, 30.0, 5.0]
RANDOM = [0.0, 10.0, 10.0, 5.0]


def cells() -> tuple[list[dict], dict]:
    """random, and ppo with two runs: run 42 halfway from random to the oracle on every seed, run 43
    at the oracle (normalized 0.5 and 1.0), whatever they score on the seed without a scale."""
    half = [r + 0.5 * (o - r) for r, o in zip(RANDOM, ORACLE, strict=True)]
    records = [record("random", RANDOM), record("ppo", half[:3] + [1.0], 42), record("ppo", ORACLE[:3] + [9.0], 43)]
    return records, {("B", "advanced"): oracle(ORACLE)}


def test_the_score_normalized_per_seed_has_its_known_value():
    records, oracles = cells()
    rows = benchmark_summary.summarize(records, oracles)
    ppo = rows[("B", "advanced", "ppo")]["heldout"]["normalized"]
    assert ppo["seeds"] == 3 and ppo["left_out_seeds"] == [FIRST + 3]
    assert ppo["per_run"] == pytest.approx([0.5, 1.0])
    assert ppo["mean"]["point"] == pytest.approx(0.75) and ppo["iqm"]["point"] == pytest.approx(0.75)
    # The interval over whole runs: a resample draws the two runs, so the mean is 0.5, 0.75 or 1.0.
    assert ppo["mean"]["low"] == pytest.approx(0.5) and ppo["mean"]["high"] == pytest.approx(1.0)
    random = rows[("B", "advanced", "random")]["heldout"]["normalized"]
    assert (random["mean"]["point"], random["mean"]["low"], random["mean"]["high"]) == (0.0, 0.0, 0.0)
    # The markdown table names the seed left out; a line without a random cell has no normalized score.
    from sorting_line_gym.reports.benchmark_tables import normalized_markdown

    table = normalized_markdown(rows)
    assert "| B | Adv | ppo | 2 | 3 | 0.75 [0.50, 1.00] | 0.75 [0.50, 1.00] |" in table
    assert f"left out: B Adv: {FIRST + 3}" in table
    # Over the lines (one here): each run's mean normalized score, the runs drawn within the line.
    aggregate = benchmark_summary.aggregates(benchmark_summary.normalized_per_seed_runs(rows))
    assert aggregate["ppo"]["mean"] == pytest.approx({"point": 0.75, "low": 0.5, "high": 1.0})
    assert "| ppo | 1 | 0.75 [0.50, 1.00] | 0.75 [0.50, 1.00] |" in table
    alone = benchmark_summary.summarize(records[1:], oracles)
    assert "normalized" not in alone[("B", "advanced", "ppo")]["heldout"] and normalized_markdown(alone) == ""


def test_references_on_other_seeds_than_the_oracles_are_refused():
    records, _ = cells()
    with pytest.raises(ValueError, match="the oracle is on seeds 20000..20003"):
        benchmark_summary.summarize(records, {("B", "advanced"): oracle(ORACLE, first=20_000)})
    # An oracle below the random agent on a seed: they were not scored on the same episodes.
    with pytest.raises(ValueError, match="below worst"):
        benchmark_summary.summarize(records, {("B", "advanced"): oracle([-1.0, 20.0, 30.0, 5.0])})


def test_results_csv_has_a_row_per_run_and_seed_and_reads_back_exactly(tmp_path):
    records, oracles = cells()
    rows = results_csv.rows_of(records, oracles)
    assert len(rows) == 4 * 4  # random, ppo 42, ppo 43, oracle
    by = {(r.agent, r.train_seed, r.heldout_seed): r for r in rows}
    assert by[("ppo", 42, FIRST)].normalized == pytest.approx(0.5)
    assert by[("ppo", 43, FIRST + 2)].normalized == pytest.approx(1.0)
    assert by[("ppo", 43, FIRST + 3)].normalized is None  # the seed without a scale
    assert by[("oracle", None, FIRST + 1)].reward == 20.0 and by[("oracle", None, FIRST + 1)].normalized == 1.0
    path = results_csv.write(tmp_path / "results.csv", rows)
    header = path.read_text().splitlines()[0]
    assert header == "setup,variant,agent,train_seed,heldout_seed,reward,normalized"
    assert results_csv.read(path) == rows


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("setup,variant,agent,heldout_seed\nB,advanced,x,1\n", "no column train_seed, reward; needed: setup"),
        (
            "setup,variant,agent,train_seed,heldout_seed,reward\nE,advanced,x,1,2,3\n",
            "setup 'E' is not known: allowed A, B, C, D",
        ),
        ("setup,variant,agent,train_seed,heldout_seed,reward\nB,fancy,x,1,2,3\n", "variant 'fancy' is not known"),
        ("setup,variant,agent,train_seed,heldout_seed,reward\nB,basic,x,1,2,nan\n", "line 2: reward 'nan' is not"),
        ("setup,variant,agent,train_seed,heldout_seed,reward\nB,basic,x,one,2,3\n", "train_seed 'one' is not valid"),
        (
            "setup,variant,agent,train_seed,heldout_seed,reward\nB,basic,x,1,2,3\nB,basic,x,1,2,4\n",
            "line 3: agent 'x' on B basic, train_seed 1, heldout_seed 2 is given twice",
        ),
        ("setup,variant,agent,train_seed,heldout_seed,reward\n", "has a header but no rows"),
    ],
)
def test_a_results_file_not_in_the_format_is_refused_naming_the_value(tmp_path, text, says):
    path = tmp_path / "mine.csv"
    path.write_text(text)
    with pytest.raises(results_csv.ResultsError, match=None) as error:
        results_csv.read(path)
    assert says in str(error.value), str(error.value)


def renamed(rows, agent: str, name: str) -> list[results_csv.ResultRow]:
    """Our ``agent``'s rows under the user's ``name``, its runs and seeds as they are."""
    return [
        results_csv.ResultRow(r.setup, r.variant, name, r.train_seed, r.heldout_seed, r.reward)
        for r in rows
        if r.agent == agent
    ]


def test_our_own_rows_compare_as_equal():
    """ppo's rows as the user's agent "mine": its mean, IQM and normalized score are Table 1's to
    the bit, P(mine > ppo) = 0.5, and P(mine > random) is Table 1's P(ppo > random)."""
    records, oracles = cells()
    ours = results_csv.rows_of(records, oracles)
    result = comparison.compare(renamed(ours, "ppo", "mine"), ours)
    (line,) = result["lines"]
    mine, ppo = line["yours"]["mine"], line["ours"]["ppo"]
    table = benchmark_summary.summarize(records, oracles)[("B", "advanced", "ppo")]["heldout"]
    assert mine["mean"] == ppo["mean"] == table["mean"] and mine["iqm"] == table["iqm"]
    assert mine["normalized"] == table["normalized"]
    assert mine["probability_of_improvement"]["ppo"]["point"] == 0.5
    ppo_vs_random = stats.probability_of_improvement_interval(
        benchmark_summary.episode_rewards(records[1:]), benchmark_summary.episode_rewards(records[:1])
    )
    assert mine["probability_of_improvement"]["random"] == ppo_vs_random.as_dict()
    text = comparison.markdown(result, "mine.csv")
    assert "| B | Adv | **yours: mine** | 2 |" in text and "| B | Adv | mine | " in text


def test_a_file_that_does_not_fit_the_table_is_refused_naming_the_value():
    records, oracles = cells()
    ours = results_csv.rows_of(records, oracles)
    mine = renamed(ours, "ppo", "mine")
    assert comparison.mismatch(mine, ours) is None
    elsewhere = [results_csv.ResultRow("D", "basic", r.agent, r.train_seed, r.heldout_seed, r.reward) for r in mine]
    assert comparison.mismatch(elsewhere, ours) == (
        "agent 'mine' on D basic: the table has no cells on D basic: allowed the table's lines (B advanced)"
    )
    fewer = [r for r in mine if r.heldout_seed != FIRST + 2]
    assert comparison.mismatch(fewer, ours) == (
        "agent 'mine' on B advanced, train_seed 42: held-out seeds 10000, 10001, 10003, but the table's are "
        "10000..10003: allowed exactly those, each once (missing: 10002)"
    )
    one = [r for r in mine if r.train_seed == 42]
    assert comparison.mismatch(one, ours) == (
        "agent 'mine' on B advanced has 1 run (train_seed 42): an interval over runs needs at least 2; "
        "allowed 2 or more training seeds"
    )
    with pytest.raises(ValueError, match="has 1 run"):
        comparison.compare(one, ours)


def test_the_benchmark_writes_results_csv_and_compares_a_users_file(tmp_path, capsys):
    """`sorting-line-benchmark` on the native backend (random and rba-hold on B advanced, 20 held-out
    seeds): results.csv has a row per agent and seed, the oracle's among them; rba-hold's rows as
    two runs of "mine" compare from --report-only as equal to rba-hold (P = 0.5 exactly: every
    resample pairs equal runs); a file on other seeds, or without a reward column, is refused with
    exit 2 before anything is drawn."""
    from sorting_line_gym.studies import benchmark

    out = tmp_path / "bench"
    argv = "--backend native --setups B --variants advanced --agents random rba-hold --heldout-episodes 20".split()
    assert benchmark.main([*argv, "--out", str(out)]) == 0
    ours = results_csv.read(out / "results.csv")
    assert sorted({r.agent for r in ours}) == ["oracle", "random", "rba-hold"] and len(ours) == 60
    cached = json.loads(next((out / "oracle").glob("B_advanced_seed10000_x20.json")).read_text())
    assert [r.reward for r in ours if r.agent == "oracle"] == [e["reward"] for e in cached["per_episode"]]
    assert {r.normalized for r in ours if r.agent == "random"} == {0.0}
    hold = [r for r in ours if r.agent == "rba-hold"]
    mine = [
        results_csv.ResultRow(r.setup, r.variant, "mine", s, r.heldout_seed, r.reward) for s in (1, 2) for r in hold
    ]
    results_csv.write(tmp_path / "mine.csv", mine)
    capsys.readouterr()
    compare = [*argv, "--out", str(out), "--report-only", "--compare"]
    assert benchmark.main([*compare, str(tmp_path / "mine.csv")]) == 0
    printed = capsys.readouterr().out
    report = json.loads((out / "compare" / "mine.json").read_text())
    (line,) = report["lines"]
    # Equal but for rounding: the mean of two copies of the 20 rewards against the mean of the 20.
    assert line["yours"]["mine"]["mean"] == pytest.approx(line["ours"]["rba-hold"]["mean"], rel=1e-12)
    assert line["yours"]["mine"]["probability_of_improvement"]["rba-hold"] == {"point": 0.5, "low": 0.5, "high": 0.5}
    table = json.loads((out / "table.json").read_text())
    (row,) = [r for r in table["rows"] if r["agent"] == "rba-hold"]
    per_seed = table["aggregate_normalized_per_seed"]["rba-hold"]  # one line, one run: its mean
    assert per_seed["lines"] == 1 and per_seed["iqm"]["point"] == row["heldout"]["normalized"]["per_run"][0]
    assert line["yours"]["mine"]["normalized"]["iqm"] == pytest.approx(row["heldout"]["normalized"]["iqm"], rel=1e-12)
    assert "| B | Adv | mine | " in printed and (out / "compare" / "mine.png").stat().st_size > 10_000
    # Other seeds: refused, naming them, before anything is drawn (the table is not rewritten).
    (out / "table.md").unlink()
    shifted = [
        results_csv.ResultRow(r.setup, r.variant, r.agent, r.train_seed, r.heldout_seed + 1, r.reward) for r in mine
    ]
    results_csv.write(tmp_path / "shifted.csv", shifted)
    assert benchmark.main([*compare, str(tmp_path / "shifted.csv")]) == 2
    err = capsys.readouterr().err
    assert "held-out seeds 10001..10020, but the table's are 10000..10019" in err and "(missing: 10000)" in err, err
    assert not (out / "table.md").exists() and not (out / "compare" / "shifted.md").exists()
    (tmp_path / "bad.csv").write_text("setup,variant,agent,train_seed,heldout_seed\nB,advanced,mine,1,10000\n")
    with pytest.raises(SystemExit) as exit_code:
        benchmark.main([*compare, str(tmp_path / "bad.csv")])
    assert exit_code.value.code == 2 and "argument --compare: " in capsys.readouterr().err


def test_the_documented_snippet_writes_a_file_compare_takes(tmp_path):
    """docs/benchmark.md's `my_results.py` (on 3 held-out seeds instead of 100) writes rows that
    --compare accepts, its rewards those of `sorting_line eval` for the same constant action."""
    import re
    import subprocess
    import sys

    from sorting_line_gym.line.process import find_node_binary

    page = (Path(__file__).resolve().parents[3] / "docs" / "benchmark.md").read_text()
    (code,) = re.findall(r"<!-- test: my-results -->\n```python\n(.*?)\n```", page, re.S)
    assert "range(10000, 10100)" in code
    script = tmp_path / "my_results.py"
    script.write_text(code.replace("range(10000, 10100)", "range(10000, 10003)"))
    subprocess.run([sys.executable, str(script)], cwd=tmp_path, check=True, timeout=120)
    mine = results_csv.read(tmp_path / "my_results.csv")
    assert len(mine) == 3 * 3 and {r.agent for r in mine} == {"mine"}
    argv = [find_node_binary(), "eval", "--agent", "constant:1:1", "--setup", "B", "--variant", "advanced"]
    library = subprocess.run([*argv, "--seed", "10000", "--episodes", "3", "--json"], capture_output=True, check=True)
    expected = [e["reward"] for e in json.loads(library.stdout)["per_episode"]]
    assert [r.reward for r in mine if r.train_seed == 1] == expected
    ours = [results_csv.ResultRow("B", "advanced", "rba-hold", None, 10_000 + i, 1.0) for i in range(3)]
    assert comparison.mismatch(mine, ours) is None
