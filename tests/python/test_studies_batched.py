"""`sorting-line-benchmark --engine batched` and `sorting-line-transfer --engine batched`, on tiny
budgets (A2C, two training seeds; native lines, and the benchmark on ROS lines too): the seeds of
a line are trained in one batched run, each is saved as a cell of its own naming the engine, and a
batch that was cut is resumed by training only the missing seed. The default engine (sb3) keeps its cells and records:
test_training.py, test_native_tools.py and the transfer tests hold it.

What must hold:
- one cell per seed (the benchmark's named ``..._batched_seed<S>``), its record naming the engine;
- a rerun with a cell missing trains that seed alone (a batch of one) and leaves the others;
- a transfer cell's evaluations equal SB3's cell of the same seed (its curve to float32), and so do a
  shrink-and-perturb cell's (the same perturbation in both engines), whose curve up to the change is
  the transfer cell's of its seed, and a cloned cell's (the same behaviour cloning);
- a transfer cell saved before forgetting was measured (no evaluations on the line before the
  change) is trained again, the other cells kept;
- on one node's lines (``--backend ros``) a batch records the scores native lines give;
- bad input fails at start: an unknown engine, a batch too large for one node, the batched
  transfer on the ROS backend (the evolving line's masks are native only).
"""

from __future__ import annotations

import json

import pytest

ARGV = [
    "--engine", "batched", "--setups", "D", "--variants", "basic", "--agents", "a2c",
    "--train-seeds", "42", "43", "--timesteps", "200", "--heldout-episodes", "3",
]  # fmt: skip


def test_a_batched_benchmark_saves_a_cell_per_seed_and_resumes_the_missing_one(tmp_path, capsys):
    from sorting_line_gym.studies import benchmark

    out = tmp_path / "bench"
    argv = [*ARGV, "--out", str(out)]
    assert benchmark.main(argv) == 0
    assert "2 to run" in capsys.readouterr().err
    cells = {s: out / "cells" / f"D_basic_a2c_batched_seed{s}.json" for s in (42, 43)}
    first = {s: json.loads(path.read_text()) for s, path in cells.items()}
    for seed, record in first.items():
        assert record["engine"] == "batched" and record["cell"]["engine"] == "batched"
        assert record["cell"]["train_seed"] == seed and record["timesteps"] == 200
        assert record["training"]["seed"] == seed
        assert record["training"]["versions"]["engine"] == "batched (2 seeds at once)"
        assert record["training"]["model_path"].endswith(f"models_batched/a2c_D_basic_seed{seed}.zip")
        assert len(record["heldout"]["per_episode"]) == 3 and len(record["evaluation"]["per_episode"]) == 10
    assert (out / "table.md").is_file()

    # A batch cut after seed 42's cell was saved: the rerun trains seed 43 alone.
    cells[43].unlink()
    kept = cells[42].stat().st_mtime_ns
    assert benchmark.main(argv) == 0
    assert "1 already done, 1 to run" in capsys.readouterr().err
    assert cells[42].stat().st_mtime_ns == kept
    again = json.loads(cells[43].read_text())
    assert again["training"]["versions"]["engine"] == "batched (1 seeds at once)"
    # Each seed is a run of its own: trained alone, it scores as it did beside seed 42.
    assert again["heldout"]["per_episode"] == first[43]["heldout"]["per_episode"]


def test_bad_engine_input_fails_at_start(tmp_path, capsys):
    from sorting_line_gym.studies import benchmark

    with pytest.raises(SystemExit) as stopped:
        benchmark.main(["--engine", "jax", "--out", str(tmp_path)])
    assert stopped.value.code == 2
    assert "'jax'" in (err := capsys.readouterr().err) and "'sb3', 'batched'" in err
    # On ROS lines a batch trains on one node of seeds x n-envs lines: at most 64.
    assert benchmark.main([*ARGV, "--backend", "ros", "--n-envs", "64", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "2 --train-seeds x --n-envs 64 = 128 lines is not valid" in err and "seeds x n-envs <= 64" in err
    assert not (tmp_path / "cells").exists() or not any((tmp_path / "cells").iterdir())


def test_a_batched_benchmark_on_ros_lines_records_what_native_lines_do(tmp_path, capsys):
    """The same batch on one node's lines (trained and evaluated over ROS 2): the same scores."""
    from sorting_line_gym.studies import benchmark

    records = {}
    for backend in ("native", "ros"):
        out = tmp_path / backend
        assert benchmark.main([*ARGV, "--backend", backend, "--out", str(out)]) == 0
        records[backend] = {
            s: json.loads((out / "cells" / f"D_basic_a2c_batched_seed{s}.json").read_text()) for s in (42, 43)
        }
    capsys.readouterr()
    for seed in (42, 43):
        native, ros = records["native"][seed], records["ros"][seed]
        for part in ("heldout", "evaluation"):
            assert ros[part]["per_episode"] == native[part]["per_episode"], (seed, part)


TRANSFER = ["--engine", "batched", "--scenarios", "upgrade", "--algos", "a2c", "--seeds", "1", "2",
            "--before", "10", "--after", "10", "--evaluations", "2"]  # fmt: skip


def test_a_batched_transfer_saves_a_cell_per_seed_equal_to_sb3s_and_resumes(tmp_path, capsys):
    from sorting_line_gym.studies import transfer
    from sorting_line_gym.studies import transfer_cells as tc

    out = tmp_path / "transfer"
    argv = [*TRANSFER, "--out", str(out)]
    assert transfer.main(argv) == 0
    assert "2 seeds" in capsys.readouterr().err
    store = json.loads((out / "study.json").read_text())
    assert store["key"]["engine"] == "batched"
    names = [f"upgrade_a2c_{kind}_seed{s}" for kind in ("transfer", "scratch", "perturbed", "cloned") for s in (1, 2)]
    first = {n: json.loads((out / "cells" / f"{n}.json").read_text()) for n in names}
    for record in first.values():
        assert record["engine"] == "batched" and record["batch"]["seeds"] == [1, 2]
    # SB3's scratch and perturbed cells of seed 2, on the same native line: the same evaluations, the same curve.
    for kind, curve in (("scratch", "scratch_curve"), ("perturbed", "perturbed_curve"), ("cloned", "cloned_curve")):
        cell = tc.Cell("upgrade", kind, "a2c", 2)
        sb3 = tc.run_cell(cell, tc.Settings(10, 10, 2, backend="native"), out)
        batched = first[cell.name]
        for key in tc.BEFORE_EVALUATIONS[kind] + (f"{kind}_eval",):
            assert batched[key] == sb3[key], (kind, key)
        assert batched[curve] == pytest.approx(sb3[curve], rel=1e-5, abs=1e-5), kind
    # Shrink-and-perturb is the transfer cell's agent up to the change; after it, another one.
    perturbed, through = first["upgrade_a2c_perturbed_seed1"], first["upgrade_a2c_transfer_seed1"]
    assert perturbed["perturbed_curve"][:10] == through["continued_curve"][:10]
    assert perturbed["perturbed_at_change_eval"] != through["frozen_eval"]
    assert len(through["continued_before_eval"]) == len(through["frozen_before_eval"]) == 2
    summary = json.loads((out / "transfer.json").read_text())["summary"]["upgrade"]["algos"]["a2c"]["continual"]
    assert first["upgrade_a2c_cloned_seed2"]["clone_losses"] == sb3["clone_losses"]  # sb3: the cloned cell's
    for strategy in ("continued", "scratch", "perturbed", "cloned"):
        f = summary[strategy]["forgetting"]["iqm"]
        assert f["low"] <= f["point"] <= f["high"] and summary[strategy]["forgetting"]["runs"] == 2, strategy
    assert "by construction" in summary["frozen"]["forgetting_note"]

    # A batch cut after seed 1's cell was saved: the rerun trains seed 2 alone.
    (out / "cells" / "upgrade_a2c_transfer_seed2.json").unlink()
    assert transfer.main(argv) == 0
    assert "8 already done, 1 to run" in capsys.readouterr().err
    again = json.loads((out / "cells" / "upgrade_a2c_transfer_seed2.json").read_text())
    assert again["batch"]["seeds"] == [2] and again["invocation"] == 2
    for key in ("continued_curve", "continued_eval", "frozen_eval", "continued_before_eval", "frozen_before_eval"):
        assert again[key] == first["upgrade_a2c_transfer_seed2"][key], key
    an_old_cell_is_trained_again(transfer, out, argv, names, capsys)
    # The store of one engine refuses the other's options.
    assert transfer.main([*TRANSFER[2:], "--backend", "native", "--out", str(out)]) == 2
    assert "engine: saved 'batched', asked None" in capsys.readouterr().err


def an_old_cell_is_trained_again(transfer, out, argv, names, capsys) -> None:
    """A transfer cell saved before forgetting was measured: trained again, saying so; the rest kept."""
    old_cell = out / "cells" / "upgrade_a2c_transfer_seed1.json"
    old = json.loads(old_cell.read_text())
    kept = {n: (out / "cells" / f"{n}.json").stat().st_mtime_ns for n in names if n != old_cell.stem}
    old_cell.write_text(json.dumps({k: v for k, v in old.items() if not k.endswith("_before_eval")}))
    assert transfer.main([*argv, "--report-only"]) == 0  # reported as it is: without its forgetting
    assert (
        "No forgetting for continued: cells saved before forgetting was measured" in (out / "transfer.md").read_text()
    )
    assert transfer.main(argv) == 0
    err = capsys.readouterr().err
    assert "upgrade_a2c_transfer_seed1: a transfer cell without evaluations on the line before the change" in err
    assert "trained again" in err and "8 already done, 1 to run" in err
    redone = json.loads(old_cell.read_text())
    assert redone["invocation"] == 3 and redone["frozen_before_eval"] == old["frozen_before_eval"]
    assert {n: (out / "cells" / f"{n}.json").stat().st_mtime_ns for n in kept} == kept


def test_the_transfer_refuses_the_batched_engine_on_ros(tmp_path, capsys):
    from sorting_line_gym.studies import transfer

    with pytest.raises(SystemExit) as stopped:
        transfer.main([*TRANSFER, "--backend", "ros", "--out", str(tmp_path)])
    assert stopped.value.code == 2
    assert "--engine batched --backend ros is not valid" in capsys.readouterr().err
    assert not (tmp_path / "cells").exists()
