"""ROS messages <-> the numpy arrays and dataclasses of the pure cores, in one place.

Message types stay at the edge: the loop, controller and estimator only see numpy and the core
dataclasses, and every node converts through these functions, so a frame or a field order is
decided once. Frames: poses and twists are in the robot's base frame (its URDF's root link, which
the caller names: ``panda_link0`` for the Panda), wrenches in the tool frame (``tool``, see
``qg_common/types.py`` for the sign convention).
"""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseStamped, TwistStamped, Wrench, WrenchStamped
from qg_interfaces.msg import AtRest
from qg_interfaces.msg import GroundTruth as GroundTruthMsg
from qg_interfaces.msg import WrenchSetpoint as WrenchSetpointMsg
from qg_interfaces.srv import MoveToStart
from sensor_msgs.msg import JointState as JointStateMsg
from visualization_msgs.msg import Marker, MarkerArray

from qg_common.rotations import matrix_from_quaternion, quaternion_from_matrix
from qg_common.task_scene import TaskScene
from qg_common.types import (
    TOOL_FRAME,
    GroundTruth,
    JointState,
    PoseReference,
    StartPose,
    StepResult,
    WrenchSetpoint,
)

__all__ = ["TOOL_FRAME", "time_msg", "time_ns", "joint_state_msg",
           "joint_state_from_msg", "wrench_msg", "wrench_from_msg", "wrench_stamped",
           "ground_truth_msg", "ground_truth_from_msg", "quaternion_from_matrix",
           "matrix_from_quaternion", "pose_msg", "pose_stamped", "twist_stamped", "at_rest_msg",
           "setpoint_from_msg", "setpoint_msg", "start_pose_request", "start_pose_from_request",
           "marker_array_msg"]


# --- time ---------------------------------------------------------------------------------------
def time_msg(ns: int) -> Time:
    """``builtin_interfaces/Time`` from integer nanoseconds."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def time_ns(stamp: Time) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


# --- joints -------------------------------------------------------------------------------------
def joint_state_msg(state: JointState, stamp: Time, names: tuple[str, ...]) -> JointStateMsg:
    """``sensor_msgs/JointState`` of the arm joints ``names``; effort is the measured torque."""
    msg = JointStateMsg(name=list(names), position=state.q.tolist(),
                        velocity=state.dq.tolist(), effort=state.tau.tolist())
    msg.header.stamp = stamp
    return msg


def joint_state_from_msg(msg: JointStateMsg, n: int) -> JointState:
    """The core ``JointState`` of an ``n``-joint arm; a missing effort reads as zero torque.

    :raises ValueError: if position or velocity do not have ``n`` entries.
    """
    if len(msg.position) != n or len(msg.velocity) != n:
        raise ValueError(f"joint state needs {n} positions and velocities, got "
                         f"{len(msg.position)} and {len(msg.velocity)}")
    tau = np.asarray(msg.effort, float) if len(msg.effort) == n else np.zeros(n)
    return JointState(q=np.asarray(msg.position, float), dq=np.asarray(msg.velocity, float),
                      tau=tau)


# --- wrenches -----------------------------------------------------------------------------------
def wrench_msg(wrench: np.ndarray) -> Wrench:
    """``geometry_msgs/Wrench`` from ``[Fx, Fy, Fz, Tx, Ty, Tz]``."""
    w = [float(v) for v in wrench]
    msg = Wrench()
    msg.force.x, msg.force.y, msg.force.z = w[0], w[1], w[2]
    msg.torque.x, msg.torque.y, msg.torque.z = w[3], w[4], w[5]
    return msg


def wrench_from_msg(msg: Wrench) -> np.ndarray:
    """``[Fx, Fy, Fz, Tx, Ty, Tz]`` of a ``geometry_msgs/Wrench``."""
    f, t = msg.force, msg.torque
    return np.array([f.x, f.y, f.z, t.x, t.y, t.z])


def wrench_stamped(wrench: np.ndarray, stamp: Time, frame: str = TOOL_FRAME) -> WrenchStamped:
    """A tool-frame wrench with its header."""
    msg = WrenchStamped(wrench=wrench_msg(wrench))
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    return msg


# --- ground truth -------------------------------------------------------------------------------
def ground_truth_msg(truth: GroundTruth, stamp: Time) -> GroundTruthMsg:
    """``qg_interfaces/GroundTruth`` from the simulator's ``GroundTruth``."""
    msg = GroundTruthMsg(contact_wrench=wrench_msg(truth.wrench),
                         insertion_depth=float(truth.insertion_depth),
                         plunger_travel=float(truth.plunger_travel), success=bool(truth.success),
                         position_error=float(truth.position_error),
                         orientation_error=np.asarray(truth.orientation_error, float),
                         lateral_offset=float(truth.lateral_offset), tilt=float(truth.tilt))
    msg.header.stamp = stamp
    msg.header.frame_id = TOOL_FRAME
    return msg


def ground_truth_from_msg(msg: GroundTruthMsg) -> GroundTruth:
    """The simulator's ``GroundTruth`` back from its message."""
    return GroundTruth(wrench=wrench_from_msg(msg.contact_wrench),
                       insertion_depth=msg.insertion_depth, plunger_travel=msg.plunger_travel,
                       success=msg.success, position_error=msg.position_error,
                       orientation_error=np.array(msg.orientation_error, float),
                       lateral_offset=msg.lateral_offset, tilt=msg.tilt)


# --- poses (quaternions: ``qg_common.rotations``) ---------------------------------------------
def pose_msg(position: np.ndarray, rotation: np.ndarray) -> Pose:
    """``geometry_msgs/Pose`` from a position and a rotation matrix."""
    msg = Pose()
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in position)
    o = msg.orientation
    o.x, o.y, o.z, o.w = quaternion_from_matrix(rotation)
    return msg


def pose_stamped(position: np.ndarray, rotation: np.ndarray, stamp: Time,
                 base_frame: str) -> PoseStamped:
    """The tool pose in the base frame, with its header."""
    msg = PoseStamped(pose=pose_msg(position, rotation))
    msg.header.stamp = stamp
    msg.header.frame_id = base_frame
    return msg


def twist_stamped(twist: np.ndarray, stamp: Time, base_frame: str) -> TwistStamped:
    """The tool twist ``[v; w]`` in the base frame, with its header."""
    msg = TwistStamped()
    v = [float(x) for x in twist]
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = v[0], v[1], v[2]
    msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = v[3], v[4], v[5]
    msg.header.stamp = stamp
    msg.header.frame_id = base_frame
    return msg


# --- RL step ------------------------------------------------------------------------------------
def at_rest_msg(seq: int, result: StepResult, position: np.ndarray, rotation: np.ndarray,
                stamp: Time, base_frame: str, foreign_setpoints: int = 0) -> AtRest:
    """The ``AtRest`` event completing setpoint ``seq`` (0 after a reset).

    A run without an estimator reports a zero wrench estimate.
    :param base_frame: the frame of its pose (the robot's base).
    :param foreign_setpoints: setpoints of other sessions ignored since the last reset.
    """
    wrench = np.zeros(6) if result.wrench_estimate is None else result.wrench_estimate
    msg = AtRest(seq=int(seq), duration=float(result.duration),
                 linear_speed=float(result.linear_speed),
                 angular_speed=float(result.angular_speed), timed_out=bool(result.timed_out),
                 wrench_estimate=wrench_msg(wrench), ee_pose=pose_msg(position, rotation),
                 ground_truth=ground_truth_msg(result.ground_truth, stamp),
                 foreign_setpoints=int(foreign_setpoints), fault=result.fault)
    msg.header.stamp = stamp
    msg.header.frame_id = base_frame
    return msg


# --- start poses -------------------------------------------------------------------------------
def start_pose_request(start: StartPose, session: str = "",
                       request_id: str = "") -> MoveToStart.Request:
    """The ``move_to_start`` request of a start (what the executor sends)."""
    request = MoveToStart.Request(start=pose_msg(start.position, start.rotation),
                                  start_index=int(start.label), session=session,
                                  request_id=request_id)
    request.approach.x, request.approach.y, request.approach.z = \
        (float(v) for v in start.approach)
    return request


def start_pose_from_request(request: MoveToStart.Request) -> StartPose:
    """The start a ``move_to_start`` request asks for (values are checked by the server)."""
    p, o, a = request.start.position, request.start.orientation, request.approach
    return StartPose(position=np.array([p.x, p.y, p.z]),
                     rotation=matrix_from_quaternion(o.x, o.y, o.z, o.w),
                     approach=np.array([a.x, a.y, a.z]), label=int(request.start_index))


# --- setpoints ----------------------------------------------------------------------------------
def setpoint_from_msg(msg: WrenchSetpointMsg) -> WrenchSetpoint:
    """The core setpoint; values are not checked here (the safety filter rejects NaN/inf)."""
    reference = None
    if not msg.reference_from_current:
        p, o = msg.pose_reference.position, msg.pose_reference.orientation
        reference = PoseReference(np.array([p.x, p.y, p.z]),
                                  matrix_from_quaternion(o.x, o.y, o.z, o.w))
    return WrenchSetpoint(wrench_from_msg(msg.wrench), reference)


def setpoint_msg(seq: int, setpoint: WrenchSetpoint, stamp: Time,
                 session: str = "") -> WrenchSetpointMsg:
    """The message of a core setpoint (what the executor sends).

    :param session: the episode it belongs to, as named in its ``MoveToStart`` request.
    """
    msg = WrenchSetpointMsg(seq=int(seq), session=session, wrench=wrench_msg(setpoint.wrench),
                            reference_from_current=setpoint.reference is None)
    if setpoint.reference is not None:
        msg.pose_reference = pose_msg(setpoint.reference.position, setpoint.reference.rotation)
    msg.header.stamp = stamp
    return msg


# --- the task's parts ---------------------------------------------------------------------------
def marker_array_msg(scene: TaskScene, base_frame: str, stamp: Time) -> MarkerArray:
    """The parts of ``scene`` as ``visualization_msgs/MarkerArray`` (``ns`` the part's name, ids
    in order, ``BASE`` as ``base_frame``), each locked to its frame so it moves with it
    (``task_scene.part_from_marker`` reads one back)."""
    markers = []
    for k, part in enumerate(scene.parts):
        marker = Marker(ns=part.name, id=k, type=part.kind, action=Marker.ADD, frame_locked=True)
        marker.header.frame_id = part.frame or base_frame      # BASE is ""
        marker.header.stamp = stamp
        p, r = marker.pose.position, marker.pose.orientation
        p.x, p.y, p.z = map(float, part.position)
        r.x, r.y, r.z, r.w = map(float, part.rotation)
        marker.scale.x, marker.scale.y, marker.scale.z = map(float, part.scale)
        marker.color.r, marker.color.g, marker.color.b, marker.color.a = map(float, part.colour)
        marker.points = [Point(x=x, y=y, z=z) for x, y, z in part.points]
        markers.append(marker)
    return MarkerArray(markers=markers)
