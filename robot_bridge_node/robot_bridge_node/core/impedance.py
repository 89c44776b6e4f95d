"""Hybrid task-space force/impedance control of a torque-controlled arm, in libfranka's callback
shape.

The residual policy commands a wrench, not a motion: along the shaft (EEF z) the stiffness is
zero, so the feed-forward force pushes; across it a soft spring (250 N/m) and about every axis a
rotational spring (4 Nm/rad) hold the pose the step started from, while the feed-forward torques
turn the shaft against them. Damping makes every step settle so the rest detector can end it,
and the redundant degrees of freedom (the Panda's and the xArm's seventh joint) are held by a
damped null-space posture spring: left free, the elbow keeps drifting and the tool never comes
to rest.

    tau = J^T (-F_ff + K (x_ref - x) - D v) + N (k_n (q_n - q) - d_n dq) - d_j dq + C dq + g

with ``F_ff`` the feed-forward contact wrench (see ``types``) turned into the base frame,
``K``, ``D`` diagonal in the EEF frame, and ``N`` the null-space projector of ``J^T``.

**Holding.** When the loop holds the pose on its own (the realtime watchdog: no setpoint for
10 ms) nothing pushes along z any more, and a stiffness of 0 there would let an arm whose gravity
model is off (an unknown payload) sink or rise while "holding". ``hold`` therefore makes every
axis stiff and the translations about critically damped (``HOLD_STIFFNESS``, ``HOLD_DAMPING``)
until the next setpoint ``release``s it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from qg_common.params import config_from_dict
from qg_common.types import PoseReference, WrenchSetpoint

from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.native import ImpedanceKernel

__all__ = ["ImpedanceConfig", "HybridImpedanceController", "ToolState", "HOLD_STIFFNESS",
           "HOLD_DAMPING"]

#: [N/m x 3, Nm/rad x 3] The least stiffness of every axis while the loop holds the pose on its
#: own (the safety behaviour, not a tuning: the bridge's parameters cannot lower it). An unknown
#: 0.1 kg on the hand (the realistic arm's payload error) then sags 0.33 mm; at the task's
#: 250 N/m it sank 3.8 mm in 0.6 s, at 0 N/m (z before) 4.2 mm (the realistic Panda).
HOLD_STIFFNESS = (3000.0, 3000.0, 3000.0, 10.0, 10.0, 10.0)
#: [Ns/m x 3, Nms/rad x 3] The least damping while holding: about critical for the 5-15 kg the
#: arms have at the tool. The rotational damping stays the arm's own (``d_rot``): a light wrist
#: (the xArm's, 1.5e-4 kg m^2 about the tool axis) is unstable at 1 kHz with more.
HOLD_DAMPING = (300.0, 300.0, 300.0, 0.0, 0.0, 0.0)

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

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """(6,) stiffness ``[k_trans, k_rot]`` and (6,) damping ``[d_trans, d_rot]``, EEF frame:
        the task's gains."""
        return (np.concatenate([self.k_trans, self.k_rot]).astype(float),
                np.concatenate([self.d_trans, self.d_rot]).astype(float))

    def hold_gains(self) -> tuple[np.ndarray, np.ndarray]:
        """The gains while holding: the task's, raised to ``HOLD_STIFFNESS`` and
        ``HOLD_DAMPING`` on every axis below them (z above all)."""
        stiffness, damping = self.gains()
        return np.maximum(stiffness, HOLD_STIFFNESS), np.maximum(damping, HOLD_DAMPING)


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

    def speeds(self) -> tuple[float, float]:
        """``(linear_speed, angular_speed)``, the same numbers from one read of the twist (the
        rest detector's inputs, every tick)."""
        vx, vy, vz, wx, wy, wz = self.twist.tolist()
        return math.hypot(vx, vy, vz), math.hypot(wx, wy, wz)


class HybridImpedanceController:
    """Joint torques from a wrench setpoint, once per millisecond.

    The law above runs in compiled code (``native.ImpedanceKernel``, one call per tick: the
    same Pinocchio kinematics and dynamics, ~3 us instead of ~18 us of NumPy); this class owns
    the gains, the posture and the pose reference, and hands the kernel a new reference only
    when it changes.

    :param config: gains.
    :param model: the arm's model with the task's tool frame and payload.
    """

    def __init__(self, config: ImpedanceConfig, model: ArmModel) -> None:
        self.config = config
        self.model = model
        self._kernel = ImpedanceKernel(model.serialised(), model.tool_frame,
                                       *config.gains(),                      # EEF frame
                                       config.k_null, config.d_null, config.d_joint)
        self.holding = False
        self._kernel_reference: PoseReference | None = None
        self.reference: PoseReference | None = None
        self.q_null: np.ndarray | None = None
        self.tool: ToolState | None = None

    def reset(self, q: np.ndarray) -> None:
        """Episode start: posture and pose reference from ``q``, the task's gains."""
        self.set_posture(q)
        self.set_reference_to_current(q)
        self.release()

    def set_posture(self, q: np.ndarray) -> None:
        """The null-space posture spring's rest configuration (a motion moves it along)."""
        self.q_null = np.asarray(q, float).copy()
        self._kernel.set_posture(self.q_null)

    def hold(self, q: np.ndarray) -> PoseReference:
        """Hold the pose at ``q`` stiffly along every axis (see the module doc) until
        ``release``; the feed-forward wrench is the caller's (zero when holding)."""
        self._kernel.set_gains(*self.config.hold_gains())
        self.holding = True
        return self.set_reference_to_current(q)

    def release(self) -> None:
        """Back to the task's gains after ``hold`` (nothing to do otherwise)."""
        if self.holding:
            self._kernel.set_gains(*self.config.gains())
            self.holding = False

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
