"""The benchmark report's learning curves (reports.curves, plots.learning_curves_figure, the
``curves`` figure of studies.benchmark.write_report) from cell records made up here, whose curves
are known: no node, no training.

Per line, one series per RL algorithm and training configuration (engine, lines), each the mean
over runs on the steps every run has, with its interval over whole runs; rba-hold's and the
oracle's means on the curves' own seeds as references; the figure written (PNG and SVG) with the
cells saved beside the report's, and no figure, and no failure, without curves.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sorting_line_gym.reports import curves, plots

FIRST = 10_000  # the first held-out seed
HELDOUT = [1.0, 2.0, 3.0, 100.0]  # rba-hold's held-out rewards; a curve is scored on the first 3 seeds
ORACLE = [4.0, 5.0, 6.0, 200.0]
STEPS = [0, 5000, 10_000]


def curve(values, steps=STEPS, episodes: int = 3) -> dict:
    """A curve as studies.curves records it, its point at ``steps[i]`` of mean ``values[i]``."""
    points = [
        {"step": s, "reward_mean": float(v), "rewards": [float(v)] * episodes}
        for s, v in zip(steps, values, strict=True)
    ]
    return {"every": 5000, "episodes": episodes, "seed": FIRST, "wall_s": 0.1, "points": points}


def record(agent: str, train_seed: int | None = None, line=("B", "advanced"), values=None, **cell) -> dict:
    """A cell's record as the benchmark saves it (format 2), with held-out rewards HELDOUT and, for
    ``values``, a curve of those means."""
    episodes = [{"seed": FIRST + i, "reward": r} for i, r in enumerate(HELDOUT)]
    evaluation = {"reward_mean": 1.0, "reward_std": 0.0, "speed_mean": 0.5, "purity_mean": 0.9}
    r = {
        "cell": {"setup": line[0], "variant": line[1], "agent": agent, "train_seed": train_seed, **cell},
        "timesteps": 10_000 if train_seed is not None else None,
        "evaluation": evaluation | {"speed_changes_mean": 1.0},
        "heldout": {"seed": FIRST, "episodes": len(HELDOUT), "per_episode": episodes},
        "format": 2,
    }
    if train_seed is not None:  # what the --n-envs check reads of a training
        r["training"] = {"wall_s": 1.0, "hyperparams": {}, "n_envs": cell.get("n_envs", 1)}
    if "engine" in cell:
        r["engine"] = cell["engine"]
    return r | ({"curve": curve(values)} if values is not None else {})


def cells() -> list[dict]:
    """B advanced: ppo on one line (two runs, the second with a point at a step the first lacks), on
    8 lines and batched (two runs each), dqn (one run), rba-hold, and a ppo cell of format 1
    (no curve); D basic: a2c."""
    ppo_43 = record("ppo", 43)
    ppo_43["curve"] = curve([2.0, 6.0, 12.0, 99.0], steps=[*STEPS, 10_240])  # only this run has 10240
    old = record("ppo", 44)
    del old["format"]
    return [
        record("rba-hold"),
        record("dqn", 42, values=[1.0, 1.0, 1.0]),
        record("ppo", 42, values=[0.0, 4.0, 8.0]),
        ppo_43,
        old,
        record("ppo", 42, values=[1.0, 1.0, 1.0], n_envs=8),
        record("ppo", 43, values=[3.0, 3.0, 3.0], n_envs=8),
        record("ppo", 42, values=[5.0, 5.0, 5.0], engine="batched"),
        record("ppo", 43, values=[7.0, 7.0, 7.0], engine="batched"),
        record("a2c", 42, line=("D", "basic"), values=[-1.0, 0.0, 1.0]),
    ]


def oracles() -> dict:
    return {line: {"per_episode": [{"seed": FIRST + i, "reward": r} for i, r in enumerate(ORACLE)]}
            for line in (("B", "advanced"), ("D", "basic"))}  # fmt: skip


def test_each_series_is_the_mean_of_its_runs_with_their_interval():
    panels = curves.benchmark_curves(cells(), oracles())
    assert list(panels) == [("B", "advanced"), ("D", "basic")]
    b = panels[("B", "advanced")]
    by = {s["label"]: s for s in b["series"]}
    assert list(by) == ["ppo", "ppo, 8 lines", "ppo (batched)", "dqn"]  # ALGOS' order, SB3's one line first
    ppo = by["ppo"]
    assert ppo["runs"] == 2 and ppo["steps"] == STEPS  # 10240: not every run has it
    assert ppo["mean"] == pytest.approx([1.0, 5.0, 10.0])
    # Two runs: a resample is both of one run (a chance of 1/4 each) or one of each, so the 95 %
    # interval runs from the lower run to the higher.
    assert ppo["low"] == pytest.approx([0.0, 4.0, 8.0]) and ppo["high"] == pytest.approx([2.0, 6.0, 12.0])
    assert by["ppo, 8 lines"]["mean"] == pytest.approx([2.0] * 3) and by["ppo, 8 lines"]["n_envs"] == 8
    assert by["ppo (batched)"]["mean"] == pytest.approx([6.0] * 3) and by["ppo (batched)"]["engine"] == "batched"
    dqn = by["dqn"]  # one run: nothing to resample
    assert dqn["runs"] == 1 and dqn["mean"] == dqn["low"] == dqn["high"] == [1.0] * 3
    # The references on the curves' seeds (the first 3), not on every held-out seed.
    assert b["seeds"] == {"first": FIRST, "episodes": 3}
    assert b["references"] == {"rba-hold": pytest.approx(2.0), "oracle": pytest.approx(5.0)}
    d = panels[("D", "basic")]
    assert [s["label"] for s in d["series"]] == ["a2c"] and d["series"][0]["mean"] == pytest.approx([-1.0, 0.0, 1.0])
    assert d["references"] == {"oracle": pytest.approx(5.0)}  # no rba-hold cell on D basic


def test_no_curve_no_panel_and_no_figure(tmp_path):
    without = [{k: v for k, v in r.items() if k != "curve"} for r in cells()]
    assert curves.benchmark_curves(without, oracles()) == {}
    assert plots.learning_curves_figure({}, tmp_path / "curves") == []
    assert not list(tmp_path.iterdir())


def _real_png(path: Path) -> None:
    import matplotlib.image

    assert path.is_file() and path.stat().st_size > 10_000, path
    pixels = matplotlib.image.imread(path)
    assert len(np.unique(pixels.reshape(-1, pixels.shape[2]), axis=0)) > 50, f"{path} is nearly uniform"


def _report(out: Path, records: list[dict], monkeypatch) -> list[Path]:
    """write_report on ``records``, its oracles from the cache (no node), without Figure 3 (the
    node's reward table)."""
    from sorting_line_gym.reports.benchmark_summary import Heldout
    from sorting_line_gym.studies import benchmark

    monkeypatch.setattr(plots, "analysis_figure", lambda stem: [])
    paper = {"reward_mean": 1.0, "reward_std": 0.0, "speed_mean": 0.5, "purity_mean": 0.9, "speed_changes_mean": 1.0}
    (out / "oracle").mkdir(parents=True, exist_ok=True)
    for (setup, variant), o in oracles().items():
        (out / "oracle" / f"{setup}_{variant}_seed{FIRST}_x4.json").write_text(json.dumps(o))
        (out / "oracle" / f"{setup}_{variant}_seed42_x10.json").write_text(json.dumps(paper | {"per_episode": []}))
    return benchmark.write_report(out, records, 10_000, heldout=Heldout(FIRST, len(HELDOUT)))


def test_the_report_draws_its_cells_curves_beside_the_saved_ones(tmp_path, monkeypatch):
    from sorting_line_gym.studies.benchmark_cells import Cell

    out = tmp_path / "bench"
    records = [r for r in cells() if r["cell"].get("engine") is None and r["cell"].get("n_envs", 1) == 1]
    (out / "cells").mkdir(parents=True)
    for r in cells():  # the batched cells only in the store, as a run of the other engine leaves them
        (out / "cells" / f"{Cell(**r['cell']).name}.json").write_text(json.dumps(r))
    stale = record("ppo", 45, values=[50.0] * 3, engine="batched")
    stale["timesteps"] = 20_000  # another budget: not this report's
    (out / "cells" / "B_advanced_ppo_batched_seed45.json").write_text(json.dumps(stale))
    written = _report(out, records, monkeypatch)
    assert out / "curves.png" in written and out / "curves.svg" in written
    _real_png(out / "curves.png")
    panels = json.loads((out / "table.json").read_text())["learning_curves"]
    b = next(p for p in panels if (p["setup"], p["variant"]) == ("B", "advanced"))
    assert [s["label"] for s in b["series"]] == ["ppo", "ppo, 8 lines", "ppo (batched)", "dqn"]
    assert [s["runs"] for s in b["series"]] == [2, 2, 2, 1]  # the stale budget's seed 45 left out


def test_a_report_without_curves_writes_no_curve_figure(tmp_path, monkeypatch):
    out = tmp_path / "bench"
    records = [{k: v for k, v in r.items() if k != "curve"} for r in cells() if r["cell"].get("engine") is None]
    written = _report(out, records, monkeypatch)
    assert out / "table.md" in written and not (out / "curves.png").exists() and not (out / "curves.svg").exists()
    assert json.loads((out / "table.json").read_text())["learning_curves"] == []
