"""The ``wrench_estimator`` node: the EKF estimate of the contact wrench in the tool frame."""
from __future__ import annotations

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from sim_robot_node.node_runtime import node_params, run_nodes
from sim_robot_node.sim_node import SENSOR_QOS


class WrenchEstimatorNode(Node):
    """Estimates the external wrench from joint states and commanded torques."""

    def __init__(self) -> None:
        super().__init__("wrench_estimator", automatically_declare_parameters_from_overrides=True)
        self.params = node_params(self)
        self.wrench = self.create_publisher(WrenchStamped, "/wrench_estimate", SENSOR_QOS)
        self.create_subscription(JointState, "/joint_states", self._on_joint_state, SENSOR_QOS)

    def _on_joint_state(self, msg: JointState) -> None:
        pass


def main(args: list[str] | None = None) -> int:
    return run_nodes([WrenchEstimatorNode], ["wrench_estimator.yaml"], args)


if __name__ == "__main__":
    raise SystemExit(main())
