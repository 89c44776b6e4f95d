"""What a peg run's progress file costs: the time to save and to load it, and its size.

Why: a thesis-budget peg run saves its progress every ``run_progress.PROGRESS_EVERY`` seconds so
that a stopped sweep continues it (``qg_experiments/run_progress.py``). A save stops the run
while it lasts, so its cost at the run's largest memory sets how often it can save. The peg's
learner (3 x 200 networks, QG-DDPG: replay memory and Q-Graph) is filled with ``--transitions``
random transitions (a 300-episode run holds at most 60,000), then saved ``--rounds`` times.

Usage: python benchmarks/progress_save_bench.py [--transitions 60000] [--rounds 3]
The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from qg_experiments.peg import PegRunSpec, peg_learner_config
from qg_experiments.run_progress import PROGRESS_EVERY, RunProgress
from qg_learning_node.learner.learner_core import LearnerCore


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--transitions", type=int, default=60_000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    spec = PegRunSpec(algorithm="qgddpg", lr=1e-3, seed=0, episodes=300)
    learner = LearnerCore(peg_learner_config(spec, action_dim=3), 3, 3)
    rng = np.random.default_rng(0)
    for t in range(args.transitions):
        learner.add_transition(rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), -1.0,
                               rng.uniform(-1, 1, 3), t % spec.episode_steps == 0)
    episodes = [{"episode": k, "steps": 200, "success": False, "return": -200.0}
                for k in range(spec.episodes)]
    with tempfile.TemporaryDirectory() as folder:
        keeper = RunProgress(Path(folder) / "run.progress.pt", spec)
        saves, loads = [], []
        for _ in range(args.rounds):
            start = time.perf_counter()
            keeper.save({"learner": learner.state_dict(), "episodes": episodes},
                        len(episodes), spec.episodes, 0.0, force=True)
            saves.append(time.perf_counter() - start)
            start = time.perf_counter()
            LearnerCore.from_state_dict(keeper.load()["learner"])
            loads.append(time.perf_counter() - start)
        size = keeper.path.stat().st_size
    save = statistics.median(saves)
    print(f"{args.transitions} transitions: save {save:.2f} s, load {statistics.median(loads):.2f}"
          f" s, {size / 1e6:.1f} MB; every {PROGRESS_EVERY:.0f} s that is "
          f"{100 * save / PROGRESS_EVERY:.2f} % of a run's time")
    print(json.dumps({"transitions": args.transitions, "save_s": save,
                      "load_s": statistics.median(loads), "megabytes": size / 1e6,
                      "every_s": PROGRESS_EVERY, "share_of_run": save / PROGRESS_EVERY}))


if __name__ == "__main__":
    main()
