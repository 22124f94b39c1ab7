"""sorting-line-transfer at smoke size, against real nodes over DDS: the pipeline of the full study
(the baselines and the oracle offline, MaskablePPO continued / frozen / from scratch /
shrink-and-perturb / cloned from the oracle through the evolving node, the statistics and the
plot), stopped after some cells and resumed.

What must hold:
- a stopped study resumes without redoing finished cells: their files are not rewritten (same
  mtime, same bytes, still marked as run by the first invocation) and the second invocation runs
  exactly the rest (``study.json`` lists what each invocation ran), here two at a time in workers;
- the report has IQM intervals per strategy, probabilities of improvement, steps to recover and
  forgetting (frozen's 0 by construction) with intervals, and the plot;
- progress comes as plain lines with a projected end when stderr is not a terminal;
- other result-changing options into the same --out are refused, naming what differs, and so is
  a --out with the earlier format's transfer.json; bad flags fail at once with exit code 2;
- the statistics on known records (no node): steps to recover, a run that never recovers counted
  as its budget, IQM and probability of improvement.

Cost: 67 s of CPU, 121 s of wall time for the whole file on 2026-12-03 (9 cells of 10 + 10
episodes, 3 evaluation episodes on each side of the change; the last 7 two at a time).
"""

from __future__ import annotations

import json

import pytest

from support.images import assert_real_image

SMOKE = ["--smoke", "--scenarios", "upgrade", "--algos", "ppo", "--seeds", "1", "2"]
FIRST = ["upgrade_baselines", "upgrade_ppo_transfer_seed1"]
REST = [
    "upgrade_ppo_scratch_seed1",
    "upgrade_ppo_perturbed_seed1",
    "upgrade_ppo_cloned_seed1",
    "upgrade_ppo_transfer_seed2",
    "upgrade_ppo_scratch_seed2",
    "upgrade_ppo_perturbed_seed2",
    "upgrade_ppo_cloned_seed2",
]


def snapshot(cells) -> dict[str, tuple[int, bytes]]:
    return {p.stem: (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(cells.glob("*.json"))}


def test_a_stopped_study_resumes_without_redoing_cells_and_reports_intervals(tmp_path, capsys):
    from sorting_line_gym.studies import transfer

    out = tmp_path / "transfer"
    argv = [*SMOKE, "--out", str(out)]
    assert transfer.main([*argv, "--max-cells", "2"]) == 0
    err = capsys.readouterr().err
    assert "9 cells, 0 already done, 9 to run" in err and "cell 2/9 done: upgrade_ppo_transfer_seed1" in err
    assert "projected end" in err and "2 of 9 cells done; 7 left" in err
    first = snapshot(out / "cells")
    assert sorted(first) == sorted(FIRST)

    assert transfer.main([*argv, "--jobs", "2"]) == 0  # the rest two at a time, in worker processes
    err = capsys.readouterr().err
    assert "9 cells, 2 already done, 7 to run, 2 at a time" in err and "9 of 9 cells done" in err
    after = snapshot(out / "cells")
    assert {name: after[name] for name in FIRST} == first, "a finished cell was run again"
    invocations = json.loads((out / "study.json").read_text())["invocations"]
    assert [sorted(i["ran"]) for i in invocations] == [sorted(FIRST), sorted(REST)]  # two at a time: any order
    for name in FIRST + REST:
        assert json.loads((out / "cells" / f"{name}.json").read_text())["invocation"] == (1 if name in FIRST else 2)

    summary = json.loads((out / "transfer.json").read_text())["summary"]["upgrade"]
    ppo = summary["algos"]["ppo"]
    for strategy in ("continued", "frozen", "scratch", "perturbed", "cloned"):
        iqm = ppo["strategies"][strategy]["iqm"]
        assert ppo["strategies"][strategy]["runs"] == 2 and iqm["low"] <= iqm["point"] <= iqm["high"], strategy
    for pair in ("continued > scratch", "continued > frozen", "scratch > frozen", "continued > rba-hold",
                 "perturbed > continued", "cloned > scratch"):  # fmt: skip
        p = ppo["improvement"][pair]
        assert 0.0 <= p["low"] <= p["point"] <= p["high"] <= 1.0, pair
    recovery = ppo["recovery"]
    assert recovery["continued"]["runs"] == 2 and recovery["budget_steps"] == 500
    assert (
        recovery["continued"]["iqm"]["low"]
        <= recovery["continued"]["iqm"]["point"]
        <= recovery["continued"]["iqm"]["high"]
    )
    # The upgraded line is advanced B: the oracle applies, and is above every agent.
    baselines = summary["baselines"]
    assert baselines["after"]["oracle"] > max(
        baselines["after"]["rba-hold"], ppo["strategies"]["continued"]["iqm"]["point"]
    )
    table = (out / "transfer.md").read_text()
    assert "| upgrade | ppo | 2/2/2/2/2 | " in table and "IQM [95 % CI]" in table and "reached)" in table
    # Forgetting on the line before the change (basic B), against the snapshot of the same seed.
    for strategy in ("continued", "scratch", "perturbed", "cloned"):
        f = ppo["continual"][strategy]["forgetting"]
        assert f["runs"] == 2 and f["iqm"]["low"] <= f["iqm"]["point"] <= f["iqm"]["high"], strategy
    assert "forgetting" not in ppo["continual"]["frozen"] and "0 (by construction)" in table
    assert_real_image(out / "transfer.png")
    assert (out / "transfer.svg").stat().st_size > 10_000
    # Each strategy's runs beside its interval: one mean per training seed.
    assert len(ppo["strategies"]["continued"]["per_run"]) == 2
    assert_real_image(out / "transfer_runs.png")

    assert transfer.main([*SMOKE, "--evaluations", "4", "--out", str(out)]) == 2
    assert "holds cells of another configuration (evaluations: saved 3, asked 4)" in capsys.readouterr().err
    assert snapshot(out / "cells") == after


@pytest.mark.parametrize(
    "argv,names",
    [
        (["--before", "15"], "--before = 15"),
        (["--after", "0"], "--after = 0"),
        (["--evaluations", "0"], "--evaluations = 0"),
        (["--max-cells", "0"], "--max-cells = 0"),
        (["--jobs", "0"], "--jobs = 0"),
        (["--full", "--smoke"], "not allowed with argument"),
    ],
)
def test_transfer_rejects_bad_arguments(argv, names, tmp_path, capsys):
    from sorting_line_gym.studies import transfer

    with pytest.raises(SystemExit) as exit_:
        transfer.main([*argv, "--out", str(tmp_path / "t")])
    assert exit_.value.code == 2 and names in capsys.readouterr().err
    assert not (tmp_path / "t").exists(), "nothing is written when the arguments are bad"


def _record(kind: str, seed: int, **values) -> dict:
    return {"cell": {"scenario": "upgrade", "kind": kind, "algo": "ppo", "seed": seed}, **values}


def test_transfer_statistics_on_known_records():
    """Steps to recover against 90 % of the from-scratch IQM, a run that never reaches it counted as
    its whole budget; the strategies' IQM and probability of improvement; no node."""
    from sorting_line_gym.reports import transfer_report as tr

    key = {"before": 10, "after": 20, "episode_steps": 50, "window": 10, "evaluations": 4, "eval_seed": 10_000}
    ramp = [float(k) for k in range(20)]  # the 10-episode moving mean is k - 4.5 at index k: 9.5 at 14
    records = [
        _record("transfer", 1, continued_curve=[0.0] * 10 + ramp, continued_eval=[10.0] * 4, frozen_eval=[1.0] * 4),
        _record("transfer", 2, continued_curve=[0.0] * 30, continued_eval=[11.0] * 4, frozen_eval=[2.0] * 4),
        _record("scratch", 1, scratch_curve=[10.0] * 20, scratch_eval=[10.0] * 4),
        _record("scratch", 2, scratch_curve=[10.0] * 20, scratch_eval=[10.0] * 4),
        {
            "cell": {"scenario": "upgrade", "kind": "baselines", "algo": None, "seed": None},
            "before": {"rba": [1.0] * 4, "rba-hold": [2.0] * 4, "oracle": [20.0] * 4},
            "after": {"rba": [3.0] * 4, "rba-hold": [10.5] * 4, "oracle": [30.0] * 4},
        },
    ]
    summary = tr.summarize(records, key, ["upgrade"], ["ppo"])["upgrade"]
    ppo = summary["algos"]["ppo"]
    recovery = ppo["recovery"]
    assert recovery["target"] == pytest.approx(9.0) and recovery["budget_steps"] == 1000
    assert recovery["continued"]["per_run"] == [15 * 50, None] and recovery["continued"]["reached"] == 1
    assert recovery["scratch"]["per_run"] == [500, 500]  # the first full window
    # The run that never reaches the target counts as the budget: IQM of [750, 1000] is their mean.
    assert recovery["continued"]["iqm"]["point"] == pytest.approx(875.0)
    assert recovery["continued"]["iqm"]["low"] == 750.0 and recovery["continued"]["iqm"]["high"] == 1000.0
    assert ppo["strategies"]["continued"]["iqm"]["point"] == pytest.approx(10.5)
    assert ppo["improvement"]["continued > frozen"]["point"] == 1.0
    assert ppo["improvement"]["continued > rba-hold"]["point"] == 0.5  # 10 and 11 against 10.5
    assert tr.recovery_target(-10.0) == pytest.approx(-11.0)  # within 10 % of a negative score
    assert summary["baselines"]["after"]["oracle"] == 30.0


def test_transfer_keeps_the_runs_of_its_earlier_format(tmp_path, capsys):
    """A --out holding the earlier sorting-line-transfer's transfer.json (a list of runs) is left alone."""
    from sorting_line_gym.studies import transfer

    earlier = tmp_path / "transfer.json"
    earlier.write_text('{"runs": [], "baselines": {}}\n')
    assert transfer.main([*SMOKE, "--out", str(tmp_path)]) == 2
    assert "holds the runs of the earlier sorting-line-transfer" in capsys.readouterr().err
    assert earlier.read_text() == '{"runs": [], "baselines": {}}\n' and not (tmp_path / "cells").exists()


def test_ppo_settings_are_part_of_the_key_and_the_default_key_is_unchanged(tmp_path, capsys):
    """`--ppo-settings paper` trains PPO with the paper's gamma, learning rate and entropy on the
    study's rollouts, is its own configuration (refused into a --out of the default's cells), and
    leaves the default key as studies saved before the option have it; no node."""
    from sorting_line_gym.studies import transfer
    from sorting_line_gym.studies import transfer_cells as tc
    from sorting_line_gym.studies.cell_store import CellStore

    study = tc.Settings(2000, 2000, 100).key()
    assert "ppo_settings" not in study
    assert study["hyperparameters"]["ppo"] == {"n_steps": 500, "batch_size": 100, "n_epochs": 5}
    paper = tc.Settings(2000, 2000, 100, "paper").key()
    assert paper["hyperparameters"]["ppo"] == {
        "gamma": 0.85,
        "learning_rate": 0.0007,
        "ent_coef": 0.03,
        "n_steps": 500,
        "batch_size": 100,
        "n_epochs": 5,
    }
    assert paper["hyperparameters"]["a2c"] == study["hyperparameters"]["a2c"]

    args = transfer.options([*SMOKE, "--out", str(tmp_path)])
    CellStore(tmp_path, args.settings.key()).begin(["a study with the default PPO settings"])
    assert transfer.main([*SMOKE, "--ppo-settings", "paper", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "holds cells of another configuration (hyperparameters: saved" in err and "'gamma': 0.85" in err
    with pytest.raises(SystemExit) as exit_:
        transfer.main([*SMOKE, "--ppo-settings", "tuned", "--out", str(tmp_path / "t")])
    assert exit_.value.code == 2 and "--ppo-settings: invalid choice: 'tuned'" in capsys.readouterr().err
