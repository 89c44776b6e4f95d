"""What a viewer draws of the task beside the arm: its frames and its parts, without ROS.

A URDF describes the robot; the task's fixture (the housing with its bore, the Nextage's holed
block) and the part the robot holds (the shaft, the peg) are not in it. A robot package
describes them as a ``TaskScene`` from its task's geometry: fixed frames (``TaskFrame``, to
the robot's base or to its tool) and shapes in those frames (``TaskPart``, which are
``visualization_msgs/Marker``'s cubes, cylinders and triangle lists, field for field). The
robot process publishes the frames on ``/tf_static`` and the parts on ``/scene_markers``,
every episode bag records both, and the episode renderer draws the same parts (``qgl
render``, the Gymnasium environments' ``rgb_array``), so a viewer shows what the simulation
simulates.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from qg_common.types import TOOL_FRAME

__all__ = ["BASE", "TOOL", "CUBE", "CYLINDER", "TRIANGLE_LIST", "TaskFrame", "TaskPart",
           "TaskScene", "tube", "part_from_marker"]

#: A frame's parent named ``BASE`` is the robot's base frame, whatever its URDF calls it (the
#: URDF's root link, which the robot's description gives).
BASE = ""
#: The tool frame (the controller's: the flange with the tool's offset), a frame of every robot.
TOOL = TOOL_FRAME
#: ``visualization_msgs/Marker`` types a part can have.
CUBE, CYLINDER, TRIANGLE_LIST = 1, 3, 11

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]
_IDENTITY: Quaternion = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class TaskFrame:
    """A fixed frame of the task: ``child``'s pose in ``parent`` (``BASE``, ``TOOL`` or another
    task frame).

    :param translation: [m]; :param rotation: unit quaternion ``(x, y, z, w)``.
    """
    parent: str
    child: str
    translation: Vector3
    rotation: Quaternion = _IDENTITY


@dataclass(frozen=True)
class TaskPart:
    """A shape of the task, a ``visualization_msgs/Marker`` in all but name.

    :param name: what it is (the marker's ``ns``).
    :param frame: the frame it is fixed in (it moves with that frame).
    :param kind: ``CUBE`` (``scale``: the sides), ``CYLINDER`` (``scale``: the diameters in x
        and y and the height in z, centred on ``position``, axis z) or ``TRIANGLE_LIST``
        (``points``: every three a triangle, in the part's own frame; ``scale`` 1).
    :param position: [m] and :param rotation: ``(x, y, z, w)`` of the shape in ``frame``.
    :param colour: ``(r, g, b, a)`` in [0, 1].
    """
    name: str
    frame: str
    kind: int
    scale: Vector3
    colour: tuple[float, float, float, float]
    position: Vector3 = (0.0, 0.0, 0.0)
    rotation: Quaternion = _IDENTITY
    points: tuple[Vector3, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in (CUBE, CYLINDER, TRIANGLE_LIST):
            raise ValueError(f"{self.name}: kind must be CUBE, CYLINDER or TRIANGLE_LIST, "
                             f"got {self.kind}")
        if self.kind == TRIANGLE_LIST and (not self.points or len(self.points) % 3):
            raise ValueError(f"{self.name}: a triangle list needs a multiple of 3 points, got "
                             f"{len(self.points)}")


@dataclass(frozen=True)
class TaskScene:
    """The task's frames and parts (see the module docstring)."""
    frames: tuple[TaskFrame, ...] = ()
    parts: tuple[TaskPart, ...] = ()


def tube(name: str, frame: str, inner: float, outer: float, z_low: float, z_high: float,
         colour: tuple[float, float, float, float], segments: int = 48) -> TaskPart:
    """A thick-walled tube about the frame's z axis as a triangle list: a bore's wall.

    :param inner, outer: [m] radii; :param z_low, z_high: [m] its ends along z.
    """
    if not 0.0 <= inner < outer or not z_low < z_high or segments < 3:
        raise ValueError(f"{name}: need 0 <= inner < outer, z_low < z_high and >= 3 segments, "
                         f"got {inner}, {outer}, {z_low}, {z_high}, {segments}")
    angles = np.linspace(0.0, 2.0 * math.pi, segments + 1)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)

    def at(radius: float, z: float, k: int) -> Vector3:
        return (float(radius * ring[k, 0]), float(radius * ring[k, 1]), float(z))

    points: list[Vector3] = []

    def quad(a: Vector3, b: Vector3, c: Vector3, d: Vector3) -> None:
        points.extend((a, b, c, a, c, d))       # counter-clockwise seen from outside

    for k in range(segments):
        quad(at(outer, z_low, k), at(outer, z_low, k + 1), at(outer, z_high, k + 1),
             at(outer, z_high, k))                                    # outer wall
        quad(at(inner, z_low, k + 1), at(inner, z_low, k), at(inner, z_high, k),
             at(inner, z_high, k + 1))                                # inner wall
        quad(at(inner, z_high, k), at(outer, z_high, k), at(outer, z_high, k + 1),
             at(inner, z_high, k + 1))                                # top
        quad(at(inner, z_low, k + 1), at(outer, z_low, k + 1), at(outer, z_low, k),
             at(inner, z_low, k))                                     # bottom
    return TaskPart(name, frame, TRIANGLE_LIST, (1.0, 1.0, 1.0), colour, points=tuple(points))


def part_from_marker(marker: Any) -> TaskPart:
    """The part a ``visualization_msgs/Marker`` shows (an rclpy message, or one decoded from a
    bag: anything with its fields), as ``conversions.marker_array_msg`` made it.

    :raises ValueError: for a marker type a part cannot have.
    """
    p, r, s, c = (marker.pose.position, marker.pose.orientation, marker.scale, marker.color)
    return TaskPart(marker.ns, marker.header.frame_id, int(marker.type), (s.x, s.y, s.z),
                    (c.r, c.g, c.b, c.a), (p.x, p.y, p.z), (r.x, r.y, r.z, r.w),
                    tuple((q.x, q.y, q.z) for q in marker.points))
