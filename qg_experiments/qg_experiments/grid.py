"""Experiments 2-4: the learning-rate x iterations grid, mean Q over training, and variants.

Cells are (critic learning rate, training iterations per cycle); in each, vanilla DDPG and QG-DDPG
train for a number of episodes and are then tested without noise. A cell "beats random" when its
mean test steps (failures counted at the test cap) are below the best random baseline's mean
steps. Experiment 4 reruns each algorithm's best cell with the sparse reward or a small replay.
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from qg_experiments.profile import GridBudget, VariantBudget
from qg_experiments.runner import RunSpec

__all__ = ["grid_specs", "variant_specs", "cell_table", "best_cells", "test_steps"]


def grid_specs(budget: GridBudget, estimator: str = "ekf",
               config_dir: str | None = None) -> list[RunSpec]:
    """Every (cell, algorithm, seed) run of the grid."""
    return [RunSpec(algorithm=algorithm, critic_lr=float(lr), iterations=int(iterations),
                    seed=seed, train_episodes=budget.train_episodes,
                    test_episodes=budget.test_episodes, train_max_steps=budget.train_max_steps,
                    test_max_steps=budget.test_max_steps, cycle_steps=budget.cycle_steps,
                    estimator=estimator, config_dir=config_dir, observation=budget.observation)
            for lr, iterations in budget.cells for algorithm in budget.algorithms
            for seed in budget.seeds]


def variant_specs(grid: GridBudget, variants: VariantBudget, best: dict[str, tuple[float, int]],
                  estimator: str = "ekf", config_dir: str | None = None) -> list[RunSpec]:
    """Sparse-reward and small-replay runs at each algorithm's ``best`` (lr, iterations) cell."""
    base = {s.algorithm: s for s in grid_specs(dataclasses.replace(grid, seeds=variants.seeds[:1]),
                                               estimator, config_dir)}
    specs = []
    for algorithm, (lr, iterations) in sorted(best.items()):
        cell = dataclasses.replace(base[algorithm], critic_lr=lr, iterations=iterations,
                                   experiment="variants")
        for seed in variants.seeds:
            specs += [dataclasses.replace(cell, seed=seed, reward=r) for r in variants.rewards]
            specs += [dataclasses.replace(cell, seed=seed, replay_capacity=c)
                      for c in variants.replay_capacities]
    return specs


def test_steps(result: dict[str, Any]) -> list[int]:
    """Steps of the test episodes of one run (a failed episode counts its cap)."""
    return [e["steps"] for e in result["episodes"] if e["mode"] == "test"]


def cell_table(results: list[dict[str, Any]], random_bar: float | None) -> list[dict[str, Any]]:
    """One row per (algorithm, cell, reward, replay): mean test steps over seeds and episodes."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in results:
        s = r["spec"]
        key = (s["algorithm"], s["critic_lr"], s["iterations"], s["reward"], s["replay_capacity"])
        groups.setdefault(key, []).append(r)
    rows = []
    for (algorithm, lr, iterations, reward, capacity), group in sorted(groups.items()):
        steps = np.array([n for r in group for n in test_steps(r)], dtype=float)
        successes = [e["success"] for r in group for e in r["episodes"] if e["mode"] == "test"]
        train = [e for r in group for e in r["episodes"] if e["mode"] == "train"]
        mean = float(steps.mean()) if steps.size else float("nan")
        rows.append({"algorithm": algorithm, "critic_lr": lr, "iterations": iterations,
                     "reward": reward, "replay_capacity": capacity, "seeds": len(group),
                     "mean_test_steps": mean,
                     "test_success_rate": float(np.mean(successes)) if successes else 0.0,
                     "train_success_rate": float(np.mean([e["success"] for e in train]))
                     if train else 0.0,
                     "beats_random": bool(random_bar is not None and mean < random_bar),
                     "final_mean_q": float(np.mean([r["cycles"][-1]["mean_q"] for r in group
                                                    if r["cycles"]] or [np.nan])),
                     "wall_time": float(sum(r["wall_time"] for r in group))})
    return rows


def best_cells(rows: list[dict[str, Any]]) -> dict[str, tuple[float, int]]:
    """Each algorithm's (critic_lr, iterations) with the fewest mean test steps (dense, default)."""
    best: dict[str, dict[str, Any]] = {}
    for row in rows:
        if row["reward"] != "dense" or row["replay_capacity"] is not None:
            continue
        if row["algorithm"] not in best or row["mean_test_steps"] < best[row["algorithm"]][
                "mean_test_steps"]:
            best[row["algorithm"]] = row
    return {a: (r["critic_lr"], r["iterations"]) for a, r in best.items()}
