"""QG-DDPG, our DDPG, SB3's DDPG, TD3 (and SAC) on Pendulum-v1, MountainCarContinuous-v0 and the
sparse-reward mountain car, same budget, the report's seeds (``qg_experiments.standard_tasks``).

Usage (measured: a Pendulum run of ours 22-75 s, a MountainCar run 1-5 min, at 25-100 % of a
shared core; the 65 runs of the three tasks x 5 seeds, each task's algorithms, 1.5-3 hours):

    nice -n 10 .venv/bin/python benchmarks/standard_tasks_bench.py
    .venv/bin/python benchmarks/standard_tasks_bench.py --tasks Pendulum-v1 --seeds 100 --steps 2000
    .venv/bin/python benchmarks/standard_tasks_bench.py --table-only

Each run is saved as ``<out>/standard_tasks/<name>.json`` as it ends, so the sweep resumes. The
last line printed is the table as JSON (``standard_tasks.standard_table``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from qg_experiments.peers import REPORT_SEEDS
from qg_experiments.standard_tasks import TASKS, StandardSpec, standard_table
from qg_experiments.stats import Interval, format_interval
from qg_experiments.tasks import load_results, run_specs
from qg_learning_node.learner.algorithms import keys


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", choices=sorted(TASKS), default=list(TASKS))
    parser.add_argument("--algorithms", nargs="+", choices=keys(), default=None,
                        help="the registry's keys (learner/algorithms.py); default: each task's")
    parser.add_argument("--seeds", nargs="+", type=int, default=list(REPORT_SEEDS))
    parser.add_argument("--steps", type=int, default=None, help="default: the task's budget")
    parser.add_argument("--out", type=Path, default=Path("runs/experiments/thesis"))
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args()
    specs = [StandardSpec(task, algorithm, seed, args.steps) for task in args.tasks
             for seed in args.seeds for algorithm in args.algorithms or TASKS[task]["algorithms"]]
    if not args.table_only:
        run_specs(specs, args.out, workers=1, description="standard tasks")
    rows = standard_table(load_results(args.out, "standard_tasks"))
    for row in rows:
        print(f"{row['task']:26s} {row['algorithm']:9s} seeds {len(row['seeds'])}  final return "
              f"{format_interval(Interval(**row['final_return']))}  steps to TD3's final "
              f"{row['steps_to_td3']}")
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
