"""The statistics behind every table and figure of the report: intervals, the random bar, paired
tests. One module, so results, the peers' table and the plots count the same way.

What is independent: a learning run is one seed (its networks, its noise, its robot), and its 8
test episodes share all of that, so a cell's uncertainty is the spread of its **per-seed means**
(failed episodes counted at the test cap). A random baseline's episodes are independent draws, so
its interval is over episodes.

Which tools, and why: SciPy's ``stats.bootstrap`` (bias-corrected and accelerated, 10,000
resamples, a fixed generator so a report regenerates identically), ``stats.wilcoxon`` and
``stats.binomtest``. They are maintained, already pinned for the stack (no new dependency), and
cover what the report needs per cell. Within a cell the interval stays over its 5 per-seed means
(an interquartile mean of 5 values would drop the best and worst run and hide the failures the
report must show); over all cells of a setting, ``aggregates`` adds rliable's estimators
(Agarwal et al. 2021). Several settings judged at once are corrected with :func:`holm`, and
"no difference" is claimed only by an equivalence test (:func:`equivalence_p`).
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["CONFIDENCE", "Interval", "mean_interval", "beats", "PairedComparison",
           "paired_comparison", "PairedEvents", "paired_events", "format_interval", "holm",
           "equivalence_p", "pairs_to_detect", "VERDICTS", "verdict"]


def _scipy_stats():
    """``scipy.stats``, imported when a statistic is computed: it takes 0.65 s of CPU to load,
    and every worker that only runs a learning run imports this module with the run's spec."""
    from scipy import stats
    return stats


#: The confidence level of every interval in the report.
CONFIDENCE = 0.95
#: Bootstrap resamples: the interval's ends move by well under 1 % between generators.
RESAMPLES = 10_000


@dataclass(frozen=True)
class Interval:
    """A mean and its two-sided :data:`CONFIDENCE` bootstrap interval over ``n`` values."""
    mean: float
    low: float
    high: float
    n: int

    def as_dict(self) -> dict[str, float]:
        return {"mean": self.mean, "low": self.low, "high": self.high, "n": self.n}


def mean_interval(values: Sequence[float], seed: int = 0) -> Interval:
    """The mean of ``values`` with its BCa bootstrap interval.

    With one value, or all values equal, the interval is the point (nothing varies to resample);
    where BCa's acceleration is undefined (a sample with one outlier against ties, common with
    failures at the cap) the percentile interval is used instead.
    :param seed: of the resampling generator; fixed, so the same data give the same interval.
    """
    data = np.asarray(values, dtype=float)
    if data.ndim != 1 or data.size == 0 or not np.all(np.isfinite(data)):
        raise ValueError(f"need a non-empty 1-D sample of finite values, got {values!r}")
    mean = float(data.mean())
    if data.size == 1 or np.all(data == data[0]):
        return Interval(mean, mean, mean, int(data.size))
    for method in ("BCa", "percentile"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # BCa's degenerate-sample warning: handled below
            result = _scipy_stats().bootstrap((data,), np.mean, confidence_level=CONFIDENCE,
                                              n_resamples=RESAMPLES, method=method,
                                              random_state=np.random.default_rng(seed))
        low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
        if math.isfinite(low) and math.isfinite(high):
            return Interval(mean, min(low, mean), max(high, mean), int(data.size))
    raise RuntimeError(f"no bootstrap interval for {values!r}")  # pragma: no cover


def beats(interval: Interval, bar: float) -> bool:
    """Fewer steps than the random bar, beyond doubt: the interval's upper end is below it."""
    return interval.high < bar


@dataclass(frozen=True)
class PairedComparison:
    """Algorithm A against B on the same (cell, seed) pairs; lower values (steps) are better.

    :param difference: B minus A per pair, with its interval: positive means A needs fewer steps.
    :param wins_a: pairs where A needs fewer steps; ``wins_b`` the other way; ``ties`` equal.
    :param wilcoxon_p: two-sided Wilcoxon signed-rank p-value (zero differences dropped;
        1.0 when every pair ties).
    :param sign_p: two-sided sign test (binomial, ties dropped).
    """
    n: int
    difference: Interval
    wins_a: int
    wins_b: int
    ties: int
    wilcoxon_p: float
    sign_p: float

    def significant(self, level: float = 0.05) -> bool:
        """A is better than B at ``level`` (Wilcoxon two-sided, and in A's direction)."""
        return self.wilcoxon_p < level and self.difference.mean > 0.0

    def as_dict(self) -> dict[str, float]:
        return {"n": self.n, "difference": self.difference.as_dict(), "wins_a": self.wins_a,
                "wins_b": self.wins_b, "ties": self.ties, "wilcoxon_p": self.wilcoxon_p,
                "sign_p": self.sign_p}


def paired_comparison(a: Sequence[float], b: Sequence[float]) -> PairedComparison:
    """Compare paired samples ``a[i]``, ``b[i]`` (e.g. QG-DDPG's and DDPG's mean test steps of
    one cell and seed)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape or x.ndim != 1 or x.size == 0:
        raise ValueError(f"need two paired 1-D samples of one length, got {x.shape}, {y.shape}")
    diff = y - x
    wins_a, wins_b = int(np.sum(diff > 0)), int(np.sum(diff < 0))
    if wins_a + wins_b == 0:
        wilcoxon_p, sign_p = 1.0, 1.0
    else:
        wilcoxon_p = float(_scipy_stats().wilcoxon(x, y, zero_method="wilcox",
                                                  alternative="two-sided").pvalue)
        sign_p = float(_scipy_stats().binomtest(wins_a, wins_a + wins_b, 0.5).pvalue)
    return PairedComparison(n=int(x.size), difference=mean_interval(diff), wins_a=wins_a,
                            wins_b=wins_b, ties=int(x.size) - wins_a - wins_b,
                            wilcoxon_p=wilcoxon_p, sign_p=sign_p)


@dataclass(frozen=True)
class PairedEvents:
    """An event (a diverged critic, say) in A's and B's runs of the same (setting, cell, seed).

    :param only_a: pairs where A's run had the event and B's did not; ``only_b`` the reverse.
    :param both: pairs where both runs had it; ``neither`` where none did.
    :param p: two-sided exact McNemar test: the discordant pairs against a fair coin
        (``binomtest``); 1.0 without discordant pairs.
    """
    only_a: int
    only_b: int
    both: int
    neither: int
    p: float


def paired_events(a: Sequence[bool], b: Sequence[bool]) -> PairedEvents:
    """Compare how often an event happens in paired runs ``a[i]``, ``b[i]``. Only the pairs
    where exactly one run had it carry information (McNemar), so the test is on those."""
    x, y = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if x.shape != y.shape or x.ndim != 1 or x.size == 0:
        raise ValueError(f"need two paired 1-D samples of one length, got {x.shape}, {y.shape}")
    only_a, only_b = int(np.sum(x & ~y)), int(np.sum(~x & y))
    binomtest = _scipy_stats().binomtest
    p = 1.0 if only_a + only_b == 0 else float(binomtest(only_a, only_a + only_b, 0.5).pvalue)
    return PairedEvents(only_a=only_a, only_b=only_b, both=int(np.sum(x & y)),
                        neither=int(np.sum(~x & ~y)), p=p)


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of a family of p-values (in their given order): the k-th
    smallest is multiplied by (m - k + 1), made non-decreasing, capped at 1. Rejecting where the
    adjusted p is below the level keeps the family-wise error at that level."""
    p = np.asarray(pvalues, dtype=float)
    if p.ndim != 1 or np.any((p < 0) | (p > 1)):
        raise ValueError(f"need p-values in [0, 1], got {pvalues!r}")
    order = np.argsort(p, kind="stable")
    scaled = np.minimum(1.0, np.maximum.accumulate((len(p) - np.arange(len(p))) * p[order]))
    adjusted = np.empty_like(p)
    adjusted[order] = scaled
    return adjusted.tolist()


def equivalence_p(a: Sequence[float], b: Sequence[float], margin: float) -> float:
    """Two one-sided tests (TOST) that paired samples differ by less than ``margin``: the
    differences ``b - a`` are shifted by -margin and +margin and tested with one-sided Wilcoxon
    signed-rank tests (below zero, above zero); the larger p-value is the test's. A small p means
    the shift lies inside (-margin, margin) beyond doubt."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape or x.ndim != 1 or x.size == 0 or not margin > 0:
        raise ValueError("need two paired 1-D samples of one length and a margin > 0")
    d = y - x

    def one_sided(shifted: np.ndarray, alternative: str) -> float:
        if not np.any(shifted):            # every difference on the margin: not inside it
            return 1.0
        return float(_scipy_stats().wilcoxon(shifted, alternative=alternative).pvalue)
    return max(one_sided(d - margin, "less"), one_sided(d + margin, "greater"))


def pairs_to_detect(a: Sequence[float], b: Sequence[float], level: float = 0.05,
                    power: float = 0.8) -> tuple[float, float]:
    """How many pairs would detect the observed mean difference of ``b - a`` with a two-sided
    test at ``level`` and the given ``power``, and the differences' standard deviation, by the
    normal approximation n = ((z(1 - level/2) + z(power)) sd / mean)^2: what an undecided
    comparison would have needed, were the observed difference the true one (``inf`` for a mean
    of 0 or a single pair, whose spread is unknown: ``nan``)."""
    d = np.asarray(b, dtype=float) - np.asarray(a, dtype=float)
    if d.ndim != 1 or d.size == 0:
        raise ValueError("need paired 1-D samples")
    if d.size == 1:
        return math.inf, math.nan
    norm = _scipy_stats().norm
    sd, mean = float(np.std(d, ddof=1)), float(np.mean(d))
    if mean == 0.0:
        return math.inf, sd
    return ((norm.ppf(1 - level / 2) + norm.ppf(power)) * sd / mean) ** 2, sd


#: The verdicts of :func:`verdict`.
VERDICTS = ("A better", "B better", "equivalent", "undecided")


def verdict(difference: float, difference_p: float, equivalence: float,
            level: float = 0.05) -> str:
    """One of :data:`VERDICTS` for a paired comparison: a difference beyond doubt (its p below
    ``level``, the direction by the sign of ``difference`` = B minus A, positive when A needs
    fewer), else an equivalence beyond doubt (the TOST p below ``level``), else undecided. Pass
    multiplicity-adjusted p-values (:func:`holm`) when several settings are judged at once."""
    if difference_p < level:
        return VERDICTS[0] if difference > 0 else VERDICTS[1]
    return VERDICTS[2] if equivalence < level else VERDICTS[3]


def format_interval(interval: Interval, digits: int = 1) -> str:
    """``12.3 [8.1, 17.0]``."""
    return (f"{interval.mean:.{digits}f} [{interval.low:.{digits}f}, "
            f"{interval.high:.{digits}f}]")
