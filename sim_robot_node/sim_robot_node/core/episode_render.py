"""Episodes as videos: ``render_bag(bag, out)`` (``qgl render``) replays an episode bag's joint
states into the robot the bag describes (``/robot_description``, ``/tf_static``,
``/scene_markers``) and writes a video, each frame (``scene_renderer``) with the step, the
setpoint (the residual torques), the wrench estimate and the tilt of its moment. The bag alone
suffices: nothing of the simulation that recorded it is used, so any robot's bag renders, and
the simulation may change.

Other packages reach this module through the entry-point group ``qg_learning_node.renderers``
(name ``pybullet``: a module with ``SceneRenderer`` and ``render_bag``): nothing imports
``sim_robot_node``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image
from qg_common.task_scene import part_from_marker

from sim_robot_node.core.scene_renderer import SceneRenderer, StaticTransform

__all__ = ["SceneRenderer", "VideoWriter", "render_bag"]


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
        recorded by an older stack, or not an episode's).
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
                         f"recorded the robot, or it is not an episode's bag")
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
