"""``qgl train`` — QG-DDPG (or our DDPG) on any Gymnasium environment, from the command line.

The same learner as the stack's (``learner/gym_agent.py``), pointed at a Gymnasium id:
``qgl train --env Pendulum-v1`` trains for ``--steps`` environment steps, writes TensorBoard
scalars under Stable-Baselines3's tags to ``<runs>/train_<env>_<time>/`` and prints the mean
return of a few deterministic test episodes. ``--set name=value`` changes any setting of
``AgentSettings`` (values in YAML: ``--set critic_lr=1e-4 --set actor_hidden=[64,64]``);
``--preset sb3`` starts from Stable-Baselines3 DDPG's settings instead of the thesis's.
Environments of a module register by ``module:Id``, e.g. ``qg_experiments:QGInsertion-v0``.
"""
from __future__ import annotations

import argparse
import time

from qg_common.params import runs_dir
from qg_learning_node.learner import algorithms

__all__ = ["add_parser"]


def _setting(text: str) -> tuple[str, object]:
    import yaml
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected name=value, got {text!r}")
    parsed = yaml.safe_load(value)
    return name, tuple(parsed) if isinstance(parsed, list) else parsed


def _cmd_train(args: argparse.Namespace) -> int:
    import gymnasium
    import numpy as np
    from qg_learning_node.learner.gym_agent import QGDDPG, SB3_DDPG_SETTINGS
    settings = {**(SB3_DDPG_SETTINGS if args.preset == "sb3" else {}),
                "algorithm": args.algorithm, "seed": args.seed, **dict(args.set)}
    folder = (runs_dir() / f"train_{args.env.split(':')[-1]}_{time.strftime('%Y%m%d_%H%M%S')}")
    env = gymnasium.make(args.env)
    try:
        agent = QGDDPG(env, **settings)
    except ValueError as exc:
        print(f"qgl train: {exc}")
        return 2
    start = time.perf_counter()
    agent.learn(args.steps, tensorboard_log=folder)
    agent.close()
    print(f"[qgl] {args.algorithm} on {args.env}: {args.steps} steps, {agent.episodes} episodes "
          f"in {time.perf_counter() - start:.0f} s; TensorBoard: tensorboard --logdir {folder}")
    returns = []
    for index in range(args.test_episodes):
        obs, _ = env.reset(seed=10_000 + index)
        done, total = False, 0.0
        while not done:
            action, _ = agent.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    if returns:
        print(f"[qgl] test return over {len(returns)} episodes: {np.mean(returns):.2f} "
              f"(min {np.min(returns):.2f}, max {np.max(returns):.2f})")
    env.close()
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    train = sub.add_parser("train", help="QG-DDPG on a Gymnasium environment (no ROS)")
    train.add_argument("--env", required=True, help="a Gymnasium id, e.g. Pendulum-v1")
    train.add_argument("--steps", type=int, default=20_000, help="environment steps")
    train.add_argument("--algorithm", choices=algorithms.keys("ours"), default="qgddpg",
                       help="one of our algorithms (learner/algorithms.py)")
    train.add_argument("--preset", choices=("thesis", "sb3"), default="thesis",
                       help="start from the thesis's settings or SB3 DDPG's")
    train.add_argument("--set", type=_setting, action="append", default=[], metavar="NAME=VALUE",
                       help="one AgentSettings field (repeatable)")
    train.add_argument("--seed", type=int, default=0)
    train.add_argument("--test-episodes", type=int, default=5)
    train.set_defaults(func=_cmd_train)
