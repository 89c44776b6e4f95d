"""The ``sim`` node: the simulated robot as ROS sees it (joint states, ground truth, reset)."""
from __future__ import annotations

import rclpy.qos
from geometry_msgs.msg import WrenchStamped
from qg_interfaces.msg import GroundTruth
from qg_interfaces.srv import ResetSim
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from sim_robot_node.node_runtime import node_params, run_nodes

SENSOR_QOS = rclpy.qos.QoSProfile(depth=1, reliability=rclpy.qos.ReliabilityPolicy.BEST_EFFORT)


class SimNode(Node):
    """Publishes the simulated hardware's state; serves ``/sim/reset``."""

    def __init__(self) -> None:
        super().__init__("sim", automatically_declare_parameters_from_overrides=True)
        self.params = node_params(self)
        self.joint_states = self.create_publisher(JointState, "/joint_states", SENSOR_QOS)
        self.ground_truth = self.create_publisher(GroundTruth, "/sim/ground_truth", SENSOR_QOS)
        self.ground_truth_wrench = self.create_publisher(
            WrenchStamped, "/sim/ground_truth_wrench", SENSOR_QOS)
        self.clock = self.create_publisher(Clock, "/clock", SENSOR_QOS)
        self.create_subscription(JointState, "/joint_commands", self._on_command, SENSOR_QOS)
        self.create_service(ResetSim, "/sim/reset", self._on_reset)
        self.last_command: JointState | None = None

    def _on_command(self, msg: JointState) -> None:
        self.last_command = msg

    def _on_reset(self, request: ResetSim.Request, response: ResetSim.Response) -> ResetSim.Response:
        if not 0 <= request.initial_pose <= 7:
            response.success = False
            response.message = f"initial_pose must be 0..7, got {request.initial_pose}"
            return response
        response.success = True
        response.message = f"reset to pose {request.initial_pose}"
        return response


def main(args: list[str] | None = None) -> int:
    return run_nodes([SimNode], ["sim.yaml"], args)


if __name__ == "__main__":
    raise SystemExit(main())
