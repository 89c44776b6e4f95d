"""A test client for the robot-side nodes: resets, setpoints and at-rest events, like the executor."""
from __future__ import annotations

import uuid

import numpy as np
import rclpy.qos
from qg_common import conversions, types
from qg_common.conversions import start_pose_request, time_msg
from qg_common.params import config_file, load_ros_params
from qg_common.peg_task import PegCell
from qg_common.ros_client import RESEND_AFTER, CliNode, call_service
from qg_common.shaft_task import ShaftTaskGeometry
from qg_interfaces.msg import AtRest, WrenchSetpoint
from qg_interfaces.srv import MoveToStart


def shaft_start(index: int) -> types.StartPose:
    """The installed shaft cell's start ``index`` (what the executor asks for)."""
    return ShaftTaskGeometry.from_dict(
        load_ros_params(config_file("shaft_task.yaml"))["shaft_task"]).start_pose(index)


def peg_start(index: int) -> types.StartPose:
    """The installed peg cell's start ``index`` (the Nextage's)."""
    return PegCell.from_dict(
        load_ros_params(config_file("peg_task.yaml"))["peg_task"]).start_pose(index)

#: Best effort like the 1 kHz publishers, deep enough that a slow test process loses nothing.
DEEP = rclpy.qos.QoSProfile(depth=2000, reliability=rclpy.qos.ReliabilityPolicy.BEST_EFFORT)


class RobotClient:
    """Resets the sim, sends setpoints and collects ``ee_at_rest`` on one test node.

    :param namespace: the robot's namespace (``--ros-args -r __ns:=...``); "" is the root.
    """

    def __init__(self, cli: CliNode, namespace: str = "") -> None:
        self.cli = cli
        self.namespace = namespace
        self.events: list[AtRest] = []
        cli.node.create_subscription(AtRest, f"{namespace}/ee_at_rest", self.events.append, 100)
        self.setpoints = cli.node.create_publisher(WrenchSetpoint, f"{namespace}/wrench_setpoint",
                                                   10)

    def reset(self, pose: int | types.StartPose, timeout: float = 60.0,
              session: str = "") -> MoveToStart.Response:
        """Move to the shaft cell's start ``pose`` (or to a given start); the bridge then serves
        only ``session``'s setpoints ("" = any).

        Asked again after ``RESEND_AFTER`` s without a reply (a reply to a client the server has
        not matched yet is lost), with the same request id: the robot answers that without
        moving twice.
        """
        start = shaft_start(pose) if isinstance(pose, int) else pose
        request = start_pose_request(start, session=session, request_id=uuid.uuid4().hex)
        return call_service(self.cli, MoveToStart, f"{self.namespace}/move_to_start", request,
                            timeout, resend_after=RESEND_AFTER)

    def send(self, seq: int, wrench: tuple[float, ...], session: str = "") -> None:
        assert self.cli.spin_until(lambda: self.setpoints.get_subscription_count() > 0, 30.0), \
            "nobody subscribes /wrench_setpoint"
        setpoint = types.WrenchSetpoint(np.array(wrench, float))
        self.setpoints.publish(conversions.setpoint_msg(seq, setpoint, time_msg(0), session))

    def event(self, seq: int) -> AtRest | None:
        return next((e for e in self.events if e.seq == seq), None)

    def step(self, seq: int, wrench: tuple[float, ...], timeout: float = 20.0,
             session: str = "") -> AtRest | None:
        """Send setpoint ``seq`` once (it holds until its step ends) and wait for its
        ``AtRest`` (None on timeout)."""
        self.send(seq, wrench, session)
        self.cli.spin_until(lambda: self.event(seq) is not None, timeout)
        return self.event(seq)


def wrench(msg) -> np.ndarray:
    """The 6 numbers of a ``geometry_msgs/Wrench``."""
    return conversions.wrench_from_msg(msg)
