"""What one learning run of the shaft insertion is: its fields, their checks and its name.

Why: a run is a pure function of its :class:`RunSpec`; the name and the fields are how a saved
run is found and reused (``tasks``), so they are kept apart from how a run executes
(``training``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_learning_node.learner import algorithms
from qg_learning_node.learner.learner_config import LearnerConfig

from qg_experiments.core.insertion_robot import ESTIMATORS
from qg_experiments.core.stack_settings import ARMS, DEFAULT_ROBOT, stall_recovery_config

__all__ = ["ALGORITHMS", "RunSpec", "algorithm_config"]

#: Our learner's algorithms, as the registry names them (``learner/algorithms.py``): vanilla
#: DDPG (no bounds, no zero-action loops), QG-DDPG (graph + a-priori bounds, the zero residual as
#: zero action) and QG-DDPG's parts apart.
ALGORITHMS = algorithms.keys("ours")


def algorithm_config(base: LearnerConfig, algorithm: str, action_dim: int) -> LearnerConfig:
    """``base`` with the bounds, zero action and graph of ``algorithm`` (see :data:`ALGORITHMS`);
    the residual's zero action is zero torque."""
    return algorithms.algorithm(algorithm, "ours").learner_config(base, (0.0,) * action_dim)


@dataclass(frozen=True)
class RunSpec:
    """One learning run: a grid cell (or variant) of one algorithm with one seed.

    :param critic_lr: the actor's is one tenth (``learner.yaml``'s ``actor_lr: 0``).
    :param iterations: training iterations per cycle of ``cycle_steps`` RL steps.
    :param replay_capacity: ``None`` keeps ``learner.yaml``'s setting; so does ``cycle_steps``.
    :param reward: ``dense`` | ``sparse``.
    :param observation: the state (``residual_task.OBSERVATIONS``); ``None`` keeps
        ``executor.yaml``'s.
    :param test_housing_yaw: [rad] housing rotation about the vertical in the test episodes
        (training always runs at 0): the generalisation test.
    :param test_housing_tilt: [rad] the housing's fixture tilt in the test episodes (about its x
        axis, after the yaw); the test then measures the tilt against the tilted bore axis, as
        a real cell would from its fixture (``shaft_task.housing_tilt``).
    :param graph_resolution: Q-Graph state merging (``LearnerConfig.graph_resolution``).
    :param schedule: the learner's schedule, ``cycle`` | ``async`` (``learner_core``); with
        ``async``, ``updates_per_step`` and ``publish_every`` apply.
    :param eval_every: > 0: after every this many training episodes, test on the test poses
        (``evaluations`` in the result, simulated robot time included) and stop at the first
        evaluation that solves them all; the final test phase is then left out.
    :param arm: ``realistic`` | ``ideal`` (:data:`ARMS`); the arm's seed is ``seed``.
    :param gamma: the discount; ``None`` keeps ``learner.yaml``'s.
    :param robot: the robot plugin (:data:`DEFAULT_ROBOT`; ``sim_panda_mujoco``, ...).
    :param stall_recovery: after the test episodes (the thesis protocol, untouched), the same
        poses again with stall recovery (``executor.yaml``'s ``stall_recovery``), as episodes
        of mode ``recovery``, each with its ``recoveries``: counted apart, never in the test
        numbers.
    """
    algorithm: str
    critic_lr: float
    iterations: int
    seed: int
    train_episodes: int = 40
    test_episodes: int = 8
    train_max_steps: int = 1000
    test_max_steps: int = 200
    reward: str = "dense"
    replay_capacity: int | None = None
    cycle_steps: int | None = None
    estimator: str = "ekf"
    config_dir: str | None = None
    experiment: str = "grid"
    observation: str | None = None
    test_housing_yaw: float = 0.0
    test_housing_tilt: float = 0.0
    graph_resolution: float = 0.0
    schedule: str = "cycle"
    updates_per_step: float = 10.0
    publish_every: int = 20
    eval_every: int = 0
    arm: str = "realistic"
    gamma: float | None = None
    robot: str = DEFAULT_ROBOT
    stall_recovery: bool = False

    def __post_init__(self) -> None:
        if self.arm not in ARMS:
            raise ValueError(f"arm must be one of {ARMS}, got {self.arm!r}")
        if self.gamma is not None and not 0.0 < self.gamma < 1.0:
            raise ValueError(f"gamma must be in (0, 1), got {self.gamma}")
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {self.algorithm!r}")
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {self.estimator!r}")
        if self.train_episodes < 0 or self.test_episodes < 0:
            raise ValueError("episode counts must be >= 0")
        if not self.critic_lr > 0 or self.iterations < 1:
            raise ValueError("critic_lr must be > 0 and iterations >= 1")

    @property
    def name(self) -> str:
        """The run's file name: the algorithm, rate and iterations, each field off its default,
        the seed."""
        extra = f"_{self.reward}" if self.reward != "dense" else ""
        extra += f"_cap{self.replay_capacity}" if self.replay_capacity else ""
        extra += f"_{self.observation}" if self.observation else ""
        extra += f"_yaw{self.test_housing_yaw:g}" if self.test_housing_yaw else ""
        extra += f"_tilt{self.test_housing_tilt:g}" if self.test_housing_tilt else ""
        extra += f"_res{self.graph_resolution:g}" if self.graph_resolution else ""
        extra += (f"_async{self.updates_per_step:g}x{self.publish_every}"
                  if self.schedule == "async" else "")
        extra += f"_eval{self.eval_every}" if self.eval_every else ""
        extra += f"_g{self.gamma:g}" if self.gamma is not None else ""
        extra += "_ideal" if self.arm == "ideal" else ""
        extra += f"_{self.robot}" if self.robot != DEFAULT_ROBOT else ""
        extra += "_recovery" if self.stall_recovery else ""
        return f"{self.algorithm}_lr{self.critic_lr:g}_it{self.iterations}{extra}_s{self.seed}"

    @property
    def task_settings(self) -> dict[str, Any]:
        """Numbers the run reads beside its fields and ``config_digest``'s: with
        ``stall_recovery``, ``executor.yaml``'s ``stall_recovery`` section. Saved with the run;
        a saved run is reused only under the same (``tasks``)."""
        if not self.stall_recovery:
            return {}
        return {"stall_recovery": dataclasses.asdict(stall_recovery_config(self.config_dir))}

    def learner_config(self, base: LearnerConfig) -> LearnerConfig:
        """``learner.yaml``'s ``base`` with this run's algorithm, rates, seed and schedule."""
        config = algorithm_config(base, self.algorithm, ACTION_DIM)
        ddpg = dataclasses.replace(config.ddpg, critic_lr=self.critic_lr, actor_lr=None,
                                   seed=self.seed,
                                   gamma=config.ddpg.gamma if self.gamma is None else self.gamma)
        return dataclasses.replace(
            config, ddpg=ddpg, iterations_per_cycle=self.iterations, seed=self.seed,
            graph_resolution=self.graph_resolution, schedule=self.schedule,
            updates_per_step=self.updates_per_step, publish_every=self.publish_every,
            replay_capacity=self.replay_capacity or config.replay_capacity,
            cycle_steps=self.cycle_steps or config.cycle_steps)

    def run(self) -> dict[str, Any]:
        """Train and test (``training.run_training``): the run's saved record."""
        from qg_experiments.training import run_training
        return run_training(self)
