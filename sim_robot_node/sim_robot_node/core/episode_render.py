"""Episodes as pictures: the robot's URDF and the task's parts in a pybullet world of their own,
drawn by pybullet's CPU renderer (``ER_TINY_RENDERER``: no display, no GPU), with what happened
written on the frame.

- ``render_bag(bag, out)`` (``qgl render``): replays an episode bag's joint states into the
  robot the bag describes (``/robot_description``, ``/tf_static``, ``/scene_markers``) and
  writes a video, each frame with the step, the setpoint (the residual torques), the wrench
  estimate and the tilt of its moment. The bag alone suffices: nothing of the simulation that
  recorded it is used, so any robot's bag renders, and the simulation may change.
- ``SceneRenderer``: the Gymnasium environments' ``rgb_array`` (and ``human``, in pybullet's
  window where a display exists), drawn from the robot in process.

The robot is posed by pybullet's forward kinematics of the joint positions (the URDF's other
joints at zero, as the bridge's model locks them); every frame that is not a link (the tool,
the shaft, the housing) hangs from a link or the base by its static transform. Each link is
drawn with its collision geometry: the Panda's visual meshes (COLLADA) took 86 ms a frame,
its collision meshes 10 ms (320 x 240, the loaded 2-core machine). A wide view shows the arm
and the task, an inset the task up close, where the tilt that jams the shaft shows.

Other packages reach this module through the entry-point group ``qg_learning_node.renderers``
(name ``pybullet``): nothing imports ``sim_robot_node``.
"""
from __future__ import annotations

import math
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
from qg_common.task_scene import CUBE, CYLINDER, TRIANGLE_LIST, TaskPart, part_from_marker

__all__ = ["ARM_COLOUR", "Camera", "SceneRenderer", "StaticTransform", "VideoWriter",
           "render_bag", "renderable_urdf", "overlay"]

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


class VideoWriter:
    """Frames into ``path``: ``.mp4`` (H.264 through the ffmpeg of ``imageio-ffmpeg``) or
    ``.gif`` (Pillow)."""

    def __init__(self, path: Path, fps: float, size: tuple[int, int]) -> None:
        self.path, self.fps, self.size = Path(path), float(fps), size
        self.frames = 0
        self._gif: list[Image.Image] = []
        suffix = self.path.suffix.lower()
        if suffix not in (".mp4", ".gif"):
            raise ValueError(f"{self.path}: the video must be .mp4 or .gif")
        self._mp4 = None
        if suffix == ".mp4":
            import imageio_ffmpeg
            self._mp4 = imageio_ffmpeg.write_frames(
                str(self.path), size, fps=self.fps, codec="libx264", pix_fmt_out="yuv420p",
                macro_block_size=8, quality=7, ffmpeg_log_level="error")
            self._mp4.send(None)

    def add(self, frame: np.ndarray) -> None:
        if self._mp4 is not None:
            self._mp4.send(np.ascontiguousarray(frame))
        else:
            self._gif.append(Image.fromarray(frame).quantize(colors=128))
        self.frames += 1

    def close(self) -> None:
        if self._mp4 is not None:
            self._mp4.close()
        elif self._gif:
            self._gif[0].save(self.path, save_all=True, append_images=self._gif[1:],
                              duration=round(1000 / self.fps), loop=0)


# --- an episode bag ----------------------------------------------------------------------------
_TOPICS = ("/robot_description", "/tf_static", "/scene_markers", "/joint_states",
           "/wrench_setpoint", "/wrench_estimate", "/sim/ground_truth", "/episode_status")


def _stamp(msg: Any) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


class _Series:
    """Values by time: the latest at or before a moment."""

    def __init__(self) -> None:
        self.t: list[int] = []
        self.values: list[Any] = []

    def add(self, t_ns: int, value: Any) -> None:
        self.t.append(t_ns)
        self.values.append(value)

    def index_at(self, t_ns: int) -> int:
        """How many values came at or before ``t_ns``."""
        return int(np.searchsorted(self.t, t_ns, side="right"))

    def at(self, t_ns: int) -> Any:
        k = self.index_at(t_ns) - 1
        return self.values[k] if k >= 0 else None


class _FirstInEachFrame:
    """Of the high-rate topics, only the first message in each frame's time is decoded (one
    joint state in forty at 25 frames a second); everything else is."""

    HIGH_RATE = ("/joint_states", "/wrench_estimate", "/sim/ground_truth")

    def __init__(self, frame_ns: int) -> None:
        self.frame_ns = frame_ns
        self.start: int | None = None
        self.last: dict[str, int] = {}

    def __call__(self, topic: str, t_ns: int) -> bool:
        if topic not in self.HIGH_RATE:
            return True
        if self.start is None:
            self.start = t_ns
        frame = (t_ns - self.start) // self.frame_ns
        if self.last.get(topic) == frame:
            return False
        self.last[topic] = frame
        return True


def _static_transforms(msg: Any) -> list[StaticTransform]:
    out = []
    for t in msg.transforms:
        v, r = t.transform.translation, t.transform.rotation
        out.append((t.header.frame_id, t.child_frame_id, (v.x, v.y, v.z), (r.x, r.y, r.z, r.w)))
    return out


def _lines(t_ns: int, start: int, series: Mapping[str, _Series], header: str) -> list[str]:
    """What the frame at ``t_ns`` says: the episode, the time and step, the setpoint, the
    wrench estimate and the tilt of that moment."""
    lines = [header]
    setpoints = series["/wrench_setpoint"]
    setpoint = setpoints.at(t_ns)          # the bag's k-th setpoint is the episode's step k
    step = "start" if setpoint is None else f"step {setpoints.index_at(t_ns)}"
    lines.append(f"{step}   t {(t_ns - start) * 1e-9:6.2f} s")
    if setpoint is not None:
        f, m = setpoint.wrench.force, setpoint.wrench.torque
        lines.append(f"setpoint  Fz {f.z:+6.1f} N   residual Tx {m.x:+5.2f}  Ty {m.y:+5.2f} Nm")
    estimate = series["/wrench_estimate"].at(t_ns)
    if estimate is not None:
        f, m = estimate.wrench.force, estimate.wrench.torque
        lines.append(f"estimate  Fz {f.z:+6.1f} N   Fx {f.x:+5.1f}  Fy {f.y:+5.1f} N   "
                     f"Tx {m.x:+5.2f}  Ty {m.y:+5.2f} Nm")
    truth = series["/sim/ground_truth"].at(t_ns)
    if truth is not None:
        lines.append(f"tilt {math.degrees(truth.tilt):5.2f} deg   depth "
                     f"{truth.insertion_depth * 1e3:+6.2f} mm")
    return lines


def render_bag(bag: Path, out: Path, fps: float = 25.0, speed: float = 1.0,
               width: int = 448, height: int = 336) -> dict[str, Any]:
    """Replay the episode recorded in ``bag`` into a video at ``out`` (``.mp4`` or ``.gif``):
    one frame every ``speed / fps`` seconds of the bag's clock, from its first joint state to
    its last. Returns the frames written and the episode's span [s].

    :raises ValueError: if the bag has no ``/robot_description`` or no joint states (a bag
        recorded before issue 37, or not an episode's).
    """
    from qg_recording.bag_reader import read_bag
    if not fps > 0 or not speed > 0:
        raise ValueError(f"fps and speed must be > 0, got {fps}, {speed}")
    series = {topic: _Series() for topic in _TOPICS}
    states = _Series()
    frame_ns = int(1e9 * speed / fps)
    for topic, _, t_ns, msg in read_bag(Path(bag), _TOPICS, _FirstInEachFrame(frame_ns)):
        if topic == "/joint_states":
            states.add(_stamp(msg), dict(zip(msg.name, msg.position)))
        elif topic in ("/wrench_estimate", "/sim/ground_truth"):
            series[topic].add(_stamp(msg), msg)
        else:
            series[topic].add(t_ns, msg)
    if not series["/robot_description"].values:
        raise ValueError(f"{bag} has no /robot_description: it was recorded before the stack "
                         f"recorded the robot (issue 37), or it is not an episode's bag")
    if not states.values:
        raise ValueError(f"{bag} has no /joint_states")
    statics = series["/tf_static"]
    markers = series["/scene_markers"].values
    parts = [part_from_marker(m) for m in markers[-1].markers] if markers else []
    status = series["/episode_status"].values
    header = (f"{status[-1].episode_id}  ({status[-1].mode}, start {status[-1].initial_pose})"
              if status else Path(bag).name)
    renderer = SceneRenderer(series["/robot_description"].values[0].data,
                             _static_transforms(statics.values[0]) if statics.values else (),
                             parts, width, height)
    writer = VideoWriter(out, fps, (renderer.width, renderer.height))
    try:
        start, end = states.t[0], states.t[-1]
        static_seen = 1
        for t_ns in range(start, end + 1, frame_ns):
            while static_seen < len(statics.t) and statics.t[static_seen] <= t_ns:
                renderer.set_static(_static_transforms(statics.values[static_seen]))
                static_seen += 1
            writer.add(renderer.frame(states.at(t_ns), _lines(t_ns, start, series, header)))
    finally:
        writer.close()
        renderer.close()
    return {"frames": writer.frames, "seconds": (end - start) * 1e-9, "out": str(out)}
