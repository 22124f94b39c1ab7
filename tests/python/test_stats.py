"""The benchmark's statistics (sorting_line_gym.reports.stats) on inputs whose answers are known.

No ROS: IQM, the stratified bootstrap, probability of improvement, normalization and performance
profiles are pure functions of arrays.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as scipy_stats

from sorting_line_gym.reports import stats


def test_iqm_is_the_mean_of_the_middle_half():
    assert stats.iqm([1, 2, 3, 4, 5, 6, 7, 8]) == pytest.approx(4.5)  # mean of 3, 4, 5, 6
    # The outliers are cut: the same middle half, whatever the tails do.
    assert stats.iqm([-1000, 2, 3, 4, 5, 6, 7, 1000]) == pytest.approx(4.5)
    # Runs x tasks are pooled, as rliable does.
    assert stats.iqm(np.array([[1, 2, 3, 4], [5, 6, 7, 8]])) == pytest.approx(4.5)
    assert stats.iqm([[2.0, 4.0, 4.0, 6.0]], axis=-1) == pytest.approx([4.0])


def test_a_single_run_or_identical_runs_give_a_point_interval():
    one_run = np.array([[3.0, 5.0, 7.0, 9.0]])
    assert stats.iqm_interval(one_run) == stats.Interval(6.0, 6.0, 6.0)
    same = np.tile(np.array([[1.0, 2.0, 3.0]]), (5, 1))
    interval = stats.mean_interval(same)
    assert (interval.low, interval.point, interval.high) == pytest.approx((2.0, 2.0, 2.0))


def test_the_bootstrap_resamples_within_strata_never_across():
    """Two tasks, one all 0, one all 1: a stratified resample always holds ten of each, so the
    pooled mean is exactly 0.5 in every resample (a plain bootstrap of the 20 values would move)."""
    scores = np.column_stack([np.zeros(10), np.ones(10)])
    interval = stats.mean_interval(scores)
    assert (interval.low, interval.point, interval.high) == (0.5, 0.5, 0.5)


def test_the_bootstrap_interval_has_the_width_theory_gives():
    """One task, 400 runs with mean 0 and std 1: the 95 % interval of the mean is about +- 1.96 / 20
    around 0."""
    runs = np.random.default_rng(7).normal(0.0, 1.0, size=(400, 1))
    runs = (runs - runs.mean()) / runs.std()
    interval = stats.mean_interval(runs)
    assert interval.point == pytest.approx(0.0, abs=1e-12)
    assert interval.low == pytest.approx(-1.96 / 20, rel=0.2) and interval.high == pytest.approx(1.96 / 20, rel=0.2)
    assert interval.high - interval.low == pytest.approx(2 * 1.96 / 20, rel=0.15)
    # Same seed, same interval: a report redrawn from the same cells does not change.
    assert stats.mean_interval(runs) == interval


def test_probability_of_improvement_on_known_inputs():
    better = np.array([[2.0, 3.0], [4.0, 5.0]])
    worse = np.array([[0.0, 1.0]])
    assert stats.probability_of_improvement(better, worse) == 1.0
    assert stats.probability_of_improvement(worse, better) == 0.0
    assert stats.probability_of_improvement(better, better) == 0.5  # ties count half
    # Against scipy's Mann-Whitney U: P(X > Y) = U / (n m) per task, averaged over tasks.
    rng = np.random.default_rng(3)
    x, y = rng.integers(0, 5, size=(6, 3)).astype(float), rng.integers(0, 5, size=(4, 3)).astype(float)
    expected = np.mean([scipy_stats.mannwhitneyu(x[:, t], y[:, t]).statistic / (6 * 4) for t in range(3)])
    assert stats.probability_of_improvement(x, y) == pytest.approx(expected)


def test_probability_of_improvement_interval():
    x = np.array([[1.0, 1.0], [3.0, 3.0]])  # one run below y, one above, on both tasks
    y = np.array([[2.0, 2.0]])
    interval = stats.probability_of_improvement_interval(x, y)
    assert interval.point == 0.5
    # Resampling x's two runs per task: each task gives 0, 0.5 or 1, the mean of two of them.
    assert 0.0 <= interval.low < 0.5 < interval.high <= 1.0
    assert stats.probability_of_improvement_interval(y, y) == stats.Interval(0.5, 0.5, 0.5)
    with pytest.raises(ValueError, match="same tasks"):
        stats.probability_of_improvement_interval(x, np.array([[1.0, 2.0, 3.0]]))


def test_normalization_and_performance_profile():
    assert stats.normalized([10.0, 20.0, 30.0], worst=10.0, best=30.0) == pytest.approx([0.0, 0.5, 1.0])
    with pytest.raises(ValueError, match="best > worst"):
        stats.normalized([1.0], worst=2.0, best=2.0)
    profile = stats.performance_profile([[0.1, 0.5], [0.9, 1.0]], [0.0, 0.5, 0.95])
    assert profile == pytest.approx([1.0, 0.5, 0.25])


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="runs x tasks"):
        stats.iqm_interval(np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="runs x tasks"):
        stats.mean_interval(np.zeros((0, 3)))
