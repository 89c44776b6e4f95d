"""The ``wrench_estimator`` node: the EKF estimate of the contact wrench in the tool frame.

In the composed ``robot`` process the EKF is the loop's estimator and this node only publishes
its output. Run on its own (``ros2 run robot_bridge_node wrench_estimator``), ``SeparateEstimator``
runs the EKF on every ``joint_states`` message (position, velocity and the applied torque in
``effort``), one simulator step per message.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from qg_common import topics
from qg_common.conversions import joint_state_from_msg, time_ns, wrench_stamped
from qg_common.node_parameters import declare_parameters, package_defaults
from qg_common.node_runtime import run_nodes
from rclpy.node import Node
from sensor_msgs.msg import JointState as JointStateMsg
from std_msgs.msg import Header

from robot_bridge_node.core.hardware_interface import ROBOT_SECTION, RobotPlugin, robot_plugin
from robot_bridge_node.core.panda_model import PandaModel
from robot_bridge_node.core.robot_loop import tool_model
from robot_bridge_node.core.parameter_sections import EKF_SECTION
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig

__all__ = ["WrenchEstimatorNode", "EKF_SECTION", "SeparateEstimator", "build_ekf", "main"]



def build_ekf(params: dict[str, Any], model: PandaModel) -> WrenchEKF:
    """The EKF from the node parameters (``ekf`` section of ``config/wrench_estimator.yaml``)."""
    return WrenchEKF(WrenchEKFConfig.from_dict(params.get("ekf", {})), model)


class WrenchEstimatorNode(Node):
    """Publishes the contact wrench estimate (``wrench_estimate``, tool frame).

    A torque robot's estimate is the EKF's (parameters ``ekf.*``); a position robot's is its
    wrist sensor's, which has no parameters here. The robot is the plugin named by the
    ``robot`` parameter unless ``plugin`` is given.
    """

    def __init__(self, plugin: RobotPlugin | None = None) -> None:
        super().__init__("wrench_estimator")
        if plugin is None:
            plugin = robot_plugin(declare_parameters(self, [ROBOT_SECTION])["robot"])
        self.plugin = plugin
        sections = [EKF_SECTION] if plugin.interface == "torque" else []
        self.params = declare_parameters(self, sections,
                                         (("robot_bridge_node", "wrench_estimator.yaml"),))
        self.wrench = self.create_publisher(WrenchStamped, topics.WRENCH_ESTIMATE,
                                            topics.SENSOR_QOS)

    def publish(self, stamp: Time, wrench: np.ndarray) -> None:
        self.wrench.publish(wrench_stamped(wrench, stamp))


class SeparateEstimator:
    """The EKF fed by ``/joint_states`` of the separate sim process.

    Each message is one simulator step (``dt`` = the scene's time step): wall-clock stamp
    differences would only add jitter the physics does not have. The filter restarts at the
    first state and at the first state after each ``/sim/restarted``.
    """

    def __init__(self, node: WrenchEstimatorNode) -> None:
        self.node = node
        if node.plugin.interface != "torque":
            raise ValueError("the separate estimator runs the EKF of torque robots only")
        # The robot's own parameters belong to the separate sim process: its defaults.
        robot = node.plugin.describe(package_defaults("sim", node.plugin.config_files))
        self.dt = robot.dt
        self.n_joints = len(robot.joint_names)
        self.ekf = build_ekf(node.params, tool_model(robot.tool))
        self._restart_time: float | None = 0.0     # restart at the first state from then on
        node.create_subscription(JointStateMsg, topics.JOINT_STATES, self._on_state,
                                 topics.SENSOR_QOS)
        node.create_subscription(Header, topics.SIM_RESTARTED, self._on_restarted,
                                 topics.RESTARTED_QOS)

    def _on_restarted(self, msg: Header) -> None:
        self._restart_time = time_ns(msg.stamp) * 1e-9

    def _on_state(self, msg: JointStateMsg) -> None:
        try:
            state = joint_state_from_msg(msg, self.n_joints)
            restart = self._restart_time
            if restart is not None and time_ns(msg.header.stamp) * 1e-9 >= restart:
                self.ekf.reset(state.q)
                self._restart_time = None
            wrench = self.ekf.update(state.q, state.dq, state.tau, self.dt)
        except ValueError as exc:
            self.node.get_logger().error(f"bad joint_states: {exc}", throttle_duration_sec=1.0)
            return
        self.node.publish(msg.header.stamp, wrench)


def _start_separate_estimator(nodes: list[Node]) -> Callable[[], None]:
    node = nodes[0]
    assert isinstance(node, WrenchEstimatorNode)
    SeparateEstimator(node)
    return lambda: None


def main(args: list[str] | None = None) -> int:
    # Its one callback runs the EKF on a state and publishes: nothing waits.
    return run_nodes([WrenchEstimatorNode], args, background=_start_separate_estimator,
                     blocking_callbacks=False)


if __name__ == "__main__":
    raise SystemExit(main())
