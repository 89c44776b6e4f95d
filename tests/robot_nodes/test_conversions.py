"""Message converters: rotations survive the quaternion round trip, setpoints and events keep
their numbers, and bad input turns into something the safety filter rejects."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytestmark = pytest.mark.ros


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3), st.floats(0.0, math.pi))
def test_quaternion_round_trip_recovers_the_rotation(axis, angle):
    from qg_common.conversions import matrix_from_quaternion, quaternion_from_matrix
    from qg_common.rotations import axis_angle_matrix
    axis = np.asarray(axis)
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.0, 0.0, 1.0])
    rotation = axis_angle_matrix(axis / np.linalg.norm(axis), angle)
    q = quaternion_from_matrix(rotation)
    assert math.isclose(sum(v * v for v in q), 1.0, rel_tol=1e-12)
    # Eigen's sign rule (tests/robot/test_rotations.py): w > 0 if the trace is positive, else
    # the component of the largest diagonal entry
    assert (q[3] if np.trace(rotation) > 0.0 else q[int(np.argmax(np.diag(rotation)))]) > 0.0
    np.testing.assert_allclose(matrix_from_quaternion(*q), rotation, atol=1e-12)


def test_setpoint_messages_convert_both_ways_and_nan_reaches_the_safety_filter():
    from qg_common.conversions import setpoint_from_msg, setpoint_msg, time_msg
    from qg_common.types import PoseReference, WrenchSetpoint
    from robot_bridge_node.core.safety import SafetyFilter, SetpointRejected
    residual = WrenchSetpoint.residual(-15.0, 0.5, -0.25)
    back = setpoint_from_msg(setpoint_msg(7, residual, time_msg(0)))
    assert back.reference is None
    np.testing.assert_array_equal(back.wrench, [0.0, 0.0, -15.0, 0.5, -0.25, 0.0])

    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    posed = WrenchSetpoint(np.zeros(6), PoseReference(np.array([0.4, 0.1, 0.3]), turn))
    msg = setpoint_msg(8, posed, time_msg(0))
    assert msg.seq == 8 and not msg.reference_from_current
    back = setpoint_from_msg(msg)
    np.testing.assert_allclose(back.reference.rotation, turn, atol=1e-15)
    np.testing.assert_array_equal(back.reference.position, [0.4, 0.1, 0.3])

    msg.pose_reference.orientation.w = 0.0
    msg.pose_reference.orientation.z = 0.0        # a zero quaternion: no rotation at all
    with pytest.raises(SetpointRejected, match="pose reference"):
        SafetyFilter().check_setpoint(setpoint_from_msg(msg))
    msg = setpoint_msg(9, residual, time_msg(0))
    msg.wrench.torque.x = math.inf
    with pytest.raises(SetpointRejected, match="NaN/inf"):
        SafetyFilter().check_setpoint(setpoint_from_msg(msg))


def test_at_rest_and_joint_state_messages_carry_the_numbers():
    from qg_common.conversions import (
        at_rest_msg,
        joint_state_from_msg,
        joint_state_msg,
        time_msg,
        time_ns,
        wrench_from_msg,
    )
    from qg_common.panda_description import JOINT_NAMES
    from qg_common.types import GroundTruth, JointState, StepResult
    truth = GroundTruth(wrench=np.arange(6.0), insertion_depth=0.004, plunger_travel=0.001,
                        success=False, position_error=0.01, orientation_error=np.array([0.1, -0.2]),
                        lateral_offset=0.002, tilt=0.26)
    result = StepResult(duration=0.123, timed_out=True, linear_speed=0.001, angular_speed=0.01,
                        ground_truth=truth, wrench_estimate=-np.arange(6.0))
    stamp = time_msg(3_000_000_123)
    assert (stamp.sec, stamp.nanosec) == (3, 123) and time_ns(stamp) == 3_000_000_123
    event = at_rest_msg(42, result, np.array([0.45, 0.0, 0.31]), np.diag([1.0, -1.0, -1.0]), stamp,
                        "panda_link0")
    assert event.header.frame_id == "panda_link0"
    assert (event.seq, event.duration, event.timed_out) == (42, 0.123, True)
    np.testing.assert_array_equal(wrench_from_msg(event.wrench_estimate), -np.arange(6.0))
    np.testing.assert_array_equal(wrench_from_msg(event.ground_truth.contact_wrench), np.arange(6.0))
    np.testing.assert_array_equal(event.ground_truth.orientation_error, [0.1, -0.2])
    assert event.ee_pose.orientation.x == pytest.approx(1.0)   # 180 deg about x: tool z down

    state = JointState(q=np.linspace(-1, 1, 7), dq=np.ones(7), tau=np.arange(7.0))
    msg = joint_state_msg(state, stamp, JOINT_NAMES)
    assert list(msg.name) == list(JOINT_NAMES)
    back = joint_state_from_msg(msg, 7)
    for name in ("q", "dq", "tau"):
        np.testing.assert_array_equal(getattr(back, name), getattr(state, name))
    short = joint_state_msg(state, stamp, JOINT_NAMES)
    short.position = [0.0] * 6
    with pytest.raises(ValueError, match="7 positions"):
        joint_state_from_msg(short, 7)
