"""Sections 5 and 6 of ``docs/results.md``: the clearance-fit peg, free and on the simulated
Nextage; learning curves, the spread of Q across seeds, and the paired late-episode return."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import label

from qg_experiments import peg, stats
from qg_experiments.profile import PegBudget
from qg_experiments.report import plots
from qg_experiments.report.markdown import fmt, speed, table

__all__ = ["peg_section", "peg_paired", "peg_budget"]

#: Per peg experiment: section heading, figure-name prefix, what moved the peg.
_PEG_PAGES = {
    "peg": ("## 5. Clearance-fit peg (free peg)", "exp5_peg",
            "Free peg (a drive constraint moves it; no arm)"),
    "nextage": ("## 6. The peg on the simulated Nextage, through the stack's cores", "exp6_nextage",
                "The Nextage arm (`robot:=sim_nextage`) through the stack's cores in one process "
                "(`experiments/nextage_peg.py`): the robot plugin, the bridge's 1 kHz position "
                "loop with its task-space IK and rest detector, and the executor's `PegTask`, "
                "read from the ROS nodes' config files; the same start positions as the free peg"),
}


def peg_section(results: list[dict[str, Any]], figures: Path,
                experiment: str = "peg") -> tuple[list[str], dict]:
    """The section of a peg experiment, and its curves and spread for the closing comparison
    (empty without runs)."""
    heading, prefix, robot = _PEG_PAGES[experiment]
    lines = [heading, ""]
    if not results:
        return lines + ["Not run in this profile.", ""], {}
    curves = peg.learning_curves(results)
    spread = peg.q_spread(results)
    spec = results[0]["spec"]
    window = 5 if spec["episodes"] >= 20 else 1
    plots.peg_learning(curves, window, figures / f"{prefix}_learning.png")
    if spread:
        plots.q_spread(spread, figures / f"{prefix}_q_std.png")
    tail = max(1, spec["episodes"] // 5)
    rows = []
    for (a, lr), c in curves.items():
        s = spread.get((a, lr))
        rows.append([label(a), f"{lr:g}", str(c["seeds"]),
                     fmt(float(np.mean(c["return_mean"][-tail:])), 1),
                     f"{float(np.mean(c['success_mean'][-tail:])):.0%}",
                     fmt(float(np.mean(c["steps_mean"][-tail:])), 0),
                     "n/a" if s is None else fmt(float(np.median(s)), 3)])
    lines += [f"{robot}. {spec['episodes']} episodes of at most {spec['episode_steps']} steps "
              f"per run, {spec['train_iterations']} minibatch updates after each episode (thesis: "
              "50 epochs x up to 15 minibatches, 300 episodes, 10 seeds). Networks 3 x 200, no "
              f"target networks, actor lr = critic lr. Speed: {speed(results)}.", "",
              f"![{experiment} learning curves](figures/{prefix}_learning.png)", ""]
    if spread:
        lines += [f"![{experiment} Q spread](figures/{prefix}_q_std.png)", ""]
    lines += table(["algorithm", "lr", "seeds", f"mean return, last {tail} episodes",
                    "success, last episodes", "steps, last episodes",
                    "median std of Q (27 x 11)"], rows)
    return lines + [""], {"curves": curves, "spread": spread, "tail": tail, "robot": experiment}


def peg_paired(results: list[dict[str, Any]], tail: int) -> str:
    """QG-DDPG against DDPG on the same seeds of a peg experiment: late-episode return."""
    late: dict[tuple[float, int], dict[str, float]] = {}
    for r in results:
        s = r["spec"]
        late.setdefault((s["lr"], s["seed"]), {})[s["algorithm"]] = float(
            np.mean([e["return"] for e in r["episodes"][-tail:]]))
    keys = sorted(k for k, v in late.items() if {"qgddpg", "ddpg"} <= set(v))
    if not keys:
        return ""
    # Lower is better in paired_comparison: compare the negated returns.
    c = stats.paired_comparison([-late[k]["qgddpg"] for k in keys],
                                [-late[k]["ddpg"] for k in keys])
    return (f"QG-DDPG against DDPG on the same {c.n} (lr, seed) pairs, mean return of the last "
            f"{tail} episodes: QG-DDPG higher in {c.wins_a}, DDPG in {c.wins_b}, {c.ties} "
            f"tie(s); QG-DDPG minus DDPG {stats.format_interval(c.difference, 2)}; Wilcoxon "
            f"p = {c.wilcoxon_p:.3g} (with 5 pairs the smallest two-sided p is 0.0625).")


def peg_budget(budget: PegBudget) -> str:
    """A peg budget in words, for the budget table."""
    return (f"{budget.episodes} episodes x {len(budget.seeds)} seeds, {len(budget.lrs)} lrs, "
            f"{budget.train_iterations} updates/episode")

