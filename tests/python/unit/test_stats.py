"""The benchmark's statistics (sorting_line_gym.reports.stats) on inputs whose answers are known.

No ROS: IQM, the bootstrap over whole runs (stratified by line in an aggregate), probability of
improvement, normalization and performance profiles are pure functions of arrays.
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


def test_a_drawn_run_brings_all_its_tasks():
    """Two tasks, every run scoring 0 on one and 1 on the other: whichever runs a resample draws,
    it holds as many 0s as 1s, so the pooled mean is exactly 0.5 in every resample (a bootstrap of
    the 20 values one by one would move)."""
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


def test_normalization_and_performance_profile():
    assert stats.normalized([10.0, 20.0, 30.0], worst=10.0, best=30.0) == pytest.approx([0.0, 0.5, 1.0])
    with pytest.raises(ValueError, match="best > worst"):
        stats.normalized([1.0], worst=2.0, best=2.0)
    profile = stats.performance_profile([[0.1, 0.5], [0.9, 1.0]], [0.0, 0.5, 0.95])
    assert profile == pytest.approx([1.0, 0.5, 0.25])


def test_normalization_per_task_and_the_tasks_without_a_scale():
    """Each task by its own worst (0) and best (1); a task where best == worst has no scale and is left
    out (mask False), whatever the scores on it; a best below the worst is refused."""
    scores = np.array([[1.0, 2.0, 3.0], [3.0, 9.0, 5.0]])
    values, kept = stats.normalized_per_task(scores, worst=[1.0, 2.0, 3.0], best=[3.0, 2.0, 7.0])
    assert kept.tolist() == [True, False, True]
    assert values.tolist() == [[0.0, 0.0], [1.0, 0.5]]
    # Within the rounding threshold is no scale either; no scale anywhere leaves no task.
    values, kept = stats.normalized_per_task(scores, worst=[1.0, 2.0, 3.0], best=[1.0, 2.0 + 1e-12, 3.0])
    assert values.shape == (2, 0) and not kept.any()
    with pytest.raises(ValueError, match="best 0.5 is below worst 1.0 on task 0"):
        stats.normalized_per_task(scores, worst=[1.0, 2.0, 3.0], best=[0.5, 3.0, 4.0])
    with pytest.raises(ValueError, match="one value per task"):
        stats.normalized_per_task(scores, worst=[1.0], best=[2.0])


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="runs x tasks"):
        stats.iqm_interval(np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="runs x tasks"):
        stats.mean_interval(np.zeros((0, 3)))


# Intervals over whole runs: inputs whose bootstrap distribution is known exactly.

#: Five runs that differ by a constant on every evaluation seed (a good run is good on all of them).
OFFSETS = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])


def _offset_runs(tasks: int = 100) -> np.ndarray:
    seeds = np.random.default_rng(11).normal(20.0, 4.0, size=tasks)  # what each evaluation seed allows
    return seeds[None, :] + OFFSETS[:, None]


def _exact_bootstrap_of_the_mean_offset() -> tuple[float, float]:
    """The 2.5 % and 97.5 % points of the mean of 5 offsets drawn with replacement: all 5^5 draws."""
    draws = np.array(np.meshgrid(*[OFFSETS] * 5, indexing="ij")).reshape(5, -1)
    low, high = np.percentile(draws.mean(axis=0), [2.5, 97.5])
    return float(low), float(high)


def _per_seed_strata_interval(scores: np.ndarray) -> tuple[float, float]:
    """The earlier rule, for comparison: runs drawn independently within each evaluation seed."""
    rng = np.random.default_rng(0)
    runs, tasks = scores.shape
    picks = rng.integers(0, runs, size=(2000, runs, tasks))
    means = scores[picks, np.arange(tasks)].mean(axis=(1, 2))
    low, high = np.percentile(means, [2.5, 97.5])
    return float(low), float(high)


def test_runs_that_differ_by_a_constant_give_an_interval_as_wide_as_their_spread():
    """The mean over runs x seeds is the seeds' mean plus the mean of the runs' offsets, so its
    bootstrap over whole runs is exactly the bootstrap of 5 offsets: +-1.2 here. Drawing runs per
    seed instead mixes a good run's seed with a bad run's next one and gives about a tenth of it."""
    scores = _offset_runs()
    base = scores.mean()
    exact_low, exact_high = _exact_bootstrap_of_the_mean_offset()
    interval = stats.mean_interval(scores)
    assert interval.point == pytest.approx(base)
    assert interval.low - base == pytest.approx(exact_low, abs=0.25)
    assert interval.high - base == pytest.approx(exact_high, abs=0.25)
    old_low, old_high = _per_seed_strata_interval(scores)
    assert interval.high - interval.low > 5 * (old_high - old_low)
    # The IQM moves with the runs the same way (the seeds' spread, 4, is much wider than the runs').
    iqm = stats.iqm_interval(scores)
    assert iqm.high - iqm.low == pytest.approx(exact_high - exact_low, rel=0.35)
    assert iqm.high - iqm.low > 5 * (old_high - old_low)


def test_probability_of_improvement_over_whole_runs_on_an_analytic_case():
    """X's two runs score 1 and 3 on every seed, Y's one run 2. A resample of X holds both low runs
    (P = 0, chance 1/4), one of each (P = 0.5, 1/2) or both high (P = 1, 1/4): the interval is
    [0, 1]. Resampled per seed, the 100 seeds' draws would average out to about 0.5 +- 0.1."""
    x = np.vstack([np.full(100, 1.0), np.full(100, 3.0)])
    y = np.full((1, 100), 2.0)
    assert stats.probability_of_improvement_interval(x, y) == stats.Interval(0.5, 0.0, 1.0)
    assert stats.probability_of_improvement_interval(y, x) == stats.Interval(0.5, 0.0, 1.0)
    assert stats.probability_of_improvement_interval(y, y) == stats.Interval(0.5, 0.5, 0.5)
    with pytest.raises(ValueError, match="same tasks"):
        stats.probability_of_improvement_interval(x, np.array([[1.0, 2.0, 3.0]]))


def test_probability_of_improvement_of_two_normal_populations():
    """Runs of X ~ N(1, 1) against runs of Y ~ N(0, 1), one task: P(X > Y) = Phi(1 / sqrt 2) = 0.760;
    with 120 runs a side the interval holds it and is about +-0.06 (the Mann-Whitney AUC's error)."""
    # The populations' quantiles (not random draws), so the sample's P is the population's to 0.01.
    y = scipy_stats.norm.ppf((np.arange(120) + 0.5) / 120)[:, None]
    x = y + 1.0
    truth = scipy_stats.norm.cdf(1 / np.sqrt(2))
    interval = stats.probability_of_improvement_interval(x, y)
    assert interval.point == pytest.approx(stats.probability_of_improvement(x, y))
    assert interval.point == pytest.approx(truth, abs=0.01) and interval.contains(truth)
    assert 0.06 < interval.high - interval.low < 0.18


def test_an_aggregate_over_lines_draws_each_lines_runs_from_that_line():
    """Line A's two runs score 0 and 2, line B's one run 100. A resample always holds two runs of A
    and B's run: the pooled mean is (a + a' + 100) / 3, from 100/3 (both A runs the low one, chance
    1/4) to 104/3 (1/4). Drawing the three runs as one pool would reach 0 and 100."""
    lines = [np.array([0.0, 2.0]), np.array([100.0])]
    interval = stats.mean_interval_over_lines(lines)
    assert (interval.point, interval.low, interval.high) == pytest.approx((34.0, 100 / 3, 104 / 3))
    pooled = stats.mean_interval(np.array([[0.0], [2.0], [100.0]]))
    assert pooled.low < 10 and pooled.high > 60
    # Lines of runs x seeds, with other numbers of runs and seeds: each line keeps its own counts.
    lines = [np.zeros((2, 3)), np.ones((3, 5))]
    assert stats.mean_interval_over_lines(lines) == stats.Interval(15 / 21, 15 / 21, 15 / 21)
    iqm = stats.iqm_interval_over_lines([np.array([1.0, 2.0, 3.0, 4.0]), np.array([5.0])])
    assert iqm.point == pytest.approx(3.0) and iqm.low < iqm.point < iqm.high
    # The earlier API: one value per run in each stratum, the same bootstrap.
    same = stats.stratified_bootstrap([np.array([0.0, 2.0]), np.array([100.0])], lambda v: np.mean(v, axis=-1))
    assert same == stats.mean_interval_over_lines([np.array([0.0, 2.0]), np.array([100.0])])


def test_single_runs_stay_a_point_and_the_bootstrap_refuses_nonsense():
    rba_hold = np.array([[1.0, 5.0, 2.0, 8.0]])  # a deterministic baseline: one run, exact on its seeds
    assert stats.mean_interval(rba_hold) == stats.Interval(4.0, 4.0, 4.0)
    assert stats.mean_interval_over_lines([rba_hold, np.array([[3.0, 3.0]])]) == stats.Interval(11 / 3, 11 / 3, 11 / 3)
    with pytest.raises(ValueError, match="at least one stratum"):
        stats.run_bootstrap([], lambda b: np.zeros(1))
    with pytest.raises(ValueError, match="runs x tasks"):
        stats.mean_interval_over_lines([np.zeros((2, 2, 2))])
    with pytest.raises(ValueError, match="confidence"):
        stats.mean_interval(np.zeros((3, 2)), confidence=1.5)
