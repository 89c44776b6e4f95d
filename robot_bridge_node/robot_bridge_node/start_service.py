"""The ``move_to_start`` service: a robot taken to an episode's start, validated and answered once.

Served by whatever gets the robot to a start: the composed robot process's ``bridge`` node
(``robot_process.RobotProcess``: its loop teleports a simulation or moves the arm), or the
separate sim of ``sim_robot_node`` (it teleports, the separate bridge settles).
"""
from __future__ import annotations

from typing import Protocol

import numpy as np
from qg_common import topics
from qg_common.conversions import start_pose_from_request
from qg_common.retried_requests import answered_once
from qg_common.types import StartPose
from qg_interfaces.msg import AtRest
from qg_interfaces.srv import MoveToStart
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

__all__ = ["StartMover", "check_start", "serve_move_to_start"]


class StartMover(Protocol):
    """Gets the robot to a start, settles it, and returns the settled observation."""

    def move_to_start(self, start: StartPose, timeout: float = 30.0,
                      session: str = "") -> AtRest: ...


def check_start(start: StartPose) -> str:
    """Why ``start`` cannot be a start ("" if it can): every number finite, a rotation."""
    values = np.concatenate([start.position, start.rotation.ravel(), start.approach])
    if not np.all(np.isfinite(values)):
        return f"the start pose and approach must be finite, got {values.tolist()}"
    return ""


def serve_move_to_start(node: Node, mover: StartMover) -> None:
    """Serve ``move_to_start`` on ``node``: validate the request, then ``mover.move_to_start``.

    The call blocks until the robot has settled (a motion takes seconds), so the service has a
    callback group of its own and the node's other callbacks keep running meanwhile. A reply can
    be lost (a client the server has not matched yet, ``qg_common/ros_client.py``), so a client retries
    with the same ``request_id``; that retry is answered with the first reply, and the robot,
    which may have moved on since, is not moved twice (``qg_common.retried_requests``).
    """
    def answer(request: MoveToStart.Request,
               response: MoveToStart.Response) -> MoveToStart.Response:
        response.success = False
        start = start_pose_from_request(request)
        why = check_start(start)
        if why:
            response.message = why
            return response
        what = f"start {request.start_index}" if request.start_index >= 0 else "the start"
        try:
            response.observation = mover.move_to_start(start, session=request.session)
        except (RuntimeError, ValueError, TimeoutError) as exc:
            node.get_logger().error(f"moving to {what} failed: {exc}")
            response.message = f"moving to {what} failed: {exc}"
            return response
        response.success = True
        response.message = f"at {what}"
        return response

    node.create_service(MoveToStart, topics.MOVE_TO_START,
                        answered_once(answer, "move_to_start", node.get_logger().info),
                        callback_group=MutuallyExclusiveCallbackGroup())
