"""The robot's frames as tf2 carries them: the ``/tf`` and ``/tf_static`` messages.

The transforms are ``frame_kinematics``' (the URDF's joints, the tool, the task's frames); here
they become messages. The driven joints' transforms go on ``/tf``, every other on
``/tf_static``. The loop's records come to the robot process in blocks; ``tf_rows`` takes the
ticks of the tf rate among them (``TF_RATE``: Foxglove and RViz draw 100 Hz smoothly, 1 kHz would
be ten times the work for nothing) and gives them as rows of numbers, which the bag writer and
the publishers encode with ``cdr.tf_layout`` as they do the 1 kHz topics. Nothing of it runs in
the loop process.
"""
from __future__ import annotations

import numpy as np
from qg_common.task_scene import TaskScene
from qg_recording.cdr import FixedLayout, tf_layout

from robot_bridge_node.core.frame_kinematics import (
    TASK_SCENE_GROUP,
    FrameKinematics,
    Transform,
    base_frame,
    task_scene,
    urdf_root_link,
    urdf_with_absolute_meshes,
)
from robot_bridge_node.core.hardware_interface import RobotDescription
from robot_bridge_node.core.tick_messages import TopicRows

# The kinematics' names are here too: the robot process builds its frames and scene from this
# module alone.
__all__ = ["TF_RATE", "RobotFrames", "TASK_SCENE_GROUP", "Transform", "base_frame",
           "urdf_root_link", "urdf_with_absolute_meshes", "task_scene"]

#: [Hz] of ``/tf`` (of the loop's clock: simulated time in lockstep).
TF_RATE = 100.0


class RobotFrames(FrameKinematics):
    """A robot's tf2 frames as messages (see the module docstring).

    :param description: the robot's (its URDF, driven joints, tool frame and tool offset).
    :param rate: [Hz] of ``/tf`` on the loop's clock.
    :raises ValueError: if the URDF has no single root or lacks a joint or the tool frame.
    """

    def __init__(self, description: RobotDescription, rate: float = TF_RATE) -> None:
        super().__init__(description)
        self.every = max(1, round(1.0 / (rate * description.dt)))
        self.tf_layout: FixedLayout = tf_layout(self.moving_frames)

    def static_message(self, t_ns: int, scene: TaskScene = TaskScene()) -> bytes:
        """The serialized ``/tf_static`` message (CDR): ``static_transforms(scene)``."""
        transforms = self.static_transforms(scene)
        layout = tf_layout(tuple((t.parent, t.child) for t in transforms))
        return layout.encode(t_ns, [v for t in transforms for v in t.values])

    def tf_rows(self, records: np.ndarray) -> TopicRows | None:
        """The ``/tf`` messages of a block of the loop's records (``sample_ring.record_dtype``):
        one per tick of the tf rate; None if the block has none."""
        ticks = records["tick"] % self.every == 0
        if not ticks.any():
            return None
        chosen = records[ticks]
        return TopicRows("/tf", ticks, chosen["t_ns"], self.moving_rows(chosen["q"]),
                         fixed_layout=self.tf_layout)
