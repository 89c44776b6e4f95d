"""Aggregate statistics over the grid's cells, as Agarwal et al. (2021, "Deep RL at the edge of
the statistical precipice") recommend: the interquartile mean with stratified-bootstrap
intervals, the probability of improvement, and performance profiles.

Why: the per-cell table answers "how did this cell do"; a reviewer also asks "over all 8 cells,
which algorithm is better, and how sure are we", with 5 runs per cell. These estimators answer it
robustly: the interquartile mean (IQM) of all runs drops the best and worst quarter (a few runs
stuck at the step cap move it less than the mean), and the stratified bootstrap resamples the
runs within each cell, so every cell keeps its weight in every resample.

Why not rliable itself: ``rliable==1.2.0`` pulls ``arch``, ``statsmodels``, ``pandas`` and
``seaborn`` into the stack, and with today's releases (arch 7.2.0, pandas 3.1.1) ``import
rliable.library`` fails (``arch``'s ``deprecate_kwarg`` against pandas 3). The estimators are
a few lines of NumPy; ``tests/experiments/test_stats.py`` checks them against rliable's
published test values and against intervals rliable 1.2.0 computed (with pandas 2).

Conventions, as rliable's: a score matrix is ``runs x tasks`` (here: seeds x cells) and higher
is better; pass negated test steps (fewer steps is better). Intervals are percentile intervals
of :data:`RESAMPLES` bootstrap resamples from a fixed generator, so a report regenerates
identically.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from qg_experiments.stats import CONFIDENCE, RESAMPLES, Interval

__all__ = ["iqm", "stratified_interval", "probability_of_improvement",
           "improvement_interval", "performance_profile", "profile_band", "count_below"]

#: Resamples of a performance profile's band (rliable's default for profiles).
PROFILE_RESAMPLES = 2_000


def _matrix(scores: np.ndarray) -> np.ndarray:
    m = np.asarray(scores, dtype=float)
    if m.ndim != 2 or m.size == 0 or not np.all(np.isfinite(m)):
        raise ValueError(f"need a non-empty runs x tasks matrix of finite values, got {m.shape}")
    return m


def iqm(scores: np.ndarray) -> float:
    """Interquartile mean of every run of every task: the mean of the middle half (the 25 %
    trimmed mean of rliable's ``aggregate_iqm``)."""
    from scipy.stats import trim_mean
    return float(trim_mean(_matrix(scores), 0.25, axis=None))


def _iqm_rows(resampled: np.ndarray) -> np.ndarray:
    """IQM of each resample (``reps x runs x tasks``)."""
    from scipy.stats import trim_mean
    return trim_mean(resampled.reshape(len(resampled), -1), 0.25, axis=1)


def _resample(scores: np.ndarray, reps: int, rng: np.random.Generator) -> np.ndarray:
    """``reps`` stratified resamples: each task's runs drawn with replacement, independently per
    task (rliable's ``StratifiedBootstrap`` without task bootstrap)."""
    runs, tasks = scores.shape
    rows = rng.integers(0, runs, size=(reps, runs, tasks))
    return scores[rows, np.arange(tasks)]


def _percentiles(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    tail = 100 * (1 - CONFIDENCE) / 2
    low, high = np.percentile(values, [tail, 100 - tail], axis=0)
    return low, high


def stratified_interval(scores: np.ndarray,
                        statistic: Callable[[np.ndarray], np.ndarray] = _iqm_rows,
                        reps: int = RESAMPLES, seed: int = 0) -> Interval:
    """A statistic of ``scores`` (runs x tasks) with its stratified-bootstrap percentile
    interval; the default statistic is the IQM.

    :param statistic: maps ``reps x runs x tasks`` resamples to ``reps`` values (vectorised).
    """
    m = _matrix(scores)
    point = float(statistic(m[None])[0])
    low, high = _percentiles(statistic(_resample(m, reps, np.random.default_rng(seed))))
    return Interval(point, min(float(low), point), max(float(high), point), int(m.size))


def _improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y) averaged over tasks, ties counting half, for stacked resamples
    (``reps x runs x tasks``): the Mann-Whitney U statistic over ``n_x * n_y`` per task."""
    greater = (x[:, :, None, :] > y[:, None, :, :]).mean(axis=(1, 2))
    ties = (x[:, :, None, :] == y[:, None, :, :]).mean(axis=(1, 2))
    return (greater + 0.5 * ties).mean(axis=1)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """The probability that a run of X scores higher than a run of Y on the same task, averaged
    over tasks (rliable's ``probability_of_improvement``; X and Y may have different numbers of
    runs, the same tasks)."""
    a, b = _matrix(x), _matrix(y)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"X and Y need the same tasks, got {a.shape} and {b.shape}")
    return float(_improvement(a[None], b[None])[0])


def improvement_interval(x: np.ndarray, y: np.ndarray, reps: int = RESAMPLES,
                         seed: int = 0) -> Interval:
    """:func:`probability_of_improvement` with its interval: X's and Y's runs resampled
    independently within each task (rliable's ``StratifiedIndependentBootstrap``)."""
    a, b = _matrix(x), _matrix(y)
    point = probability_of_improvement(a, b)
    rng = np.random.default_rng(seed)
    values = np.concatenate([_improvement(_resample(a, n, rng), _resample(b, n, rng))
                             for n in _chunks(reps)])
    low, high = _percentiles(values)
    return Interval(point, min(float(low), point), max(float(high), point), int(a.size))


def _chunks(reps: int, size: int = 1_000) -> list[int]:
    """``reps`` in chunks of at most ``size`` (the pairwise comparisons of a chunk stay small)."""
    return [size] * (reps // size) + ([reps % size] if reps % size else [])


def performance_profile(scores: np.ndarray, taus: Sequence[float]) -> np.ndarray:
    """The fraction of runs (over all tasks) scoring above each threshold in ``taus``
    (rliable's score distribution, ``create_performance_profile``)."""
    m = _matrix(scores)
    return (m.reshape(-1)[None, :] > np.asarray(taus, dtype=float)[:, None]).mean(axis=1)


def profile_band(scores: np.ndarray, taus: Sequence[float], reps: int = PROFILE_RESAMPLES,
                 seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`performance_profile` with its pointwise stratified-bootstrap interval:
    (profile, low, high), one value per threshold."""
    m = _matrix(scores)
    t = np.asarray(taus, dtype=float)
    resampled = _resample(m, reps, np.random.default_rng(seed)).reshape(reps, -1)
    low, high = _percentiles((resampled[:, None, :] > t[None, :, None]).mean(axis=2))
    return performance_profile(m, t), low, high


def count_below(scores: np.ndarray, bar: float, reps: int = RESAMPLES,
                seed: int = 0) -> Interval:
    """How many tasks' mean score lies below ``bar`` (e.g. cells whose mean test steps beat the
    random bar), with its stratified-bootstrap interval over the runs of each task."""
    m = _matrix(scores)

    def below(resampled: np.ndarray) -> np.ndarray:
        return (resampled.mean(axis=1) < bar).sum(axis=1).astype(float)
    return stratified_interval(m, below, reps, seed)
