"""Every robot's bag carries the arm in ROS's standard types: ``/robot_description``,
``/tf_static`` and ``/tf``, with the tool where forward kinematics of the recorded joints puts
it, and the task's parts as markers.

The three robots run at once, each in a namespace of its own; each records one short episode
driven by hand (a status, a reset, two steps, the final status). The bags are read back with
the ``mcap`` library's ROS 2 decoder, the reader Foxglove's authors ship.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from conftest import SHORT_STEP
from robot_client import RobotClient

pytestmark = pytest.mark.ros

ROBOTS = ("sim_panda", "sim_xarm7", "sim_nextage")
#: ``ros2 topic info -v /tf`` on ROS 2 Jazzy (the standard definition's RIHS01 hash).
TF_MESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def _status(episode: str, state: str):
    from qg_common.conversions import time_msg
    from qg_interfaces.msg import EpisodeStatus
    return EpisodeStatus(stamp=time_msg(time.time_ns()), episode_id=episode, state=state,
                         mode="test", reward_type="sparse", initial_pose=1, step=0, max_steps=2)


def _decoded(bag: Path) -> dict[str, list[tuple[int, object]]]:
    """Every message of ``bag``'s MCAP file by topic: (log time, decoded message)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    (file,) = bag.glob("*.mcap")
    messages: dict[str, list[tuple[int, object]]] = {}
    with open(file, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages():
            messages.setdefault(channel.topic, []).append((message.log_time, decoded))
    return messages


def _stamp(header) -> int:
    return header.stamp.sec * 10**9 + header.stamp.nanosec


def test_every_robots_bag_has_its_description_and_frames_and_the_tool_is_where_fk_puts_it(
        stack) -> None:
    import pinocchio as pin
    from qg_common.frame_tree import FrameTree
    from qg_common.node_parameters import package_defaults
    from qg_common.task_scene import part_from_marker
    from qg_common.topics import LATCHED
    from qg_interfaces.msg import EpisodeStatus
    from qg_recording.bag_reader import bag_info
    from robot_bridge_node.core.arm_model import ArmModel
    from robot_bridge_node.core.frame_kinematics import urdf_root_link
    from robot_bridge_node.core.hardware_interface import robot_plugin

    stack.start(*(("robot_" + r, "robot_bridge_node", "robot",
                   ("--ros-args", "-r", f"__ns:=/{r}", "-p", f"robot:={r}", *SHORT_STEP))
                  for r in ROBOTS))
    episodes = Path(stack.env["QG_RUNS_DIR"]) / "episodes"
    with stack.client() as cli:
        statuses = {r: cli.node.create_publisher(EpisodeStatus, f"/{r}/episode_status", LATCHED)
                    for r in ROBOTS}
        clients = {r: RobotClient(cli, f"/{r}") for r in ROBOTS}
        for robot, client in clients.items():
            assert client.reset(1).success, stack.logs()          # the robot is up
            statuses[robot].publish(_status(f"{robot}_ep", "resetting"))
            assert cli.spin_until((episodes / f"{robot}_ep").exists, 30.0), stack.logs()
            assert client.reset(1).success
            step = (0.0, 0.0, -8.0, 0.3, -0.2, 0.0) if robot != "sim_nextage" else \
                (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            for seq in (1, 2):
                assert client.step(seq, step) is not None, stack.logs()
            statuses[robot].publish(_status(f"{robot}_ep", "done"))
        for robot in ROBOTS:
            bag = episodes / f"{robot}_ep"
            assert cli.spin_until(lambda: bag_info(bag).complete, 30.0), stack.logs()

    for robot in ROBOTS:
        bag = episodes / f"{robot}_ep"
        info = {t.name: t for t in bag_info(bag).topics}
        assert info["/tf"].type_hash == info["/tf_static"].type_hash == TF_MESSAGE_HASH
        messages = _decoded(bag)
        (_, description), = messages["/robot_description"]
        model = pin.buildModelFromXML(description.data)      # urdfdom, through Pinocchio
        plugin = robot_plugin(robot)
        params = package_defaults("sim", plugin.config_files)
        arm = ArmModel.from_description(plugin.describe(params))
        assert set(arm.joint_names) <= set(model.names), robot

        tree = FrameTree()
        (_, static), = messages["/tf_static"]
        for t in static.transforms:
            r, v = t.transform.rotation, t.transform.translation
            tree.set(t.header.frame_id, t.child_frame_id, (v.x, v.y, v.z), (r.x, r.y, r.z, r.w))
        states = {_stamp(m.header): np.array(m.position) for _, m in messages["/joint_states"]}
        tf = messages["/tf"]
        stamps = [_stamp(m.transforms[0].header) for _, m in tf]
        # 100 Hz of the loop's clock, every transform of a message stamped alike
        span = (max(states) - min(states)) * 1e-9
        assert len(tf) >= 3 and abs(len(tf) - 100 * span) <= 3, (robot, len(tf), span)
        assert np.median(np.diff(stamps)) == 10**7 and np.all(np.diff(stamps) > 0), robot
        worst = (0.0, 0.0)
        for _, message in tf:
            for t in message.transforms:
                r, v = t.transform.rotation, t.transform.translation
                tree.set(t.header.frame_id, t.child_frame_id, (v.x, v.y, v.z),
                         (r.x, r.y, r.z, r.w))
            fk = arm.kinematics(states[_stamp(message.transforms[0].header)])
            tool = tree.pose("tool")
            worst = (max(worst[0], np.linalg.norm(tool[:3, 3] - fk.position)),
                     max(worst[1], np.linalg.norm(pin.log3(tool[:3, :3].T @ fk.rotation))))
        assert worst[0] < 1e-4 and worst[1] < np.radians(0.1), (robot, worst)
        assert tree.root_of("tool") == urdf_root_link(description.data), robot
        parts = [part_from_marker(m) for _, array in messages["/scene_markers"]
                 for m in array.markers]
        task = {"sim_nextage": {"peg", "block_base", "block_wall", "table"}}.get(
            robot, {"shaft", "bore", "counterbore", "bearing"})
        assert {p.name for p in parts} == task, robot
        assert all(tree.root_of(p.frame) == tree.root_of("tool") for p in parts), robot
