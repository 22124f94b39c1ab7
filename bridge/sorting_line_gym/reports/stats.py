"""Interval estimates of the benchmark: IQM, bootstrap confidence intervals over whole runs,
probability of improvement and performance profiles, the method of rliable (Agarwal et al., *Deep
RL at the Edge of the Statistical Precipice*, NeurIPS 2021), on numpy and scipy.stats.

Why not rliable itself: it is archived, ships as an sdist only, and pulls in arch, statsmodels,
pandas 3 and seaborn (ten packages) for a percentile bootstrap and ``scipy.stats.trim_mean(x,
0.25)`` (the interquartile mean). This module is only the thin layer that says what is resampled.

Vocabulary (rliable's): a *run* is one training seed of an algorithm (a deterministic baseline has
one run); a *task* is what every run is scored on: one evaluation seed within a cell. Scores come
as a ``runs x tasks`` array. A *stratum* is a group of runs the bootstrap never mixes with another:
one line (setup x variant) in an aggregate over lines, one agent in a comparison of two agents.

What is resampled: **whole runs**. A resample draws a stratum's runs with replacement, and a drawn
run brings its scores on every task with it, so an interval says how much the figure would move
with other training seeds, and a run that is good (or bad) on every seed counts as one draw. The
earlier rule made each evaluation seed a stratum and drew the runs independently per seed; that
mixes one run's seed 1 with another's seed 2, and averages the spread between runs away by about
the square root of the number of seeds (PPO on B advanced: runs spread +-1.53, interval +-0.22).
A stratum of one run is held fixed (a deterministic baseline: nothing to resample); if every
stratum is, the interval is the point.

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
#: Resamples evaluated at once: bounds the memory of a statistic over (resamples, runs, tasks),
#: e.g. P(X > Y)'s pairs of runs (100 x 20 x 20 x 100 values), whatever the number of resamples.
_CHUNK = 100

#: A statistic of resampled strata: it gets one array per stratum, shaped (resamples, runs, tasks)
#: in the strata's order, and returns one value per resample.
Statistic = Callable[[list[np.ndarray]], np.ndarray]


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


def _stratum(runs) -> np.ndarray:
    """A stratum as runs x tasks; a 1-D array is one value per run (one task)."""
    values = np.asarray(runs, dtype=float)
    return _runs_by_task(values[:, None] if values.ndim == 1 else values)


def run_bootstrap(
    strata: Sequence,
    statistic: Statistic,
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> Interval:
    """Percentile interval of ``statistic`` when each stratum's runs (rows) are drawn with
    replacement, independently per stratum, a drawn run keeping all its tasks (columns).

    ``strata``: runs x tasks arrays (a 1-D array: one value per run). The point is the statistic
    of the strata as given. A stratum of one run is held fixed; if all are, the interval is the
    point."""
    groups = [_stratum(s) for s in strata]
    if not groups:
        raise ValueError("the bootstrap needs at least one stratum")
    if not 0 < confidence < 1 or resamples < 1:
        raise ValueError(f"confidence must be in (0, 1) and resamples >= 1, got {confidence}, {resamples}")
    point = float(np.asarray(statistic([g[None] for g in groups]))[0])
    free = [i for i, g in enumerate(groups) if g.shape[0] > 1]
    if not free:
        return Interval(point, point, point)
    rng = np.random.default_rng(seed)
    draws = {i: rng.integers(0, groups[i].shape[0], size=(resamples, groups[i].shape[0])) for i in free}
    values = np.empty(resamples)
    for start in range(0, resamples, _CHUNK):
        stop = min(resamples, start + _CHUNK)
        batch = [
            g[draws[i][start:stop]] if i in draws else np.broadcast_to(g, (stop - start, *g.shape))
            for i, g in enumerate(groups)
        ]
        values[start:stop] = statistic(batch)
    tail = 50 * (1 - confidence)
    low, high = np.percentile(values, [tail, 100 - tail])
    # The percentiles of a statistic whose resamples all equal the point may round off it by an ulp.
    return Interval(point, min(float(low), point), max(float(high), point))


def _pooled(batch: list[np.ndarray]) -> np.ndarray:
    """Every stratum's runs x tasks of each resample as one row: (resamples, all scores)."""
    return np.concatenate([b.reshape(b.shape[0], -1) for b in batch], axis=-1)


def _iqm_of(batch: list[np.ndarray]) -> np.ndarray:
    return np.asarray(iqm(_pooled(batch), axis=-1))


def _mean_of(batch: list[np.ndarray]) -> np.ndarray:
    return np.mean(_pooled(batch), axis=-1)


def iqm_interval(scores, **kwargs) -> Interval:
    """IQM over all runs x tasks, with the bootstrap interval over whole runs."""
    return run_bootstrap([_runs_by_task(scores)], _iqm_of, **kwargs)


def mean_interval(scores, **kwargs) -> Interval:
    """Mean over all runs x tasks, with the bootstrap interval over whole runs."""
    return run_bootstrap([_runs_by_task(scores)], _mean_of, **kwargs)


def iqm_interval_over_lines(lines: Sequence, **kwargs) -> Interval:
    """IQM over every line's runs x tasks pooled, with the bootstrap interval over whole runs
    stratified by line: each resample draws each line's runs from that line's own (``lines``:
    one runs x tasks array, or one value per run, per line)."""
    return run_bootstrap(list(lines), _iqm_of, **kwargs)


def mean_interval_over_lines(lines: Sequence, **kwargs) -> Interval:
    """Mean over every line's runs x tasks pooled, the interval as :func:`iqm_interval_over_lines`."""
    return run_bootstrap(list(lines), _mean_of, **kwargs)


def stratified_bootstrap(
    strata: Sequence[np.ndarray],
    statistic: Callable[[np.ndarray], float | np.ndarray],
    **kwargs,
) -> Interval:
    """Percentile interval of ``statistic`` when every value of a stratum is one run, the runs
    drawn with replacement within each stratum. ``statistic(pooled)`` gets the strata joined along
    the last axis (resamples stacked in front) and reduces that axis. (:func:`run_bootstrap` with
    one task per run; kept for callers of the earlier API.)"""
    return run_bootstrap(
        [np.asarray(s, dtype=float).ravel() for s in strata], lambda b: np.asarray(statistic(_pooled(b))), **kwargs
    )


def probability_of_improvement(x, y) -> float:
    """P(X > Y): the chance that a run of X beats a run of Y on a task, averaged over tasks
    (ties count half), from two ``runs x tasks`` arrays on the same tasks; per task it is the
    Mann-Whitney U of X against Y over the number of pairs."""
    x, y = _same_tasks(x, y)
    return float(np.mean(_pairwise_wins(x, y)))


def _same_tasks(x, y) -> tuple[np.ndarray, np.ndarray]:
    x, y = _runs_by_task(x), _runs_by_task(y)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x and y must be scored on the same tasks: {x.shape[1]} vs {y.shape[1]}")
    return x, y


def _pairwise_wins(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per task (last axis of the result), the fraction of (run of x, run of y) pairs where x wins,
    ties half. x: (..., n, tasks), y: (..., m, tasks)."""
    diff = x[..., :, None, :] - y[..., None, :, :]
    return np.mean((diff > 0) + 0.5 * (diff == 0), axis=(-3, -2))


def probability_of_improvement_interval(x, y, **kwargs) -> Interval:
    """P(X > Y) with the bootstrap interval over whole runs: X's runs and Y's are drawn
    independently (two strata), each run with its scores on every task."""
    x, y = _same_tasks(x, y)
    return run_bootstrap([x, y], lambda b: np.mean(_pairwise_wins(b[0], b[1]), axis=-1), **kwargs)


def normalized(score, worst: float, best: float):
    """``(score - worst) / (best - worst)``: 0 at ``worst`` (the random agent), 1 at ``best``
    (the oracle), so lines with different reward scales can be pooled."""
    if not best > worst:
        raise ValueError(f"normalization needs best > worst, got best {best}, worst {worst}")
    return (np.asarray(score, dtype=float) - worst) / (best - worst)


#: A task whose best score exceeds its worst by no more than this has no scale to normalize by:
#: there (score - worst) / (best - worst) is 0 / 0, or a difference of rounding blown up to any size.
DEGENERATE_SCALE = 1e-9


def normalized_per_task(scores, worst, best) -> tuple[np.ndarray, np.ndarray]:
    """Each task's scores normalized by that task's own ``worst`` (0) and ``best`` (1):
    ``(score - worst[t]) / (best[t] - worst[t])`` for a ``runs x tasks`` array and one ``worst``
    and ``best`` per task. Returns the normalized ``runs x kept tasks`` and the mask of the kept
    tasks: a task where ``best - worst <= DEGENERATE_SCALE`` is left out (it has no scale; every
    agent normalized by the same references leaves out the same tasks, so their tasks stay
    aligned). ``best < worst`` beyond that is refused: a best (the exact oracle) below the worst
    (the random agent) means the two were not scored on the same tasks."""
    values = _runs_by_task(scores)
    worst, best = np.asarray(worst, dtype=float), np.asarray(best, dtype=float)
    if worst.shape != (values.shape[1],) or best.shape != worst.shape:
        raise ValueError(
            f"worst and best need one value per task ({values.shape[1]}), got shapes {worst.shape}, {best.shape}"
        )
    scale = best - worst
    below = np.flatnonzero(scale < -DEGENERATE_SCALE)
    if below.size:
        t = below[0]
        raise ValueError(f"best {best[t]} is below worst {worst[t]} on task {t}: allowed best >= worst on every task")
    kept = scale > DEGENERATE_SCALE
    return (values[:, kept] - worst[kept]) / scale[kept], kept


def performance_profile(scores, thresholds) -> np.ndarray:
    """Fraction of all runs x tasks scoring above each threshold (rliable's score distribution)."""
    values = np.asarray(scores, dtype=float).ravel()
    return np.array([np.mean(values > t) for t in np.asarray(thresholds, dtype=float)])
