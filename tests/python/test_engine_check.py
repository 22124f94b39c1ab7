"""`sorting-line-engine-check`, reduced (issue 54 item 4 in CI): PPO, A2C and DQN on D basic, 4 training
seeds per engine, 2048 steps (one PPO rollout and update), 20 held-out seeds, curves every 1024 steps; both
engines, end to end through the benchmark's cells, then the report. Deterministic (fixed seeds, one torch
thread, native lines), so it passes or fails the same way every time.

What must hold: for each algorithm the 95 % interval (bootstrap of whole runs) of the difference of the
engines' means lies within +-REDUCED_MARGIN. The full check's margin is 1.5 at 10 seeds and 100k steps;
with 4 seeds the interval is about sqrt(10 / 4) = 1.6 times as wide, and a few thousand steps leave the
runs spread further, hence 3.0: wide enough that a correct engine's intervals lie well inside it, narrow
enough that an engine that does not learn (learning rate 0) falls outside it (the runs that showed both,
and what the test costs: docs/results/engine-check.md, "Reduced check in CI"). Bad input fails before any
training.
"""

from __future__ import annotations

import json

import pytest

from support.training_stack import needs_training

pytestmark = [needs_training, pytest.mark.usefixtures("one_torch_thread")]

REDUCED_MARGIN = 3.0
ALGOS = ("ppo", "a2c", "dqn")
REDUCED = [
    "--algos", *ALGOS, "--lines", "D:basic", "--train-seeds", "42", "43", "44", "45", "--timesteps", "2048",
    "--heldout-episodes", "20", "--curve-every", "1024", "--curve-episodes", "20", "--jobs", "2",
    "--margin", str(REDUCED_MARGIN),
]  # fmt: skip


def test_the_reduced_engine_check_finds_the_engines_equal(tmp_path, capsys):
    from sorting_line_gym.studies import engine_check

    out = tmp_path / "check"
    assert engine_check.main([*REDUCED, "--out", str(out)]) == 0
    report = json.loads((out / "engine_check.json").read_text())
    rows = {r["algo"]: r for r in report["rows"]}
    assert sorted(rows) == sorted(ALGOS)
    for algo, row in rows.items():
        d = row["difference"]
        assert row["sb3"]["runs"] == row["batched"]["runs"] == 4
        assert -REDUCED_MARGIN <= d["low"] <= d["point"] <= d["high"] <= REDUCED_MARGIN, (algo, d)
        assert row["verdict"] == f"within +-{REDUCED_MARGIN:g}", (algo, row["verdict"])
        curves = report["curves"][f"{algo} D basic"]
        # After the update that reaches each multiple: PPO's rollouts are 2048 steps, A2C's 5, DQN's 4.
        steps = {"ppo": [0, 2048], "a2c": [0, 1025, 2050], "dqn": [0, 1024, 2048]}[algo]
        assert curves["sb3"]["steps"] == curves["batched"]["steps"] == steps
    for name in ("engine_check.md", "engine_check.csv", "engine_check_runs.png", "engine_check_curves.png"):
        assert (out / name).is_file(), name
    assert "batched - sb3" in (out / "engine_check.md").read_text()
    # Resumable: a rerun trains nothing and writes the same table.
    capsys.readouterr()
    assert engine_check.main([*REDUCED, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "12 cells, 12 already done, 0 to run" in err
    assert json.loads((out / "engine_check.json").read_text())["rows"] == report["rows"]


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--algos", "sac"], "invalid choice: 'sac'"),
        (["--lines", "E:basic"], "line 'E:basic' is not valid: allowed SETUP:VARIANT"),
        (["--lines", "B"], "line 'B' is not valid"),
        (["--train-seeds", "42", "43"], "2 seed(s) give no interval over runs: allowed 3 or more"),
        (["--train-seeds", "42", "42", "43"], "allowed distinct seeds"),
        (["--margin", "0"], "--margin = 0.0 is not valid"),
        (["--timesteps", "0"], "--timesteps = 0 is not valid"),
    ],
)
def test_bad_input_fails_before_any_training(tmp_path, capsys, flags, message):
    from sorting_line_gym.studies import engine_check

    out = tmp_path / "check"
    try:
        code = engine_check.main(["--out", str(out), *flags])
    except SystemExit as stopped:  # argparse's own refusals
        code = stopped.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_directory_of_another_study_or_configuration_is_refused(tmp_path, capsys):
    from sorting_line_gym.studies import engine_check

    other = tmp_path / "bench"
    (other / "cells").mkdir(parents=True)
    assert engine_check.main(["--out", str(other)]) == 2
    assert "holds files but no engine check" in capsys.readouterr().err
    out = tmp_path / "check"
    out.mkdir()
    (out / "study.json").write_text(json.dumps({"key": {"study": "engine-check", "timesteps": 50_000}}))
    assert engine_check.main(["--out", str(out)]) == 2
    assert "timesteps: saved 50000, asked 100000" in capsys.readouterr().err
    (out / "study.json").write_text(json.dumps({"key": {"study": "transfer"}}))
    assert engine_check.main(["--out", str(out)]) == 2
    assert "holds cells of another configuration" in capsys.readouterr().err
