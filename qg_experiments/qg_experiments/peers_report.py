"""The peers' section of ``docs/results.md``: SB3 on the shaft task and QG-DDPG on standard tasks.

``docs/results.md`` is written by ``report`` from the suite's runs; the peers' runs are made by
their own benchmarks (``benchmarks/peers_bench.py``, ``benchmarks/standard_tasks_bench.py``), so
their section is written here, between markers, and a regenerated report keeps it when it copies
the marked blocks over (or they are written again with ``python -m qg_experiments.peers_report``).
SB3 on the shaft task and the standard tasks are two blocks with markers of their own, because
their runs are made apart (hours each, not always on the same machine): each block is written
from the runs found under ``--out`` and left as it is when there are none. Every number is
counted by ``stats``: per-seed means, BCa intervals, paired comparisons on the same seeds.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import REGISTRY, label

from qg_experiments.peers import REPORT_SEEDS, peer_table
from qg_experiments.report.markdown import PEERS_BLOCK, STANDARD_BLOCK, write_marked_block
from qg_experiments.runner import config_digest
from qg_experiments.standard_tasks import TASKS, standard_table
from qg_experiments.stats import Interval, format_interval, paired_comparison
from qg_experiments.tasks import load_results

__all__ = ["BEGIN", "END", "STANDARD_BEGIN", "STANDARD_END", "ours_rows", "peers_section",
           "standard_section", "write_section"]

BEGIN, END = PEERS_BLOCK
STANDARD_BEGIN, STANDARD_END = STANDARD_BLOCK
#: The prefix :func:`ours_rows` gives our runner's runs in the peers' table.
RUNNER = "runner_"


def _peer_name(key: str) -> str:
    """A peers' table row: SB3's algorithm, ours at SB3 DDPG's settings, or our runner's."""
    if key.startswith(RUNNER):
        return f"{label(key.removeprefix(RUNNER))} (ours, the runner)"
    ours = key in REGISTRY and REGISTRY[key].ours
    return f"our {label(key)} at SB3 DDPG's settings" if ours else label(key)


def _standard_name(key: str) -> str:
    """A standard tasks' table row: ``QG-DDPG (ours)``, ``SB3 TD3``."""
    return f"{label(key)} (ours)" if key in REGISTRY and REGISTRY[key].ours else label(key)


def _train_steps(result: dict[str, Any]) -> int:
    return int(sum(e["steps"] for e in result["episodes"] if e["mode"] == "train"))


def _test_mean(result: dict[str, Any]) -> float:
    return float(np.mean([e["steps"] for e in result["episodes"] if e["mode"] == "test"]))


def ours_rows(grid_results: list[dict[str, Any]], seeds: set[int]) -> list[dict[str, Any]]:
    """Our runner's grid runs on ``seeds`` as rows of the peers' table (one per algorithm and
    cell), counted like :func:`peers.peer_table`."""
    peers_like = [{**r, "train_steps": _train_steps(r),
                   "spec": {**r["spec"], "algorithm": RUNNER + r["spec"]["algorithm"],
                            "setting": "grid"}}
                  for r in grid_results if r["spec"]["seed"] in seeds
                  and r["spec"].get("reward", "dense") == "dense"
                  and not r["spec"].get("replay_capacity")]
    return peer_table(peers_like)


def _row_line(row: dict[str, Any]) -> str:
    name = _peer_name(row["algorithm"])
    cell = ("defaults" if row["setting"] == "defaults"
            else f"lr {row['critic_lr']:g}, {row['iterations']} it/20 steps")
    steps, train = Interval(**row["mean_test_steps"]), Interval(**row["train_steps"])
    return (f"| {name} | {cell} | {len(row['seeds'])} | {format_interval(steps)} | "
            f"{row['solved']}/{row['tests']} | {row['all_solved_seeds']}/{len(row['seeds'])} | "
            f"{format_interval(train, 0)} |")


def _paired_line(label: str, a: dict[int, float], b: dict[int, float], digits: int = 1,
                 higher_is_better: bool = False) -> str:
    """``label``: the paired difference on the common seeds, signed so that positive means A
    is better (fewer steps, or with ``higher_is_better`` a higher return)."""
    seeds = sorted(set(a) & set(b))
    if len(seeds) < 2:
        return f"- {label}: fewer than 2 common seeds"
    sign = -1.0 if higher_is_better else 1.0     # paired_comparison: B - A > 0 is A better
    c = paired_comparison([sign * a[s] for s in seeds], [sign * b[s] for s in seeds])
    which = "A - B" if higher_is_better else "B - A"
    return (f"- {label}: {which} = {format_interval(c.difference, digits)} over seeds {seeds} "
            f"(A better on {c.wins_a}, B on {c.wins_b}, ties {c.ties}; Wilcoxon p = "
            f"{c.wilcoxon_p:.2f}, sign test p = {c.sign_p:.2f})")


def _current(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The runs made under today's config files (a changed arm makes older runs another task)."""
    digest = config_digest()
    return [r for r in results if r.get("config_digest") == digest]


def _shaft(out: Path) -> list[str]:
    peers = _current(load_results(out, "peers"))
    rows = peer_table(peers) + ours_rows(_current(load_results(out, "grid")), set(REPORT_SEEDS))
    lines = ["### The shaft task (`QGInsertion-v0`): SB3 beside ours", "",
             "Protocol of the grid on the realistic arm of each seed: 40 training episodes of at "
             "most 50 robot steps (poses 0..7 in turn), then the 8 poses once each, "
             "deterministically, at most 200 steps (a failure counts 200). Intervals: 95 % BCa "
             "bootstrap over the per-seed means (`stats.mean_interval`). *Training robot steps* "
             "are the steps of the 40 training episodes (fewer when episodes reach the goal "
             "early). SB3 defaults: each algorithm's constructor defaults plus Gaussian action "
             "noise 0.1 for TD3 and DDPG (RL Zoo's); a grid cell sets SB3's one learning rate "
             "and trains that many gradient steps after every 20 steps (our grid's actor learns "
             "at a tenth of the critic's rate).", "",
             "| algorithm | setting | seeds | mean test steps [95 % CI] | poses solved | seeds "
             "solving all 8 | training robot steps [95 % CI] |", "|---|---|---|---|---|---|---|"]
    lines += [_row_line(row) for row in rows]
    by = {(r["algorithm"], r["setting"]): r for r in rows}
    lines += [""]
    ours, sb3 = by.get(("ddpg", "defaults")), by.get(("sb3_ddpg", "defaults"))
    if ours and sb3:
        def per_seed(row: dict[str, Any], key: str) -> dict[int, float]:
            return {int(s): float(v[key]) for s, v in row["per_seed"].items()}
        lines += ["Our DDPG against SB3's DDPG at SB3 DDPG's settings (A = ours, B = SB3; "
                  "positive: ours needs fewer steps):",
                  _paired_line("mean test steps", per_seed(ours, "mean_test_steps"),
                               per_seed(sb3, "mean_test_steps")),
                  _paired_line("training robot steps", per_seed(ours, "train_steps"),
                               per_seed(sb3, "train_steps"), 0), ""]
    return lines


def _task_settings() -> str:
    """The tasks' own settings of our agents (``TASKS[task]["ours"]``), as a sentence."""
    named = [f"on {task.split(':')[-1]} " + ", ".join(f"`{k}` {v}" for k, v in s["ours"].items())
             for task, s in TASKS.items() if s.get("ours")]
    return ("Our agents' settings of a task alone (`standard_tasks.TASKS`): "
            + "; ".join(named) + ". ") if named else ""


def _standard(out: Path) -> list[str]:
    results = load_results(out, "standard_tasks")
    lines = ["### QG-DDPG on standard Gymnasium tasks", "",
             f"Runs: `benchmarks/standard_tasks_bench.py`; per-run JSON under "
             f"`{out}/standard_tasks`.", "",
             "Same budget and settings for all (`qg_experiments.standard_tasks`): SB3 DDPG's "
             "defaults with 64-64 networks, RL Zoo's noise per task; QG-DDPG takes the task's "
             "known reward range as a-priori bounds. *Final return*: mean of the deterministic "
             "evaluation episodes after the last step, per seed, then over seeds. *Steps to "
             "TD3's final*: the first evaluation at which a seed reached SB3 TD3's mean final "
             "return (inf: never). Where the graph can help, by construction: Pendulum has no "
             "terminal state and its states never repeat, so the graph bounds nothing and QG-DDPG "
             "differs from our DDPG only where the a-priori bounds clip a target; on the mountain "
             "cars every episode that reached the goal bounds its whole chain, none before the "
             "first success. `QGSparseMountainCar-v0` is the same car with the thesis's sparse "
             "reward (-1 per step, 0 at the goal; its return is minus the steps to the goal), "
             "where SB3's SAC runs too. " + _task_settings() + "Why ours lost Pendulum seeds and "
             "QG-DDPG MountainCar seeds, and what the settings change: "
             "[learning.md](learning.md), section 13.", "",
             "*Goal found*: per seed, the training episodes (noisy actions) that reached the "
             "goal, of all it played; a seed at 0 never saw a reward but the step's cost.", "",
             "| task | algorithm | steps | seeds | final return [95 % CI] | final return per seed "
             "| steps to TD3's final return, per seed | goal found in training, per seed |",
             "|---|---|---|---|---|---|---|---|"]
    steps = {r["spec"]["task"]: r["evaluations"][-1]["steps"] for r in results}
    final = {(r["spec"]["task"], r["spec"]["algorithm"], r["spec"]["seed"]): r["final_return"]
             for r in results}
    for row in standard_table(results):
        reach = row["steps_to_td3"] or {}
        finals = ", ".join(f"{final[row['task'], row['algorithm'], s]:.1f}" for s in row["seeds"])
        lines.append(f"| {row['task']} | {_standard_name(row['algorithm'])} | "
                     f"{steps[row['task']]} | {len(row['seeds'])} | "
                     f"{format_interval(Interval(**row['final_return']))} | {finals} | "
                     + ", ".join("inf" if math.isinf(v) else str(int(v))
                                 for _, v in sorted(reach.items())) + " | "
                     + ", ".join("-" if found is None else f"{found[0]}/{found[1]}"
                                 for _, found in sorted(row["goal_found"].items())) + " |")
    lines += [""]
    for task in sorted({k[0] for k in final}):
        def of(algorithm: str) -> dict[int, float]:
            return {s: v for (t, a, s), v in final.items() if t == task and a == algorithm}
        lines += [f"{task}, final return (positive: A returns more):"]
        lines += [_paired_line(f"{_standard_name(a)} (A) vs {_standard_name(b)} (B)", of(a),
                               of(b), higher_is_better=True)
                  for a, b in (("ddpg", "sb3_ddpg"), ("qgddpg", "ddpg"), ("qgddpg", "sb3_ddpg"),
                               ("qgddpg", "sb3_td3"), ("qgddpg", "sb3_sac"))
                  if of(a) and of(b)] + [""]
    return lines


def peers_section(out: Path) -> str:
    """The peers' marked block (SB3 on the shaft task) from the saved runs under ``out``."""
    lines = [BEGIN, "## 8. Peers: Stable-Baselines3 on our task, QG-DDPG on standard tasks", "",
             "Runs: `benchmarks/peers_bench.py` (and `--ours` for our runner's runs on the same "
             "seeds), `benchmarks/standard_tasks_bench.py`; per-run JSON under "
             f"`{out}/peers`, `{out}/grid`, `{out}/standard_tasks`; the peers' TensorBoard "
             f"scalars beside ours in `{out}/tensorboard/peers`.", ""]
    lines += _shaft(out) + [END]
    return "\n".join(lines) + "\n"


def standard_section(out: Path) -> str:
    """The standard tasks' marked block from the saved runs under ``out``."""
    return "\n".join([STANDARD_BEGIN, *_standard(out), STANDARD_END]) + "\n"


def write_section(results_md: Path, out: Path) -> None:
    """Replace each marked block in ``results_md`` whose runs are under ``out`` (or append it);
    a block without runs there is left as the page has it."""
    if (out / "peers").is_dir():
        write_marked_block(results_md, BEGIN, END, peers_section(out))
    if load_results(out, "standard_tasks"):
        write_marked_block(results_md, STANDARD_BEGIN, STANDARD_END, standard_section(out))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("runs/experiments/thesis"))
    parser.add_argument("--results", type=Path, default=Path("docs/results.md"))
    args = parser.parse_args()
    write_section(args.results, args.out)
    print(f"wrote the peers' blocks of {args.results} from the runs under {args.out}")


if __name__ == "__main__":
    main()
