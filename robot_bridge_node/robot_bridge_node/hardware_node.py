"""The ``hardware`` node: a real robot's state as ROS sees it, where a simulated one has ``sim``.

In the composed ``robot`` process the node that publishes ``joint_states`` and declares the
robot's own parameters is the ``sim`` node when the robot plugin is a simulation, and this one
when it is not (``RobotPlugin.simulated``): a real arm has no ground truth to publish, no
simulated ``clock``, and its loop always runs at the robot's pace. Its settings are the
``hardware.*`` parameters (``HardwareConfig``, the defaults the robot's own config file gives,
e.g. ``config/franka.yaml``), which answer the robot process's questions as ``SimConfig`` does
for a simulation (clock mode, rates, realtime priority).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from geometry_msgs.msg import WrenchStamped
from qg_common import topics
from qg_common.node_parameters import declare_parameters
from qg_common.params import ParameterSection, config_from_dict
from rclpy.node import Node
from sensor_msgs.msg import JointState as JointStateMsg

from robot_bridge_node.core.hardware_interface import RobotPlugin

__all__ = ["HardwareConfig", "HARDWARE_SECTION", "HardwareNode"]


@dataclass(frozen=True)
class HardwareConfig:
    """How the robot process runs a real robot's loop (the ``hardware`` section).

    :param publish_rate: [Hz] rate of the 1 kHz topics (``joint_states`` & co).
    :param realtime_priority: ``SCHED_FIFO`` priority (1..99) of the 1 kHz loop, as
        ros2_control's controller manager asks for 50; 0 keeps the normal scheduler. A real arm
        needs it (a loop late by the robot's signal timeout stops the arm).
    """
    publish_rate: float = 1000.0
    realtime_priority: int = 50

    def __post_init__(self) -> None:
        if not (math.isfinite(self.publish_rate) and 0.0 < self.publish_rate <= 1000.0):
            raise ValueError(f"publish_rate must be in (0, 1000] Hz, got {self.publish_rate}")
        if not 0 <= self.realtime_priority <= 99:
            raise ValueError(f"realtime_priority must be in 0..99 (0: normal scheduling), "
                             f"got {self.realtime_priority}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> HardwareConfig:
        """From the ``hardware`` section of a robot's config file."""
        return config_from_dict(cls, params)

    #: A real robot runs on its own clock: the loop is always realtime.
    realtime = True
    clock_mode = "realtime"

    def publish_every(self, dt: float) -> int:
        """Publish the 1 kHz topics every this many ticks of ``dt`` seconds."""
        return max(1, round(1.0 / (self.publish_rate * dt)))

    def ground_truth_every(self, dt: float) -> int:
        """A real robot has no ground truth: 0, never."""
        del dt
        return 0


#: The ``hardware.*`` parameters (defaults in the robot's own config file).
HARDWARE_SECTION = ParameterSection("hardware", HardwareConfig, ranges={
    "publish_rate": (0.0, 1000.0), "realtime_priority": (0, 99)})


class HardwareNode(Node):
    """Publishes a real robot's joint state and its own wrench estimate where it has one (node
    ``hardware``), and declares its parameters (``hardware.*`` and the plugin's own)."""

    def __init__(self, plugin: RobotPlugin) -> None:
        super().__init__("hardware")
        self.plugin = plugin
        self.params = declare_parameters(self, [HARDWARE_SECTION, *plugin.parameters],
                                         plugin.config_files)
        self.config = HardwareConfig.from_dict(self.params["hardware"])
        self.joint_names = plugin.describe(self.params).joint_names
        self.joint_states = self.create_publisher(JointStateMsg, topics.JOINT_STATES,
                                                  topics.SENSOR_QOS)
        #: The robot's own wrench estimate, beside the loop's (``RobotPlugin.own_wrench_topic``).
        self.own_wrench = self.create_publisher(WrenchStamped, plugin.own_wrench_topic,
                                                topics.SENSOR_QOS) \
            if plugin.own_wrench_topic else None
