"""Which runs' critics diverged: the mean predicted Q against the realisable range of the rewards.

Predictions are not clipped (only the TD targets are), so fitting noise overshoots the range by a
few hundredths of it; the thesis's soft divergence runs away by many widths (Fig. 9.6). A run
therefore counts as diverged only beyond :data:`DIVERGENCE_FRACTION` of the range's width, and as
overshot below that.
"""
from __future__ import annotations

import math
from typing import Any

__all__ = ["DIVERGENCE_FRACTION", "divergence_margin", "split_by_excess", "run_excess",
           "run_divergence", "divergence_counts"]

#: Mean Q counts as diverged beyond the realisable range by more than this share of its width.
DIVERGENCE_FRACTION = 0.1


def divergence_margin(q_range: tuple[float, float]) -> float:
    """How far outside ``q_range`` a mean Q must go to count as diverged."""
    return DIVERGENCE_FRACTION * (q_range[1] - q_range[0])


def split_by_excess(excess: dict[str, float], q_range: tuple[float, float]
                    ) -> tuple[list[str], list[str]]:
    """Runs whose mean Q left ``q_range``: (diverged, overshot) names, each by growing excess.

    :param excess: per run, the largest distance of its mean Q outside the range (<= 0: inside).
    :param q_range: the realisable Q range of the rewards (lowest, highest).
    """
    margin = divergence_margin(q_range)
    ordered = sorted((n for n, e in excess.items() if e > 0), key=excess.get)
    return ([n for n in ordered if excess[n] > margin], [n for n in ordered if excess[n] <= margin])


def run_excess(result: dict[str, Any], gamma: float, r_min: float, r_max: float) -> float:
    """How far the run's mean Q went outside its realisable range (its own discount)."""
    g = result["spec"].get("gamma") or gamma
    low, high = min(r_min, r_min / (1 - g)), max(r_max, r_max / (1 - g))
    # The mean Q after each block of updates: a training cycle of the robot's runs, an episode
    # of the peg's (whose runs train after every episode and record no cycles).
    blocks = result["cycles"] if "cycles" in result else result["episodes"]
    return max((max(c["mean_q"] - high, low - c["mean_q"]) for c in blocks), default=-math.inf)


def run_divergence(result: dict[str, Any], gamma: float, r_min: float = -1.0,
                   r_max: float = 0.0) -> tuple[bool, bool]:
    """(diverged, overshot) of one run by :func:`split_by_excess`, against the range of its own
    discount."""
    g = result["spec"].get("gamma") or gamma
    q_range = (min(r_min, r_min / (1 - g)), max(r_max, r_max / (1 - g)))
    d, o = split_by_excess({"run": run_excess(result, gamma, r_min, r_max)}, q_range)
    return bool(d), bool(o)


def divergence_counts(results: list[dict[str, Any]], gamma: float, r_min: float = -1.0,
                      r_max: float = 0.0) -> dict[str, tuple[int, int, int]]:
    """Per algorithm: (diverged, overshot, runs) by :func:`run_divergence`."""
    counts = {}
    for a in sorted({r["spec"]["algorithm"] for r in results}):
        runs = [r for r in results if r["spec"]["algorithm"] == a and r["cycles"]]
        flags = [run_divergence(r, gamma, r_min, r_max) for r in runs]
        counts[a] = (sum(d for d, _ in flags), sum(o for _, o in flags), len(runs))
    return counts
