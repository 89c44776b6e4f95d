"""Episode resets by motion (``reset.teleport: false``, what every real arm does): on the MuJoCo
Panda with the realistic arm's unknown payload and joint friction, the loop takes the shaft out
of the fixture, moves to the start and arrives within the issue's 1 mm and 0.5 deg, whether
the arm comes from where it was parked or from a fully inserted shaft (which a stiff withdrawal
jammed in 1 of 4 resets)."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from qg_common.params import config_file, load_ros_params, merge_params
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from robot_bridge_node.core.start_motion import ResetConfig
from robot_bridge_node.core.wrench_source import MeasuredWrench

ROBOT = "sim_panda_mujoco"


@pytest.fixture(scope="module")
def loop() -> RobotLoop:
    bridge = merge_params(load_ros_params(config_file("bridge.yaml")),
                          {"reset": {"teleport": False}, "rest": {"max_time": 3.0}})
    loop = build_loop(load_robot(ROBOT), bridge,
                      estimator=lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench))
    loop.begin()
    yield loop
    loop.simulation.close()


def _true_error(loop: RobotLoop, index: int) -> tuple[float, float]:
    """[m], [rad]: where the simulated tool truly is against start ``index``."""
    start = loop.simulation.scene.geometry.start_pose(index)
    position, rotation = loop.simulation.scene.tool_pose()
    return (float(np.linalg.norm(position - start.position)),
            float(np.linalg.norm(pin.log3(start.rotation @ rotation.T))))


def _tilt_back(loop: RobotLoop) -> tuple[float, float]:
    """Residual torques that turn the shaft upright (from the truth): inserts in a few steps."""
    return tuple(np.clip(-20.0 * loop.simulation.scene.ground_truth().orientation_error,
                         -3.0, 3.0))


def _insert(loop: RobotLoop) -> None:
    """The base push with the tilt-back residuals, until the shaft is in (at most 20 steps)."""
    for _ in range(20):
        if loop.execute(WrenchSetpoint.residual(-15.0, *_tilt_back(loop))).ground_truth.success:
            return


def test_a_reset_moves_the_arm_to_its_start_within_a_millimetre(loop: RobotLoop) -> None:
    loop.reset(loop.simulation.scene.geometry.start_pose(0))
    off, turned = _true_error(loop, 0)
    assert off < 0.001 and np.degrees(turned) < 0.5, (off, np.degrees(turned))
    truth = loop.simulation.scene.ground_truth()
    assert truth.insertion_depth < 0.0 and not truth.success      # above the bearing face


def test_a_reset_takes_an_inserted_shaft_out_and_to_the_next_start(loop: RobotLoop) -> None:
    scene = loop.simulation.scene
    loop.reset(scene.geometry.start_pose(1))
    _insert(loop)
    assert scene.ground_truth().success                          # fully in: 16 mm deep
    loop.reset(scene.geometry.start_pose(5))
    off, turned = _true_error(loop, 5)
    assert off < 0.001 and np.degrees(turned) < 0.5, (off, np.degrees(turned))
    assert not scene.ground_truth().success


def test_a_part_that_does_not_come_out_fails_the_reset_with_why(loop: RobotLoop) -> None:
    """The withdrawal is bounded: a pull too weak to lift the arm fails in its time limit."""
    scene = loop.simulation.scene
    loop.reset(scene.geometry.start_pose(2))
    _insert(loop)
    weak = loop.reset_config
    loop.reset_config = ResetConfig(**{**weak.__dict__, "withdraw_force": 0.5,
                                       "withdraw_force_max": 0.5, "withdraw_timeout": 0.5})
    try:
        with pytest.raises(RuntimeError, match="did not come out of the fixture within 0.5 s"):
            loop.reset(scene.geometry.start_pose(3))
    finally:
        loop.reset_config = weak
    loop.reset(scene.geometry.start_pose(3))                    # the default pull: out
    assert _true_error(loop, 3)[0] < 0.001


def test_the_realtime_watchdog_leaves_a_stuck_pull_alone() -> None:
    """The pull is the loop's own motion: a part that does not move at first (here a pull too
    weak to lift the arm) is at rest after the rest detector's 20 ms, and the realtime watchdog
    held it stiffly 0.1 s later, ending every franky-sim reset after a jam. Now the pull goes on
    until its time limit, and the watchdog begins no hold."""
    bridge = merge_params(load_ros_params(config_file("bridge.yaml")),
                          {"reset": {"teleport": False, "withdraw_force": 0.5,
                                     "withdraw_force_max": 0.5, "withdraw_timeout": 0.5},
                           "loop": {"realtime": True}})
    loop = build_loop(load_robot(ROBOT), bridge,
                      estimator=lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench))
    scene = loop.simulation.scene
    try:
        assert loop.config.realtime
        loop.begin()
        scene.teleport(scene.geometry.start_pose(2))          # at the bore's mouth, tilted
        for _ in range(5):
            loop.execute(WrenchSetpoint.residual(-15.0, 0.0, 0.0))   # the base push jams it
        assert not scene.ground_truth().success
        holds = loop.watchdog_holds
        with pytest.raises(RuntimeError, match="did not come out of the fixture within 0.5 s"):
            loop.reset(scene.geometry.start_pose(3))
        assert loop.watchdog_holds == holds
    finally:
        scene.close()


def test_a_pull_too_weak_at_first_grows_until_the_part_comes_out(loop: RobotLoop) -> None:
    """A first pull that cannot lift the arm (0.5 N, see above) grows to ``withdraw_force_max``
    over half the timeout: the part comes out and the arm reaches the next start."""
    scene = loop.simulation.scene
    loop.reset(scene.geometry.start_pose(4))
    for _ in range(5):
        loop.execute(WrenchSetpoint.residual(-15.0, 0.0, 0.0))      # jammed at the mouth
    weak = loop.reset_config
    loop.reset_config = ResetConfig(**{**weak.__dict__, "withdraw_force": 0.5})
    try:
        loop.reset(scene.geometry.start_pose(6))
    finally:
        loop.reset_config = weak
    off, turned = _true_error(loop, 6)
    assert off < 0.001 and np.degrees(turned) < 0.5, (off, np.degrees(turned))
