"""Episodes as pictures: the renderer draws the arm where it is, a moving arm
changes the picture, and ``qgl render`` turns an episode bag into a video, offscreen."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from qg_common.node_parameters import package_defaults
from robot_bridge_node.core.hardware_interface import robot_plugin
from robot_bridge_node.core.robot_frames import RobotFrames, task_scene
from sim_robot_node.core.scene_renderer import ARM_COLOUR, SceneRenderer

ROOT = Path(__file__).resolve().parents[2]
#: Two configurations of the Panda near the shaft task's start, 0.4 rad apart at two joints.
Q0 = np.array([0.0, 0.3, 0.0, -2.0, 0.0, 2.3, 0.8])
Q1 = Q0 + np.array([0.4, 0.0, 0.0, 0.4, 0.0, 0.0, 0.0])


def _panda():
    plugin = robot_plugin("sim_panda")
    params = package_defaults("sim", plugin.config_files)
    description = plugin.describe(params)
    return description, RobotFrames(description), task_scene("sim_panda", params)


def _arm_pixels(image: np.ndarray, box: tuple[int, int, int, int]) -> int:
    """Pixels of the arm's hue (orange: red well above blue, green between) inside ``box``."""
    c0, r0, c1, r1 = box
    rgb = image[r0:r1, c0:c1].astype(int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.count_nonzero((r - b > 60) & (g > b) & (r > g)))


@pytest.fixture(scope="module")
def panda_renderer():
    description, frames, scene = _panda()
    static = [(t.parent, t.child, t.translation, t.rotation)
              for t in frames.static_transforms(scene)]
    renderer = SceneRenderer(frames.urdf, static, scene.parts)
    yield renderer, description
    renderer.close()


def test_a_frame_shows_the_arm_inside_its_projected_box_and_a_moving_arm_changes_it(
        panda_renderer) -> None:
    renderer, description = panda_renderer
    assert ARM_COLOUR[0] > ARM_COLOUR[1] > ARM_COLOUR[2]        # what _arm_pixels looks for
    images = []
    for q in (Q0, Q1):
        renderer.pose(dict(zip(description.joint_names, q)))
        camera = renderer.wide()
        image = renderer.image(camera)
        columns, rows = renderer.project(renderer.arm_corners(), camera).T
        box = (int(max(columns.min(), 0)), int(max(rows.min(), 0)),
               int(min(columns.max() + 1, renderer.width)),
               int(min(rows.max() + 1, renderer.height)))
        inside = _arm_pixels(image, box)
        everywhere = _arm_pixels(image, (0, 0, renderer.width, renderer.height))
        area = (box[2] - box[0]) * (box[3] - box[1])
        assert inside > 0.1 * area, (inside, area)            # the arm fills its box
        assert inside > 0.9 * everywhere, (inside, everywhere)  # and is nowhere else
        images.append(image)
    changed = np.any(images[0] != images[1], axis=2).mean()
    assert changed > 0.02, changed


@pytest.mark.slow
def test_qgl_render_writes_a_video_of_an_episode_bag(tmp_path: Path) -> None:
    """A bag as the robot process records it (description, static frames, markers, joint
    states, setpoints; the arm swinging from Q0 to Q1 in 1 s) becomes a video whose frames
    differ as the arm moves."""
    import imageio_ffmpeg
    from qg_common.conversions import marker_array_msg, time_msg
    from qg_recording.cdr import CdrBuffer
    from qg_recording.episode_recorder import EpisodeRecorder
    from rclpy.serialization import serialize_message

    description, frames, scene = _panda()
    recorder = EpisodeRecorder(tmp_path)
    bag = recorder.start("render_test")
    recorder.record_raw("/robot_description", 0, CdrBuffer().string(frames.urdf).message())
    recorder.record_raw("/tf_static", 0, frames.static_message(0, scene))
    recorder.record_raw("/scene_markers", 0, serialize_message(
        marker_array_msg(scene, frames.base, time_msg(0))))
    t = np.arange(1001) * 1_000_000
    q = Q0 + np.outer(np.linspace(0.0, 1.0, len(t)), Q1 - Q0)
    recorder.record_rows("/joint_states", t, np.hstack([q, np.zeros_like(q), np.zeros_like(q)]),
                         names=description.joint_names)
    recorder.stop()
    out = tmp_path / "episode.mp4"
    done = subprocess.run([str(ROOT / ".venv" / "bin" / "qgl"), "render", str(bag), "--out",
                           str(out), "--fps", "10"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "11 frames" in done.stdout, done.stdout
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = reader.__next__()
    width, height = meta["size"]
    video = [np.frombuffer(f, np.uint8).reshape(height, width, 3) for f in reader]
    assert len(video) == 11
    moved = [np.abs(a.astype(int) - b).max(axis=2).mean() for a, b in zip(video, video[1:])]
    assert min(moved) > 0.5, moved                      # every frame shows the arm further on
    missing = subprocess.run([sys.executable, "-m", "qg_bringup.main", "render",
                              str(tmp_path / "nothing")], capture_output=True, text=True,
                             timeout=60)
    assert missing.returncode == 2 and "no such bag" in missing.stderr


def test_the_fr3s_description_names_its_meshes_where_any_reader_finds_them() -> None:
    """franky-sim's FR3 URDF gives its meshes relative to its file; the published description
    gives them as ``file://`` URIs of files that exist, so a bag of the real-arm plugin renders
    (pybullet refused the relative ones: the franky-sim demo's video failed)."""
    from xml.etree import ElementTree

    from franka_robot_node.core.fr3_description import FR3_READY
    from franka_robot_node.plugin import describe_franka
    description = describe_franka({})
    frames = RobotFrames(description)
    meshes = [m.get("filename") for m in ElementTree.fromstring(frames.urdf).iter("mesh")]
    assert len(meshes) > 10
    assert all(m.startswith("file://") and Path(m[len("file://"):]).is_file() for m in meshes)
    renderer = SceneRenderer(frames.urdf, [], [])
    try:
        renderer.pose(dict(zip(description.joint_names, FR3_READY)))
        image = renderer.image(renderer.wide())
        assert _arm_pixels(image, (0, 0, renderer.width, renderer.height)) > 2000
    finally:
        renderer.close()

