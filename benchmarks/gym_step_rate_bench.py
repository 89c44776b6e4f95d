"""RL steps per second: ``QGInsertion-v0`` against the in-process runner it wraps.

Usage (in the stack's environment; about a minute):

    eval "$(.venv/bin/qgl env)"
    .venv/bin/python benchmarks/gym_step_rate_bench.py --rounds 3 --episodes 8 --steps 20

Both paths execute the same actions (seeded uniform residuals) from the same start poses on the
same arm, so they take the same physics; rounds alternate the two paths so that a load change on
a shared machine hits both. Per round it prints each path's RL steps per wall second and their
ratio, then the totals; the last line is JSON.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch
from qg_experiments.gym_envs.insertion import InsertionEnv
from qg_experiments.runner import InsertionRobot, StackSettings, run_episode
from qg_learning_node.executor.episode import Episode


def _actions(episodes: int, steps: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (episodes, steps, 2))


def runner_path(actions: np.ndarray, arm_seed: int) -> tuple[int, float]:
    """(RL steps, wall seconds) of the runner's ``InsertionRobot`` + ``Episode`` + ``run_episode``
    (building the robot counted, as the environment's first reset builds it)."""
    start, steps = time.perf_counter(), 0
    task = InsertionRobot(StackSettings.load().with_arm_seed(arm_seed))
    for index, episode_actions in enumerate(actions):
        sequence = iter(episode_actions)
        episode = Episode(f"e{index}", "train", index % 8, "dense", task.residual)
        episode.max_steps = len(episode_actions)
        steps += run_episode(task, episode, lambda state: next(sequence))["steps"]
    elapsed = time.perf_counter() - start
    task.close()
    return steps, elapsed


def env_path(actions: np.ndarray, arm_seed: int) -> tuple[int, float]:
    """(RL steps, wall seconds) of the Gymnasium environment on the same actions."""
    env = InsertionEnv(max_steps=actions.shape[1])
    start, steps = time.perf_counter(), 0
    for index, episode_actions in enumerate(actions):
        # the first reset builds the robot of that seed, as the runner's InsertionRobot is built
        env.reset(seed=arm_seed if index == 0 else None, options={"pose": index % 8})
        for action in episode_actions:
            *_, terminated, truncated, _ = env.step(action)
            steps += 1
            if terminated or truncated:
                break
    elapsed = time.perf_counter() - start
    env.close()
    return steps, elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--steps", type=int, default=20, help="cap per episode")
    parser.add_argument("--seed", type=int, default=100, help="the arm's and the actions' seed")
    args = parser.parse_args()
    torch.set_num_threads(1)
    actions = _actions(args.episodes, args.steps, args.seed)
    totals = {"runner": [0, 0.0], "env": [0, 0.0]}
    rounds = []
    for index in range(args.rounds):
        order = (("runner", runner_path), ("env", env_path))
        measured = {}
        for name, path in (order if index % 2 == 0 else order[::-1]):
            steps, seconds = path(actions, args.seed)
            measured[name] = (steps, seconds)
            totals[name][0] += steps
            totals[name][1] += seconds
        assert measured["runner"][0] == measured["env"][0], "the paths took different steps"
        rates = {k: s / t for k, (s, t) in measured.items()}
        rounds.append(rates)
        print(f"round {index}: runner {rates['runner']:.1f} RL steps/s, env {rates['env']:.1f} "
              f"RL steps/s, env/runner {rates['env'] / rates['runner']:.3f} "
              f"({measured['env'][0]} steps each)", flush=True)
    rate = {k: s / t for k, (s, t) in totals.items()}
    print(f"total: runner {rate['runner']:.1f}, env {rate['env']:.1f} RL steps/s, "
          f"env/runner {rate['env'] / rate['runner']:.3f}")
    print(json.dumps({"rounds": rounds, "total": rate}))


if __name__ == "__main__":
    main()
