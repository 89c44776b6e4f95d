"""The ``executor`` node: runs episodes of the residual force policy on request."""
from __future__ import annotations

import uuid

import rclpy.qos
from qg_interfaces.msg import ActorParameters, EpisodeStatus, Transition, WrenchSetpoint
from qg_interfaces.srv import StartEpisode, StopEpisode
from rclpy.node import Node

from sim_robot_node.node_runtime import node_params, run_nodes

from qg_learning_node.core.episode_request import EpisodeRequest

RELIABLE_DEEP = rclpy.qos.QoSProfile(depth=1000, reliability=rclpy.qos.ReliabilityPolicy.RELIABLE)
LATCHED = rclpy.qos.QoSProfile(depth=1, reliability=rclpy.qos.ReliabilityPolicy.RELIABLE,
                               durability=rclpy.qos.DurabilityPolicy.TRANSIENT_LOCAL)


class ExecutorNode(Node):
    """Episode state machine idle -> resetting -> running -> done, started by service call."""

    def __init__(self) -> None:
        super().__init__("executor", automatically_declare_parameters_from_overrides=True)
        self.params = node_params(self)
        self.status = self.create_publisher(EpisodeStatus, "/episode_status", LATCHED)
        self.transitions = self.create_publisher(Transition, "/transitions", RELIABLE_DEEP)
        self.setpoints = self.create_publisher(WrenchSetpoint, "/wrench_setpoint", 10)
        self.create_subscription(ActorParameters, "/actor_parameters", self._on_actor, LATCHED)
        self.create_service(StartEpisode, "/executor/start_episode", self._on_start)
        self.create_service(StopEpisode, "/executor/stop_episode", self._on_stop)
        self.state = "idle"
        self.episode_id = ""

    def _on_actor(self, msg: ActorParameters) -> None:
        pass

    def _on_start(self, request: StartEpisode.Request,
                  response: StartEpisode.Response) -> StartEpisode.Response:
        try:
            EpisodeRequest(request.mode, request.initial_pose, request.seed, request.reward)
        except ValueError as exc:
            response.success, response.message = False, str(exc)
            return response
        self.episode_id = uuid.uuid4().hex[:12]
        self.state = "done"
        self._publish_status()
        response.success, response.message, response.episode_id = True, "started", self.episode_id
        return response

    def _on_stop(self, request: StopEpisode.Request,
                 response: StopEpisode.Response) -> StopEpisode.Response:
        response.success, response.message = False, "no episode is running"
        return response

    def _publish_status(self) -> None:
        msg = EpisodeStatus(episode_id=self.episode_id, state=self.state)
        msg.stamp = self.get_clock().now().to_msg()
        self.status.publish(msg)


def main(args: list[str] | None = None) -> int:
    return run_nodes([ExecutorNode], ["executor.yaml"], args)


if __name__ == "__main__":
    raise SystemExit(main())
