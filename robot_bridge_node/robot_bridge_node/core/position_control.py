"""Task-space position control for a position-controlled arm (the Nextage): damped-least-squares IK.

A Nextage takes joint position targets, not torques, so the bridge turns the robot-agnostic pose
reference into a joint target every millisecond. Like the manufacturer's task-space interface, the
commanded pose moves toward the reference on a straight line at bounded linear and angular speed
(a far reference becomes a smooth motion, not a jump); IK maps it to joints, and the joint target
is rate-limited once more as a last guard. The motors' force limits (not this code) decide how
hard the arm pushes when the peg is blocked. The same
safety ideas as for the Panda apply: a non-finite reference is rejected (the last valid one is
kept) and the reference position is clamped to a workspace box.

All poses are 4x4 homogeneous transforms of the tool frame in the base frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from qg_common.params import config_from_dict

from robot_bridge_node.core.impedance import ToolState

__all__ = ["PositionControlConfig", "IKResult", "TaskSpacePositionController", "pose_matrix"]


def pose_matrix(position: np.ndarray, rotation: np.ndarray | None = None) -> np.ndarray:
    """A 4x4 homogeneous transform from a position and an optional rotation (identity)."""
    pose = np.eye(4)
    pose[:3, 3] = np.asarray(position, float)
    if rotation is not None:
        pose[:3, :3] = np.asarray(rotation, float)
    return pose


@dataclass(frozen=True)
class PositionControlConfig:
    """Gains and limits of the IK position controller.

    :param damping: damping of the least-squares step; trades accuracy near singularities for
        bounded joint steps.
    :param orientation_weight: length that makes a rotation error comparable to a position
        error [m/rad] (0.1: 1 rad weighs as much as 10 cm).
    :param max_iterations: IK iterations per call of ``solve``.
    :param max_iteration_step: largest joint change of one IK iteration [rad]; keeps the
        linearisation valid far from the solution.
    :param position_tolerance: IK stops below this position error [m] ...
    :param orientation_tolerance: ... and this orientation error [rad].
    :param linear_speed_limit: how fast the commanded position moves toward the reference [m/s].
    :param angular_speed_limit: how fast the commanded orientation turns toward it [rad/s].
    :param joint_speed_limit: how fast the joint target may move [rad/s].
    :param dt: control period [s].
    :param workspace_min: lower corner of the box the reference position is clamped to, base
        frame [m].
    :param workspace_max: upper corner of that box [m].
    """
    damping: float = 1e-3
    orientation_weight: float = 0.1
    max_iterations: int = 100
    max_iteration_step: float = 0.2
    position_tolerance: float = 1e-5
    orientation_tolerance: float = 1e-4
    linear_speed_limit: float = 0.1
    angular_speed_limit: float = 1.0
    joint_speed_limit: float = 2.0
    dt: float = 1e-3
    workspace_min: tuple[float, float, float] = (-1.0, -1.0, -1.0)
    workspace_max: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        for name in ("damping", "orientation_weight", "max_iteration_step", "position_tolerance",
                     "orientation_tolerance", "linear_speed_limit", "angular_speed_limit",
                     "joint_speed_limit", "dt"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {self.max_iterations}")
        lo, hi = np.asarray(self.workspace_min, float), np.asarray(self.workspace_max, float)
        if lo.shape != (3,) or hi.shape != (3,):
            raise ValueError("workspace_min and workspace_max need 3 entries each")
        if np.any(lo >= hi):
            raise ValueError(f"workspace_min {lo} must be below workspace_max {hi} on every axis")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> PositionControlConfig:
        """Build from a parameter dict; unknown keys are an error (typos fail loudly)."""
        return config_from_dict(cls, params)


@dataclass(frozen=True)
class IKResult:
    """Outcome of ``solve``: the configuration and its remaining errors."""
    q: np.ndarray
    position_error: float      # [m]
    orientation_error: float   # [rad]
    converged: bool


class TaskSpacePositionController:
    """Pose reference in, rate-limited joint position target out.

    :param model_urdf: URDF of the arm (all its joints are controlled).
    :param tool_frame: name of the controlled frame.
    :param config: gains and limits.
    """

    def __init__(self, model_urdf: Path | str, tool_frame: str,
                 config: PositionControlConfig | None = None) -> None:
        self.config = config or PositionControlConfig()
        self.model = pin.buildModelFromUrdf(str(model_urdf))
        self.data = self.model.createData()
        if not self.model.existFrame(tool_frame):
            raise ValueError(f"{model_urdf} has no frame {tool_frame!r}")
        self.tool_frame = tool_frame
        self._frame = self.model.getFrameId(tool_frame)
        self.q_lower = self.model.lowerPositionLimit.copy()
        self.q_upper = self.model.upperPositionLimit.copy()
        self._ws_lo = np.asarray(self.config.workspace_min, float)
        self._ws_hi = np.asarray(self.config.workspace_max, float)
        self._max_joint_step = self.config.joint_speed_limit * self.config.dt
        self._weights = np.concatenate((np.ones(3), np.full(3, self.config.orientation_weight)))
        self._damping_matrix = self.config.damping ** 2 * np.eye(6)
        self._q_target: np.ndarray | None = None
        self._solution: np.ndarray | None = None
        self._pose_command: np.ndarray | None = None
        self._reference: np.ndarray | None = None
        self.rejected_references = 0
        #: The tool's state at the last ``measure`` (None before the first).
        self.tool: ToolState | None = None

    @property
    def nq(self) -> int:
        """Number of joints."""
        return self.model.nq

    def forward(self, q: np.ndarray) -> np.ndarray:
        """Tool pose (4x4) at configuration ``q``."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, float))
        return self.data.oMf[self._frame].homogeneous.copy()

    def measure(self, q: np.ndarray, dq: np.ndarray) -> ToolState:
        """The tool's pose and twist (base frame) at the measured joints, kept as ``tool``:
        what the rest detector watches and the bridge publishes."""
        q, dq = np.asarray(q, float), np.asarray(dq, float)
        pin.forwardKinematics(self.model, self.data, q, dq)
        pose = pin.updateFramePlacement(self.model, self.data, self._frame)
        twist = pin.getFrameVelocity(self.model, self.data, self._frame, pin.LOCAL_WORLD_ALIGNED)
        self.tool = ToolState(pose.translation.copy(), pose.rotation.copy(),
                              np.concatenate((twist.linear, twist.angular)))
        return self.tool

    def solve(self, q0: np.ndarray, pose: np.ndarray) -> IKResult:
        """Damped-least-squares IK for ``pose`` from ``q0``, within the joint limits."""
        cfg = self.config
        target = pin.SE3(np.asarray(pose, float))
        weights = self._weights
        q = np.clip(np.asarray(q0, float), self.q_lower, self.q_upper)
        for _ in range(cfg.max_iterations):
            pos_err, rot_err = self._errors(q, target)
            if (np.linalg.norm(pos_err) < cfg.position_tolerance
                    and np.linalg.norm(rot_err) < cfg.orientation_tolerance):
                break
            J = pin.computeFrameJacobian(self.model, self.data, q, self._frame,
                                         pin.LOCAL_WORLD_ALIGNED) * weights[:, None]
            e = np.concatenate((pos_err, rot_err)) * weights
            dq = J.T @ np.linalg.solve(J @ J.T + self._damping_matrix, e)
            largest = np.max(np.abs(dq))
            if largest > cfg.max_iteration_step:
                dq *= cfg.max_iteration_step / largest
            q = np.clip(q + dq, self.q_lower, self.q_upper)
        pos_err, rot_err = self._errors(q, target)
        p_norm, r_norm = float(np.linalg.norm(pos_err)), float(np.linalg.norm(rot_err))
        return IKResult(q, p_norm, r_norm, bool(p_norm < cfg.position_tolerance
                                                  and r_norm < cfg.orientation_tolerance))

    def reset(self, q: np.ndarray) -> None:
        """Start from the measured configuration ``q``, holding its pose."""
        self._q_target = np.asarray(q, float).copy()
        self._solution = self._q_target.copy()
        self._pose_command = self.forward(q)
        self._reference = self._pose_command.copy()

    def clamp_reference(self, pose: np.ndarray) -> np.ndarray:
        """``pose`` with its position clamped to the workspace box."""
        clamped = np.asarray(pose, float).copy()
        clamped[:3, 3] = np.clip(clamped[:3, 3], self._ws_lo, self._ws_hi)
        return clamped

    @property
    def pose_command(self) -> np.ndarray | None:
        """The pose currently being tracked (on its way to the reference); None before ``reset``."""
        return None if self._pose_command is None else self._pose_command.copy()

    def step(self, q: np.ndarray, pose_reference: np.ndarray) -> np.ndarray:
        """Next joint position target toward ``pose_reference`` (4x4, base frame).

        :param q: measured joint positions; the controller starts from them on the first call.
        :raises ValueError: if ``q`` is not finite (a driver fault, nothing safe to compute).
        """
        q = np.asarray(q, float)
        if not np.all(np.isfinite(q)):
            raise ValueError(f"measured joint positions are not finite: {q}")
        if self._q_target is None:
            self.reset(q)
        pose_reference = np.asarray(pose_reference, float)
        if pose_reference.shape == (4, 4) and np.all(np.isfinite(pose_reference)):
            self._reference = self.clamp_reference(pose_reference)
        else:
            self.rejected_references += 1
        command = self._move_toward(self._pose_command, self._reference)
        if not np.array_equal(command, self._pose_command):
            self._pose_command = command
            self._solution = self.solve(self._solution, command).q
        step = np.clip(self._solution - self._q_target, -self._max_joint_step, self._max_joint_step)
        self._q_target = self._q_target + step
        return self._q_target.copy()

    def _move_toward(self, pose: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """One control period of straight-line, speed-limited motion toward ``reference``."""
        cfg = self.config
        moved = pose.copy()
        delta = reference[:3, 3] - pose[:3, 3]
        distance = float(np.linalg.norm(delta))
        max_move = cfg.linear_speed_limit * cfg.dt
        moved[:3, 3] = reference[:3, 3] if distance <= max_move else \
            pose[:3, 3] + delta * (max_move / distance)
        turn = pin.log3(reference[:3, :3] @ pose[:3, :3].T)
        angle = float(np.linalg.norm(turn))
        max_turn = cfg.angular_speed_limit * cfg.dt
        moved[:3, :3] = reference[:3, :3] if angle <= max_turn else \
            pin.exp3(turn * (max_turn / angle)) @ pose[:3, :3]
        return moved

    def _errors(self, q: np.ndarray, target: pin.SE3) -> tuple[np.ndarray, np.ndarray]:
        """Position and rotation-vector error (target minus current), base frame."""
        pin.framesForwardKinematics(self.model, self.data, q)
        current = self.data.oMf[self._frame]
        return (target.translation - current.translation,
                pin.log3(target.rotation @ current.rotation.T))
