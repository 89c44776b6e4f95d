"""Rigid-body model of a torque-controlled arm from its URDF (Pinocchio), shared by the controller,
the safety filter and the EKF.

The robot plugin's ``RobotDescription`` names the URDF, the driven joints, the tool mount frame, the
tool held there and, where the datasheet overrides the URDF, the limits; everything else (joint
count, kinematics, inertias, torque and velocity limits) is what Pinocchio reads from the URDF.
The simulated arms load the same file, so model and "hardware" agree except where a scene chooses
otherwise (``sim_robot_node/core/arm_imperfections.py``). All quantities are in the base frame
unless a name says otherwise; Jacobians are 6xn with the linear part first (LOCAL_WORLD_ALIGNED).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from qg_common.arm_description import ArmDescription

from robot_bridge_node.core.hardware_interface import RobotDescription

__all__ = ["ArmModel", "JointLimits", "Kinematics", "driven_model"]


@dataclass(frozen=True)
class Kinematics:
    """Tool pose and Jacobian at one configuration."""
    position: np.ndarray      # (3,) tool position, base frame [m]
    rotation: np.ndarray      # (3, 3) tool orientation, base frame
    jacobian: np.ndarray      # (6, n) [linear; angular], LOCAL_WORLD_ALIGNED


@dataclass(frozen=True)
class JointLimits:
    """What the safety filter holds every joint to: (n,) each."""
    torque: np.ndarray        # [Nm] magnitude
    torque_rate: np.ndarray   # [Nm/s] change of the command (inf: unlimited)
    velocity: np.ndarray      # [rad/s] magnitude

    def __post_init__(self) -> None:
        n = len(self.torque)
        for name in ("torque", "torque_rate", "velocity"):
            value = np.asarray(getattr(self, name), float)
            finite = np.all(np.isfinite(value)) or name == "torque_rate"
            if value.shape != (n,) or not finite or not np.all(value > 0.0):
                raise ValueError(f"{name} limits must be {n} values > 0"
                                 f"{'' if name == 'torque_rate' else ', finite'}, got {value}")


class ArmModel:
    """The driven joints of an arm (every other joint locked at neutral), a tool frame at an
    offset from the tool mount, and the held part as a payload.

    :param urdf: path of the URDF.
    :param joint_names: the driven joints, in the order of every joint vector; must be the
        URDF's order of those joints.
    :param tool_mount: the URDF frame the tool is fixed to.
    :param tool_offset: translation of the tool frame from its mount, in the mount's frame [m].
    :param payload_mass: mass rigidly held at the tool mount [kg] (e.g. the held part).
    :param payload_com: its centre of mass in the mount's frame [m]; default the tool origin.
    :param torque_limits: (n,) [Nm] overriding the URDF's ``effort`` limits; ``None`` keeps them.
    :param torque_rate_limits: (n,) [Nm/s]; ``None`` leaves the rate unlimited.
    :raises ValueError: if a joint or the tool mount is missing, the joints are out of the URDF's
        order, a joint is not a single degree of freedom, or a URDF limit is missing.
    """

    def __init__(self, urdf: str, joint_names: tuple[str, ...], tool_mount: str,
                 tool_offset: np.ndarray | None = None, payload_mass: float = 0.0,
                 payload_com: np.ndarray | None = None,
                 torque_limits: tuple[float, ...] | None = None,
                 torque_rate_limits: tuple[float, ...] | None = None) -> None:
        self.model = driven_model(urdf, joint_names)
        if not self.model.existFrame(tool_mount):
            raise ValueError(f"{urdf}: no frame {tool_mount!r}")
        self.joint_names = tuple(joint_names)
        mount_id = self.model.getFrameId(tool_mount)
        parent = self.model.frames[mount_id].parentJoint
        placement = self.model.frames[mount_id].placement
        offset = np.zeros(3) if tool_offset is None else np.asarray(tool_offset, float)
        tool_placement = placement * pin.SE3(np.eye(3), offset)
        self.tool_frame = self.model.addFrame(
            pin.Frame("tool", parent, mount_id, tool_placement, pin.FrameType.OP_FRAME))
        if payload_mass > 0.0:
            com = tool_placement.translation if payload_com is None else \
                (placement * pin.SE3(np.eye(3), np.asarray(payload_com, float))).translation
            self.model.inertias[parent] += pin.Inertia(
                payload_mass, com, np.diag([1e-5, 1e-5, 1e-5]))
        self.data = self.model.createData()
        self.q_lower = self.model.lowerPositionLimit.copy()
        self.q_upper = self.model.upperPositionLimit.copy()
        self.limits = JointLimits(
            torque=_urdf_limit(self.model.effortLimit, "effort", urdf) if torque_limits is None
            else np.asarray(torque_limits, float),
            torque_rate=np.full(self.nv, np.inf) if torque_rate_limits is None
            else np.asarray(torque_rate_limits, float),
            velocity=_urdf_limit(self.model.velocityLimit, "velocity", urdf))

    @classmethod
    def of_arm(cls, arm: ArmDescription, tool_offset: np.ndarray | None = None,
               payload_mass: float = 0.0, payload_com: np.ndarray | None = None) -> ArmModel:
        """The model of an arm from its description (``qg_common``), e.g. the Panda's
        (``panda_description.panda_arm()``), with an optional tool and payload."""
        return cls(arm.urdf, arm.joint_names, arm.tool_mount, tool_offset, payload_mass, payload_com,
                   torque_limits=arm.torque_limits, torque_rate_limits=arm.torque_rate_limits)

    @classmethod
    def from_description(cls, description: RobotDescription) -> ArmModel:
        """The model of a torque robot as its plugin describes it (URDF, joints, tool mount, tool)."""
        if not description.urdf or not description.tool_frame:
            raise ValueError("a torque robot's description must name its urdf and tool_frame "
                             "(the frame the tool is fixed to)")
        tool = description.tool
        return cls(description.urdf, description.joint_names, description.tool_frame,
                   tool_offset=tool.offset, payload_mass=tool.payload_mass,
                   payload_com=tool.payload_com, torque_limits=description.torque_limits,
                   torque_rate_limits=description.torque_rate_limits)

    @property
    def nv(self) -> int:
        """Number of driven joints."""
        return self.model.nv

    def serialised(self) -> str:
        """The model in Pinocchio's text serialisation: how the compiled kernels
        (``core/native``) get exactly this model, tool frame and payload included."""
        return self.model.saveToString()

    # --- kinematics -----------------------------------------------------------------------
    def kinematics(self, q: np.ndarray) -> Kinematics:
        """Forward kinematics and the tool Jacobian."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        oMf = self.data.oMf[self.tool_frame]
        J = pin.getFrameJacobian(self.model, self.data, self.tool_frame, pin.LOCAL_WORLD_ALIGNED)
        return Kinematics(oMf.translation.copy(), oMf.rotation.copy(), J.copy())

    def inverse_kinematics(self, position: np.ndarray, rotation: np.ndarray,
                           q0: np.ndarray, tolerance: float = 1e-7,
                           iterations: int = 200) -> np.ndarray:
        """Joint angles that put the tool exactly at ``position``, ``rotation`` (base frame):
        damped least squares from ``q0``, so the solution is the one nearest it (the posture a
        start pose is reached with; the arm's seventh joint is redundant).

        :raises RuntimeError: if the pose is out of reach (the error stays above 1e-6).
        """
        position = np.asarray(position, float)
        rotation = np.asarray(rotation, float)
        q = np.array(q0, float)
        error = np.full(6, np.inf)
        for _ in range(iterations):
            kin = self.kinematics(q)
            error = np.concatenate([position - kin.position,
                                    pin.log3(rotation @ kin.rotation.T)])
            if np.linalg.norm(error) < tolerance:
                return self._within_limits(q)
            jac = kin.jacobian
            q = q + jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), error)
        if np.linalg.norm(error) < 1e-6:
            # Some rotated-housing starts (yaw 90 deg, pose 7) stall at ~2.5e-7 near the wrist's
            # limit; 1 um / 1 urad is far below the 0.5 mm start clearance.
            return self._within_limits(q)
        raise RuntimeError(
            f"inverse kinematics did not converge (error {np.linalg.norm(error):.2e})")

    def _within_limits(self, q: np.ndarray) -> np.ndarray:
        """``q`` with each joint outside its position range turned by whole turns into it where
        that fits: the same pose. The solver does not know the ranges; the flange joint of a
        housing turned 90 deg came out at 5.5 rad (range +-2.9), which pybullet's torque mode let
        pass and MuJoCo's joint limits pushed back by 4 deg within the reset's settling."""
        lower, upper = self.model.lowerPositionLimit, self.model.upperPositionLimit
        q = q.copy()
        for i in range(min(len(q), len(lower))):
            if not lower[i] <= q[i] <= upper[i]:
                turned = q[i] - 2.0 * np.pi * np.round((q[i] - 0.5 * (lower[i] + upper[i]))
                                                       / (2.0 * np.pi))
                if lower[i] <= turned <= upper[i]:
                    q[i] = turned
        return q

    def tool_twist(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Tool twist (v, w) in the base frame."""
        return self.kinematics(q).jacobian @ dq

    # --- dynamics -------------------------------------------------------------------------
    def gravity(self, q: np.ndarray) -> np.ndarray:
        """Generalised gravity torques g(q)."""
        return pin.computeGeneralizedGravity(self.model, self.data, q).copy()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia M(q) (symmetric)."""
        M = pin.crba(self.model, self.data, q)
        return np.triu(M) + np.triu(M, 1).T

    def nonlinear_effects(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """C(q, dq) dq + g(q)."""
        return pin.nonLinearEffects(self.model, self.data, q, dq).copy()

    def forward_dynamics(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Joint accelerations ddq = M^-1 (tau - C dq - g)."""
        return pin.aba(self.model, self.data, q, dq, tau).copy()


def driven_model(urdf: str, joint_names: tuple[str, ...]) -> pin.Model:
    """The URDF's model with only ``joint_names`` moving (every other joint locked at neutral,
    its frames kept), one degree of freedom each, in the order of ``joint_names``.

    :raises ValueError: if a joint is missing, the joints are out of the URDF's order, or a
        joint is not a single degree of freedom.
    """
    full = pin.buildModelFromUrdf(str(urdf))
    missing = [n for n in joint_names if not full.existJointName(n)]
    if missing:
        raise ValueError(f"{urdf}: no joints {missing}")
    lock = [j for j in range(1, full.njoints) if full.names[j] not in joint_names]
    model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
    names = tuple(model.names[j] for j in range(1, model.njoints))
    if names != tuple(joint_names):
        raise ValueError(f"{urdf}: joint_names must be the URDF's order {names}, "
                         f"got {tuple(joint_names)}")
    if not model.nq == model.nv == len(joint_names):
        raise ValueError(f"{urdf}: every driven joint must have one degree of freedom "
                         f"(nq {model.nq}, nv {model.nv})")
    return model


def _urdf_limit(values: np.ndarray, name: str, urdf: str) -> np.ndarray:
    """A limit the URDF gives every driven joint (``<limit effort=... velocity=...>``).

    :raises ValueError: if a joint has none (Pinocchio reads a missing one as 0 or inf).
    """
    if not (np.all(values > 0.0) and np.all(np.isfinite(values))):
        raise ValueError(f"{urdf}: every driven joint needs a {name} limit, got {values}")
    return values.copy()
