"""The strip plots of per-run scores (reports.plots.strip_figure, the benchmark's runs_figure, the
transfer study's runs_plot) drawn from records made up here: no node, no training.

Each cell's runs are shown beside its interval: the figures are written (PNG and SVG) and are
more than a blank canvas, the transfer report keeps each run's mean that its plot draws, and no
panels write no file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sorting_line_gym.reports import plots, stats, transfer_report


def _real_png(path: Path) -> None:
    import matplotlib.image

    assert path.is_file() and path.stat().st_size > 10_000, path
    pixels = matplotlib.image.imread(path)
    assert pixels.ndim == 3 and min(pixels.shape[:2]) > 200
    assert len(np.unique(pixels.reshape(-1, pixels.shape[2]), axis=0)) > 50, f"{path} is nearly uniform"


def _row(runs: np.ndarray) -> dict:
    return {"heldout": {"per_seed": runs.mean(axis=1).tolist(), "iqm": stats.iqm_interval(runs).as_dict()}}


def test_the_benchmarks_runs_figure_has_a_dot_per_run(tmp_path):
    seeds = np.linspace(20, 30, 20)
    ppo = seeds[None, :] + np.array([-1.5, -0.5, 0.0, 0.4, 1.6])[:, None]  # five runs, spread over seeds
    rows = {
        ("B", "advanced", "ppo"): _row(ppo),
        ("B", "advanced", "rba-hold"): _row(seeds[None, :] - 0.3),  # one deterministic run
        ("B", "advanced", "oracle"): {"heldout": {"mean": {"point": 33.4}}},
    }
    check = {
        "setup": "B",
        "variant": "advanced",
        "agent": "ppo",
        "n_envs": 8,
        "mapping": "same-rollout",
        "per_run": [ppo.mean(axis=1).tolist(), (ppo.mean(axis=1) - 1).tolist()],
        "iqm_1": stats.iqm_interval(ppo).as_dict(),
        "iqm_n": stats.iqm_interval(ppo - 1).as_dict(),
    }
    written = plots.runs_figure(rows, [check], tmp_path / "runs")
    assert written == [tmp_path / "runs.png", tmp_path / "runs.svg"]
    _real_png(written[0])
    assert plots.runs_figure({}, [], tmp_path / "none") == []  # nothing to draw, nothing written


def test_the_transfer_studys_runs_plot(tmp_path):
    def record(kind: str, seed: int, **values) -> dict:
        return {"cell": {"scenario": "upgrade", "kind": kind, "algo": "a2c", "seed": seed}, **values}

    key = {"before": 10, "after": 20, "episode_steps": 50, "window": 10, "evaluations": 4, "eval_seed": 10_000}
    records = [
        record("transfer", s, continued_curve=[1.0] * 30, continued_eval=[s, s + 1.0, s, s], frozen_eval=[0.0] * 4)
        for s in (1.0, 2.0, 3.0)
    ] + [record("scratch", s, scratch_curve=[2.0] * 20, scratch_eval=[s + 1.0] * 4) for s in (1.0, 2.0)]
    records.append(
        {
            "cell": {"scenario": "upgrade", "kind": "baselines", "algo": None, "seed": None},
            "before": {"rba": [1.0] * 4, "rba-hold": [2.0] * 4},
            "after": {"rba": [3.0] * 4, "rba-hold": [2.5] * 4, "oracle": [5.0] * 4},
        }
    )
    summary = transfer_report.summarize(records, key, ["upgrade"], ["a2c"])
    strategies = summary["upgrade"]["algos"]["a2c"]["strategies"]
    assert strategies["continued"]["per_run"] == [1.25, 2.25, 3.25]  # each run's mean over the 4 seeds
    assert strategies["scratch"]["per_run"] == [2.0, 3.0]
    written = transfer_report.runs_plot(summary, tmp_path / "transfer_runs")
    _real_png(written[0])
    assert written[1].stat().st_size > 10_000
