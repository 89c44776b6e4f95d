"""Experiments 2-4: the learning-rate x iterations grid, mean Q over training, and variants.

Cells are (critic learning rate, training iterations per cycle); in each, vanilla DDPG and QG-DDPG
train for a number of episodes and are then tested without noise. A cell "beats random" when the
95 % interval of its mean test steps (failures counted at the test cap; one mean per seed) lies
below the best random baseline's mean steps (``stats``). Experiment 4 reruns fixed cells with one
setting changed (the sparse reward, a small replay, another discount), both algorithms on the
same seeds, so every (cell, seed) is a pair for the paired comparison.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from qg_experiments import stats
from qg_experiments.profile import GridBudget, VariantBudget
from qg_experiments.run_spec import RunSpec

__all__ = ["grid_specs", "pair_key", "paired_values", "variant_specs", "cell_table",
           "test_steps", "seed_means", "pairs", "variant_name", "by_variant", "score_matrices",
           "graph_diagnostics"]

#: A per-run value compared between the two algorithms' runs of a pair.
T = TypeVar("T")


def grid_specs(budget: GridBudget, estimator: str = "ekf", config_dir: str | None = None,
               arm: str = "realistic", experiment: str = "grid") -> list[RunSpec]:
    """Every (cell, algorithm, seed) run of the grid."""
    return [RunSpec(algorithm=algorithm, critic_lr=float(lr), iterations=int(iterations),
                    seed=seed, train_episodes=budget.train_episodes,
                    test_episodes=budget.test_episodes, train_max_steps=budget.train_max_steps,
                    test_max_steps=budget.test_max_steps, cycle_steps=budget.cycle_steps,
                    estimator=estimator, config_dir=config_dir, observation=budget.observation,
                    arm=arm, experiment=experiment, stall_recovery=budget.stall_recovery)
            for lr, iterations in budget.cells for algorithm in budget.algorithms
            for seed in budget.seeds]


def variant_specs(grid: GridBudget, variants: VariantBudget, estimator: str = "ekf",
                  config_dir: str | None = None, arm: str = "realistic") -> list[RunSpec]:
    """Every (setting, cell, algorithm, seed) run of experiment 4: the grid's protocol at the
    variants' cells with the setting's fields changed."""
    cells = dataclasses.replace(grid, cells=variants.cells, seeds=variants.seeds)
    return [dataclasses.replace(spec, experiment="variants", **changes)
            for _, changes in variants.overrides()
            for spec in grid_specs(cells, estimator, config_dir, arm)]


def variant_name(spec: dict[str, Any], default_gamma: float) -> str:
    """Which setting a variant run changed, from its spec: ``sparse``, ``replay 300``, ..."""
    parts = []
    if spec.get("reward", "dense") != "dense":
        parts.append(f"{spec['reward']} reward")
    if spec.get("replay_capacity"):
        parts.append(f"replay {spec['replay_capacity']}")
    if spec.get("gamma") is not None and spec["gamma"] != default_gamma:
        parts.append(f"gamma {spec['gamma']:g}")
    if spec.get("observation"):
        parts.append(f"state {spec['observation']}")
    return ", ".join(parts) or "the grid's settings"


def by_variant(results: list[dict[str, Any]], default_gamma: float
               ) -> dict[str, list[dict[str, Any]]]:
    """``results`` grouped by the setting they changed (:func:`variant_name`), by name."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault(variant_name(r["spec"], default_gamma), []).append(r)
    return dict(sorted(groups.items()))


def test_steps(result: dict[str, Any]) -> list[int]:
    """Steps of the test episodes of one run (a failed episode counts its cap)."""
    return [e["steps"] for e in result["episodes"] if e["mode"] == "test"]


def seed_means(group: list[dict[str, Any]]) -> dict[int, float]:
    """Per seed, the mean test steps of that seed's run: the independent unit of a cell."""
    return {r["spec"]["seed"]: float(np.mean(test_steps(r))) for r in group if test_steps(r)}


def pair_key(spec: dict[str, Any]) -> tuple:
    """What two algorithms' runs share when they are a pair: cell, setting and seed."""
    return (spec["critic_lr"], spec["iterations"], spec["reward"], spec["replay_capacity"],
            spec.get("gamma"), spec.get("observation"), spec["seed"])


def paired_values(results: list[dict[str, Any]], value: Callable[[dict[str, Any]], T | None],
                  a: str = "qgddpg", b: str = "ddpg") -> tuple[list[T], list[T], list[tuple]]:
    """``value(run)`` of ``a``'s and ``b``'s runs on the same (cell, setting, seed), aligned,
    and the pairs' keys; a run whose value is None (nothing to compare) has no pair."""
    runs: dict[tuple, dict[str, T]] = {}
    for r in results:
        v = value(r)
        if v is not None:
            runs.setdefault(pair_key(r["spec"]), {})[r["spec"]["algorithm"]] = v
    keys = sorted((k for k, v in runs.items() if a in v and b in v), key=str)
    return [runs[k][a] for k in keys], [runs[k][b] for k in keys], keys


def pairs(results: list[dict[str, Any]], a: str = "qgddpg", b: str = "ddpg"
          ) -> tuple[list[float], list[float], list[tuple]]:
    """Per-seed mean test steps of ``a`` and ``b`` on the same (cell, setting, seed), aligned:
    the pairs of the paired comparison, and their keys."""
    return paired_values(
        results, lambda r: float(np.mean(test_steps(r))) if test_steps(r) else None, a, b)


def score_matrices(results: list[dict[str, Any]], a: str = "qgddpg", b: str = "ddpg"
                   ) -> tuple[np.ndarray, np.ndarray, list[tuple[float, int]], list[int]]:
    """Per-run mean test steps of ``a`` and ``b`` as seeds x cells matrices (the aggregates'
    runs x tasks), over the cells both ran and the seeds every one of those cells has for both;
    an unfinished profile's complete part. Also the cells and seeds, in the matrices' order."""
    steps: dict[tuple[str, tuple[float, int], int], float] = {}
    for r in results:
        s = r["spec"]
        if test_steps(r):
            steps[(s["algorithm"], (s["critic_lr"], s["iterations"]), s["seed"])] = float(
                np.mean(test_steps(r)))
    ran = {(x, c) for (x, c, _) in steps}
    cells = sorted({c for (_, c, _) in steps if (a, c) in ran and (b, c) in ran})
    seeds = sorted(seed for seed in {k[2] for k in steps}
                   if all((x, c, seed) in steps for x in (a, b) for c in cells))

    def matrix(x: str) -> np.ndarray:
        return np.array([[steps[(x, c, seed)] for c in cells] for seed in seeds], dtype=float)
    return matrix(a), matrix(b), cells, seeds


def graph_diagnostics(group: list[dict[str, Any]]) -> dict[str, float]:
    """What the bounds did in these runs: the share of TD targets a lower bound raised (mean
    over all training cycles) and the critic's final mean |Q - Monte-Carlo return| on the
    goal-reaching training episodes (``critic_check.MonteCarloCheck``), averaged over runs."""
    raised = [c["frac_raised_lower"] for r in group for c in r["cycles"]
              if "frac_raised_lower" in c]
    errors = [next((c["critic_mc_error"] for c in reversed(r["cycles"])
                    if np.isfinite(c.get("critic_mc_error", np.nan))), np.nan) for r in group]
    errors = [e for e in errors if np.isfinite(e)]
    return {"targets_raised": float(np.mean(raised)) if raised else float("nan"),
            "critic_mc_error": float(np.mean(errors)) if errors else float("nan")}


def cell_table(results: list[dict[str, Any]], random_bar: float | None) -> list[dict[str, Any]]:
    """One row per (algorithm, cell, setting): mean test steps over seeds and episodes, with the
    95 % interval over the per-seed means."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in results:
        s = r["spec"]
        key = (s["algorithm"], s["critic_lr"], s["iterations"], s["reward"], s["replay_capacity"],
               s.get("gamma"), s.get("observation"))
        groups.setdefault(key, []).append(r)
    rows = []
    for (algorithm, lr, iterations, reward, capacity, gamma, observation), group in sorted(
            groups.items(), key=lambda item: str(item[0])):
        steps = np.array([n for r in group for n in test_steps(r)], dtype=float)
        successes = [e["success"] for r in group for e in r["episodes"] if e["mode"] == "test"]
        train = [e for r in group for e in r["episodes"] if e["mode"] == "train"]
        per_seed = seed_means(group)
        interval = stats.mean_interval(list(per_seed.values())) if per_seed else None
        mean = float(steps.mean()) if steps.size else float("nan")
        rows.append({"algorithm": algorithm, "critic_lr": lr, "iterations": iterations,
                     "reward": reward, "replay_capacity": capacity, "gamma": gamma,
                     "observation": observation, "seeds": len(group),
                     "mean_test_steps": mean,
                     "ci_low": interval.low if interval else float("nan"),
                     "ci_high": interval.high if interval else float("nan"),
                     "seed_means": [round(per_seed[k], 2) for k in sorted(per_seed)],
                     "test_failures": int(sum(not s for s in successes)),
                     "test_episodes": len(successes),
                     "test_success_rate": float(np.mean(successes)) if successes else 0.0,
                     "train_success_rate": float(np.mean([e["success"] for e in train]))
                     if train else 0.0,
                     "beats_random": bool(random_bar is not None and interval is not None
                                          and stats.beats(interval, random_bar)),
                     "final_mean_q": float(np.mean([r["cycles"][-1]["mean_q"] for r in group
                                                    if r["cycles"]] or [np.nan])),
                     **graph_diagnostics(group),
                     "wall_time": float(sum(r["wall_time"] for r in group))})
    return rows


