"""Where the loop's contact wrench comes from: an estimator (the EKF) or a measurement.

The loop updates it once a tick with the state it read and the torques it last commanded; a
measurement ignores those and reads a sensor (or a simulation's truth, a perfect sensor).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

__all__ = ["WrenchEstimator", "MeasuredWrench"]


class WrenchEstimator(Protocol):
    """Plug-in contact-wrench estimator (the EKF in ``wrench_ekf``)."""

    def reset(self, q: np.ndarray) -> None: ...

    def update(self, q: np.ndarray, dq: np.ndarray, tau_cmd: np.ndarray,
               dt: float) -> np.ndarray:
        """(6,) contact wrench ``(Fx, Fy, Fz, Tx, Ty, Tz)`` on the tool, tool frame."""
        ...


class MeasuredWrench:
    """A wrench source that reads a measurement instead of estimating one: a wrist force-torque
    sensor (``sensor.read_wrench``), or in simulation the true contact wrench
    (``simulation.contact_wrench``), a perfect sensor for tests and for comparing with the EKF.

    :param read: returns the (6,) wrench ``(Fx, Fy, Fz, Tx, Ty, Tz)`` on the tool, tool frame.
    """

    def __init__(self, read: Callable[[], np.ndarray]) -> None:
        self.read = read

    def reset(self, q: np.ndarray) -> None:
        del q

    def update(self, q: np.ndarray, dq: np.ndarray, tau_cmd: np.ndarray,
               dt: float) -> np.ndarray:
        del q, dq, tau_cmd, dt
        return self.read()
