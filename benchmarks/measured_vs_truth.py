"""Success measured as a real cell measures it against the simulator's truth, every step:
the executor decides success from forward kinematics of the measured joints against
the fixture's pose (``ResidualTask.succeeded``); the simulator's truth rides along for
evaluation only. Seeded random-residual episodes on each simulated shaft robot, in process
(the stack's cores and config files); printed per robot: steps, steps where the two disagree,
and the largest gap between the measured and the true insertion depth.

Usage: python benchmarks/measured_vs_truth.py [--episodes 4] [--max-steps 30]
       [--robot sim_panda --robot sim_panda_pybullet --robot sim_xarm7]
The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import dataclasses
import json

from qg_common.types import N_START_POSES
from qg_experiments.runner import InsertionRobot, StackSettings, zero_policy
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.noise import ActionNoise
from qg_learning_node.executor.residual_task import ACTION_DIM

ROBOTS = ("sim_panda", "sim_panda_pybullet", "sim_xarm7")


def agreement(robot: str, episodes: int, max_steps: int) -> dict:
    """Random-residual episodes on ``robot``: how often measured and true success differ."""
    settings = StackSettings.load(robot=robot).with_arm_seed(0)
    settings = dataclasses.replace(settings, task=dataclasses.replace(
        settings.task, train_max_steps=max_steps))
    env = InsertionRobot(settings, "ekf")
    task = env.residual
    steps = disagreements = inserted = 0
    depth_gap = 0.0
    for index in range(episodes):
        noise = ActionNoise(settings.noise, ACTION_DIM, 100 + index)
        episode = Episode(f"check{index}", "train", index % N_START_POSES, "dense", task, noise)
        episode.begin(env.reset(episode.initial_pose))
        while not episode.done:
            action = episode.choose_action(zero_policy)      # the base push plus noise
            obs = env.step(action)
            measured = task.measure(obs)
            steps += 1
            disagreements += measured.inserted != bool(obs.truth.success)
            depth_gap = max(depth_gap, abs(measured.insertion_depth
                                           - obs.truth.insertion_depth))
            episode.observe(action, obs)
        inserted += bool(episode.success)
    return {"robot": robot, "episodes": episodes, "inserted": inserted, "steps": steps,
            "disagreements": disagreements, "max_depth_gap_mm": round(depth_gap * 1e3, 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--max-steps", type=int, default=30)
    parser.add_argument("--robot", action="append", default=None)
    args = parser.parse_args()
    rows = []
    for robot in args.robot or ROBOTS:
        rows.append(agreement(robot, args.episodes, args.max_steps))
        print(f"{robot}: {rows[-1]}", flush=True)
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
