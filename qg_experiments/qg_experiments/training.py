"""One training-and-test run of the residual shaft insertion, in one process, without DDS.

The ROS stack runs the simulator, the bridge with its 1 kHz loop, the EKF, the executor and the
learner as separate nodes. Here the same cores are called directly: ``RobotLoop`` (sim + bridge +
estimator, in ``core.InsertionRobot``) executes each wrench, ``Episode`` / ``ResidualTask`` /
``ActionNoise`` decide actions, rewards and episode ends exactly as the executor node does, and
``LearnerCore`` trains after every cycle of 20 steps exactly as the learner node does. Everything
is read from the same ``config/`` files; a run is a pure function of its ``RunSpec``, so the same
seed gives the same steps.

Difference to the ROS stack, by construction: the learner trains synchronously at the end of a
cycle (the node trains while the robot keeps moving), and the executor's actor is refreshed right
after each cycle instead of when the parameters message arrives.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Any, Protocol

import numpy as np
import torch
from qg_common.types import N_START_POSES
from qg_learning_node.executor.episode import Episode, TransitionRecord
from qg_learning_node.executor.noise import ActionNoise
from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_learning_node.executor.stall_recovery import StallRecovery
from qg_learning_node.learner.actor_mlp import ActorMLP
from qg_learning_node.learner.ddpg import DDPG
from qg_learning_node.learner.learner_config import LearnerConfig
from qg_learning_node.learner.learner_core import LearnerCore

from qg_experiments.core.insertion_robot import InsertionRobot
from qg_experiments.core.stack_settings import StackSettings, config_digest, stall_recovery_config
from qg_experiments.critic_check import MonteCarloCheck
from qg_experiments.episodes import episode_noise_seed, recovery_seed, run_episode

__all__ = ["LivePolicy", "TrainingSpec", "run_training"]


class TrainingSpec(Protocol):
    """What the training loop reads of a run (``run_spec.RunSpec`` is one; a frozen dataclass,
    saved whole with the result)."""
    name: str
    experiment: str
    config_dir: str | None
    arm: str
    robot: str
    seed: int
    estimator: str
    reward: str
    observation: str | None
    train_episodes: int
    test_episodes: int
    train_max_steps: int
    test_max_steps: int
    eval_every: int
    test_housing_yaw: float
    test_housing_tilt: float
    stall_recovery: bool
    task_settings: dict[str, Any]

    def learner_config(self, base: LearnerConfig) -> LearnerConfig: ...


class LivePolicy:
    """The executor's copy of the actor, replaced after every training cycle."""

    def __init__(self, agent: DDPG) -> None:
        self.update(agent)

    def update(self, agent: DDPG) -> None:
        """Copy ``agent``'s actor, as the executor takes a published one."""
        self.actor = ActorMLP.from_tensors(agent.actor_tensors())

    def __call__(self, state: np.ndarray) -> np.ndarray:
        return self.actor(state)


def run_training(spec: TrainingSpec) -> dict[str, Any]:
    """Train for ``spec.train_episodes`` episodes, then test; records per episode and cycle.

    :returns: ``spec``, ``episodes`` (train then test), ``cycles`` (diagnostics of every training
        cycle, including ``mean_q``: the critic's mean prediction on that cycle's minibatches,
        and ``critic_mc_error``: see :class:`MonteCarloCheck`), simulated/wall time and step
        counts.
    """
    torch.set_num_threads(1)
    start = time.perf_counter()
    settings = StackSettings.load(spec.config_dir, spec.arm, spec.robot).with_arm_seed(spec.seed)
    task_config = dataclasses.replace(settings.task, train_max_steps=spec.train_max_steps,
                                      test_max_steps=spec.test_max_steps,
                                      observation=spec.observation or settings.task.observation)
    settings = dataclasses.replace(settings, task=task_config)
    env = InsertionRobot(settings, spec.estimator)
    learner = LearnerCore(spec.learner_config(settings.learner), env.residual.state_dim,
                          ACTION_DIM)
    policy = LivePolicy(learner.agent)
    cycles: list[dict[str, Any]] = []
    check = MonteCarloCheck(learner.config.ddpg.gamma)

    def learn(record: TransitionRecord) -> None:
        check.add(record)
        learner.add_transition(record.state, record.action, record.reward, record.next_state,
                               record.terminal)
        while learner.training_due():
            diagnostics = learner.train_cycle()
            diagnostics["critic_mc_error"] = check.error(learner.agent)
            cycles.append({k: float(v) for k, v in diagnostics.items()})
            policy.update(learner.agent)

    def test_phase(tag: str, on: InsertionRobot) -> list[dict[str, Any]]:
        return [run_episode(on, Episode(f"{tag}{index:03d}", "test", index % N_START_POSES,
                                        spec.reward, on.residual), policy)
                for index in range(spec.test_episodes)]

    episodes, evaluations = [], []
    for index in range(spec.train_episodes):
        noise = ActionNoise(settings.noise, ACTION_DIM, episode_noise_seed(spec.seed, index))
        episode = Episode(f"train{index:03d}", "train", index % N_START_POSES, spec.reward,
                          env.residual, noise)
        episodes.append(run_episode(env, episode, policy, learn))
        if spec.eval_every and (index + 1) % spec.eval_every == 0:
            tests = test_phase(f"eval{index + 1:03d}_", env)
            evaluations.append({"train_episodes": index + 1, "sim_time": env.sim_time,
                                "rl_steps": env.steps,
                                "successes": sum(e["success"] for e in tests),
                                "mean_steps": float(np.mean([e["steps"] for e in tests]))})
            if evaluations[-1]["successes"] == spec.test_episodes:
                break
    moved = spec.test_housing_yaw or spec.test_housing_tilt
    test_env = env if not moved else InsertionRobot(
        settings.with_cell(housing_yaw=spec.test_housing_yaw,
                           housing_tilt=spec.test_housing_tilt), spec.estimator)
    if not spec.eval_every:
        episodes += test_phase("test", test_env)
    recovery = stall_recovery_config(spec.config_dir) if spec.stall_recovery else None
    if recovery is not None:        # apart from the test episodes: mode ``recovery``
        for index in range(spec.test_episodes):
            watch = StallRecovery(recovery, ACTION_DIM, recovery_seed(spec.seed, index),
                                  settings.noise, test_env.residual.progress_dims)
            result = run_episode(test_env, Episode(f"recovery{index:03d}", "test",
                                                   index % N_START_POSES, spec.reward,
                                                   test_env.residual), policy, recovery=watch)
            episodes.append({**result, "mode": "recovery"})
    envs = (env,) if test_env is env else (env, test_env)
    return {"experiment": spec.experiment, "name": spec.name,
            "spec": dataclasses.asdict(spec),
            "config_digest": config_digest(spec.config_dir), **settings.step_record,
            **({} if recovery is None else {"stall_recovery": dataclasses.asdict(recovery),
                                            "task_settings": spec.task_settings}),
            "episodes": episodes,
            "evaluations": evaluations, "cycles": cycles,
            "rl_steps": sum(e.steps for e in envs),
            "step_timeouts": sum(e.step_timeouts for e in envs),
            "sim_time": sum(e.sim_time for e in envs), "wall_time": time.perf_counter() - start}
