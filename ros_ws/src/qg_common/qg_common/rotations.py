"""Rotation helpers shared by the simulator, the controller, the task and the message
conversions.

Thin names over Pinocchio's SO(3) maps, which the controller already uses (`pin.log3` in the
impedance law): `log3` (right up to and at pi, where a formula through ``acos`` and the skew part
loses the axis' signs), and Eigen's quaternion of a matrix, its algorithm in NumPy
(``quaternions_from_matrices``: eigenpy leaks a copy there); Pinocchio is imported by those
functions only, so the task's geometry (``shaft_task``, which the executor's core uses on a
machine without the robot's libraries) needs NumPy alone: a rotation from an axis and an angle
is Rodrigues' formula. Eigen picks
the sign by the matrix (``w > 0`` if the trace is positive, else the component of the largest
diagonal entry), so the quaternion is continuous around the tool pointing down (a half turn,
w close to 0, x chosen positive), where a ``w >= 0`` rule flips every sign whenever the tool
tilts across it. tests/robot/test_rotations.py holds them
against scipy's ``Rotation`` near 0, pi/2 and pi.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["axis_angle_matrix", "housing_rotation", "matrix_from_quaternion",
           "quaternion_from_matrix", "quaternions_from_matrices", "rotation_log",
           "tilt_from_down"]


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix about ``axis`` by ``angle`` [rad] (Rodrigues; the rotation vector is
    ``axis * angle``, so a non-unit axis scales the angle, as ``exp3`` of it would)."""
    vector = np.asarray(axis, float) * float(angle)
    theta = math.sqrt(float(vector @ vector))
    if theta < 1e-12:
        return np.eye(3)
    x, y, z = vector / theta
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(theta) * k + (1.0 - math.cos(theta)) * (k @ k)


def housing_rotation(yaw: float, tilt: float = 0.0) -> np.ndarray:
    """Orientation of the housing in the base frame: turned by ``yaw`` about the vertical, then
    tilted by ``tilt`` about its own x axis [rad]. Its z axis points out of the bore, so the bore
    axis, tip first, is ``-housing_rotation(yaw, tilt)[:, 2]``.
    """
    cy, sy, ct, st = math.cos(yaw), math.sin(yaw), math.cos(tilt), math.sin(tilt)
    return np.array([[cy, -sy * ct, sy * st], [sy, cy * ct, -cy * st], [0.0, st, ct]])


def rotation_log(rotation: np.ndarray) -> np.ndarray:
    """Angle-axis vector (angle in [0, pi]) of a rotation matrix."""
    import pinocchio as pin
    return pin.log3(np.asarray(rotation, float))


def quaternion_from_matrix(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix, with Eigen's sign (see above)."""
    x, y, z, w = quaternions_from_matrices(np.asarray(rotation, float)[None])[0].tolist()
    return x, y, z, w


def quaternions_from_matrices(rotations: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions ``(x, y, z, w)`` of (n, 3, 3) rotation matrices: Eigen's
    algorithm and sign (``Quaternion(const MatrixBase&)``), in NumPy for a whole block at once.

    Not ``pin.Quaternion(matrix)``: eigenpy 3.13 leaks the copy it makes of a C-ordered NumPy
    matrix there (80 bytes a call), and the robot process made one per recorded and per
    published tick, 0.45 MiB an episode (``tests/robot_nodes/test_robot_process_memory.py``).

    :raises ValueError: if ``rotations`` is not (n, 3, 3).
    """
    m = np.asarray(rotations, float)
    if m.ndim != 3 or m.shape[1:] != (3, 3):
        raise ValueError(f"rotations must be (n, 3, 3), got shape {m.shape}")
    out = np.empty((len(m), 4))
    trace = np.trace(m, axis1=1, axis2=2)
    positive = trace > 0.0
    if positive.any():        # w is the largest component: taken from the trace
        p = m[positive]
        t = np.sqrt(trace[positive] + 1.0)
        out[positive, 3] = 0.5 * t
        h = 0.5 / t
        out[positive, 0] = (p[:, 2, 1] - p[:, 1, 2]) * h
        out[positive, 1] = (p[:, 0, 2] - p[:, 2, 0]) * h
        out[positive, 2] = (p[:, 1, 0] - p[:, 0, 1]) * h
    for i in range(3):        # else the component of the largest diagonal entry (first of ties)
        rows = ~positive & (np.argmax(np.diagonal(m, axis1=1, axis2=2), axis=1) == i)
        if not rows.any():
            continue
        j, k = (i + 1) % 3, (i + 2) % 3
        p = m[rows]
        t = np.sqrt(p[:, i, i] - p[:, j, j] - p[:, k, k] + 1.0)
        out[rows, i] = 0.5 * t
        h = 0.5 / t
        out[rows, 3] = (p[:, k, j] - p[:, j, k]) * h
        out[rows, j] = (p[:, j, i] + p[:, i, j]) * h
        out[rows, k] = (p[:, k, i] + p[:, i, k]) * h
    return out


def matrix_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of the quaternion ``(x, y, z, w)``, normalised first.

    A zero or non-finite quaternion gives a NaN matrix, which the safety filter rejects.
    """
    import pinocchio as pin
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not (math.isfinite(norm) and norm > 0.0):
        return np.full((3, 3), math.nan)
    return pin.Quaternion(w / norm, x / norm, y / norm, z / norm).toRotationMatrix()


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
