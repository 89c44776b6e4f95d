"""Hybrid task-space force/impedance control of the Panda, in libfranka's callback shape.

The residual policy commands a wrench, not a motion: along the shaft (EEF z) the stiffness is
zero, so the feed-forward force pushes; across it a soft spring (250 N/m) and about every axis a
rotational spring (4 Nm/rad) hold the pose the step started from, while the feed-forward torques
turn the shaft against them. Damping makes every step settle so the rest detector can end it,
and the redundant seventh degree of freedom is held by a damped null-space posture spring: left
free, the elbow keeps drifting and the tool never comes to rest.

    tau = J^T (-F_ff + K (x_ref - x) - D v) + N (k_n (q_n - q) - d_n dq) - d_j dq + C dq + g

with ``F_ff`` the feed-forward contact wrench (see ``types``) turned into the base frame,
``K``, ``D`` diagonal in the EEF frame, and ``N`` the null-space projector of ``J^T``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack
from qg_common.params import config_from_dict

from robot_bridge_node.core.panda_model import PandaModel
from qg_common.types import PoseReference, WrenchSetpoint

__all__ = ["ImpedanceConfig", "HybridImpedanceController", "ToolState"]


@dataclass(frozen=True)
class ImpedanceConfig:
    """Gains of the hybrid force/impedance law. Vectors are (x, y, z) in the EEF frame.

    At the start poses the arm's operational-space inertia is about 11/5 kg along EEF x/y and
    0.16/0.43/0.007 kg m^2 about x/y/z, so critical damping would be ~100/70 Ns/m and ~1.6/2.6/0.3
    Nms/rad. The defaults sit near it. Halving or doubling them (with 5x the joint and
    null-space damping) did not change how often random-residual steps reach rest (~5-12 %):
    with 4 Nm/rad the tilt modes are at 0.5-0.8 Hz, too slow to settle within 0.5 s unless a
    contact blocks them; blocked (jammed) steps do rest, after ~21 ms.
    """
    k_trans: tuple[float, ...] = (250.0, 250.0, 0.0)   # [N/m]
    k_rot: tuple[float, ...] = (4.0, 4.0, 4.0)         # [Nm/rad]
    d_trans: tuple[float, ...] = (60.0, 60.0, 60.0)    # [Ns/m]
    d_rot: tuple[float, ...] = (1.0, 1.0, 1.0)         # [Nms/rad]
    k_null: float = 10.0                               # [Nm/rad] posture spring, null space
    d_null: float = 2.0                                # [Nms/rad] posture damping, null space
    d_joint: float = 0.2                               # [Nms/rad] damping on every joint

    def __post_init__(self) -> None:
        for name in ("k_trans", "k_rot", "d_trans", "d_rot"):
            value = getattr(self, name)
            if len(value) != 3:
                raise ValueError(f"{name} needs 3 entries (x, y, z), got {len(value)}")
            if any(v < 0.0 or not math.isfinite(v) for v in value):
                raise ValueError(f"{name} entries must be finite and >= 0, got {value}")
        for name in ("k_null", "d_null", "d_joint"):
            value = getattr(self, name)
            if value < 0.0 or not math.isfinite(value):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ImpedanceConfig:
        """From the ``impedance`` section of ``config/bridge.yaml``."""
        return config_from_dict(cls, params)


@dataclass(frozen=True)
class ToolState:
    """Tool pose and twist (base frame) at the last controller step."""
    position: np.ndarray
    rotation: np.ndarray
    twist: np.ndarray        # (6,) [v; w]

    @property
    def linear_speed(self) -> float:
        return math.hypot(*self.twist[:3].tolist())

    @property
    def angular_speed(self) -> float:
        return math.hypot(*self.twist[3:].tolist())


class HybridImpedanceController:
    """Joint torques from a wrench setpoint, once per millisecond.

    :param config: gains.
    :param model: the Panda model with the task's tool frame and payload.
    """

    def __init__(self, config: ImpedanceConfig, model: PandaModel) -> None:
        self.config = config
        self.model = model
        self._stiffness = np.concatenate([config.k_trans, config.k_rot]).astype(float)  # EEF
        self._damping = np.concatenate([config.d_trans, config.d_rot]).astype(float)
        self._rot6 = np.zeros((6, 6))
        self._error = np.zeros(6)
        self._reg = 1e-6 * np.eye(6)
        self.reference: PoseReference | None = None
        self.q_null: np.ndarray | None = None
        self.tool: ToolState | None = None

    def reset(self, q: np.ndarray) -> None:
        """Episode start: posture and pose reference from ``q``."""
        self.q_null = np.asarray(q, float).copy()
        self.set_reference_to_current(q)

    def set_reference_to_current(self, q: np.ndarray) -> PoseReference:
        """Hold the pose at ``q`` (what the residual policy does at each RL step)."""
        kin = self.model.kinematics(np.asarray(q, float))
        self.reference = PoseReference(kin.position, kin.rotation)
        return self.reference

    def step(self, q: np.ndarray, dq: np.ndarray, setpoint: WrenchSetpoint,
             dt: float) -> np.ndarray:
        """The 7 joint torques [Nm] for this tick (before the safety filter's torque limits).

        :param setpoint: feed-forward wrench and reference; a ``None`` reference keeps the one
            set by ``reset``/``set_reference_to_current``.
        :param dt: tick period [s] (the law is static; kept for the libfranka shape).
        """
        del dt
        if self.q_null is None:
            self.reset(q)
        if setpoint.reference is not None:
            self.reference = setpoint.reference
        ref = self.reference
        kin = self.model.kinematics(q)
        rot, jac = kin.rotation, kin.jacobian
        self.tool = ToolState(kin.position, rot, jac.dot(dq))
        # Gains are diagonal in the EEF frame: work there. ``jac_eef_t`` maps an EEF-frame
        # wrench to joint torques, and its transpose joint velocities to the EEF-frame twist.
        # (ndarray.dot rather than @: the same products at a fraction of the call overhead.)
        rot6 = self._rot6
        rot6[:3, :3] = rot
        rot6[3:, 3:] = rot
        jac_t = jac.T
        jac_eef_t = jac_t.dot(rot6)
        error = self._error
        error[:3] = ref.position - kin.position
        error[3:] = pin.log3(ref.rotation.dot(rot.T))
        wrench = (self._stiffness * rot6.T.dot(error) - self._damping * jac_eef_t.T.dot(dq)
                  - np.asarray(setpoint.wrench, float))
        tau_task = jac_eef_t.dot(wrench)
        c = self.config
        posture = c.k_null * (self.q_null - q) - c.d_null * dq
        # Projector I - J^T (J J^T)^-1 J, regularised near singularities.
        _, projected, info = lapack.dposv(jac.dot(jac_t) + self._reg, jac.dot(posture))
        if info != 0:
            raise np.linalg.LinAlgError(f"null-space projection failed (LAPACK info {info})")
        null = posture - jac_t.dot(projected)
        return tau_task + null - c.d_joint * dq + self.model.nonlinear_effects(q, dq)
