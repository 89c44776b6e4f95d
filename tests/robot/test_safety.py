"""Safety filter: rejected and clamped setpoints, tilt cone, torque limits, watchdog."""
from __future__ import annotations

import math

import numpy as np
import pytest
from robot_bridge_node.core.panda_model import DTAU_MAX, TAU_MAX
from robot_bridge_node.core.safety import SafetyFilter, SafetyLimits, SetpointRejected
from qg_common.types import PoseReference, WrenchSetpoint
from qg_common.rotations import axis_angle_matrix, tilt_from_down

DOWN = np.diag([1.0, -1.0, -1.0])  # tool z pointing down


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_setpoints_are_rejected_with_a_reason(bad: float) -> None:
    safety = SafetyFilter()
    with pytest.raises(SetpointRejected, match="NaN/inf"):
        safety.check_setpoint(WrenchSetpoint(np.array([0.0, 0.0, -15.0, bad, 0.0, 0.0])))
    ref = PoseReference(np.array([0.4, 0.0, bad]), np.eye(3))
    with pytest.raises(SetpointRejected, match="reference"):
        safety.check_setpoint(WrenchSetpoint(np.zeros(6), ref))
    with pytest.raises(SetpointRejected, match="6 entries"):
        safety.check_setpoint(WrenchSetpoint(np.zeros(5)))


def test_force_norm_and_torques_are_clamped() -> None:
    checked = SafetyFilter().check_setpoint(
        WrenchSetpoint(np.array([30.0, 0.0, -40.0, 5.0, -7.0, 0.5])))
    assert np.linalg.norm(checked.wrench[:3]) == pytest.approx(20.0)
    np.testing.assert_allclose(checked.wrench[:3] / 20.0, [0.6, 0.0, -0.8])  # direction kept
    np.testing.assert_allclose(checked.wrench[3:], [3.0, -3.0, 0.5])
    inside = np.array([1.0, 2.0, -15.0, 2.9, -2.9, 0.0])
    np.testing.assert_array_equal(SafetyFilter().check_setpoint(WrenchSetpoint(inside)).wrench,
                                  inside)


@pytest.mark.parametrize("name,value", [("tilt_max", 1.0), ("force_max", 25.0),
                                        ("torque_max", 3.5), ("watchdog_timeout", 0.05),
                                        ("force_max", 0.0)])
def test_limits_cannot_be_loosened_or_disabled(name: str, value: float) -> None:
    with pytest.raises(ValueError, match=name):
        SafetyLimits(**{name: value})


def test_torques_respect_magnitude_and_rate_limits() -> None:
    safety = SafetyFilter()
    safety.reset(np.zeros(7))
    dt = 0.001
    tau = safety.limit_torques(np.full(7, 50.0), dt)
    np.testing.assert_allclose(tau, DTAU_MAX * dt)  # 1 Nm per ms
    for _ in range(200):
        tau = safety.limit_torques(np.array([200.0, -200.0, 50, -50, 20, -20, 5]), dt)
    np.testing.assert_allclose(tau, [87.0, -87.0, 50, -50, 12, -12, 5])
    assert np.all(np.abs(tau) <= TAU_MAX)


def test_tilt_inside_the_cone_leaves_the_wrench_alone() -> None:
    wrench = np.array([0.0, 0.0, -15.0, 3.0, -3.0, 0.0])
    rotation = axis_angle_matrix(np.array([0.0, 1.0, 0.0]), 0.5) @ DOWN
    np.testing.assert_array_equal(SafetyFilter().limit_tilt(wrench, rotation), wrench)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_tilt_past_the_cone_drops_outward_torque_and_pushes_back(sign: float) -> None:
    safety = SafetyFilter()
    rotation = axis_angle_matrix(np.array([0.0, 1.0, 0.0]), math.pi / 4 + 0.02) @ DOWN
    tilt, back = tilt_from_down(rotation)
    assert tilt == pytest.approx(math.pi / 4 + 0.02)
    wrench = np.concatenate([[0.0, 0.0, -15.0], sign * 3.0 * (rotation.T @ back)])
    limited = safety.limit_tilt(wrench, rotation)
    applied = -(rotation @ limited[3:])  # what the robot applies (contact convention)
    excess = tilt - (safety.limits.tilt_max - safety.limits.tilt_margin)
    restoring = safety.limits.tilt_stiffness * excess
    # Robot applying along -back tilts further: that part goes; the restoring torque is added.
    expected = restoring + (3.0 if sign < 0 else 0.0)
    assert applied @ back == pytest.approx(expected)
    np.testing.assert_array_equal(limited[:3], wrench[:3])


def test_watchdog_fires_after_the_timeout_only() -> None:
    safety = SafetyFilter()
    assert not safety.watchdog_expired(1.0)  # no setpoint yet: nothing to hold against
    safety.feed_watchdog(1.0)
    assert not safety.watchdog_expired(1.009)
    assert safety.watchdog_expired(1.011)
    safety.feed_watchdog(1.011)
    assert not safety.watchdog_expired(1.02)
