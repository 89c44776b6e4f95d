"""The robot's frames from its URDF and its joints: every transform tf2 carries, as numbers.

As ``robot_state_publisher`` reads a URDF, every joint is a transform from its parent link to its
child link: the driven joints' transforms move with the joints, every other joint's (fixed, or
locked where the bridge's model locks it, a gripper's fingers) is static, as are the tool (the
flange and the tool's offset, the frame the wrench estimate is in) and the task's frames
(``qg_common.task_scene``: the shaft, the housing, the bore). The base frame is the URDF's root
link, whatever the robot calls it.

Forward kinematics is Pinocchio's on the model ``arm_model.driven_model`` builds from the URDF
(the bridge's own). What draws the robot (a Gymnasium environment's renderer) needs only this
module; the ``/tf`` and ``/tf_static`` messages are ``robot_frames``', so this one imports no
message definitions.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
from qg_common.plugins import load_registered, registered_names
from qg_common.task_scene import TOOL, TaskScene

from robot_bridge_node.core.arm_model import driven_model
from robot_bridge_node.core.hardware_interface import (
    RobotDescription,
)

__all__ = ["TASK_SCENE_GROUP", "Transform", "FrameKinematics", "base_frame", "urdf_root_link",
           "urdf_with_absolute_meshes", "task_scene"]

#: The entry-point group where robot packages register their task's scene by robot name: a
#: callable ``(robot parameters, housing yaw [rad]) -> TaskScene`` (``sim_robot_node``'s
#: ``core/task_visuals.py``). A robot without one gets no task frames or parts.
TASK_SCENE_GROUP = "robot_bridge_node.task_scenes"


def task_scene(robot: str, params: dict[str, Any]) -> TaskScene:
    """The scene registered for ``robot`` with its parameters (``robot``'s plugin's sections:
    its task's cell); empty if none is registered."""
    if robot not in registered_names(TASK_SCENE_GROUP):
        return TaskScene()
    scene = load_registered(TASK_SCENE_GROUP, robot, object, "task scene")(params)
    if not isinstance(scene, TaskScene):
        raise TypeError(f"the task scene of {robot!r} gave a {type(scene).__name__}, "
                        f"not a TaskScene")
    return scene


@dataclass(frozen=True)
class Transform:
    """``child``'s pose in ``parent``: translation [m] and unit quaternion ``(x, y, z, w)``."""
    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]

    @property
    def values(self) -> tuple[float, ...]:
        """The seven numbers of a ``geometry_msgs/Transform``."""
        return (*self.translation, *self.rotation)


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    parent: str
    child: str


def _urdf_joints(urdf: ElementTree.Element) -> list[_Joint]:
    return [_Joint(j.get("name", ""), j.get("type", ""), j.find("parent").get("link", ""),
                   j.find("child").get("link", "")) for j in urdf.findall("joint")]


def base_frame(description: RobotDescription) -> str:
    """The robot's base frame: the root link of its URDF (``panda_link0``, the FR3's ``base``,
    the Nextage's ``CHEST``), the frame its poses and twists are given in."""
    return urdf_root_link(Path(description.urdf).read_text())


def urdf_root_link(urdf_text: str) -> str:
    """The link no joint of the URDF moves: the robot's base frame.

    :raises ValueError: if the URDF has no single root link.
    """
    root = ElementTree.fromstring(urdf_text)
    children = {j.child for j in _urdf_joints(root)}
    roots = [link.get("name") for link in root.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ValueError(f"a URDF needs exactly one root link, found {roots}")
    return str(roots[0])


def urdf_with_absolute_meshes(path: Path) -> str:
    """The URDF at ``path`` with every mesh given relative to its file (franky-sim's FR3:
    ``meshes/link0.stl``) as a ``file://`` URI: a description published on
    ``/robot_description`` is read where the file is unknown (Foxglove, a bag, a renderer).
    ``package://`` and other URIs and absolute paths stay as they are."""
    text = Path(path).read_text()
    root = ElementTree.fromstring(text)
    relative = [m for m in root.iter("mesh")
                if "://" not in m.get("filename", "") and not m.get("filename", "/").startswith("/")]
    if not relative:
        return text
    folder = Path(path).resolve().parent
    for mesh in relative:
        mesh.set("filename", (folder / mesh.get("filename", "")).as_uri())
    return ElementTree.tostring(root, encoding="unicode")


def _transform(parent: str, child: str, pose: pin.SE3) -> Transform:
    x, y, z, w = pin.Quaternion(pose.rotation).coeffs().tolist()
    return Transform(parent, child, tuple(pose.translation.tolist()), (x, y, z, w))


class FrameKinematics:
    """A robot's frames from its description (see the module docstring).

    :param description: the robot's (its URDF, driven joints, tool frame and tool offset).
    :raises ValueError: if the URDF has no single root or lacks a joint or the tool frame.
    """

    def __init__(self, description: RobotDescription) -> None:
        if not description.urdf or not description.tool_frame:
            raise ValueError("the robot's description must name its urdf and tool_frame")
        self.urdf = urdf_with_absolute_meshes(Path(description.urdf))
        self.base = urdf_root_link(self.urdf)
        self.joint_names = tuple(description.joint_names)
        self.model = driven_model(description.urdf, self.joint_names)
        self.data = self.model.createData()
        joints = _urdf_joints(ElementTree.fromstring(self.urdf))
        moving = {name: k for k, name in enumerate(self.joint_names)}
        self._moving = sorted((j for j in joints if j.name in moving), key=lambda j: moving[j.name])
        self._links = [(self._body(j.parent), self._body(j.child)) for j in self._moving]
        pin.framesForwardKinematics(self.model, self.data, pin.neutral(self.model))
        self._fixed = [self._relative(j.parent, j.child) for j in joints if j.name not in moving]
        self._body(description.tool_frame)            # the tool's frame must be a link
        offset = np.asarray(description.tool.offset, float)
        self._tool = Transform(description.tool_frame, TOOL, tuple(offset.tolist()),
                               (0.0, 0.0, 0.0, 1.0))

    @property
    def moving_frames(self) -> tuple[tuple[str, str], ...]:
        """``(parent, child)`` of each driven joint, in the order of ``joint_names``: the
        transforms of ``moving_rows``."""
        return tuple((j.parent, j.child) for j in self._moving)

    def _body(self, link: str) -> int:
        if not self.model.existFrame(link):
            raise ValueError(f"the URDF has no link {link!r}")
        return self.model.getFrameId(link)

    def _relative(self, parent: str, child: str) -> Transform:
        """``child``'s pose in ``parent`` at the configuration of the last kinematics."""
        placements = self.data.oMf
        return _transform(parent, child,
                          placements[self._body(parent)].actInv(placements[self._body(child)]))

    def static_transforms(self, scene: TaskScene = TaskScene()) -> list[Transform]:
        """Every transform that does not move: the URDF's fixed and locked joints, the tool, and
        ``scene``'s frames (``BASE`` as their parent is the base link)."""
        task = [Transform(f.parent or self.base, f.child, tuple(map(float, f.translation)),
                          tuple(map(float, f.rotation))) for f in scene.frames]
        return [*self._fixed, self._tool, *task]

    def moving_rows(self, q: np.ndarray) -> np.ndarray:
        """(n, 7 k) the driven joints' transforms (translation, quaternion ``(x, y, z, w)``, in
        the order of :attr:`moving_frames`) at the n configurations ``q`` (n, nq)."""
        q = np.atleast_2d(np.asarray(q, float))
        rows = np.empty((len(q), 7 * len(self._moving)))
        model, data = self.model, self.data
        for i, configuration in enumerate(q):
            pin.framesForwardKinematics(model, data, configuration)
            placements = data.oMf
            for k, (parent, child) in enumerate(self._links):
                pose = placements[parent].actInv(placements[child])
                rows[i, 7 * k:7 * k + 3] = pose.translation
                rows[i, 7 * k + 3:7 * k + 7] = pin.Quaternion(pose.rotation).coeffs()
        return rows
