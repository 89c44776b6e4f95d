"""Train on MuJoCo in process, test the deterministic actor, export it as a policy file.

The first half of the MuJoCo -> franky-sim transfer (docs/deployment.md): QG-DDPG learns the
shaft insertion in process on the default robot (``sim_panda``: MuJoCo, steps that end at
rest, the realistic arm, the default ``tilt_motion`` state), with the grid's training budget (40 episodes
of at most 50 steps); its deterministic actor is tested on the 8 start poses in process, and the
first seed whose actor inserts from all of them is exported (``qgl export-policy``'s
``export_core``). The second half runs the file on franky-sim through libfranka:
``qgl up --config config/stack_franka.yaml --policy FILE`` and
``qgl episode start --mode test --initial-pose k --wait`` for k = 0..7.

One JSON line per seed tried; the last line says which file was written (or none).

Usage: python benchmarks/policy_transfer.py OUT.npz [--seeds 0 1 2] [--lr 1e-3] [--iterations 50]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch
from qg_bringup.policy import export_core
from qg_common.types import N_START_POSES
from qg_experiments.runner import (
    InsertionRobot,
    RunSpec,
    run_episode,
)
from qg_learning_node.executor.episode import Episode
from qg_learning_node.learner.learner_core import LearnerCore
from qg_learning_node.policy_file import load_policy

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stall_probe import learn_in_process  # noqa: E402  (the stall probe's learning)

TRAIN_CAP = 50        # [steps] the grid's training episodes
TEST_CAP = 200        # [steps] the thesis's test episodes


def train_and_test(spec: RunSpec) -> tuple[InsertionRobot, LearnerCore, list[dict]]:
    """``spec``'s training in process (the stall probe's), then a deterministic test episode
    per start pose."""
    env, learner, policy, _, trained = learn_in_process(spec, TEST_CAP)
    tests = []
    for pose in range(N_START_POSES):
        result = run_episode(env, Episode(f"test{pose}", "test", pose, spec.reward,
                                          env.residual), policy)
        tests.append({"pose": pose, "success": bool(result["success"]),
                      "steps": int(result["steps"])})
    return env, learner, [{"train_inserted": trained}, *tests]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--lr", type=float, default=1e-3, help="critic learning rate")
    parser.add_argument("--iterations", type=int, default=50, help="train steps per cycle")
    args = parser.parse_args()
    torch.set_num_threads(1)
    written = None
    for seed in args.seeds:
        start = time.monotonic()
        spec = RunSpec("qgddpg", args.lr, args.iterations, seed, train_max_steps=TRAIN_CAP)
        env, learner, rows = train_and_test(spec)
        tests = rows[1:]
        inserted = sum(r["success"] for r in tests)
        print(json.dumps({"seed": seed, "train_inserted": rows[0]["train_inserted"],
                          "test_inserted": inserted, "test_steps": [r["steps"] for r in tests],
                          "rl_steps": learner.steps, "seconds": round(time.monotonic() - start)}),
              flush=True)
        if inserted == N_START_POSES:
            written = export_core(learner, "residual", env.residual, spec.robot,
                                  Path(args.output), f"benchmarks/policy_transfer.py seed {seed} "
                                  f"(qgddpg, lr {args.lr}, {args.iterations} iterations)")
            spec_line = load_policy(written).spec
            print(json.dumps({"file": str(written), "seed": seed, "robot": spec_line.robot,
                              "observation": spec_line.observation,
                              "steps": spec_line.provenance["steps"]}))
            return
    print(json.dumps({"file": None, "seeds": args.seeds}))


if __name__ == "__main__":
    main()
