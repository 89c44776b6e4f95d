"""The executor's parameters as sections (names, ranges, which may change while it runs), and
the validated loaders of its config files.

Pure (no rclpy), so the executor node declares exactly these sections and what reads
``config/executor.yaml`` without a node (the in-process experiments) checks the same ranges
through ``load_task`` / ``load_noise``: a value the node refuses is refused there too.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from qg_common.params import POSITIVE, ParameterSection, check_section, config_from_dict
from qg_common.peg_task import PEG_TASK_FILE, PEG_TASK_SECTION
from qg_common.shaft_task import SHAFT_TASK_FILE, SHAFT_TASK_SECTION, ShaftTaskGeometry

from qg_learning_node.executor.noise import NoiseConfig
from qg_learning_node.executor.peg_task import PegTaskConfig
from qg_learning_node.executor.residual_task import TaskConfig
from qg_learning_node.executor.stall_recovery import StallRecoveryConfig

__all__ = ["ExecutorConfig", "TaskChoice", "PolicyChoice", "EXECUTOR_SECTIONS", "NOISE_SECTION",
           "POLICY_SECTION", "TASK_SECTIONS",
           "CELL_SECTIONS", "TASK_CHOICE_SECTION", "TIMING_SECTION", "load_noise", "load_task",
           "load_geometry", "STALL_RECOVERY_SECTION", "load_stall_recovery"]


@dataclass(frozen=True)
class ExecutorConfig:
    """How long the executor waits for the other nodes (``config/executor.yaml``, top level).

    :param step_timeout: [s] wall time to wait for the at-rest event of one step.
    :param reset_timeout: [s] wall time to wait for ``move_to_start`` (a motion takes seconds).
    :param keepalive_period: [s] re-send the running setpoint this often; 0 = never. No robot
        needs it (a step's setpoint holds until the step ends; the realtime watchdog counts from
        a step's end); a commander whose messages may be lost can use it.
    :param learner_timeout: [s] no word from the learner this long -> degraded (zero residual).
    :param robot_grace: [s] an episode start waits this long for a robot (``move_to_start``) not
        discovered yet before it refuses.
    :param learner_grace: [s] an episode's first step waits this long for a learner not heard
        from lately (not discovered yet, or restarting) before it runs degraded with the zero
        residual.
    """
    step_timeout: float = 10.0
    reset_timeout: float = 30.0
    keepalive_period: float = 0.0
    learner_timeout: float = 2.0
    robot_grace: float = 10.0
    learner_grace: float = 3.0

    def __post_init__(self) -> None:
        for name in ("step_timeout", "reset_timeout", "learner_timeout"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0 s, got {getattr(self, name)}")
        for name in ("keepalive_period", "robot_grace", "learner_grace"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0 s, got {getattr(self, name)}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ExecutorConfig:
        """From the executor's parameters (its top-level ones; the sections are skipped)."""
        own = {f.name for f in fields(cls)}
        return config_from_dict(cls, {k: v for k, v in params.items() if k in own})


@dataclass(frozen=True)
class TaskChoice:
    """Which task the executor runs.

    :param kind: ``residual`` (the Panda's residual force policy, section ``task``) or ``peg``
        (the Nextage's peg-in-hole by position offsets, section ``peg``).
    """
    kind: str = "residual"


#: Why the task's numbers are fixed while the executor runs.
_TASK_FIXED = ("read-only: it defines the states, actions and rewards the learner's networks "
               "and replay memory were built on; restart the executor and the learner to "
               "change it")

TASK_CHOICE_SECTION = ParameterSection("task", TaskChoice, fixed=_TASK_FIXED)

#: Timeouts: every one settable while the executor runs (from the next wait on).
TIMING_SECTION = ParameterSection("", ExecutorConfig, ranges={
    "step_timeout": (0.0, 3600.0), "reset_timeout": (0.0, 3600.0),
    "keepalive_period": (0.0, 1.0), "learner_timeout": (0.0, 3600.0),
    "robot_grace": (0.0, 60.0), "learner_grace": (0.0, 60.0)},
    runtime=frozenset(f.name for f in fields(ExecutorConfig)), applies="from the next step")

#: Exploration noise: settable while the executor runs; an episode keeps the noise it began with.
NOISE_SECTION = ParameterSection("noise", NoiseConfig, ranges={
    "sigma": (0.0, 10.0), "theta": (0.0, 100.0), "dt": POSITIVE},
    runtime=frozenset(f.name for f in fields(NoiseConfig)), applies="from the next episode")


@dataclass(frozen=True)
class PolicyChoice:
    """Which actor the executor runs: the learner's, or a frozen one from a policy file.

    :param file: a policy file (``qgl export-policy``); "" runs the learner's actor from
        ``/actor_parameters``. Set, the executor runs this actor frozen, never waits for a
        learner, and refuses at start a file whose task, observation, sizes, settings or robot
        do not fit its own (``qg_learning_node/policy_file.py``).
    :param robot: the robot plugin this stack drives (the robot process's ``robot``), which a
        policy file's robot is checked against; ``qgl up --policy`` sets it from the stack file.
    """
    file: str = ""
    robot: str = "sim_panda"


#: The frozen policy: read and checked once, at start.
POLICY_SECTION = ParameterSection("policy", PolicyChoice, fixed=(
    "read-only: the policy file is loaded and checked once, at start; restart the executor "
    "to run another"))

#: Stall recovery in test episodes (off: the thesis protocol); an episode keeps the recovery it
#: began with.
STALL_RECOVERY_SECTION = ParameterSection("stall_recovery", StallRecoveryConfig, ranges={
    "window": (2, 100000), "max_period": (1, 100), "state_tolerance": (0.0, 10.0),
    "action_tolerance": (0.0, 10.0), "progress_tolerance": (0.0, 10.0), "steps": (1, 100000),
    "growth": (1.0, 100.0), "dither": (0.0, 2.0), "max_recoveries": (0, 100000)},
    runtime=frozenset(f.name for f in fields(StallRecoveryConfig)),
    applies="from the next episode")

#: The executor's parameters besides its task's.
EXECUTOR_SECTIONS = (TIMING_SECTION, NOISE_SECTION, POLICY_SECTION,
                     STALL_RECOVERY_SECTION)

#: Each task kind's section. The default reward and the step caps may change between episodes
#: (a running episode keeps its own); everything else defines the learner's MDP. Each kind's
#: cell (``CELL_SECTIONS``) is a section and a file of its own, which the robot side reads too.
TASK_SECTIONS = {
    "residual": ParameterSection("task", TaskConfig, ranges={
        "max_residual_torque": (0.0, 3.0), "force_range": POSITIVE, "torque_range": POSITIVE,
        "sigma_position": POSITIVE, "sigma_orientation": POSITIVE,
        "train_max_steps": (1, 1000000),
        "test_max_steps": (1, 1000000), "tilt_range": POSITIVE},
        runtime=frozenset({"reward", "train_max_steps", "test_max_steps"}),
        applies="from the next episode", fixed=_TASK_FIXED),
    "peg": ParameterSection("peg", PegTaskConfig, ranges={
        "action_scale": (0.0, 0.1), "reward_length": POSITIVE, "train_max_steps": (1, 1000000),
        "test_max_steps": (1, 1000000)},
        runtime=frozenset({"reward", "train_max_steps", "test_max_steps"}),
        applies="from the next episode", fixed=_TASK_FIXED),
}


#: Each task kind's cell: its parameter section and the file of its defaults (``qg_common``).
CELL_SECTIONS = {"residual": (SHAFT_TASK_SECTION, SHAFT_TASK_FILE),
                 "peg": (PEG_TASK_SECTION, PEG_TASK_FILE)}


def load_task(params: dict[str, Any], source: str = "") -> TaskConfig:
    """The residual task of the executor's parameters (``config/executor.yaml`` parsed),
    checked as the node checks it (``check_section``)."""
    values = dict(params.get("task") or {})
    values.pop("kind", None)            # the task choice, a section of its own
    return TaskConfig.from_dict(check_section(TASK_SECTIONS["residual"], values, source))


def load_noise(params: dict[str, Any], source: str = "") -> NoiseConfig:
    """The exploration noise of the executor's parameters, checked as the node checks it."""
    return NoiseConfig.from_dict(check_section(NOISE_SECTION, params.get("noise") or {}, source))


def load_stall_recovery(params: dict[str, Any], source: str = "") -> StallRecoveryConfig:
    """The stall recovery of the executor's parameters, checked as the node checks it."""
    return StallRecoveryConfig.from_dict(check_section(
        STALL_RECOVERY_SECTION, params.get("stall_recovery") or {}, source))


def load_geometry(params: dict[str, Any], source: str = "") -> ShaftTaskGeometry:
    """The shaft task's cell (``config/shaft_task.yaml`` parsed), checked as a node checks it."""
    return ShaftTaskGeometry.from_dict(check_section(SHAFT_TASK_SECTION,
                                                     params.get("shaft_task") or {}, source))
