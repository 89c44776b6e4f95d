"""The report's figures, PNG files under ``docs/figures/``, each drawn from numbers the sections
have already computed (the sections write the text that shows them)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import label

from qg_experiments.figures import pyplot
from qg_experiments.random_baselines import Bar

__all__ = ["COLORS", "random_steps", "learning_curves", "mean_q", "peg_learning", "q_spread",
           "smooth", "performance_profiles", "cell_means"]

#: One colour per algorithm in every figure.
COLORS = {"ddpg": "tab:orange", "qgddpg": "tab:blue"}


def _save(fig: Any, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)


def random_steps(rows: list[dict[str, Any]], cap: int, thesis_steps: float, path: Path) -> None:
    """Box plot of the random baselines' steps per episode, failures at ``cap``."""
    fig, ax = pyplot().subplots(figsize=(7, 3.5))
    ax.boxplot([np.minimum(r["steps"], cap) for r in rows], showmeans=True)
    ax.set_xticks(range(1, len(rows) + 1), [r["label"] for r in rows], rotation=15)
    ax.axhline(thesis_steps, color="gray", ls="--", lw=1,
               label=f"thesis: {thesis_steps:g} (real robot)")
    ax.set_ylabel("steps per episode")
    ax.set_title(f"Random residuals: steps to insertion (failures at the cap {cap})")
    ax.legend()
    _save(fig, path)


def learning_curves(chosen: dict[str, tuple[str, str, list[dict[str, Any]]]], n_train: int,
                    bar: Bar | None, path: Path) -> None:
    """Steps per episode (training, then test) of the chosen best and worst cells: the mean over
    seeds with the standard deviation of that mean shaded, as in the thesis.

    :param chosen: legend label -> (algorithm, ``best`` | ``worst``, the cell's runs).
    """
    fig, axes = pyplot().subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for ax, tag in zip(axes, ("best", "worst")):
        for name, (a, run_tag, runs) in chosen.items():
            if run_tag != tag or not runs:
                continue
            steps = np.array([[e["steps"] for e in r["episodes"]] for r in runs], dtype=float)
            mean = steps.mean(axis=0)
            sem = steps.std(axis=0) / math.sqrt(len(runs))
            x = np.arange(1, steps.shape[1] + 1)
            ax.plot(x, mean, color=COLORS[a], label=f"{name}, {len(runs)} seeds")
            ax.fill_between(x, mean - sem, mean + sem, color=COLORS[a], alpha=0.2)
        ax.axvline(n_train + 0.5, color="k", lw=1)
        ax.text(n_train + 0.7, 0.97, "test", transform=ax.get_xaxis_transform(), fontsize=8,
                va="top")
        if bar is not None:
            ax.axhline(bar.mean, color="gray", ls="--", lw=1,
                       label=f"random bar ({bar.label}, same seeds), 95 % CI shaded")
            ax.axhspan(bar.interval.low, bar.interval.high, color="gray", alpha=0.15)
        ax.set_xlabel("episode (training, then test)")
        ax.set_title(f"{tag} cell of each algorithm")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("steps per episode (failures at the cap)")
    _save(fig, path)


def mean_q(chosen: dict[str, tuple[str, str, list[dict[str, Any]]]],
           q_range: tuple[float, float], path: Path) -> None:
    """Each chosen run's mean predicted Q per training cycle, against the realisable range."""
    fig, ax = pyplot().subplots(figsize=(7, 4))
    for name, (a, tag, runs) in chosen.items():
        for i, run in enumerate(runs):
            q = [c["mean_q"] for c in run["cycles"]]
            ax.plot(range(1, len(q) + 1), q, color=COLORS[a], ls="-" if tag == "best" else ":",
                    label=name if i == 0 else None)
    ax.axhline(q_range[0], color="gray", lw=1, ls="--")
    ax.axhline(q_range[1], color="gray", lw=1, ls="--")
    ax.set_xlabel("training cycle")
    ax.set_ylabel("mean predicted Q of the cycle's minibatches")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_title(f"Mean Q; dashed: realisable range [{q_range[0]:g}, {q_range[1]:g}]")
    ax.legend(fontsize=8)
    _save(fig, path)


def smooth(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing moving average (``window`` = 1 leaves the values as they are)."""
    return np.convolve(values, np.ones(window) / window, mode="valid")


def peg_learning(curves: dict[tuple[str, float], dict[str, Any]], window: int,
                 path: Path, randoms: dict[str, dict[str, Any]] | None = None) -> None:
    """The peg's episode return per learning rate (``peg.learning_curves``), smoothed, with the
    random policies' (``peg.random_curves``) dashed in every panel."""
    lrs = sorted({k[1] for k in curves}, reverse=True)
    fig, axes = pyplot().subplots(1, len(lrs), figsize=(4 * len(lrs), 3.4), sharey=True,
                                  squeeze=False)
    for ax, lr in zip(axes[0], lrs):
        for (a, l), c in curves.items():
            if l != lr:
                continue
            mean, sem = smooth(c["return_mean"], window), smooth(c["return_sem"], window)
            x = np.arange(len(mean)) + window
            ax.plot(x, mean, color=COLORS[a], label=f"{label(a)}, {c['seeds']} seeds")
            ax.fill_between(x, mean - sem, mean + sem, color=COLORS[a], alpha=0.2)
        for (name, c), style in zip((randoms or {}).items(), ("--", ":"), strict=False):
            mean = smooth(c["return_mean"], window)
            ax.plot(np.arange(len(mean)) + window, mean, style, color="0.4", linewidth=1,
                    label=f"{name}, {c['seeds']} seeds")
        ax.set_title(f"lr {lr:g}")
        ax.set_xlabel("episode")
    axes[0][0].set_ylabel("episode return (mean ± s.e.)" + (
        f"\nmoving average of {window}" if window > 1 else ""))
    axes[0][0].legend(fontsize=8)
    _save(fig, path)


def q_spread(spread: dict[str, dict[tuple[str, float], np.ndarray]], path: Path,
             seeds: dict[tuple[str, float], int]) -> None:
    """Box plots of the std of Q across seeds per (algorithm, lr), one panel per set of points
    (``peg.Q_POINTS``: the given actions, the actor's), as thesis Fig. 8.3; ``seeds``: how many
    seeds each box is over (``peg.q_seeds``), under its name."""
    titles = {"given": "27 states x 11 given actions", "pi": "27 states, the actor's action"}
    fig, axes = pyplot().subplots(1, len(spread), figsize=(4.2 * len(spread), 3.5), sharey=True,
                                  squeeze=False)
    for ax, (points, boxes) in zip(axes[0], spread.items()):
        keys = sorted(boxes, key=lambda k: (-k[1], k[0]))
        ax.boxplot([boxes[k] for k in keys])
        ax.set_xticks(range(1, len(keys) + 1),
                      [f"{label(a)}\nlr {lr:g}\n{seeds[(a, lr)]} seeds" for a, lr in keys],
                      fontsize=8)
        ax.set_yscale("log")
        ax.set_title(titles.get(points, points), fontsize=9)
    axes[0][0].set_ylabel("std of final Q across seeds")
    _save(fig, path)


def performance_profiles(profiles: dict[str, dict[str, tuple[np.ndarray, ...]]],
                         taus: np.ndarray, path: Path) -> None:
    """One panel per setting: the fraction of runs needing at most tau test steps per episode,
    each algorithm with its pointwise 95 % band.

    :param profiles: setting -> algorithm -> (profile, low, high) over ``taus``.
    """
    fig, axes = pyplot().subplots(1, len(profiles), figsize=(3.2 * len(profiles), 3.2),
                                  sharey=True, squeeze=False)
    for ax, (setting, curves) in zip(axes[0], profiles.items()):
        for a, (profile, low, high) in curves.items():
            ax.plot(taus, profile, color=COLORS[a], label=label(a))
            ax.fill_between(taus, low, high, color=COLORS[a], alpha=0.2)
        ax.set_title(setting, fontsize=8)
        ax.set_xlabel("tau [test steps per episode]")
    axes[0][0].set_ylabel("fraction of runs with\nmean test steps <= tau")
    axes[0][0].legend(fontsize=7)
    _save(fig, path)


def cell_means(means: dict[str, dict[str, np.ndarray]], bar: Bar | None, path: Path) -> None:
    """Robustness as the thesis frames it: each cell's mean test steps, per setting and
    algorithm (a dot per cell, a bar at their mean), against the random bar.

    :param means: setting -> algorithm -> the cells' mean test steps.
    """
    fig, ax = pyplot().subplots(figsize=(1.6 + 1.4 * len(means), 3.6))
    offsets = {"qgddpg": -0.18, "ddpg": 0.18}
    for i, (setting, by_algorithm) in enumerate(means.items()):
        for a, values in by_algorithm.items():
            x = i + offsets.get(a, 0.0)
            ax.scatter(np.full(len(values), x), values, s=14, color=COLORS[a], alpha=0.8,
                       label=label(a) if i == 0 else None, zorder=3)
            ax.hlines(float(np.mean(values)), x - 0.12, x + 0.12, color=COLORS[a], lw=2)
    if bar is not None:
        ax.axhline(bar.mean, color="gray", ls="--", lw=1, label=f"random bar ({bar.label})")
    ax.set_xticks(range(len(means)), list(means), fontsize=7, rotation=15)
    ax.set_ylabel("mean test steps of a cell")
    ax.set_title("Mean test steps over the cells (dot: a cell; line: their mean)", fontsize=9)
    # Beside the axes: inside, the dots of a whole column would hide under it.
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    _save(fig, path)
