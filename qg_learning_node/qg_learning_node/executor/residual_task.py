"""The residual force-policy MDP of the shaft insertion: state, action, reward, episode end.

One definition for the ROS executor and the fast in-process runner, so both run the same task:
- state, by ``TaskConfig.observation``:
  ``thesis``: estimated contact (Fx, Fy, Tx, Ty) in the EEF frame, linearly scaled to [-1, 1]
  (SPEC section 1). At rest the contact wrench balances the commanded one, so this state echoes
  the previous action and hides which way the shaft is tilted (docs/learning.md).
  ``tilt``: the same four numbers plus the tool's tilt away from the push axis, (ex, ey) of the
  rotation that would align the tool z axis with it, in the EEF frame, from forward kinematics of
  the measured joints (a real arm has it); scaled by ``tilt_range``.
  ``tilt_only``: the tilt alone; ``tilt_force``: the tilt and (Fx, Fy). Both leave out the
  torques (Tx, Ty), which at rest echo the last action: with them the actor reads its own
  previous output, and without exploration noise that loop can hold it at a fixed point
  (docs/learning.md, section 2).
  ``tilt_depth``: the tilt and the tip's depth below the bearing face along the bore axis, from
  the same measured pose against the cell's fixture (what the reward is measured on); scaled by
  ``depth_range``. A jam and an insertion under way share a tilt; the depth tells how far each
  got (docs/learning.md, section 20).
  ``tilt_motion``: the tilt and how far the last step moved the tip along the bore axis (the
  change of that measured depth since the previous observation; 0 at an episode's start),
  scaled by ``motion_range``: a jam is a step that did not move (section 20).
- action: actor output in [-1, 1]^2 scaled to residual torques (tx, ty) of at most 3 Nm, on top
  of the constant base push Fz = -15 N: the feed-forward wrench [0, 0, Fz, tx, ty, 0];
- reward: sparse (-1 per step, 0 at the goal) or dense (pose error to the inserted pose);
- the episode ends at the goal (terminal), at its step cap, or when the shaft leaves the bore.

Reward, the goal and "left the bore" are measured on the tool pose the robot reports (forward
kinematics of its measured joints) against the cell's fixture (``qg_common.shaft_task``, the
task's ``shaft_task.*`` parameters), as a real cell measures them; a simulation's truth rides
along in the observation for evaluation only. The starts an episode begins from are the cell's.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from qg_common.shaft_task import ShaftTaskGeometry, TaskMeasure
from qg_common.types import GroundTruth, StartPose, WrenchSetpoint

__all__ = ["TaskConfig", "Observation", "ResidualTask", "OBSERVATIONS", "OBSERVATION_COMPONENTS",
           "PROGRESS_COMPONENTS", "ACTION_DIM", "state_dim", "tilt_from_push_axis"]

#: The components of each state definition (see the module docstring), in order: wrench
#: components (tool frame) and the tilt (ex, ey) away from the push axis.
OBSERVATION_COMPONENTS = {
    "thesis": ("fx", "fy", "tx", "ty"),
    "tilt": ("fx", "fy", "tx", "ty", "ex", "ey"),
    "tilt_force": ("fx", "fy", "ex", "ey"),
    "tilt_only": ("ex", "ey"),
    "tilt_depth": ("ex", "ey", "depth"),
    "tilt_motion": ("ex", "ey", "motion"),
}
#: Components that measure what the last step achieved rather than where the tool is: at a
#: stall they read about 0 (plus the measurement's noise) instead of repeating a value.
PROGRESS_COMPONENTS = ("motion",)
#: State definitions and their lengths.
OBSERVATIONS = {name: len(parts) for name, parts in OBSERVATION_COMPONENTS.items()}
_WRENCH_INDEX = {"fx": 0, "fy": 1, "tx": 3, "ty": 4}
ACTION_DIM = 2


def state_dim(observation: str) -> int:
    """Length of the scaled state of ``observation`` (one of :data:`OBSERVATIONS`)."""
    if observation not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {sorted(OBSERVATIONS)}, got {observation!r}")
    return OBSERVATIONS[observation]


def tilt_from_push_axis(rotation: np.ndarray, push_axis: np.ndarray) -> np.ndarray:
    """(ex, ey): the rotation vector, in the tool frame, that turns tool z onto ``push_axis``.

    Its direction says which way to tilt back, its norm by how much [rad]; z is always zero.
    :param rotation: (3, 3) tool orientation in the base frame; :param push_axis: unit vector,
        base frame, along which the shaft should point (tip first).
    """
    axis_in_tool = np.asarray(rotation).T @ np.asarray(push_axis, dtype=np.float64)
    # rotation taking e_z onto axis_in_tool: about e_z x axis = (-a_y, a_x, 0), angle atan2(|.|, a_z)
    sine = np.hypot(axis_in_tool[0], axis_in_tool[1])
    if sine < 1e-12:
        return np.zeros(2)
    angle = np.arctan2(sine, axis_in_tool[2])
    return angle / sine * np.array([-axis_in_tool[1], axis_in_tool[0]])


@dataclass(frozen=True)
class TaskConfig:
    """:param base_force: constant push along EEF z [N] (negative: into the bore).
    :param max_residual_torque: actor output 1.0 maps to this torque [Nm].
    :param force_range: |F| that maps to state 1.0 [N]; :param torque_range: same for torque [Nm].
    :param sigma_position: dense reward's position scale [m]; :param sigma_orientation: [rad].
    :param train_max_steps: step cap of training episodes; :param test_max_steps: of test ones.
    :param reward: default reward type, sparse | dense.
    :param observation: the state, one of :data:`OBSERVATIONS` (``thesis``: 4-D wrench;
        ``tilt_motion``, the default: the tilt and the last step's motion). The executor owns
        it and tells the learner.
    :param tilt_range: tilt [rad] that maps to state 1.0 (``tilt`` observation).
    :param depth_range: depth [m] that maps to state 1.0 (``tilt_depth``): the cell's full
        depth, 12 mm of bore and the inner ring's 4 mm of travel.
    :param motion_range: a step's motion along the bore axis [m] that maps to state 1.0
        (``tilt_motion``); 2 mm: a step that slides freely moves 1-5 mm, a jammed one < 0.1.
    """
    base_force: float = -15.0
    max_residual_torque: float = 3.0
    force_range: float = 20.0
    torque_range: float = 3.0
    sigma_position: float = 0.015
    sigma_orientation: float = 0.7
    train_max_steps: int = 1000
    test_max_steps: int = 200
    reward: str = "dense"
    observation: str = "tilt_motion"
    tilt_range: float = 0.5
    depth_range: float = 0.016
    motion_range: float = 0.002

    def __post_init__(self) -> None:
        if self.reward not in ("sparse", "dense"):
            raise ValueError(f"reward must be sparse or dense, got {self.reward!r}")
        state_dim(self.observation)
        for name in ("max_residual_torque", "force_range", "torque_range", "sigma_position",
                     "sigma_orientation", "tilt_range", "depth_range", "motion_range"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.train_max_steps < 1 or self.test_max_steps < 1:
            raise ValueError("step caps must be >= 1")

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> TaskConfig:
        unknown = set(values) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown task parameters: {sorted(unknown)}")
        return cls(**values)

    def max_steps(self, mode: str) -> int:
        return self.train_max_steps if mode == "train" else self.test_max_steps


@dataclass(frozen=True)
class Observation:
    """What the executor sees when a step comes to rest: what the robot measured.

    :param wrench: (6,) the estimated (or sensed) contact wrench, tool frame.
    :param tool_position: (3,) the tool position, base frame, from the measured joints.
    :param tool_rotation: (3, 3) the tool orientation, the same way.
    :param truth: a simulation's ground truth at that instant, for evaluation only (``None`` on
        a real arm): nothing of the MDP is computed from it.
    """
    wrench: np.ndarray
    tool_position: np.ndarray
    tool_rotation: np.ndarray
    truth: GroundTruth | None = None


class ResidualTask:
    """Maps observations to states and rewards, and actions to feed-forward wrenches.

    :param geometry: the cell: the fixture the goal is measured against, and the starts.
    """

    action_dim = ACTION_DIM

    def __init__(self, config: TaskConfig, geometry: ShaftTaskGeometry) -> None:
        self.config = config
        self.geometry = geometry
        c = config
        self.state_dim = state_dim(c.observation)
        parts = OBSERVATION_COMPONENTS[c.observation]
        scales = {"fx": c.force_range, "fy": c.force_range, "tx": c.torque_range,
                  "ty": c.torque_range, "ex": c.tilt_range, "ey": c.tilt_range,
                  "depth": c.depth_range, "motion": c.motion_range}
        self._state_scale = np.array([scales[part] for part in parts])
        self._wrench_index = [_WRENCH_INDEX[part] for part in parts if part in _WRENCH_INDEX]
        self._uses_tilt = "ex" in parts
        self._uses_depth = "depth" in parts
        self._uses_motion = "motion" in parts
        self._push_axis = geometry.bore_axis()
        #: Indices of the state's :data:`PROGRESS_COMPONENTS` (the stall detector's input).
        self.progress_dims = tuple(i for i, part in enumerate(parts)
                                   if part in PROGRESS_COMPONENTS)

    def state(self, obs: Observation, previous: Observation | None = None) -> np.ndarray:
        """The observation's components (:data:`OBSERVATION_COMPONENTS`) scaled to [-1, 1]
        (clipped); the tilt is measured from the bore axis of the cell's fixture.

        :param previous: the observation the step to ``obs`` began from (``tilt_motion`` reads
            the step's motion from it); ``None`` at an episode's start: no motion.
        """
        w = np.asarray(obs.wrench, dtype=np.float64)
        raw = [w[i] for i in self._wrench_index]
        if self._uses_tilt:
            raw.extend(tilt_from_push_axis(obs.tool_rotation, self._push_axis))
        if self._uses_depth:
            raw.append(self.measure(obs).insertion_depth)
        if self._uses_motion:
            raw.append(0.0 if previous is None else self.measure(obs).insertion_depth
                       - self.measure(previous).insertion_depth)
        return np.clip(np.array(raw) / self._state_scale, -1.0, 1.0)

    def wrench(self, action: np.ndarray) -> np.ndarray:
        """Feed-forward wrench [0, 0, Fz, tx, ty, 0] for an actor output in [-1, 1]^2.

        :raises ValueError: for a non-finite action (the caller sends the zero residual instead).
        """
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (ACTION_DIM,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be {ACTION_DIM} finite numbers, got {action!r}")
        tx, ty = np.clip(a, -1.0, 1.0) * self.config.max_residual_torque
        return np.array([0.0, 0.0, self.config.base_force, tx, ty, 0.0])

    def command(self, action: np.ndarray, obs: Observation) -> WrenchSetpoint:
        """The setpoint of ``action``: its feed-forward wrench from the pose at rest now."""
        del obs
        return WrenchSetpoint(self.wrench(action))

    def hold(self) -> WrenchSetpoint:
        """The zero residual: the base push only, from where the tool is (the safe command)."""
        return WrenchSetpoint.residual(self.config.base_force, 0.0, 0.0)

    def start_pose(self, index: int) -> StartPose:
        """The cell's start ``index`` (0..7), where an episode of that pose begins."""
        return self.geometry.start_pose(index)

    def measure(self, obs: Observation) -> TaskMeasure:
        """How far the measured tool pose is from the inserted pose, against the fixture."""
        return self.geometry.measure(obs.tool_position, obs.tool_rotation)

    def succeeded(self, obs: Observation) -> bool:
        """The goal: the shaft fully inserted, measured."""
        return self.measure(obs).inserted

    def reward(self, obs: Observation, kind: str) -> float:
        """Sparse: -1 per step, 0 at the goal. Dense: 0.5 (exp(-dR/sR) + exp(-dP/sP)) - 1."""
        m = self.measure(obs)
        if kind == "sparse":
            return 0.0 if m.inserted else -1.0
        if kind == "dense":
            c = self.config
            return 0.5 * (np.exp(-m.orientation_error_norm / c.sigma_orientation)
                          + np.exp(-m.position_error / c.sigma_position)) - 1.0
        raise ValueError(f"reward must be sparse or dense, got {kind!r}")

    def left_bore(self, obs: Observation) -> bool:
        """The shaft tip left the hole axis too far: end the episode (a failure, not terminal)."""
        return self.measure(obs).lateral_offset > self.geometry.max_lateral_offset

    @staticmethod
    def reward_range(kind: str) -> tuple[float, float]:
        """(r_min, r_max) of both reward types: [-1, 0]."""
        del kind
        return (-1.0, 0.0)
