"""Train on MuJoCo in process, test the deterministic actor, export it as a policy file.

The first half of the MuJoCo -> franky-sim transfer (docs/deployment.md): QG-DDPG learns the
shaft insertion in process on the default robot (``sim_panda``: MuJoCo, steps that end at
rest, the realistic arm, the ``tilt_only`` state), with the grid's training budget (40 episodes
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
import dataclasses
import json
import time
from pathlib import Path

import torch
from qg_common.types import N_START_POSES
from qg_experiments.runner import (
    InsertionRobot,
    LivePolicy,
    RunSpec,
    StackSettings,
    episode_noise_seed,
    run_episode,
)
from qg_learning_node.cli.policy import export_core
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.noise import ActionNoise
from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_learning_node.learner.learner_core import LearnerCore
from qg_learning_node.policy_file import load_policy

TRAIN_CAP = 50        # [steps] the grid's training episodes
TEST_CAP = 200        # [steps] the thesis's test episodes


def train_and_test(spec: RunSpec) -> tuple[InsertionRobot, LearnerCore, list[dict]]:
    """``spec``'s training in process, then a deterministic test episode per start pose."""
    settings = StackSettings.load(spec.config_dir, spec.arm, spec.robot).with_arm_seed(spec.seed)
    settings = dataclasses.replace(settings, task=dataclasses.replace(
        settings.task, train_max_steps=TRAIN_CAP, test_max_steps=TEST_CAP))
    env = InsertionRobot(settings, spec.estimator)
    learner = LearnerCore(spec.learner_config(settings.learner), env.residual.state_dim,
                          ACTION_DIM)
    policy = LivePolicy(learner.agent)

    def learn(record) -> None:
        learner.add_transition(record.state, record.action, record.reward, record.next_state,
                               record.terminal)
        while learner.training_due():
            learner.train_cycle()
            policy.update(learner.agent)

    trained = 0
    for index in range(spec.train_episodes):
        noise = ActionNoise(settings.noise, ACTION_DIM, episode_noise_seed(spec.seed, index))
        result = run_episode(env, Episode(f"train{index:03d}", "train", index % N_START_POSES,
                                          spec.reward, env.residual, noise), policy, learn)
        trained += bool(result["success"])
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
