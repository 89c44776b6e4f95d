"""The peers' runs on ``QGInsertion-v0``: SB3's SAC, TD3 and DDPG, and ours at SB3 DDPG's settings.

Usage (in the stack's environment; one run costs 1-10 min on a free core, SAC's most, since its
test episodes run to the cap):

    eval "$(.venv/bin/qgl env)"
    nice -n 10 .venv/bin/python benchmarks/peers_bench.py --setting defaults
    .venv/bin/python benchmarks/peers_bench.py --setting grid --algorithms sb3_td3 --cells 1e-3,50
    .venv/bin/python benchmarks/peers_bench.py --ours --cells 1e-3,50   # our DDPG, QG-DDPG
    .venv/bin/python benchmarks/peers_bench.py --table-only          # print what is saved

``--ours`` runs our DDPG and QG-DDPG through the runner (``RunSpec``, the grid's protocol and
layout, ``<out>/grid/``) at the given cells on the same seeds, for the comparison; the suite's
own grid runs of those seeds are the same runs (same names, skipped when saved).

Each run is saved as ``<out>/peers/<name>.json`` the moment it ends (``qg_experiments.tasks``), so
an interrupted sweep resumes where it stopped; its TensorBoard scalars go beside ours, to
``<out>/tensorboard/peers/<name>/``. Runs go seed by seed, one process at a time (``--workers``).
The last line printed is the table as JSON (``peers.peer_table``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from qg_experiments.grid import grid_specs
from qg_experiments.peers import PEER_ALGORITHMS, REPORT_SEEDS, SETTINGS, peer_specs, peer_table
from qg_experiments.profile import GridBudget
from qg_experiments.runner import ALGORITHMS
from qg_experiments.stats import Interval, format_interval
from qg_experiments.tasks import load_results, run_specs
from qg_experiments.tensorboard_log import export_runs
from qg_learning_node.learner.algorithms import COMPARED

#: The grid's cells (critic learning rate, gradient steps per 20 robot steps).
GRID_CELLS = ((1e-5, 10), (1e-5, 50), (1e-4, 10), (1e-4, 50), (1e-3, 10), (1e-3, 50),
              (1e-2, 10), (1e-2, 50))


def _cell(text: str) -> tuple[float, int]:
    lr, iterations = text.split(",")
    return float(lr), int(iterations)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--setting", choices=SETTINGS, default="defaults")
    parser.add_argument("--algorithms", nargs="+", choices=PEER_ALGORITHMS,
                        default=["sb3_ddpg", "ddpg", "sb3_td3", "sb3_sac"])
    parser.add_argument("--seeds", nargs="+", type=int, default=list(REPORT_SEEDS))
    parser.add_argument("--cells", nargs="+", type=_cell, default=list(GRID_CELLS),
                        help="grid setting: lr,iterations ...")
    parser.add_argument("--arm", choices=("realistic", "ideal"), default="realistic")
    parser.add_argument("--out", type=Path, default=Path("runs/experiments/thesis"))
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--ours", action="store_true",
                        help="run our DDPG and QG-DDPG at --cells instead (the runner's grid)")
    parser.add_argument("--ours-algorithms", nargs="+", choices=ALGORITHMS,
                        default=list(COMPARED), help="with --ours")
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args()
    if args.ours:
        budget = GridBudget(cells=tuple(args.cells), seeds=tuple(args.seeds), train_episodes=40,
                            train_max_steps=50, test_max_steps=200, observation="tilt_only",
                            algorithms=tuple(args.ours_algorithms))
        specs = grid_specs(budget)
    else:
        specs = peer_specs(args.setting, tuple(args.seeds), tuple(args.algorithms),
                           tuple(args.cells), tensorboard_dir=str(args.out / "tensorboard" /
                                                                  "peers"), arm=args.arm)
    if not args.table_only:
        results = run_specs(specs, args.out, workers=args.workers, description="peers")
        if args.ours:      # their scalars beside the peers' (SB3 writes its own while it learns)
            export_runs(results, args.out / "tensorboard")
    rows = peer_table(load_results(args.out, "peers"))
    for row in rows:
        steps, train = Interval(**row["mean_test_steps"]), Interval(**row["train_steps"])
        cell = (f"lr {row['critic_lr']:g} it {row['iterations']}" if row["setting"] == "grid"
                else "defaults")
        print(f"{row['algorithm']:12s} {cell:18s} seeds {len(row['seeds'])}  test steps "
              f"{format_interval(steps)}  solved {row['solved']}/{row['tests']}  training steps "
              f"{format_interval(train, 0)}")
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
