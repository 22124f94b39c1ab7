"""``--backend native`` on the tools: a training, an evaluation, a benchmark cell and a transfer cell
give the same results on the native backend as on the ROS backend (real nodes over DDS, so this
file runs in the tests' network namespace) for the same seeds: the same model weights, episodes and
records, wall times aside. Small runs: each costs seconds on the native backend, a few on ROS.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

BACKENDS = ("native", "ros")


def policy_weights(model_zip: Path) -> bytes:
    with zipfile.ZipFile(model_zip) as z:
        return z.read("policy.pth")


def without_timing(record: dict) -> dict:
    """A record without what differs between any two runs: wall times, speeds and paths."""
    drop = {"wall_s", "steps_per_s", "model_path", "train_seconds", "eval_seconds", "seconds"}
    return {k: without_timing(v) if isinstance(v, dict) else v for k, v in record.items() if k not in drop}


def test_training_and_evaluation_equal_on_both_backends(tmp_path):
    from sorting_line_gym.studies.evaluate import evaluate
    from sorting_line_gym.training import train

    models = {}
    for backend in BACKENDS:
        out = tmp_path / backend
        argv = ["--algo", "ppo", "--setup", "D", "--variant", "advanced", "--timesteps", "256", "--hp", "n_steps=128"]
        argv += ["--hp", "batch_size=64", "--hp", "n_epochs=2", "--hp", "episode_steps=100", "--out", str(out)]
        assert train.main([*argv, "--no-progress", "--backend", backend]) == 0
        record = json.loads((out / "ppo_D_advanced_seed42.json").read_text())
        models[backend] = (record, Path(record["model_path"]))
    (native, native_zip), (ros, ros_zip) = models["native"], models["ros"]
    assert policy_weights(native_zip) == policy_weights(ros_zip), "the same seed trained different models"
    assert without_timing(native) == without_timing(ros)
    for agent in (f"ppo:{native_zip}", "rba-hold"):
        runs = [evaluate(agent, "D", "advanced", episodes=2, backend=backend) for backend in BACKENDS]
        assert runs[0] == runs[1], agent


def test_a_benchmark_cell_is_the_same_on_both_backends(tmp_path):
    from sorting_line_gym.studies.benchmark import Cell, Heldout, run_cell

    cell = Cell(setup="C", variant="basic", agent="rba")
    records = [run_cell(cell, tmp_path / b, 0, Heldout(10_000, 3), False, backend=b) for b in BACKENDS]
    assert without_timing(records[0]) == without_timing(records[1])
    assert not (tmp_path / "native" / "dashboards").exists() and (tmp_path / "ros" / "dashboards").is_dir()


def test_a_transfer_cell_is_the_same_on_both_backends(tmp_path):
    """The evolving line through the change: the continued and frozen agents' curves and evaluations."""
    from sorting_line_gym.studies import transfer_cells as tc

    cell = tc.Cell(scenario="upgrade", kind="transfer", algo="a2c", seed=1)
    records = []
    for backend in BACKENDS:
        tc.schedules(cell.scenario, 2, tmp_path / backend)
        records.append(tc.run_cell(cell, tc.Settings(2, 2, 2, backend=backend), tmp_path / backend))
    assert without_timing(records[0]) == without_timing(records[1])
    assert len(records[0]["continued_curve"]) >= 3
