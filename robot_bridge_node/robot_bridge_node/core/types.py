"""Commands into and results out of the 1 kHz loop, shared by the controller, safety and nodes.

Wrench convention (one for setpoints, estimates and ground truth): the **contact wrench** the
environment exerts on the tool, about the tool origin, in the tool (EEF) frame, whose z axis runs
along the shaft towards its tip. A setpoint asks the controller to make the contact wrench equal
the feed-forward part, so the robot itself applies the opposite: ``Fz = -15 N`` (the environment
pushing back on the shaft) means pressing the shaft 15 N into the bore, and at rest against an
obstacle the estimated wrench equals the commanded one.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sim_robot_node.core.types import GroundTruth, StepResult  # noqa: F401 (re-export)

__all__ = ["WrenchSetpoint", "PoseReference", "StepResult"]


@dataclass(frozen=True)
class PoseReference:
    """Impedance reference pose in the base frame."""
    position: np.ndarray   # (3,) [m]
    rotation: np.ndarray   # (3, 3)


@dataclass(frozen=True)
class WrenchSetpoint:
    """One RL step's command: feed-forward contact wrench plus the impedance reference.

    :param wrench: (6,) ``[Fx, Fy, Fz, Tx, Ty, Tz]`` [N, Nm] in the EEF frame (see module doc).
    :param reference: pose reference; ``None`` takes the current pose when the step starts
        (the residual policy's choice).
    """
    wrench: np.ndarray
    reference: PoseReference | None = None

    @classmethod
    def residual(cls, force_z: float, torque_x: float, torque_y: float) -> WrenchSetpoint:
        """The residual-policy command ``[0, 0, Fz, tx, ty, 0]`` from the current pose."""
        return cls(np.array([0.0, 0.0, force_z, torque_x, torque_y, 0.0]))
