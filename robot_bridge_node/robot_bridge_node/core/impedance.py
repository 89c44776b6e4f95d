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
from qg_common.params import config_from_dict

from robot_bridge_node.core.native import ImpedanceKernel
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

    The law above runs in compiled code (``native.ImpedanceKernel``, one call per tick: the
    same Pinocchio kinematics and dynamics, ~3 us instead of ~18 us of NumPy); this class owns
    the gains, the posture and the pose reference, and hands the kernel a new reference only
    when it changes.

    :param config: gains.
    :param model: the Panda model with the task's tool frame and payload.
    """

    def __init__(self, config: ImpedanceConfig, model: PandaModel) -> None:
        self.config = config
        self.model = model
        self._kernel = ImpedanceKernel(
            model.serialised(), model.tool_frame,
            np.concatenate([config.k_trans, config.k_rot]).astype(float),     # EEF frame
            np.concatenate([config.d_trans, config.d_rot]).astype(float),
            config.k_null, config.d_null, config.d_joint)
        self._kernel_reference: PoseReference | None = None
        self.reference: PoseReference | None = None
        self.q_null: np.ndarray | None = None
        self.tool: ToolState | None = None

    def reset(self, q: np.ndarray) -> None:
        """Episode start: posture and pose reference from ``q``."""
        self.q_null = np.asarray(q, float).copy()
        self._kernel.set_posture(self.q_null)
        self.set_reference_to_current(q)

    def set_reference_to_current(self, q: np.ndarray) -> PoseReference:
        """Hold the pose at ``q`` (what the residual policy does at each RL step)."""
        kin = self.model.kinematics(np.asarray(q, float))
        self.reference = PoseReference(kin.position, kin.rotation)
        return self.reference

    def step(self, q: np.ndarray, dq: np.ndarray, setpoint: WrenchSetpoint,
             dt: float) -> np.ndarray:
        """The joint torques [Nm] for this tick (before the safety filter's torque limits).

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
        if ref is not self._kernel_reference:
            self._kernel.set_reference(ref.position, ref.rotation)
            self._kernel_reference = ref
        tau, position, rotation, twist = self._kernel.step(q, dq, setpoint.wrench)
        self.tool = ToolState(position, rotation, twist)
        return tau
