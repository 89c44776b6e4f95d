"""The stack's numbers from ``config/``, merged as the robot, bridge, estimator, executor and
learner nodes read them.

Why: the in-process paths (runs, Gymnasium environments, report) and the ROS nodes must use one
source of numbers; every default here is the one of the config dataclass that owns it.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qg_common.params import (
    ParameterSection,
    check_section,
    config_file,
    field_default,
    load_ros_params,
    merge_params,
    section_values,
)
from qg_common.shaft_task import ShaftTaskGeometry
from qg_learning_node.executor.noise import NoiseConfig
from qg_learning_node.executor.parameters import (
    load_geometry,
    load_noise,
    load_stall_recovery,
    load_task,
)
from qg_learning_node.executor.residual_task import TaskConfig
from qg_learning_node.executor.stall_recovery import StallRecoveryConfig
from qg_learning_node.learner.learner_config import LearnerConfig
from qg_learning_node.learner.learner_params import learner_config_from_params
from robot_bridge_node.core.hardware_interface import RobotPlugin, robot_defaults, robot_plugin
from robot_bridge_node.core.rest_detector import RestConfig
from robot_bridge_node.core.torque_kind import EKF_SECTION, TORQUE

__all__ = ["ARMS", "DEFAULT_ROBOT", "IDEAL_ARM_FILE", "STACK_CONFIG_FILES", "StackSettings",
           "config_digest", "stall_recovery_config"]

#: The files of ``config/`` whose numbers the runs use (the Panda's, the cell's, the free
#: peg's and the Nextage peg's), each with the sections the runs read (``None``: all of it).
#: Node-only settings (timeouts, checkpoint folders) are not the runs' numbers.
STACK_CONFIG_FILES: dict[str, tuple[str, ...] | None] = {
    "shaft_task.yaml": None, "panda_scene.yaml": None, "panda_ideal.yaml": None,
    "bridge.yaml": None, "wrench_estimator.yaml": None, "executor.yaml": ("task", "noise"),
    "learner.yaml": ("learner",), "peg_env.yaml": None, "peg_task.yaml": None,
    "nextage.yaml": None, "executor_nextage.yaml": ("task", "peg", "noise")}

#: The simulated arm: ``realistic`` (the robot's config file's imperfections, the default) or
#: ``ideal`` (:data:`IDEAL_ARM_FILE` on top: the Panda exactly as the bridge models it).
ARMS = ("realistic", "ideal")
#: The overlay of the ``ideal`` arm; it sets the Panda's scene only, so only a robot with that
#: scene section has an ideal arm.
IDEAL_ARM_FILE = "panda_ideal.yaml"
#: The robot the runs drive unless told another (a plugin of ``robot_bridge_node.robots`` with
#: the shaft task: ``sim_panda``, ``sim_panda_mujoco``, ``sim_xarm7``, ...).
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


def stall_recovery_config(config_dir: str | Path | None = None) -> StallRecoveryConfig:
    """``executor.yaml``'s ``stall_recovery`` section, checked as the node checks it, switched
    on (a run asks for recovery by ``RunSpec.stall_recovery``)."""
    params = load_ros_params(config_file("executor.yaml", config_dir))
    return dataclasses.replace(load_stall_recovery(params, "executor.yaml"), enabled=True)


def _imperfect_section(plugin: RobotPlugin) -> ParameterSection:
    """The robot's scene section, the one with its ``imperfections`` (whose ``seed`` picks the
    robot)."""
    for section in plugin.parameters:
        if "imperfections" in {f.name for f in dataclasses.fields(section.config)}:
            return section
    raise ValueError("the robot has no imperfections to seed (not a simulated shaft arm)")


def _ideal_arm(plugin: RobotPlugin, robot: str, directory: Path | None) -> dict[str, Any]:
    """:data:`IDEAL_ARM_FILE`'s parameters, for a robot that has every section it sets.

    :raises ValueError: for a robot the overlay does not describe (the xArm's scene is not the
        Panda's: layered on, it would leave the arm realistic and the run named ideal).
    """
    overlay = load_ros_params(config_file(IDEAL_ARM_FILE, directory))
    missing = sorted(set(overlay) - {section.prefix for section in plugin.parameters})
    if missing:
        raise ValueError(f"arm 'ideal' ({IDEAL_ARM_FILE}: {', '.join(missing)}) is not an arm "
                         f"of robot {robot!r}; use arm 'realistic'")
    return overlay


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
        """The config files of ``directory`` (default: the installed ones), with ``arm``.

        :raises ValueError: for an arm not in :data:`ARMS`, ``ideal`` for a robot without the
            Panda's scene, or a value its node would refuse.
        """
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
            params = merge_params(params, _ideal_arm(plugin, robot, directory))
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
        """The physics engine of the robot's scene (unset: its scene config's default)."""
        section = _imperfect_section(robot_plugin(self.robot_name))
        default = next(field_default(f) for f in dataclasses.fields(section.config)
                       if f.name == "engine")
        return str(self.robot.get(section.prefix, {}).get("engine", default))

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
        section = _imperfect_section(robot_plugin(self.robot_name)).prefix
        return dataclasses.replace(self, robot=merge_params(
            self.robot, {section: {"imperfections": {"seed": int(seed)}}}))

    def with_cell(self, **changes: Any) -> StackSettings:
        """The same settings in a cell whose ``shaft_task`` numbers differ by ``changes`` (the
        housing turned or tilted: both the simulated scene and the task see it, as in a cell
        whose fixture was measured)."""
        cell = {**self.robot.get("shaft_task", {}), **changes}
        load_geometry({"shaft_task": cell}, "with_cell")          # refused as a node would
        return dataclasses.replace(self, robot={**self.robot, "shaft_task": cell})
