"""The ``sim`` node: the robot's state and its simulation as ROS sees them.

In the composed ``robot`` process the loop thread hands ``SimulationNode`` what it produced each
published tick: ``joint_states`` (what any robot driver publishes), the simulation's ground truth
and, in lockstep, ``clock``. ``SimConfig`` holds the clock mode the composed process and the
separate sim read.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from qg_common import topics
from qg_common.conversions import ground_truth_msg, joint_state_msg, wrench_stamped
from qg_common.node_parameters import declare_parameters
from qg_common.params import POSITIVE, ParameterSection, config_from_dict
from qg_common.types import GroundTruth, JointState
from qg_interfaces.msg import GroundTruth as GroundTruthMsg
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState as JointStateMsg

from robot_bridge_node.core.hardware_interface import ROBOT_SECTION, RobotPlugin, robot_plugin

__all__ = ["SimConfig", "SIM_SECTION", "SimulationNode"]


@dataclass(frozen=True)
class SimConfig:
    """The ``sim`` section of ``config/sim.yaml``: clock mode and the separate-process sim.

    :param clock_mode: ``lockstep`` (the loop runs as fast as it can while a setpoint executes,
        publishes ``/clock``) or ``realtime`` (wall-clock 1 kHz). Separate processes are always
        realtime.
    :param publish_rate: [Hz] rate of the 1 kHz topics; 0 picks 1000 in realtime and 100 (of
        simulated time) in lockstep, where publishing would otherwise dominate the tick.
    :param ground_truth_rate: [Hz] rate of ``/sim/ground_truth(_wrench)``, at most
        ``publish_rate``: computing the ground truth costs about a third of a tick.
    :param realtime_priority: realtime: ``SCHED_FIFO`` priority (1..99) of the 1 kHz loop (its
        process in the composed robot, its thread in the separate sim), as ros2_control's
        controller manager asks for 50; 0 keeps the normal scheduler. Where the system refuses
        it (no CAP_SYS_NICE), the loop warns and runs unprioritised. With the whole stack up and
        training, 60 s: 98.2 % of ticks on time without it, 99.7 % with it
        (``benchmarks/realtime_bench.py``).
    :param command_timeout: [s] separate sim: a ``/joint_commands`` older than this is stale.
    :param hold_damping: [Nms/rad] separate sim: joint damping added to the gravity hold.
    :param reset_wait: [s] separate sim: wall time the bridge gets to settle after a reset
        before ``/sim/reset`` answers.
    """
    clock_mode: str = "lockstep"
    publish_rate: float = 0.0
    ground_truth_rate: float = 100.0
    realtime_priority: int = 50
    command_timeout: float = 0.02
    hold_damping: float = 1.0
    reset_wait: float = 0.2

    def __post_init__(self) -> None:
        if self.clock_mode not in ("lockstep", "realtime"):
            raise ValueError(f"clock_mode must be 'lockstep' or 'realtime', got {self.clock_mode!r}")
        if not (math.isfinite(self.publish_rate) and 0.0 <= self.publish_rate <= 1000.0):
            raise ValueError(f"publish_rate must be in [0, 1000] Hz (0: mode default), "
                             f"got {self.publish_rate}")
        if not (math.isfinite(self.ground_truth_rate) and 0.0 < self.ground_truth_rate <= 1000.0):
            raise ValueError(f"ground_truth_rate must be in (0, 1000] Hz, "
                             f"got {self.ground_truth_rate}")
        if not 0 <= self.realtime_priority <= 99:
            raise ValueError(f"realtime_priority must be in 0..99 (0: normal scheduling), "
                             f"got {self.realtime_priority}")
        for name in ("command_timeout", "reset_wait"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0 s, got {getattr(self, name)}")
        if self.hold_damping < 0.0:
            raise ValueError(f"hold_damping must be >= 0, got {self.hold_damping}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> SimConfig:
        """From the ``sim`` section of ``config/sim.yaml``."""
        return config_from_dict(cls, params)

    @property
    def realtime(self) -> bool:
        return self.clock_mode == "realtime"

    def publish_every(self, dt: float) -> int:
        """Publish the 1 kHz topics every this many ticks of ``dt`` seconds."""
        rate = self.publish_rate or (1000.0 if self.realtime else 100.0)
        return max(1, round(1.0 / (rate * dt)))

    def ground_truth_every(self, dt: float) -> int:
        """Publish the ground truth every this many ticks (a multiple of ``publish_every``)."""
        every = self.publish_every(dt)
        return every * max(1, round(1.0 / (self.ground_truth_rate * dt * every)))


#: The ``sim.*`` parameters (``config/sim.yaml``, installed by this package).
SIM_SECTION = ParameterSection("sim", SimConfig, ranges={
    "publish_rate": (0.0, 1000.0), "ground_truth_rate": (0.0, 1000.0),
    "realtime_priority": (0, 99),
    "command_timeout": POSITIVE, "hold_damping": POSITIVE, "reset_wait": POSITIVE})


class SimulationNode(Node):
    """Publishes the robot's joint state and the simulation's truth and clock (node ``sim``).

    Its parameters are the process's clock settings (``sim.*``) and the robot's own (the
    plugin's sections, e.g. ``panda_scene.*``); the robot is the plugin named by its ``robot``
    parameter unless ``plugin`` is given.
    """

    def __init__(self, plugin: RobotPlugin | None = None) -> None:
        super().__init__("sim")
        if plugin is None:
            plugin = robot_plugin(declare_parameters(self, [ROBOT_SECTION])["robot"])
        self.plugin = plugin
        self.params = declare_parameters(self, [SIM_SECTION, *plugin.parameters],
                                         (("robot_bridge_node", "sim.yaml"), *plugin.config_files))
        self.config = SimConfig.from_dict(self.params["sim"])
        self.joint_names = plugin.describe(self.params).joint_names
        self.joint_states = self.create_publisher(JointStateMsg, topics.JOINT_STATES,
                                                  topics.SENSOR_QOS)
        self.ground_truth = self.create_publisher(GroundTruthMsg, topics.GROUND_TRUTH,
                                                  topics.SENSOR_QOS)
        self.ground_truth_wrench = self.create_publisher(
            WrenchStamped, topics.GROUND_TRUTH_WRENCH, topics.SENSOR_QOS)
        self.clock = self.create_publisher(Clock, topics.CLOCK, topics.SENSOR_QOS)

    def publish_state(self, stamp: Time, state: JointState,
                      truth: GroundTruth | None = None) -> None:
        """``joint_states``, and with ``truth`` ``sim/ground_truth(_wrench)``."""
        self.joint_states.publish(joint_state_msg(state, stamp, self.joint_names))
        if truth is not None:
            self.ground_truth.publish(ground_truth_msg(truth, stamp))
            self.ground_truth_wrench.publish(wrench_stamped(truth.wrench, stamp))

    def publish_clock(self, stamp: Time) -> None:
        self.clock.publish(Clock(clock=stamp))
