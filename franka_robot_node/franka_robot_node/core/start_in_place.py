"""An interim stand-in for the seam's coming reset by motion: the episode starts where the arm is.

``RobotLoop.reset`` (today) teleports a simulation and refuses a robot without one, so a real
arm's loop cannot be started through it. Until the seam resets by motion (issue 34, item 0),
benchmarks and tests build the Franka's loop with this object as the robot's ``simulation``:
its reset leaves the arm where it is (the loop then restarts its clock, estimator, controller
and safety filter and settles there), and it knows no truth (``NO_GROUND_TRUTH``). It is never
part of the ``franka`` plugin's robot.
"""
from __future__ import annotations

import numpy as np
from qg_common.types import NO_GROUND_TRUTH, GroundTruth

__all__ = ["StartInPlace"]


class StartInPlace:
    """``SimulationInterface`` whose reset does not move the arm and whose truth is zeros."""

    def reset(self, initial_pose: int, housing_yaw: float = 0.0) -> None:
        del initial_pose, housing_yaw

    def ground_truth(self) -> GroundTruth:
        return NO_GROUND_TRUTH

    def contact_wrench(self) -> np.ndarray:
        return np.zeros(6)
