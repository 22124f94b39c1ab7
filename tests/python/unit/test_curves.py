"""The RL cells' learning curves (studies/curves.py), on tiny budgets on native lines:

- SB3's curve ends at the final evaluation's score on those seeds (the same episodes, the same
  code), its points at 0, the multiples of ``every`` and the end; and taking the points changes
  nothing in the training (the same weights with and without a curve);
- a batched training's curve of seed s equals, at every point, seed s's model saved at that point
  and evaluated alone by ``evaluate`` (the final evaluation's code);
- the cell records: format 2 with the curve; a format-1 record (before curves) is read without a
  curve; a record of a later format is refused with its version named; bad curve flags fail at start.
"""

from __future__ import annotations

import json

import pytest

from support.training_stack import needs_training

pytestmark = [needs_training, pytest.mark.usefixtures("one_torch_thread")]

EPISODES = 5  # a curve point's held-out seeds


def _weights(path):
    import torch
    from stable_baselines3.common.save_util import load_from_zip_file

    _, params, _ = load_from_zip_file(path)
    return {k: v.clone() for k, v in params["policy"].items()}, torch


@pytest.mark.parametrize("algo", ["a2c", "dqn"])
def test_an_sb3_curve_ends_at_the_final_score_and_changes_no_weight(tmp_path, algo):
    from sorting_line_gym.studies.benchmark import Cell, Heldout, run_cell
    from sorting_line_gym.studies.curves import CurveSettings

    cell = Cell("D", "basic", algo, 42)
    heldout = Heldout(10_000, 8)
    with_curve = run_cell(cell, tmp_path / "c", 1000, heldout, False, "native", CurveSettings(400, EPISODES, 10_000))
    without = run_cell(cell, tmp_path / "n", 1000, heldout, False, "native", CurveSettings(0, EPISODES, 10_000))
    curve = with_curve["curve"]
    assert with_curve["format"] == 2 and "curve" not in without
    assert [p["step"] for p in curve["points"]] == [0, 400, 800, 1000]
    assert (curve["every"], curve["episodes"], curve["seed"]) == (400, EPISODES, 10_000)
    final = [e["reward"] for e in with_curve["heldout"]["per_episode"][:EPISODES]]
    assert curve["points"][-1]["rewards"] == final
    from sorting_line_gym.studies.evaluate import evaluate

    alone = evaluate(f"{algo}:{with_curve['training']['model_path']}", "D", "basic", seed=10_000, episodes=EPISODES,
                     backend="native")  # fmt: skip
    assert curve["points"][-1]["reward_mean"] == alone.reward_mean
    (a, torch), (b, _) = _weights(with_curve["training"]["model_path"]), _weights(without["training"]["model_path"])
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a), "a curve changed the training"
    assert with_curve["heldout"]["per_episode"] == without["heldout"]["per_episode"]


def test_a_batched_curve_of_each_seed_equals_its_model_evaluated_alone(tmp_path, monkeypatch):
    """At every point the test saves each seed's model (the engine's save) and scores it alone."""
    from sorting_line_gym.studies import benchmark, curves
    from sorting_line_gym.studies.evaluate import evaluate
    from sorting_line_gym.training.run_record import model_stem

    alone: list[list[float]] = []  # per point, per seed: its model's mean score evaluated alone

    class Checked(curves.BatchedCurves):
        def __call__(self, engine):
            before = len(self.curves[0].points)
            super().__call__(engine)
            if len(self.curves[0].points) == before:
                return
            paths = [tmp_path / "points" / f"{model_stem('a2c', 'D', 'basic', s)}_{before}.zip" for s in engine.seeds]
            engine.save(paths)
            alone.append([evaluate(f"a2c:{p}", "D", "basic", seed=10_000, episodes=EPISODES, backend="native")
                          .reward_mean for p in paths])  # fmt: skip

    monkeypatch.setattr(curves, "BatchedCurves", Checked)
    cells = [benchmark.Cell("D", "basic", "a2c", s, engine="batched") for s in (42, 43)]
    records = benchmark.run_batch(cells, tmp_path, 1000, benchmark.Heldout(10_000, 8), False, "native",
                                  curves.CurveSettings(500, EPISODES, 10_000))  # fmt: skip
    assert len(alone) == 3, "points at 0, 500 and 1000"
    for s, record in enumerate(records):
        points = record["curve"]["points"]
        assert [p["step"] for p in points] == [0, 500, 1000]
        assert [p["reward_mean"] for p in points] == [row[s] for row in alone], f"seed {cells[s].train_seed}"
        assert points[-1]["rewards"] == [e["reward"] for e in record["heldout"]["per_episode"][:EPISODES]]


def _store(tmp_path, record: dict) -> None:
    (tmp_path / "cells").mkdir(parents=True, exist_ok=True)
    (tmp_path / "cells" / "D_basic_a2c_seed42.json").write_text(json.dumps(record))


def test_a_format_1_cell_is_read_without_a_curve_and_a_later_format_is_refused(tmp_path, capsys):
    from sorting_line_gym.studies import benchmark

    cell = benchmark.Cell("D", "basic", "a2c", 42)
    heldout = benchmark.Heldout(10_000, 3)
    old = {"cell": cell.fields(), "timesteps": 200, "heldout": {"seed": 10_000, "episodes": 3}}
    _store(tmp_path, old)
    assert benchmark.load_cell(cell, tmp_path, 200, heldout) == old
    _store(tmp_path, {**old, "format": 99})
    with pytest.raises(benchmark.CellFormatError, match="format 99.*reads formats 1 .. 2"):
        benchmark.load_cell(cell, tmp_path, 200, heldout)
    argv = ["--setups", "D", "--variants", "basic", "--agents", "a2c", "--train-seeds", "42", "--timesteps", "200",
            "--heldout-episodes", "3", "--backend", "native", "--out", str(tmp_path)]  # fmt: skip
    assert benchmark.main(argv) == 2
    assert "a cell of format 99" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--curve-every", "-1"], "--curve-every = -1 is not valid: allowed 0 (no curves) or more"),
        (["--curve-episodes", "0"], "--curve-episodes = 0 is not valid: allowed 1 .. --heldout-episodes (3)"),
        (["--curve-episodes", "4"], "--curve-episodes = 4 is not valid"),
    ],
)
def test_bad_curve_flags_fail_at_start(tmp_path, capsys, flags, message):
    from sorting_line_gym.studies import benchmark

    argv = ["--agents", "a2c", "--heldout-episodes", "3", "--backend", "native", "--out", str(tmp_path), *flags]
    assert benchmark.main(argv) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "cells").exists()
