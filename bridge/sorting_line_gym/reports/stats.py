"""Interval estimates of the benchmark: IQM, stratified bootstrap confidence intervals, probability
of improvement and performance profiles, the method of rliable (Agarwal et al., *Deep RL at the
Edge of the Statistical Precipice*, NeurIPS 2021), on scipy.stats.

Why not rliable itself: it is archived, ships as an sdist only, and pulls in arch, statsmodels,
pandas 3 and seaborn (ten packages) for what scipy does with one wheel: ``scipy.stats.bootstrap``
given several samples with ``paired=False`` resamples each one independently, which *is* the
stratified bootstrap, and ``scipy.stats.trim_mean(x, 0.25)`` is the interquartile mean. This module
is only the thin layer that says what the strata and the statistics are.

Vocabulary (rliable's): a *run* is one training seed of an algorithm (a deterministic baseline has
one run); a *task* is what every run is scored on, and the strata of the bootstrap: one evaluation
seed within a cell, one line (setup x variant) in an aggregate over lines. Scores come as a
``runs x tasks`` array. The bootstrap resamples runs, independently per task, so an interval says
how much the figure would move with other training seeds on the same tasks; a single run is held
fixed (nothing to resample: its interval is the point itself).

No I/O and no ROS here: the unit tests run on known inputs without a node.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

CONFIDENCE = 0.95
RESAMPLES = 2000
#: Fixed, so a report redrawn from the same cells shows the same intervals.
BOOTSTRAP_SEED = 0


@dataclass(frozen=True)
class Interval:
    """A point estimate and its confidence interval."""

    point: float
    low: float
    high: float

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high

    def overlaps(self, other: Interval) -> bool:
        return self.low <= other.high and other.low <= self.high

    def as_dict(self) -> dict[str, float]:
        return {"point": self.point, "low": self.low, "high": self.high}


def iqm(scores, axis=None) -> float | np.ndarray:
    """Interquartile mean: the mean of the middle 50 % of the scores (all of them, flattened,
    when ``axis`` is None), as rliable defines it."""
    values = np.asarray(scores, dtype=float)
    if axis is None:
        values, axis = values.ravel(), 0
    return stats.trim_mean(values, 0.25, axis=axis)


def _runs_by_task(scores) -> np.ndarray:
    values = np.asarray(scores, dtype=float)
    if values.ndim != 2 or values.size == 0:
        raise ValueError(f"scores must be a non-empty runs x tasks array, got shape {values.shape}")
    return values


def stratified_bootstrap(
    strata: Sequence[np.ndarray],
    statistic: Callable[[np.ndarray], float | np.ndarray],
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> Interval:
    """Percentile interval of ``statistic`` under resampling every stratum independently.

    ``strata`` are 1-D arrays of per-run values; ``statistic(pooled)`` gets the strata joined
    along the last axis (with resamples stacked in front) and reduces that axis. A stratum of one
    value is held fixed; if all are, the interval is the point."""
    strata = [np.asarray(s, dtype=float).ravel() for s in strata]
    if not strata or any(s.size == 0 for s in strata):
        raise ValueError("every stratum needs at least one value")
    point = float(statistic(np.concatenate(strata)))
    free = [i for i, s in enumerate(strata) if s.size > 1]
    if not free:
        return Interval(point, point, point)

    def pooled(*resampled, axis=-1):
        batch = np.broadcast_shapes(*(r.shape[:-1] for r in resampled))
        parts, it = [], iter(resampled)
        for i, s in enumerate(strata):
            part = next(it) if i in free else s
            parts.append(np.broadcast_to(part, batch + part.shape[-1:]))
        return statistic(np.concatenate(parts, axis=-1))

    result = stats.bootstrap(
        tuple(strata[i] for i in free),
        pooled,
        n_resamples=resamples,
        vectorized=True,
        paired=False,
        confidence_level=confidence,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    low, high = result.confidence_interval
    # scipy gives nan when every resample is the same value: then that value is the interval.
    low = point if np.isnan(low) else float(low)
    high = point if np.isnan(high) else float(high)
    return Interval(point, min(low, point), max(high, point))


def _columns(scores: np.ndarray) -> list[np.ndarray]:
    return [scores[:, t] for t in range(scores.shape[1])]


def iqm_interval(scores, **kwargs) -> Interval:
    """IQM over all runs x tasks, with the stratified bootstrap interval over runs."""
    scores = _runs_by_task(scores)
    return stratified_bootstrap(_columns(scores), lambda x: iqm(x, axis=-1), **kwargs)


def mean_interval(scores, **kwargs) -> Interval:
    """Mean over all runs x tasks, with the stratified bootstrap interval over runs."""
    scores = _runs_by_task(scores)
    return stratified_bootstrap(_columns(scores), lambda x: np.mean(x, axis=-1), **kwargs)


def probability_of_improvement(x, y) -> float:
    """P(X > Y): the chance that a run of X beats a run of Y on a task, averaged over tasks
    (ties count half), from two ``runs x tasks`` arrays on the same tasks; per task it is the
    Mann-Whitney U of X against Y over the number of pairs."""
    x, y = _runs_by_task(x), _runs_by_task(y)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x and y must be scored on the same tasks: {x.shape[1]} vs {y.shape[1]}")
    return float(np.mean(_pairwise_wins(x, y)))


def _pairwise_wins(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per task (last axis of the result), the fraction of (run of x, run of y) pairs where x wins,
    ties half. x: (..., n, tasks), y: (..., m, tasks)."""
    diff = x[..., :, None, :] - y[..., None, :, :]
    return np.mean((diff > 0) + 0.5 * (diff == 0), axis=(-3, -2))


def probability_of_improvement_interval(x, y, **kwargs) -> Interval:
    """P(X > Y) with the stratified bootstrap interval: the runs of X and of Y are resampled
    independently within each task."""
    x, y = _runs_by_task(x), _runs_by_task(y)
    n, tasks = x.shape
    if y.shape[1] != tasks:
        raise ValueError(f"x and y must be scored on the same tasks: {tasks} vs {y.shape[1]}")
    m = y.shape[0]

    def statistic(pooled: np.ndarray) -> np.ndarray:
        # pooled: (..., tasks * n + tasks * m), x's strata first, a task's runs together.
        xs = pooled[..., : tasks * n].reshape(pooled.shape[:-1] + (tasks, n))
        ys = pooled[..., tasks * n :].reshape(pooled.shape[:-1] + (tasks, m))
        return np.mean(_pairwise_wins(np.swapaxes(xs, -1, -2), np.swapaxes(ys, -1, -2)), axis=-1)

    return stratified_bootstrap(_columns(x) + _columns(y), statistic, **kwargs)


def normalized(score, worst: float, best: float):
    """``(score - worst) / (best - worst)``: 0 at ``worst`` (the random agent), 1 at ``best``
    (the oracle), so lines with different reward scales can be pooled."""
    if not best > worst:
        raise ValueError(f"normalization needs best > worst, got best {best}, worst {worst}")
    return (np.asarray(score, dtype=float) - worst) / (best - worst)


def performance_profile(scores, thresholds) -> np.ndarray:
    """Fraction of all runs x tasks scoring above each threshold (rliable's score distribution)."""
    values = np.asarray(scores, dtype=float).ravel()
    return np.array([np.mean(values > t) for t in np.asarray(thresholds, dtype=float)])
