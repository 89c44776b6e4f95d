"""Why the deterministic test actor stalls (docs/learning.md section 15).

The demo's learning in process on one seed (QG-DDPG, critic lr 1e-2, 50 iterations a cycle,
40 training episodes capped at 50 steps, the default engine and step), then each test pose
with the deterministic actor (cap 60). For a pose that stalls: how much the state and the
action change over its last 10 steps, the truth there (tilt, depth), the critic's value of it,
and the same pose four times more with the training noise on the same actor. One JSON line a
pose, the last line all of them.

Usage: python benchmarks/stall_probe.py [SEED]     (seed 0 stalled on every pose, 2026-11-27)
"""
from __future__ import annotations

import dataclasses
import json
import sys
from typing import Any

import numpy as np
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
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.noise import ActionNoise
from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_learning_node.learner.learner_core import LearnerCore

TEST_CAP = 60          # [steps] a stall shows long before the report's 200
TAIL = 10              # [steps] the end of a stalled episode that is looked at
NOISY_RETRIES = 4      # the stalled pose again with the training noise


def learn_in_process(spec: RunSpec, test_cap: int = TEST_CAP
                     ) -> tuple[InsertionRobot, LearnerCore, LivePolicy, Any, int]:
    """``spec``'s training episodes in process (its train cap, ``test_cap`` for later tests):
    the robot, learner, actor, settings and how many training episodes inserted."""
    settings = StackSettings.load(spec.config_dir, spec.arm, spec.robot).with_arm_seed(spec.seed)
    settings = dataclasses.replace(settings, task=dataclasses.replace(
        settings.task, train_max_steps=spec.train_max_steps, test_max_steps=test_cap))
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

    inserted = 0
    for index in range(spec.train_episodes):
        noise = ActionNoise(settings.noise, ACTION_DIM, episode_noise_seed(spec.seed, index))
        result = run_episode(env, Episode(f"train{index:03d}", "train", index % N_START_POSES,
                                          spec.reward, env.residual, noise), policy, learn)
        inserted += bool(result["success"])
    return env, learner, policy, settings, inserted


def trained(seed: int, critic_lr: float = 1e-2, iterations: int = 50
            ) -> tuple[InsertionRobot, LearnerCore, LivePolicy, Any]:
    """The demo's learning on ``seed`` in process (or another grid cell's learning rate and
    iterations): the robot, learner, actor and settings."""
    return learn_in_process(RunSpec("qgddpg", critic_lr, iterations, seed,
                                    train_max_steps=50))[:4]


def probe_pose(env: InsertionRobot, learner: LearnerCore, policy: LivePolicy, settings: Any,
               pose: int) -> dict[str, Any]:
    """A test episode of ``pose``; if it stalls, what the end of it looks like."""
    scene = env.loop.simulation.scene
    episode = Episode(f"test{pose}", "test", pose, "dense", env.residual)
    episode.begin(env.reset(pose))
    records = []
    while not episode.done:
        action = episode.choose_action(policy)
        records.append(episode.observe(action, env.step(action)))
    row: dict[str, Any] = {"pose": pose, "steps": episode.step, "success": bool(episode.success)}
    if episode.success:
        return row
    states = np.array([r.state for r in records[-TAIL:]])
    actions = np.array([r.action for r in records[-TAIL:]])
    truth = scene.ground_truth()
    with torch.no_grad():
        value = learner.agent.critic(torch.tensor(states[-1:], dtype=torch.float32),
                                     torch.tensor(actions[-1:], dtype=torch.float32))
    row.update(state_last=states[-1].round(3).tolist(),
               state_change=float(np.abs(np.diff(states, axis=0)).max()),
               action_last=actions[-1].round(3).tolist(),
               action_change=float(np.abs(np.diff(actions, axis=0)).max()),
               tilt_deg=round(float(np.degrees(truth.tilt)), 2),
               depth_mm=round(truth.insertion_depth * 1e3, 2), q_last=float(value.item()),
               noisy_steps=[])
    for retry in range(NOISY_RETRIES):
        noise = ActionNoise(settings.noise, ACTION_DIM, 1000 + retry)
        noisy = run_episode(env, Episode(f"noisy{pose}_{retry}", "train", pose, "dense",
                                         env.residual, noise), policy)
        row["noisy_steps"].append(noisy["steps"] if noisy["success"] else None)
    return row


def main() -> None:
    torch.set_num_threads(1)
    seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
    env, learner, policy, settings = trained(seed)
    rows = []
    for pose in range(N_START_POSES):
        rows.append(probe_pose(env, learner, policy, settings, pose))
        print(json.dumps(rows[-1]), flush=True)
    print(json.dumps({"seed": seed, "poses": rows}))


if __name__ == "__main__":
    main()
