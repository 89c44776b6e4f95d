"""Learning with N robots: the same training episodes split over N robots, test result and time.

Usage (in the stack's environment; the full measurement takes about 3 x (4 + 2.5) min):

    eval "$(.venv/bin/qgl env)"
    .venv/bin/python benchmarks/fleet_learning_bench.py --robots 1 2 --seeds 1 2 3
    .venv/bin/python benchmarks/fleet_learning_bench.py --train-episodes 4 --test-poses 2  # smoke

For every N in ``--robots`` and every seed in ``--seeds`` it runs ``qgl demo --robots N --seed
S`` as a subprocess with the same ``--train-episodes`` (default 40, the demo's), dealt to the
N robots, which train at once into one learner; the test episodes then run on robot0 as with
one robot. The claim: with N robots the test result is at least as good as with one
and the wall time drops.

Per run it prints N, seed, the total training RL steps and insertions, the test poses
inserted, the mean test steps (a failed pose counts at the test cap, 200), the wall time of
the training (first start request to last training episode's end, from ``episodes.json``) and
of the whole demo (stack start and tests included). The last line is JSON: the runs and, per N,
the means over the seeds and the training wall time relative to N = 1.
Each run's folder (``episodes.json``, bags, plot, demo output in ``demo.log``) stays under
``--runs-dir`` (default: a new temporary folder, printed).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: [steps] the executor's cap of test episodes (config/executor.yaml, task.test_max_steps).
TEST_CAP = 200


def run_demo(robots: int, seed: int, args: argparse.Namespace, runs: Path) -> dict:
    """One ``qgl demo`` run; its figures from its ``episodes.json``."""
    folder = runs / f"robots{robots}_seed{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "qg_bringup.main", "demo", "--robots",
               str(robots), "--seed", str(seed), "--train-episodes", str(args.train_episodes),
               "--test-poses", str(args.test_poses), "--runs-dir", str(folder), *args.demo_args]
    started = time.monotonic()
    with open(folder / "demo.log", "w") as log:
        code = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT).returncode
    wall = time.monotonic() - started
    (run_dir,) = folder.glob("demo_*")
    outcomes = json.loads((run_dir / "episodes.json").read_text())
    if code != 0:
        raise RuntimeError(f"qgl demo exited with {code}: see {folder / 'demo.log'}")
    train = [o for o in outcomes if o["mode"] == "train"]
    tests = [o for o in outcomes if o["mode"] == "test"]
    return {
        "robots": robots, "seed": seed,
        "train_steps": sum(o["steps"] for o in train),
        "train_inserted": sum(o["success"] for o in train), "train_episodes": len(train),
        "test_inserted": sum(o["success"] for o in tests), "test_poses": len(tests),
        "mean_test_steps": statistics.fmean(o["steps"] if o["success"] else TEST_CAP
                                            for o in tests) if tests else float("nan"),
        "train_wall_s": max(o["started"] + o["wall_time"] for o in train)
                        - min(o["started"] for o in train) if train else 0.0,
        "wall_s": wall, "run_dir": str(run_dir)}


def summarise(runs: list[dict]) -> dict[int, dict]:
    """Per N: the means over its seeds; training wall time relative to N = 1 (if measured)."""
    keys = ("train_steps", "train_inserted", "test_inserted", "mean_test_steps",
            "train_wall_s", "wall_s")
    per_n = {}
    for n in sorted({r["robots"] for r in runs}):
        mine = [r for r in runs if r["robots"] == n]
        per_n[n] = {"seeds": [r["seed"] for r in mine],
                    **{k: round(statistics.fmean(r[k] for r in mine), 2) for k in keys}}
    if 1 in per_n and per_n[1]["train_wall_s"]:
        for n, s in per_n.items():
            s["train_wall_vs_one_robot"] = round(s["train_wall_s"] / per_n[1]["train_wall_s"], 3)
    return per_n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--train-episodes", type=int, default=40,
                        help="training episodes of every run, dealt to its robots")
    parser.add_argument("--test-poses", type=int, default=8)
    parser.add_argument("--runs-dir", default=None, help="parent of the runs' folders")
    parser.add_argument("--demo-args", nargs=argparse.REMAINDER, default=[],
                        help="further `qgl demo` arguments (last on the line)")
    args = parser.parse_args()
    if min(args.robots) < 1 or args.train_episodes < 1:
        parser.error("--robots must be >= 1 and --train-episodes >= 1")
    runs_dir = Path(args.runs_dir) if args.runs_dir else Path(tempfile.mkdtemp(prefix="fleet_"))
    print(f"runs in {runs_dir}", flush=True)
    runs = []
    for n in args.robots:
        for seed in args.seeds:
            r = run_demo(n, seed, args, runs_dir)
            runs.append(r)
            print(f"N={n} seed={seed}: training {r['train_steps']} RL steps, inserted "
                  f"{r['train_inserted']}/{r['train_episodes']}; test inserted "
                  f"{r['test_inserted']}/{r['test_poses']}, mean test steps "
                  f"{r['mean_test_steps']:.1f} (failures at {TEST_CAP}); wall time: training "
                  f"{r['train_wall_s']:.0f} s, demo {r['wall_s']:.0f} s", flush=True)
    print(json.dumps({"train_episodes": args.train_episodes, "test_poses": args.test_poses,
                      "per_robots": summarise(runs), "runs": runs}))


if __name__ == "__main__":
    main()
