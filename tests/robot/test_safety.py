"""Safety filter: rejected and clamped setpoints, tilt cone, torque limits, watchdog."""
from __future__ import annotations

import math

import numpy as np
import pytest
from qg_common.panda_description import DTAU_MAX, panda_arm
from qg_common.rotations import axis_angle_matrix, tilt_from_down
from qg_common.types import PoseReference, WrenchSetpoint
from qg_common.xarm_description import xarm7_arm
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.safety import (
    VELOCITY_BRAKE_DAMPING,
    SafetyFilter,
    SafetyLimits,
    SetpointRejected,
)

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
                                        ("torque_max", 3.5), ("watchdog_timeout", 0.6),
                                        ("force_max", 0.0)])
def test_limits_cannot_be_loosened_or_disabled(name: str, value: float) -> None:
    with pytest.raises(ValueError, match=name):
        SafetyLimits(**{name: value})


PANDA_LIMITS = ArmModel.of_arm(panda_arm()).limits


def test_torques_respect_magnitude_and_rate_limits() -> None:
    """The Panda's limits come from its URDF (87 / 12 Nm, the datasheet's) and its description
    (1000 Nm/s)."""
    safety = SafetyFilter(joints=PANDA_LIMITS)
    safety.reset(np.zeros(7))
    dt = 0.001
    tau = safety.limit_torques(np.full(7, 50.0), dt)
    np.testing.assert_allclose(tau, DTAU_MAX * dt)  # 1 Nm per ms
    for _ in range(200):
        tau = safety.limit_torques(np.array([200.0, -200.0, 50, -50, 20, -20, 5]), dt)
    np.testing.assert_allclose(tau, [87.0, -87.0, 50, -50, 12, -12, 5])


def test_another_arm_gets_the_torque_and_velocity_limits_of_its_urdf() -> None:
    """The xArm 7's URDF: 50, 50, 30, 30, 30, 20, 20 Nm and 3.14 rad/s on every joint."""
    limits = ArmModel.of_arm(xarm7_arm()).limits
    np.testing.assert_array_equal(limits.torque, [50, 50, 30, 30, 30, 20, 20])
    np.testing.assert_array_equal(limits.velocity, np.full(7, 3.14))
    safety = SafetyFilter(joints=limits)
    tau = safety.limit_torques(np.array([200.0, -200.0, 50, -50, 25, -25, 5]), 0.001)
    np.testing.assert_allclose(tau, [50.0, -50.0, 30, -30, 25, -20, 5])


def test_a_joint_past_its_velocity_limit_is_braked_and_one_within_is_not() -> None:
    safety = SafetyFilter(joints=PANDA_LIMITS)
    tau = np.array([1.0, 2.0, 3.0, 4.0, 1.0, 1.0, 1.0])
    within = PANDA_LIMITS.velocity * np.array([0.99, -0.99, 0.5, 0.0, 0.99, -0.5, 0.0])
    np.testing.assert_array_equal(safety.limit_torques(tau, 0.001, within), tau)
    fast = within.copy()
    fast[1] = -PANDA_LIMITS.velocity[1] - 0.2           # 0.2 rad/s too fast, backwards
    fast[4] = PANDA_LIMITS.velocity[4] + 0.1
    braked = SafetyFilter(joints=PANDA_LIMITS).limit_torques(tau, 0.001, fast)
    expected = tau.copy()
    expected[1] += VELOCITY_BRAKE_DAMPING * 0.2
    expected[4] -= VELOCITY_BRAKE_DAMPING * 0.1
    np.testing.assert_allclose(braked, expected, atol=1e-12)


def _numpy_limit_torques(limits, last: np.ndarray | None, tau: np.ndarray, dt: float,
                         dq: np.ndarray | None) -> np.ndarray:
    """The torque limits as NumPy wrote them before the filter moved to Python floats (the
    reference the filter must match)."""
    with np.errstate(invalid="ignore"):           # inf - inf, inf * 0: NaN, as intended
        return _numpy_limits(limits, last, tau, dt, dq)


def _numpy_limits(limits, last: np.ndarray | None, tau: np.ndarray, dt: float,
                  dq: np.ndarray | None) -> np.ndarray:
    if dq is not None:
        excess = dq - np.clip(dq, -limits.velocity, limits.velocity)
        if np.any(excess):
            tau = tau - VELOCITY_BRAKE_DAMPING * excess
    tau = np.minimum(np.maximum(tau, -limits.torque), limits.torque)
    if last is not None:
        step = limits.torque_rate * dt
        tau = np.minimum(np.maximum(tau, last - step), last + step)
    return tau


@pytest.mark.parametrize("arm", [panda_arm, xarm7_arm])
def test_torque_limits_are_numpys_to_the_bit_on_random_and_non_finite_inputs(arm) -> None:
    """3000 random commands, speeds and time steps through one filter (its rate limit
    carries over), against the NumPy reference: every torque equal to the bit, NaN where it
    has NaN. A fifth of the speeds are past their limits, some entries are inf or NaN, some
    time steps 0, and an unlimited rate (inf) on one joint."""
    limits = ArmModel.of_arm(arm()).limits
    limits = type(limits)(limits.torque, np.where(np.arange(7) == 3, np.inf,
                                                  limits.torque_rate), limits.velocity)
    rng = np.random.default_rng(7)
    safety, last = SafetyFilter(joints=limits), None
    special = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0])
    for i in range(3000):
        tau = rng.normal(0.0, 1.5, 7) * limits.torque
        dq = rng.normal(0.0, 0.6, 7) * limits.velocity
        if i % 10 == 0:
            tau[rng.integers(7)] = rng.choice(special)
            dq[rng.integers(7)] = rng.choice(special)
        dt = 0.0 if i % 97 == 0 else float(rng.uniform(0.0005, 0.002))
        speeds = None if i % 3 == 0 else dq
        if i % 500 == 0:                      # a reset, with or without the applied torque
            last = None if i % 1000 == 0 else rng.normal(0.0, 0.3, 7) * limits.torque
            safety.reset(last)
        expected = _numpy_limit_torques(limits, last, tau, dt, speeds)
        got = safety.limit_torques(tau, dt, speeds)
        np.testing.assert_array_equal(got, expected)
        assert np.array_equal(np.signbit(got), np.signbit(expected))
        last = expected


def test_torque_limits_refuse_a_command_without_one_entry_per_joint() -> None:
    safety = SafetyFilter(joints=PANDA_LIMITS)
    with pytest.raises(ValueError, match="tau must have one entry per joint"):
        safety.limit_torques(np.zeros(6), 0.001)
    with pytest.raises(ValueError, match="dq must have one entry per joint"):
        safety.limit_torques(np.zeros(7), 0.001, np.zeros((7, 1)))


def test_a_filter_without_joint_limits_refuses_to_limit_torques() -> None:
    with pytest.raises(RuntimeError, match="joint limits"):
        SafetyFilter().limit_torques(np.zeros(7), 0.001)


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
    assert not safety.watchdog_expired(1.099)
    assert safety.watchdog_expired(1.101)
    safety.feed_watchdog(1.101)
    assert not safety.watchdog_expired(1.2)
