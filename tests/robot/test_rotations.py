"""qg_common.rotations (Pinocchio's SO(3) maps) held against scipy's ``Rotation``, an independent
implementation, near 0, pi/2 and pi, and the quaternion kept continuous at the operating point."""
from __future__ import annotations

import math

import numpy as np
import pytest
from qg_common.rotations import (
    axis_angle_matrix,
    matrix_from_quaternion,
    quaternion_from_matrix,
    rotation_log,
)
from scipy.spatial.transform import Rotation

_RNG = np.random.default_rng(0)
AXES = [np.array(a, float) / np.linalg.norm(a) for a in
        [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0.3, -0.5, 0.8), (-1, -1, 0.2)] + list(_RNG.normal(size=(4, 3)))]
PI = math.pi
ANGLES = [0.0, 1e-9, 1e-4, 0.3, PI / 2 - 1e-6, PI / 2, PI / 2 + 1e-6, 2.0, PI - 1e-3, PI - 1e-6, PI - 1e-9, PI]


def sign_component(matrix: np.ndarray, q: np.ndarray) -> float:
    """The component Eigen makes positive: w if the trace is positive, else that of the largest
    diagonal entry (x, y or z)."""
    return q[3] if np.trace(matrix) > 0.0 else q[int(np.argmax(np.diag(matrix)))]


def same_up_to_sign(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    return bool(np.allclose(a, b, atol=atol) or np.allclose(a, -b, atol=atol))


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("axis", AXES, ids=lambda a: np.array2string(a, precision=2))
def test_rotation_log_and_exp_match_scipy(axis: np.ndarray, angle: float) -> None:
    reference = Rotation.from_rotvec(axis * angle)
    matrix = reference.as_matrix()
    np.testing.assert_allclose(axis_angle_matrix(axis, angle), matrix, atol=1e-14)
    log = rotation_log(matrix)
    expected = Rotation.from_matrix(matrix).as_rotvec()
    if angle < PI - 1e-6:
        np.testing.assert_allclose(log, expected, atol=1e-9)
    else:  # at pi the axis' sign is a free choice; the rotation it stands for is not
        assert same_up_to_sign(log, expected, atol=1e-6), (log, expected)
        np.testing.assert_allclose(Rotation.from_rotvec(log).as_matrix(), matrix, atol=1e-9)
    assert np.linalg.norm(log) == pytest.approx(angle, abs=1e-9)


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("axis", AXES, ids=lambda a: np.array2string(a, precision=2))
def test_quaternion_matches_scipy_both_ways(axis: np.ndarray, angle: float) -> None:
    reference = Rotation.from_rotvec(axis * angle)
    q = np.array(quaternion_from_matrix(reference.as_matrix()))
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
    assert same_up_to_sign(q, reference.as_quat(), atol=1e-12)
    assert sign_component(reference.as_matrix(), q) > 0.0
    np.testing.assert_allclose(matrix_from_quaternion(*q), reference.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(matrix_from_quaternion(*(3.0 * q)), reference.as_matrix(), atol=1e-12)


def test_quaternion_is_continuous_through_the_tool_pointing_down() -> None:
    """The tool frame at the operating point is a half turn about x (w = 0); tilting it either way
    must move the quaternion a little, not flip its sign."""
    down = Rotation.from_rotvec([PI, 0.0, 0.0])
    path = [Rotation.from_rotvec([s, 0.02, -0.01]) * down for s in np.linspace(-0.05, 0.05, 101)]
    qs = np.array([quaternion_from_matrix(r.as_matrix()) for r in path])
    assert qs[:, 3].min() < 0.0 < qs[:, 3].max()  # the path crosses w = 0
    assert np.max(np.linalg.norm(np.diff(qs, axis=0), axis=1)) < 1e-3
    for q, r in zip(qs, path):
        assert same_up_to_sign(q, r.as_quat(), atol=1e-12)


def test_a_degenerate_quaternion_gives_a_matrix_the_safety_filter_rejects() -> None:
    assert np.isnan(matrix_from_quaternion(0.0, 0.0, 0.0, 0.0)).all()
    assert np.isnan(matrix_from_quaternion(math.nan, 0.0, 0.0, 1.0)).all()
    assert np.isnan(matrix_from_quaternion(math.inf, 0.0, 0.0, 1.0)).all()


def test_block_quaternions_are_eigens_and_cost_no_memory() -> None:
    """``quaternions_from_matrices`` gives Pinocchio's (Eigen's) quaternion, sign included, for
    every case of its algorithm (trace positive; largest diagonal entry x, y or z; ties), and,
    unlike ``pin.Quaternion`` of a C-ordered NumPy matrix (eigenpy 3.13 leaked 80 bytes a call,
    the robot process's growth per episode), leaves the process's memory where it was."""
    import pinocchio as pin
    from qg_common.rotations import quaternions_from_matrices

    rotations = [Rotation.from_rotvec(axis * angle).as_matrix() for axis in AXES for angle in ANGLES]
    rotations += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    block = np.array(rotations)
    qs = quaternions_from_matrices(block)
    assert {int(np.argmax(np.abs(q))) for q in qs} == {0, 1, 2, 3}   # all four branches taken
    expected = np.array([pin.Quaternion(np.asfortranarray(r)).coeffs() for r in rotations])
    np.testing.assert_allclose(qs, expected, atol=1e-12)
    np.testing.assert_allclose(qs[7], quaternion_from_matrix(block[7]), atol=0.0)
    with pytest.raises(ValueError, match=r"\(n, 3, 3\)"):
        quaternions_from_matrices(np.eye(3))

    def rss_kib() -> int:
        with open("/proc/self/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))

    many = np.repeat(block[:1], 2000, axis=0)
    quaternions_from_matrices(many)                       # warm-up: numpy's buffers
    before = rss_kib()
    for _ in range(100):                                  # 200,000 quaternions
        quaternions_from_matrices(many)
    assert rss_kib() - before < 2048, "the block quaternions grew the process by 2 MiB or more"
