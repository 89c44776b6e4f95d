"""The robot as viewers draw it, from the robot process: what ``robot_state_publisher`` and a
task's marker publisher would publish, in every episode bag too.

- ``robot_description`` (``std_msgs/String``, latched): the robot's URDF;
- ``tf_static`` (latched): the URDF's fixed joints, the tool and the task's frames (the cell's:
  its housing's pose is a parameter of the task);
- ``scene_markers`` (``visualization_msgs/MarkerArray``, latched): the task's parts;
- ``tf`` at ``robot_frames.TF_RATE``: the driven joints from the measured joints (the robot
  process hands over the rows ``RobotFrames.tf_rows`` made of the loop's records; they are
  published with the tick they belong to).

The latched messages go to the recorder as well (``RecorderNode.latch``), so every bag starts
with them. Foxglove and RViz draw the arm, its tool and the task from these topics alone.
"""
from __future__ import annotations

from collections.abc import Callable

from qg_common import topics
from qg_common.conversions import marker_array_msg, time_msg
from qg_common.task_scene import TaskScene
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.serialization import serialize_message
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from robot_bridge_node.core.robot_frames import RobotFrames
from robot_bridge_node.recorder_node import RecorderNode

__all__ = ["RobotStatePublisher"]


class RobotStatePublisher:
    """The publishers of one robot's description, frames and task parts (on ``node``).

    :param scene: the task's scene (``robot_frames.task_scene``).
    :param clock_ns: the loop's clock, for the latched messages' stamps.
    :param recorder: where the latched messages are recorded, if the process records.
    """

    def __init__(self, node: Node, frames: RobotFrames, scene: TaskScene,
                 clock_ns: Callable[[], int], recorder: RecorderNode | None = None) -> None:
        self.frames = frames
        self._clock_ns = clock_ns
        self._recorder = recorder
        self.tf = node.create_publisher(TFMessage, topics.TF, topics.TF_QOS)
        self._static = node.create_publisher(TFMessage, topics.TF_STATIC, topics.LATCHED)
        description = node.create_publisher(String, topics.ROBOT_DESCRIPTION, topics.LATCHED)
        markers = node.create_publisher(MarkerArray, topics.SCENE_MARKERS, topics.LATCHED)
        self._latch("/robot_description", description,
                    serialize_message(String(data=frames.urdf)))
        self._latch("/scene_markers", markers, serialize_message(marker_array_msg(
            scene, frames.base, time_msg(clock_ns()))))
        self._latch("/tf_static", self._static, frames.static_message(clock_ns(), scene))

    def _latch(self, topic: str, publisher: Publisher, data: bytes) -> None:
        publisher.publish(data)
        if self._recorder is not None:
            self._recorder.latch(topic, data)
