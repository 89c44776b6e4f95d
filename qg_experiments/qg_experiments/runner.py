"""One training-and-test run of the residual shaft insertion, in one process, without DDS.

The ROS stack runs the simulator, the bridge with its 1 kHz loop, the EKF, the executor and the
learner as separate nodes. Here the same cores are called directly: ``RobotLoop`` (sim + bridge +
estimator) executes each wrench, ``Episode`` / ``ResidualTask`` / ``ActionNoise`` decide actions,
rewards and episode ends exactly as the executor node does, and ``LearnerCore`` trains after every
cycle of 20 steps exactly as the learner node does. Everything is read from the same ``config/``
files; a run is a pure function of its :class:`RunSpec`, so the same seed gives the same steps.

Difference to the ROS stack, by construction: the learner trains synchronously at the end of a
cycle (the node trains while the robot keeps moving), and the executor's actor is refreshed right
after each cycle instead of when the parameters message arrives.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from qg_common.params import (
    check_section,
    config_file,
    load_ros_params,
    merge_params,
    section_values,
)
from qg_common.shaft_task import ShaftTaskGeometry
from qg_common.types import N_START_POSES, StepResult, WrenchSetpoint
from qg_learning_node.executor.episode import Actor, Episode, TransitionRecord
from qg_learning_node.executor.noise import ActionNoise, NoiseConfig
from qg_learning_node.executor.observation import observation_from_step
from qg_learning_node.executor.parameters import (
    load_geometry,
    load_noise,
    load_stall_recovery,
    load_task,
)
from qg_learning_node.executor.residual_task import (
    ACTION_DIM,
    Observation,
    ResidualTask,
    TaskConfig,
)
from qg_learning_node.executor.stall_recovery import StallRecovery, StallRecoveryConfig
from qg_learning_node.learner import algorithms
from qg_learning_node.learner.actor_mlp import ActorMLP
from qg_learning_node.learner.ddpg import DDPG
from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore
from qg_learning_node.learner.learner_params import learner_config_from_params
from robot_bridge_node.core.hardware_interface import (
    RobotPlugin,
    load_robot,
    robot_defaults,
    robot_plugin,
)
from robot_bridge_node.core.rest_detector import RestConfig
from robot_bridge_node.core.robot_loop import MeasuredWrench, RobotLoop, build_loop
from robot_bridge_node.core.torque_kind import EKF_SECTION, TORQUE
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig

__all__ = ["ALGORITHMS", "ARMS", "ESTIMATORS", "DEFAULT_ROBOT", "StackSettings", "InsertionRobot",
           "LivePolicy",
           "RunSpec", "MonteCarloCheck",
           "algorithm_config", "run_episode", "run_training", "episode_noise_seed", "zero_policy",
           "config_digest", "STACK_CONFIG_FILES", "recovery_seed", "stall_recovery_config"]

#: Our learner's algorithms, as the registry names them (``learner/algorithms.py``): vanilla
#: DDPG (no bounds, no zero-action loops), QG-DDPG (graph + a-priori bounds, the zero residual as
#: zero action) and QG-DDPG's parts apart.
ALGORITHMS = algorithms.keys("ours")
ESTIMATORS = ("ekf", "ground_truth")


def algorithm_config(base: LearnerConfig, algorithm: str, action_dim: int) -> LearnerConfig:
    """``base`` with the bounds, zero action and graph of ``algorithm`` (see :data:`ALGORITHMS`);
    the residual's zero action is zero torque."""
    return algorithms.algorithm(algorithm, "ours").learner_config(base, (0.0,) * action_dim)


#: The files of ``config/`` whose numbers the runs use (the Panda's, the cell's, the free
#: peg's and the Nextage peg's), each with the sections the runs read (``None``: all of it).
#: Node-only settings (timeouts, checkpoint folders) are not the runs' numbers.
STACK_CONFIG_FILES: dict[str, tuple[str, ...] | None] = {
    "shaft_task.yaml": None, "panda_scene.yaml": None, "panda_ideal.yaml": None,
    "bridge.yaml": None, "wrench_estimator.yaml": None, "executor.yaml": ("task", "noise"),
    "learner.yaml": ("learner",), "peg_env.yaml": None, "peg_task.yaml": None,
    "nextage.yaml": None, "executor_nextage.yaml": ("task", "peg", "noise")}

#: The simulated arm: ``realistic`` (the robot's config file's imperfections, the default) or
#: ``ideal`` (``panda_ideal.yaml`` on top: the Panda exactly as the bridge models it).
ARMS = ("realistic", "ideal")
#: The robot the runs drive unless a spec names another (a plugin of ``robot_bridge_node.robots``
#: with the shaft task: ``sim_panda``, ``sim_panda_mujoco``, ``sim_xarm7``, ...).
DEFAULT_ROBOT = "sim_panda"


def config_digest(directory: str | Path | None = None) -> str:
    """Short hash of the numbers in the stack's config files: a saved run is reused only under
    the same ones. The files are hashed as parsed (key, value), so a comment or the layout of a
    file does not count as a new setting; a changed value does."""
    parsed = {}
    for name, sections in STACK_CONFIG_FILES.items():
        params = load_ros_params(config_file(name, directory))
        parsed[name] = params if sections is None else {k: params.get(k) for k in sections}
    text = json.dumps(parsed, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def episode_noise_seed(run_seed: int, index: int) -> int:
    """Exploration-noise seed of episode ``index`` of a run (distinct across runs and episodes)."""
    return 1_000_003 * run_seed + 1000 + index


def _imperfect_section(plugin: RobotPlugin) -> str:
    """The prefix of the robot's scene section, the one with its ``imperfections`` (whose
    ``seed`` picks the robot)."""
    for section in plugin.parameters:
        if "imperfections" in {f.name for f in dataclasses.fields(section.config)}:
            return section.prefix
    raise ValueError("the robot has no imperfections to seed (not a simulated shaft arm)")


@dataclass(frozen=True)
class StackSettings:
    """What the ROS nodes read from ``config/``, read once: one source of numbers for both paths.

    :param robot_name: the robot plugin the runs drive.
    :param robot: that robot's parameters as its node declares them (its config files: the
        cell's ``shaft_task`` and its scene's section);
    :param bridge: ``ros__parameters`` of ``bridge.yaml`` under the robot's own gains; :param ekf:
        the ``ekf`` section of ``wrench_estimator.yaml``; the rest are the executor's and
        learner's parsed sections.
    """
    robot_name: str
    robot: dict[str, Any]
    bridge: dict[str, Any]
    ekf: dict[str, Any]
    task: TaskConfig
    noise: NoiseConfig
    learner: LearnerConfig

    @classmethod
    def load(cls, directory: Path | None = None, arm: str = "realistic",
             robot: str = DEFAULT_ROBOT) -> StackSettings:
        """The config files of ``directory`` (default: the installed ones), with ``arm``."""
        if arm not in ARMS:
            raise ValueError(f"arm must be one of {ARMS}, got {arm!r}")
        plugin = robot_plugin(robot)
        if directory is None:
            params = robot_defaults(plugin)
        else:
            params = {}
            for _, name in plugin.config_files:
                params = merge_params(params, load_ros_params(config_file(name, directory)))
        if arm == "ideal":
            params = merge_params(params, load_ros_params(config_file("panda_ideal.yaml",
                                                                      directory)))
        executor = load_ros_params(config_file("executor.yaml", directory))
        bridge = load_ros_params(config_file("bridge.yaml", directory))
        for _, name in plugin.config_files:   # a robot's own gains (the xArm's damping)
            own = load_ros_params(config_file(name, directory))
            bridge = merge_params(bridge, {k: v for k, v in own.items()
                                           if k in {s.prefix for s in TORQUE.controller_sections}})
        estimator = load_ros_params(config_file("wrench_estimator.yaml", directory))
        # Each file through the sections its node declares: what a node would refuse (a value
        # out of range, a misspelt key), the experiments refuse too.
        files = ", ".join(name for _, name in plugin.config_files)
        for section in plugin.parameters:
            check_section(section, section_values(section, params), files)
        for section in TORQUE.controller_sections:
            check_section(section, section_values(section, bridge), "bridge.yaml")
        return cls(robot_name=robot, robot=params, bridge=bridge,
                   ekf=check_section(EKF_SECTION, estimator["ekf"], "wrench_estimator.yaml"),
                   task=load_task(executor, "executor.yaml"),
                   noise=load_noise(executor, "executor.yaml"),
                   learner=learner_config_from_params(
                       load_ros_params(config_file("learner.yaml", directory))["learner"],
                       "learner.yaml"))

    @property
    def geometry(self) -> ShaftTaskGeometry:
        """The cell both sides use: the robot's scene and the task's target and starts."""
        return load_geometry(self.robot, "shaft_task.yaml")

    @property
    def engine(self) -> str:
        """The physics engine of the robot's scene."""
        return str(self.robot[_imperfect_section(robot_plugin(self.robot_name))].get(
            "engine", "pybullet"))

    @property
    def step_limit(self) -> float:
        """[s] the RL step's time limit (``rest.max_time``): a step not at rest by then ends."""
        return float(self.bridge.get("rest", {}).get("max_time", RestConfig().max_time))

    @property
    def step_record(self) -> dict[str, Any]:
        """The step a robot run measured, as its saved record names it (``engine``,
        ``step_limit``: what the report's ``step_label`` reads)."""
        return {"engine": self.engine, "step_limit": self.step_limit}

    def with_arm_seed(self, seed: int) -> StackSettings:
        """The same settings on robot ``seed``: the arm's biases, housing error and noise
        streams (``<scene>.imperfections.seed``). A run's seed picks its arm, so DDPG and
        QG-DDPG of one seed, and the random baseline of that seed, meet the same robot."""
        section = _imperfect_section(robot_plugin(self.robot_name))
        return dataclasses.replace(self, robot=merge_params(
            self.robot, {section: {"imperfections": {"seed": int(seed)}}}))

    def with_cell(self, **changes: Any) -> StackSettings:
        """The same settings in a cell whose ``shaft_task`` numbers differ by ``changes`` (the
        housing turned or tilted: both the simulated scene and the task see it, as in a cell
        whose fixture was measured)."""
        cell = {**self.robot.get("shaft_task", {}), **changes}
        load_geometry({"shaft_task": cell}, "with_cell")          # refused as a node would
        return dataclasses.replace(self, robot={**self.robot, "shaft_task": cell})


class InsertionRobot:
    """The robot side of the stack in-process: the robot plugin, the bridge loop and the wrench
    estimator, on the shaft task.

    It answers what the executor asks over DDS: the move to a start, and one wrench executed
    until rest, each as an :class:`Observation` (the tool pose of the measured joints).
    :param estimator: ``ekf`` (what the ROS stack runs) or ``ground_truth`` (a perfect sensor).
    """

    def __init__(self, settings: StackSettings, estimator: str = "ekf") -> None:
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
        ekf = WrenchEKFConfig.from_dict(settings.ekf)
        self.settings = settings
        self.loop: RobotLoop = build_loop(
            load_robot(settings.robot_name, settings.robot), settings.bridge,
            (lambda robot, model: WrenchEKF(ekf, model)) if estimator == "ekf"
            else (lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench)))
        self.loop.begin()
        self.residual = ResidualTask(settings.task, settings.geometry)
        self.sim_time = 0.0
        self.steps = 0
        self.step_timeouts = 0

    def _observe(self, result: StepResult) -> Observation:
        tool = self.loop.controller.tool
        return observation_from_step(result, tool.position, tool.rotation)

    def reset(self, initial_pose: int) -> Observation:
        """The task's start ``initial_pose`` reached and settled, observed like the end of a
        step."""
        self.loop.reset(self.residual.start_pose(initial_pose))
        return self._observe(self.loop.result(self.loop.time))

    def step(self, action: np.ndarray) -> Observation:
        """Execute the residual ``action`` (actor units) until the tool is at rest."""
        result = self.loop.execute(WrenchSetpoint(self.residual.wrench(action)))
        self.sim_time += result.duration
        self.steps += 1
        self.step_timeouts += int(result.timed_out)
        return self._observe(result)

    def close(self) -> None:
        """Release the simulation (the robot plugin's physics world) where it offers that;
        a process that builds many tasks, like a seeded Gymnasium environment, needs it."""
        close = getattr(self.loop.simulation, "close", None)
        if close is not None:
            close()


class LivePolicy:
    """The executor's copy of the actor, replaced after every training cycle."""

    def __init__(self, agent: DDPG) -> None:
        self.update(agent)

    def update(self, agent: DDPG) -> None:
        self.actor = ActorMLP.from_tensors(agent.actor_tensors())

    def __call__(self, state: np.ndarray) -> np.ndarray:
        return self.actor(state)


def zero_policy(state: np.ndarray) -> np.ndarray:
    """The base policy alone; with exploration noise on top it is a random residual policy."""
    del state
    return np.zeros(ACTION_DIM)


def run_episode(env: InsertionRobot, episode: Episode, actor: Actor,
                on_transition: Callable[[TransitionRecord], None] | None = None,
                recovery: StallRecovery | None = None) -> dict[str, Any]:
    """Drive ``episode`` to its end on ``env``; ``on_transition(record)`` after every step.

    :param recovery: stall recovery between the actor and the robot, as the executor node
        runs it in test episodes; the result then counts its ``recoveries`` and their steps.
    """
    episode.begin(env.reset(episode.initial_pose))
    while not episode.done:
        action = episode.choose_action(actor)
        if recovery is not None:
            action = recovery.act(episode.state, action)
        record: TransitionRecord = episode.observe(action, env.step(action))
        if on_transition is not None:
            on_transition(record)
    result = {"episode": episode.episode_id, "mode": episode.mode, "pose": episode.initial_pose,
              "steps": episode.step, "success": episode.success,
              "end_reason": episode.end_reason, "return": episode.episode_return,
              "truly_inserted": episode.truly_inserted}
    if recovery is not None:
        result.update(recoveries=recovery.recoveries, recovered_at=list(recovery.started_at))
    return result


#: Recovery episodes' perturbation seeds start here (``recovery_seed``): apart from training's.
_RECOVERY_SEEDS = 100_000


def recovery_seed(run_seed: int, index: int) -> int:
    """Perturbation seed of recovery episode ``index`` of a run (distinct from every training
    episode's noise seed of the same run)."""
    return episode_noise_seed(run_seed, _RECOVERY_SEEDS + index)


def stall_recovery_config(config_dir: str | None = None) -> StallRecoveryConfig:
    """``executor.yaml``'s ``stall_recovery`` section, checked as the node checks it, switched
    on (a run asks for recovery by ``RunSpec.stall_recovery``)."""
    params = load_ros_params(config_file("executor.yaml", config_dir))
    return dataclasses.replace(load_stall_recovery(params, "executor.yaml"), enabled=True)


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
        return run_training(self)


class MonteCarloCheck:
    """How far the critic is from the true discounted return of the episodes it was trained on.

    For every finished training episode that reached the goal, the discounted return from each
    step on is known exactly (the episode ended in a terminal state); ``error`` is the mean
    absolute difference between the critic's ``Q(s_t, a_t)`` and that return over all of them.
    Episodes cut by the step cap have no exact return and are left out.
    """

    def __init__(self, gamma: float) -> None:
        self.gamma = gamma
        self._open: list[TransitionRecord] = []
        self.states: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.returns: list[float] = []

    def add(self, record: TransitionRecord) -> None:
        self._open.append(record)
        if record.terminal:
            value = 0.0
            for step in reversed(self._open):
                value = step.reward + self.gamma * value
                self.states.append(step.state)
                self.actions.append(step.action)
                self.returns.append(value)
        if record.terminal or record.timeout:
            self._open = []

    def error(self, agent: DDPG) -> float:
        """Mean |Q(s, a) - G| over the goal-reaching episodes so far (NaN before the first)."""
        if not self.returns:
            return float("nan")
        q = agent.q_values(np.array(self.states), np.array(self.actions))
        return float(np.mean(np.abs(np.ravel(q) - np.array(self.returns))))


def run_training(spec: RunSpec) -> dict[str, Any]:
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
                                  settings.noise)
            result = run_episode(test_env, Episode(f"recovery{index:03d}", "test",
                                                   index % N_START_POSES, spec.reward,
                                                   test_env.residual), policy, recovery=watch)
            episodes.append({**result, "mode": "recovery"})
    envs = (env,) if test_env is env else (env, test_env)
    return {"experiment": spec.experiment, "name": spec.name, "spec": dataclasses.asdict(spec),
            "config_digest": config_digest(spec.config_dir), **settings.step_record,
            **({} if recovery is None else {"stall_recovery": dataclasses.asdict(recovery),
                                            "task_settings": spec.task_settings}),
            "episodes": episodes,
            "evaluations": evaluations, "cycles": cycles,
            "rl_steps": sum(e.steps for e in envs),
            "step_timeouts": sum(e.step_timeouts for e in envs),
            "sim_time": sum(e.sim_time for e in envs), "wall_time": time.perf_counter() - start}



