"""Rotation helpers shared by the simulator and the controller (no other dependencies)."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["axis_angle_matrix", "housing_rotation", "rotation_log", "tilt_from_down"]


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix about the unit vector ``axis`` by ``angle`` [rad] (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def housing_rotation(yaw: float, tilt: float = 0.0) -> np.ndarray:
    """Orientation of the housing in the base frame: turned by ``yaw`` about the vertical, then
    tilted by ``tilt`` about its own x axis [rad]. Its z axis points out of the bore, so the bore
    axis, tip first, is ``-housing_rotation(yaw, tilt)[:, 2]``.
    """
    cy, sy, ct, st = math.cos(yaw), math.sin(yaw), math.cos(tilt), math.sin(tilt)
    return np.array([[cy, -sy * ct, sy * st], [sy, cy * ct, -cy * st], [0.0, st, ct]])


def rotation_log(rotation: np.ndarray) -> np.ndarray:
    """Angle-axis vector of a rotation matrix (for angles up to pi)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation.tolist()
    cos = max(-1.0, min(1.0, (r00 + r11 + r22 - 1.0) / 2.0))
    angle = math.acos(cos)
    w = np.array([r21 - r12, r02 - r20, r10 - r01])
    if angle < 1e-9:
        return w / 2.0
    if angle > math.pi - 1e-6:  # the skew part vanishes at 180 deg: axis from the diagonal
        axis = np.sqrt(np.maximum(np.diag(rotation) + 1.0, 0.0) / 2.0)
        return axis * angle
    return w * angle / (2.0 * math.sin(angle))


def tilt_from_down(rotation: np.ndarray) -> tuple[float, np.ndarray]:
    """Angle [rad] of the frame's z axis from straight down, and the unit axis (same frame as
    ``rotation``'s columns) about which a positive rotation turns it back; zero axis if aligned.
    """
    zx, zy, zz = rotation[:, 2].tolist()
    sin = math.hypot(zx, zy)                      # |z x (0, 0, -1)| = |(-zy, zx, 0)|
    angle = math.atan2(sin, -zz)
    if sin < 1e-12:
        return angle, np.zeros(3)
    return angle, np.array([-zy / sin, zx / sin, 0.0])
