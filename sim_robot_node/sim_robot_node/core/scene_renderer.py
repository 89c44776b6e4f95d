"""The robot and the task's parts as a picture: the robot's URDF and the parts in a pybullet
world of their own, drawn by pybullet's CPU renderer (``ER_TINY_RENDERER``: no display, no GPU),
with text written on the frame.

``SceneRenderer`` draws the Gymnasium environments' ``rgb_array`` (and ``human``, in pybullet's
window where a display exists) from the robot in process, and every frame of ``episode_render``'s
videos from a bag. The robot is posed by pybullet's forward kinematics of the joint positions
(the URDF's other joints at zero, as the bridge's model locks them); every frame that is not a
link (the tool, the shaft, the housing) hangs from a link or the base by its static transform.
Each link is drawn with its collision geometry: the Panda's visual meshes (COLLADA) took 86 ms a
frame, its collision meshes 10 ms (320 x 240, the loaded 2-core machine). A wide view shows the
arm and the task, an inset the task up close, where the tilt that jams the shaft shows.
"""
from __future__ import annotations

import os
import site
import sys
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np
import pybullet as p
from PIL import Image, ImageDraw, ImageFont
from qg_common.frame_tree import FrameTree, homogeneous
from qg_common.rotations import quaternion_from_matrix
from qg_common.task_scene import CUBE, CYLINDER, TRIANGLE_LIST, TaskPart

__all__ = ["ARM_COLOUR", "Camera", "SceneRenderer", "StaticTransform", "renderable_urdf",
           "overlay"]

#: The arm's colour in every frame (a test finds the arm by it).
ARM_COLOUR = (0.93, 0.47, 0.10, 1.0)
#: (parent, child, translation, quaternion x y z w) of a frame that does not move.
StaticTransform = tuple[str, str, Sequence[float], Sequence[float]]


def _share_dirs() -> list[Path]:
    """Where ``package://<package>/...`` may be: the ament prefixes, this interpreter's prefix
    and the cmeel prefix of its site-packages (``example-robot-data``'s meshes)."""
    prefixes = [Path(x) for x in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if x]
    prefixes.append(Path(sys.prefix))
    prefixes += [Path(s) / "cmeel.prefix" for s in site.getsitepackages()]
    return [prefix / "share" for prefix in prefixes]


def _resolve(uri: str) -> str | None:
    """A mesh file's path from its URDF ``filename`` (``package://``, ``file://`` or a path)."""
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://"):].partition("/")
        for share in _share_dirs():
            if (share / package / rest).is_file():
                return str(share / package / rest)
        return None
    path = uri[len("file://"):] if uri.startswith("file://") else uri
    return path if Path(path).is_file() else None


def renderable_urdf(urdf: str) -> str:
    """``urdf`` as this renderer draws it: a link whose visuals are meshes drawn with its
    collision geometry instead (coarser, and much faster), mesh files found on this machine (a
    shape whose mesh it cannot find is left out: pybullet refuses the whole file otherwise), no
    materials (the arm gets one colour)."""
    root = ElementTree.fromstring(urdf)
    for material in root.findall("material"):
        root.remove(material)
    for link in root.findall("link"):
        visuals, collisions = link.findall("visual"), link.findall("collision")
        if collisions and any(v.find("geometry/mesh") is not None for v in visuals):
            for visual in visuals:
                link.remove(visual)
            for collision in collisions:
                visual = ElementTree.SubElement(link, "visual")
                visual.extend(list(collision))
        for shape in (*link.findall("visual"), *link.findall("collision")):
            for material in shape.findall("material"):
                shape.remove(material)
            mesh = shape.find("geometry/mesh")
            if mesh is not None:
                path = _resolve(mesh.get("filename", ""))
                if path is None:
                    link.remove(shape)
                else:
                    mesh.set("filename", path)
    return ElementTree.tostring(root, encoding="unicode")


@dataclass(frozen=True)
class Camera:
    """Where a view looks from: ``target`` [m, base frame], ``distance`` [m], ``yaw`` and
    ``pitch`` [deg] (pybullet's), ``fov`` [deg]."""
    target: tuple[float, float, float]
    distance: float
    yaw: float = 50.0
    pitch: float = -20.0
    fov: float = 50.0

    def matrices(self, aspect: float) -> tuple[list[float], list[float]]:
        view = p.computeViewMatrixFromYawPitchRoll(list(self.target), self.distance, self.yaw,
                                                   self.pitch, 0.0, 2)
        near = max(0.01, self.distance / 20)
        return view, p.computeProjectionMatrixFOV(self.fov, aspect, near, self.distance * 10)


class SceneRenderer:
    """A pybullet world of its own with the robot and the task's parts (see the module doc).

    :param urdf: the robot's URDF (text, ``package://`` meshes resolved on this machine).
    :param static: the frames that do not move (``/tf_static``: the tool, the task's frames).
    :param parts: the task's parts, each in one of those frames, a link or the base.
    :param width, height: [px] of a frame.
    :param gui: draw in pybullet's window (``human``; needs a display) instead of offscreen.
    """

    def __init__(self, urdf: str, static: Iterable[StaticTransform], parts: Sequence[TaskPart],
                 width: int = 448, height: int = 336, gui: bool = False) -> None:
        self.width, self.height = int(width), int(height)
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        if self.client < 0:
            raise RuntimeError("pybullet could not open its window (no display?)")
        c = self.client
        with tempfile.TemporaryDirectory(prefix="episode_render_") as folder:
            path = Path(folder) / "robot.urdf"
            path.write_text(renderable_urdf(urdf))
            try:
                self.robot = p.loadURDF(str(path), useFixedBase=True,
                                        flags=p.URDF_USE_IMPLICIT_CYLINDER, physicsClientId=c)
            except p.error as exc:
                p.disconnect(physicsClientId=c)
                raise RuntimeError(f"pybullet could not load the robot's URDF ({exc}); a mesh "
                                   f"given relative to a file it does not have?") from exc
        self.base = p.getBodyInfo(self.robot, physicsClientId=c)[0].decode()
        self.joints: dict[str, int] = {}
        self.links: dict[str, int] = {}
        for j in range(p.getNumJoints(self.robot, physicsClientId=c)):
            info = p.getJointInfo(self.robot, j, physicsClientId=c)
            if info[2] != p.JOINT_FIXED:
                self.joints[info[1].decode()] = j
            self.links[info[12].decode()] = j
        for j in (-1, *self.links.values()):
            p.changeVisualShape(self.robot, j, rgbaColor=list(ARM_COLOUR), physicsClientId=c)
        self.frames = FrameTree()
        self.set_static(static)
        self.parts = [(part, self._body(part)) for part in parts]
        self.task_point = self._task_point()

    def _body(self, part: TaskPart) -> int:
        c, colour = self.client, list(part.colour)
        if part.kind == CUBE:
            shape = p.createVisualShape(p.GEOM_BOX, halfExtents=[s / 2 for s in part.scale],
                                        rgbaColor=colour, physicsClientId=c)
        elif part.kind == CYLINDER:
            shape = p.createVisualShape(p.GEOM_CYLINDER, radius=part.scale[0] / 2,
                                        length=part.scale[2], rgbaColor=colour,
                                        physicsClientId=c)
        elif part.kind == TRIANGLE_LIST:
            vertices = [list(v) for v in part.points]
            shape = p.createVisualShape(p.GEOM_MESH, vertices=vertices,
                                        indices=list(range(len(vertices))), rgbaColor=colour,
                                        physicsClientId=c)
        else:
            raise ValueError(f"{part.name}: cannot draw a marker of type {part.kind}")
        return p.createMultiBody(0.0, -1, shape, physicsClientId=c)

    def set_static(self, static: Iterable[StaticTransform]) -> None:
        """The frames that do not move (again, after a reset turned the housing)."""
        for parent, child, translation, rotation in static:
            self.frames.set(parent, child, translation, rotation)

    def _task_point(self) -> np.ndarray:
        """Where the task is: the mean position of the parts fixed to the base's frames (the
        housing), else in front of the robot."""
        fixed = [self.frames.pose(part.frame)[:3, 3] for part, _ in self.parts
                 if part.frame not in self.links
                 and self.frames.root_of(part.frame) in ("", self.base)
                 and not self._moves(part.frame)]
        return np.mean(fixed, axis=0) if fixed else np.array([0.45, 0.0, 0.3])

    def _moves(self, frame: str) -> bool:
        """``frame`` hangs from a link that moves (the tool, the shaft)."""
        while frame in self.frames:
            frame = self.frames.parent_of(frame)
            if frame in self.links:
                return True
        return False

    # --- posing and drawing -----------------------------------------------------------------
    def pose(self, positions: Mapping[str, float]) -> None:
        """Joints by name at ``positions`` [rad or m] (unknown names are ignored), every link
        and part where they then are."""
        c = self.client
        for name, value in positions.items():
            joint = self.joints.get(name)
            if joint is not None:
                p.resetJointState(self.robot, joint, float(value), physicsClientId=c)
        states = p.getLinkStates(self.robot, list(self.links.values()), physicsClientId=c)
        for name, state in zip(self.links, states):
            self.frames.set(self.base, name, state[4], state[5])
        for part, body in self.parts:
            pose = self.frames.pose(part.frame) @ homogeneous(part.position, part.rotation)
            p.resetBasePositionAndOrientation(body, pose[:3, 3].tolist(),
                                              quaternion_from_matrix(pose[:3, :3]),
                                              physicsClientId=c)

    def wide(self) -> Camera:
        """The arm and the task: looking at the middle between the base and the task."""
        task = self.task_point
        reach = float(np.linalg.norm(task[:2]))
        return Camera((task[0] / 2, task[1] / 2, task[2] + 0.15), max(1.2, 3.4 * reach),
                      yaw=60.0, pitch=-12.0)

    def close_up(self) -> Camera:
        """The task up close (the shaft in the bore)."""
        t = self.task_point
        return Camera((t[0], t[1], t[2] + 0.015), 0.13, yaw=60.0, pitch=-8.0)

    def image(self, camera: Camera, width: int | None = None,
              height: int | None = None) -> np.ndarray:
        """(height, width, 3) uint8: the scene as posed, seen from ``camera``."""
        w, h = width or self.width, height or self.height
        view, projection = camera.matrices(w / h)
        rgba = p.getCameraImage(w, h, view, projection, renderer=p.ER_TINY_RENDERER,
                                flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self.client)[2]
        return np.reshape(np.asarray(rgba, np.uint8), (h, w, 4))[:, :, :3]

    def frame(self, positions: Mapping[str, float], lines: Sequence[str] = ()) -> np.ndarray:
        """The wide view with the close-up inset (bottom right) and ``lines`` written on it."""
        self.pose(positions)
        image = self.image(self.wide())
        h, w = self.height // 3, self.width // 3
        image[-h - 4:-4, -w - 4:-4] = self.image(self.close_up(), w, h)
        image[-h - 5:-3, -w - 5] = image[-h - 5, -w - 5:-3] = 80      # the inset's frame
        return overlay(image, lines)

    def project(self, points: np.ndarray, camera: Camera) -> np.ndarray:
        """(n, 2) pixel coordinates (column, row) of base-frame points in ``camera``'s image of
        this renderer's size."""
        view, projection = camera.matrices(self.width / self.height)
        v = np.reshape(view, (4, 4)).T
        pr = np.reshape(projection, (4, 4)).T
        homogeneous = np.c_[np.asarray(points, float), np.ones(len(points))]
        clip = (pr @ v @ homogeneous.T).T
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) / 2 * self.width, (1 - ndc[:, 1]) / 2 * self.height]

    def arm_corners(self) -> np.ndarray:
        """(8 n, 3) the corners of every link's bounding box (of what is drawn), as posed."""
        corners = []
        for link in (-1, *self.links.values()):
            low, high = p.getAABB(self.robot, link, physicsClientId=self.client)
            corners += [[(low, high)[i >> k & 1][k] for k in range(3)] for i in range(8)]
        return np.array(corners)

    def close(self) -> None:
        if self.client is not None and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = None


_FONT: Any = None


def overlay(image: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """``image`` with ``lines`` written at its top left, dark on a light band."""
    global _FONT
    if not lines:
        return image
    if _FONT is None:
        try:
            _FONT = ImageFont.load_default(size=13)
        except (TypeError, OSError):         # a Pillow without FreeType: the bitmap font
            _FONT = ImageFont.load_default()
    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture, "RGBA")
    height = 16 * len(lines) + 6
    draw.rectangle([0, 0, image.shape[1], height], fill=(255, 255, 255, 190))
    for k, line in enumerate(lines):
        draw.text((6, 3 + 16 * k), line, fill=(20, 20, 20, 255), font=_FONT)
    return np.asarray(picture)
