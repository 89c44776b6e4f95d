"""The Nextage as a robot of the stack: its plugin, and a peg episode through real processes
(robot with ``robot:=sim_nextage``, learner, executor with the peg task), recorded to MCAP."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from param_client import listed
from test_episodes import Episodes, wait_for_bag

STEPS = 8


def test_the_peg_task_and_the_nextage_scene_read_one_cell():
    """The executor computes the tip from the tool pose with the cell the simulated Nextage is
    built from: one file, ``config/peg_task.yaml``, which both declare."""
    from qg_common.params import config_file, load_ros_params
    from qg_common.peg_task import PEG_TASK_FILE, PEG_TASK_SECTION, PegCell
    from qg_learning_node.executor.parameters import CELL_SECTIONS
    from qg_learning_node.executor.peg_task import PegTaskConfig
    from robot_bridge_node.core.hardware_interface import robot_plugin
    peg = PegTaskConfig.from_dict(load_ros_params(config_file("executor_nextage.yaml"))["peg"])
    assert peg == PegTaskConfig()
    assert PegCell.from_dict(load_ros_params(config_file("peg_task.yaml"))["peg_task"]) \
        == PegCell()
    plugin = robot_plugin("sim_nextage")
    assert PEG_TASK_FILE in plugin.config_files and PEG_TASK_SECTION in plugin.parameters
    assert CELL_SECTIONS["peg"] == (PEG_TASK_SECTION, PEG_TASK_FILE)
    assert "geometry" not in load_ros_params(config_file("nextage.yaml"))["scene"]


@pytest.mark.ros
def test_stack_nextage_names_the_installed_peg_files():
    from qg_bringup.stack_file import load_stack_config
    from qg_common.params import config_file
    specs = {s.name: s for s in load_stack_config(config_file("stack_nextage.yaml"))}
    assert specs["robot"].args == ("--ros-args", "-p", "robot:=sim_nextage")
    for name, file in (("executor", "executor_nextage.yaml"), ("learner", "learner_nextage.yaml")):
        path = Path(specs[name].args[-1])
        assert path.is_file() and path.name == file
        assert path.parent.parts[-3:] == ("share", "qg_learning_node", "config")


def test_sim_nextage_is_a_position_robot_with_a_wrist_sensor():
    from qg_common.node_parameters import package_defaults
    from qg_common.peg_task import PegCell
    from qg_common.types import PoseReference, WrenchSetpoint
    from robot_bridge_node.core.hardware_interface import robot_plugin
    from robot_bridge_node.core.position_loop import PositionLoop, build_position_loop
    plugin = robot_plugin("sim_nextage")
    assert plugin.interface == "position"
    robot = plugin.create(package_defaults("sim", plugin.config_files))
    assert robot.hardware.joint_names == robot.description.joint_names
    loop = build_position_loop(robot, package_defaults(
        "bridge", (("robot_bridge_node", "bridge.yaml"), *plugin.config_files)))
    assert isinstance(loop, PositionLoop)
    cell = PegCell.from_dict(package_defaults("sim", plugin.config_files)["peg_task"])
    loop.reset(cell.start_pose(3))
    start = loop.controller.tool.position.copy()
    np.testing.assert_allclose(start, cell.start_pose(3).position, atol=1e-4)
    assert np.linalg.norm(loop.wrench_estimate) < 0.05        # tared in free air
    # A 1 cm move up: the pose reference goes through IK to the joint targets.
    result = loop.execute(WrenchSetpoint(np.zeros(6), PoseReference(
        start + [0.0, 0.0, 0.01], loop.controller.tool.rotation)))
    assert not result.timed_out and 0.02 <= result.duration < 0.25
    np.testing.assert_allclose(loop.controller.tool.position, start + [0.0, 0.0, 0.01],
                               atol=1e-3)
    # The same start pose is the same place every time; another pose is another place.
    loop.reset(cell.start_pose(3))
    np.testing.assert_allclose(loop.controller.tool.position, start, atol=1e-4)
    loop.reset(cell.start_pose(4))
    assert np.linalg.norm(loop.controller.tool.position - start) > 0.01
    robot.simulation.scene.close()


@pytest.mark.ros
def test_a_nextage_peg_episode_runs_through_the_ros_stack_and_is_recorded(stack):
    from qg_common.params import package_config
    from qg_common.peg_task import PegCell
    from qg_learning_node.executor.peg_task import PegTaskConfig
    from qg_recording.bag_reader import read_bag
    executor_file = package_config("qg_learning_node", "executor_nextage.yaml")
    learner_file = package_config("qg_learning_node", "learner_nextage.yaml")
    stack.start(("robot", "robot_bridge_node", "robot", ("--ros-args", "-p", "robot:=sim_nextage")),
                ("learner", "qg_learning_node", "learner",
                 ("--ros-args", "--params-file", str(learner_file),
                  "-p", "learner.cycle_steps:=4")),
                ("executor", "qg_learning_node", "executor",
                 ("--ros-args", "--params-file", str(executor_file),
                  "-p", f"peg.train_max_steps:={STEPS}")))
    with stack.client() as cli:
        episodes = Episodes(cli)
        episodes.wait_for_learner()
        # The position robot's nodes declare the Nextage's parameters, not the Panda's.
        bridge, sim = listed(cli, "/bridge"), listed(cli, "/sim")
        assert "position_control.damping" in bridge and "rest.max_time" in bridge
        assert not any(n.startswith(("impedance.", "safety.")) for n in bridge)
        assert "robot" in bridge and "robot" not in sim
        assert "peg_task.geometry.peg_radius" in sim and "panda_scene.shaft_mass" not in sim
        response = episodes.start(mode="train", initial_pose=1, seed=3)
        assert response.success, response.message + stack.logs()
        final = episodes.final(response.episode_id, timeout=120.0)
        assert final.state == "done", final.message + stack.logs()
        assert final.step == STEPS and not final.degraded
        # The learner got every transition: its heartbeat counts them.
        assert cli.spin_until(lambda: episodes.learner_heartbeats[-1].transitions == STEPS,
                              10.0), stack.logs()
        assert episodes.learner_heartbeats[-1].updates > 0   # and trained on them

    bag = wait_for_bag(Path(stack.env["QG_RUNS_DIR"]) / "episodes", response.episode_id)
    transitions, joint_names, counts = [], set(), {}
    for topic, _, _, msg in read_bag(bag):
        counts[topic] = counts.get(topic, 0) + 1
        if topic == "/transitions":
            transitions.append(msg)
        elif topic == "/joint_states":
            joint_names.add(tuple(msg.name))
    assert [t.step for t in transitions] == list(range(STEPS))
    assert joint_names == {tuple(f"RARM_JOINT{i}" for i in range(6))}
    assert counts["/joint_states"] > 10 * STEPS and counts["/wrench_setpoint"] == STEPS
    task, cell = PegTaskConfig(), PegCell()
    half = cell.geometry.workspace_side / 2
    for t in transitions:
        assert len(t.state) == len(t.action) == len(t.next_state) == 3
        assert -1.0 <= t.reward <= 0.0
        # State and reward are both the tip from the measured tool pose: the reward's
        # tip-to-goal distance is the state's, to rounding.
        tip = np.asarray(t.next_state) * half + [0.0, 0.0, half]
        distance = -task.reward_length * np.log(t.reward + 1.0)
        assert abs(np.linalg.norm(tip - cell.geometry.goal) - distance) < 1e-9, (tip, distance)
    for before, after in zip(transitions, transitions[1:]):
        assert before.next_state == after.state
    assert stack.launcher.poll() == []
