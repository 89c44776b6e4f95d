"""Rigid-body model of the Franka Panda from Pinocchio, the one the controller and the EKF share.

The URDF is the ``example-robot-data`` Panda (real inertias), the same file the simulator loads, so
model and "hardware" agree except where we choose otherwise. The tool frame is ``panda_hand_tcp``
unless a task adds a tool offset (the shaft's grasp point). All quantities are in the base frame
unless a name says otherwise; Jacobians are 6x7 with the linear part first (LOCAL_WORLD_ALIGNED).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from qg_common.panda_description import (DTAU_MAX, JOINT_NAMES, N_JOINTS, Q_READY,
                                                   TAU_MAX, panda_urdf_path)

__all__ = ["PandaModel", "panda_urdf_path", "N_JOINTS", "JOINT_NAMES", "TAU_MAX", "DTAU_MAX", "Q_READY"]


@dataclass(frozen=True)
class Kinematics:
    """Tool pose and Jacobian at one configuration."""
    position: np.ndarray      # (3,) tool position, base frame [m]
    rotation: np.ndarray      # (3, 3) tool orientation, base frame
    jacobian: np.ndarray      # (6, 7) [linear; angular], LOCAL_WORLD_ALIGNED


class PandaModel:
    """The 7 arm joints of the Panda (fingers locked), with an optional tool offset and payload.

    :param tool_offset: translation of the tool frame from ``panda_hand_tcp`` in that frame [m].
    :param payload_mass: mass rigidly held by the hand [kg] (e.g. the shaft), at the tool frame.
    """

    def __init__(self, tool_offset: np.ndarray | None = None, payload_mass: float = 0.0,
                 payload_com: np.ndarray | None = None) -> None:
        full = pin.buildModelFromUrdf(str(panda_urdf_path()))
        lock = [full.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")
                if full.existJointName(n)]
        q0 = pin.neutral(full)
        self.model = pin.buildReducedModel(full, lock, q0) if lock else full
        tcp = self.model.getFrameId("panda_hand_tcp")
        parent = self.model.frames[tcp].parentJoint
        placement = self.model.frames[tcp].placement
        offset = np.zeros(3) if tool_offset is None else np.asarray(tool_offset, float)
        tool_placement = placement * pin.SE3(np.eye(3), offset)
        self.tool_frame = self.model.addFrame(
            pin.Frame("tool", parent, tcp, tool_placement, pin.FrameType.OP_FRAME))
        if payload_mass > 0.0:
            com = tool_placement.translation if payload_com is None else \
                (placement * pin.SE3(np.eye(3), np.asarray(payload_com, float))).translation
            self.model.inertias[parent] += pin.Inertia(
                payload_mass, com, np.diag([1e-5, 1e-5, 1e-5]))
        self.data = self.model.createData()
        assert self.model.nq == N_JOINTS, self.model.nq
        self.q_lower = self.model.lowerPositionLimit.copy()
        self.q_upper = self.model.upperPositionLimit.copy()

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
