"""The ``bridge`` node: the robot-agnostic command interface in front of the (simulated) robot."""
from __future__ import annotations

from geometry_msgs.msg import PoseStamped, TwistStamped
from qg_interfaces.msg import AtRest, WrenchSetpoint
from rclpy.node import Node
from sensor_msgs.msg import JointState

from sim_robot_node.node_runtime import node_params, run_nodes
from sim_robot_node.sim_node import SENSOR_QOS

COMMAND_QOS = 10


class BridgeNode(Node):
    """Takes wrench setpoints, drives the joints at 1 kHz, reports the EEF state and rest."""

    def __init__(self) -> None:
        super().__init__("bridge", automatically_declare_parameters_from_overrides=True)
        self.params = node_params(self)
        self.joint_commands = self.create_publisher(JointState, "/joint_commands", SENSOR_QOS)
        self.ee_pose = self.create_publisher(PoseStamped, "/ee_pose", SENSOR_QOS)
        self.ee_twist = self.create_publisher(TwistStamped, "/ee_twist", SENSOR_QOS)
        self.ee_at_rest = self.create_publisher(AtRest, "/ee_at_rest", COMMAND_QOS)
        self.create_subscription(JointState, "/joint_states", self._on_joint_state, SENSOR_QOS)
        self.create_subscription(WrenchSetpoint, "/wrench_setpoint", self._on_setpoint, COMMAND_QOS)

    def _on_joint_state(self, msg: JointState) -> None:
        pass

    def _on_setpoint(self, msg: WrenchSetpoint) -> None:
        event = AtRest(seq=msg.seq)
        event.header.stamp = self.get_clock().now().to_msg()
        self.ee_at_rest.publish(event)


def main(args: list[str] | None = None) -> int:
    return run_nodes([BridgeNode], ["bridge.yaml"], args)


if __name__ == "__main__":
    raise SystemExit(main())
