"""The second torque-controlled arm, the xArm 7 from its URDF (``sim_xarm7``): the bridge's model
and the simulator read the same file and agree, and the shaft task runs through the same loop,
controller and EKF as the Panda's."""
from __future__ import annotations

import numpy as np
import pybullet as p
import pytest
from arms import start
from qg_common.types import WrenchSetpoint
from qg_common.xarm_description import xarm7_arm
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import load_robot, robot_defaults, robot_plugin
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig
from sim_robot_node.core.arm_imperfections import ArmImperfections

PUSH = -15.0  # [N] the base policy


def _bridge_params() -> dict:
    """The bridge's parameters for the xArm: config/bridge.yaml, then its own file's gains."""
    return robot_defaults(robot_plugin("sim_xarm7"), (("robot_bridge_node", "bridge.yaml"),),
                          "bridge")


@pytest.fixture(scope="module")
def ideal_xarm():
    """The ideal xArm on pybullet, whose API gives the simulator's own masses and inverse
    dynamics to hold the model against (the default engine's run is the realistic test's)."""
    zeros = ArmImperfections.ideal()
    robot = load_robot("sim_xarm7", {"xarm_scene": {"engine": "pybullet", "imperfections": {
        f: getattr(zeros, f) for f in zeros.__dataclass_fields__}}})
    yield robot
    robot.simulation.scene.close()


def test_the_model_has_the_urdfs_seven_joints_limits_and_the_simulators_masses(ideal_xarm):
    """Pinocchio and pybullet read one URDF: the same joints, the same 11.3 kg of links plus the
    shaft, and the same gravity torques wherever the arm is (a link pybullet would give 1 kg, the
    massless ``link_eef``, is massless in both)."""
    model = ArmModel.from_description(ideal_xarm.description)
    assert model.nv == 7 and model.joint_names == tuple(f"joint{i}" for i in range(1, 8))
    np.testing.assert_array_equal(model.limits.torque, [50, 50, 30, 30, 30, 20, 20])
    np.testing.assert_array_equal(model.limits.velocity, np.full(7, 3.14))
    scene = ideal_xarm.simulation.scene
    world = scene.world
    bodies = range(-1, p.getNumJoints(world.robot, physicsClientId=world.cid))
    pybullet_mass = sum(p.getDynamicsInfo(world.robot, j, physicsClientId=world.cid)[0]
                        for j in bodies)
    assert pybullet_mass == pytest.approx(sum(i.mass for i in model.model.inertias[1:])
                                          + 0.88556, abs=1e-6)   # + the fixed base link
    rng = np.random.default_rng(0)
    for _ in range(3):
        q = np.array(xarm7_arm().ready) + rng.uniform(-0.5, 0.5, 7)
        simulated = p.calculateInverseDynamics(world.robot, q.tolist(), [0.0] * 7, [0.0] * 7,
                                               physicsClientId=world.cid)
        np.testing.assert_allclose(simulated, model.gravity(q), atol=1e-6)
        assert np.abs(model.gravity(q)).max() > 5.0        # a real load, not zeros
    assert np.all(np.abs(model.gravity(scene.joint_state().q)) < 0.5 * model.limits.torque)


def test_the_ekf_is_sized_by_the_arms_model(ideal_xarm):
    ekf = WrenchEKF(WrenchEKFConfig(), ArmModel.from_description(ideal_xarm.description))
    assert ekf.covariance.shape == (2 * 7 + 6, 2 * 7 + 6)


def test_a_joint_order_other_than_the_urdfs_is_refused():
    arm = xarm7_arm()
    with pytest.raises(ValueError, match="order"):
        ArmModel(arm.urdf, tuple(reversed(arm.joint_names)), arm.tool_mount)
    with pytest.raises(ValueError, match="no frame"):
        ArmModel(arm.urdf, arm.joint_names, "no_such_flange")


def _episode(loop: RobotLoop, pose: int, rng: np.random.Generator | None,
             max_steps: int) -> tuple[bool, int]:
    loop.reset(start(pose))
    for step in range(1, max_steps + 1):
        torques = (0.0, 0.0) if rng is None else tuple(3.0 * rng.uniform(-1.0, 1.0, 2))
        if loop.execute(WrenchSetpoint.residual(PUSH, *torques)).ground_truth.success:
            return True, step
    return False, max_steps


@pytest.mark.slow
def test_the_realistic_xarm_completes_shaft_episodes_through_the_bridge_and_the_base_push_jams():
    """The Panda's loop, controller and EKF on the xArm (its default, realistic arm): random
    residuals insert (8/8 starts, 12-66 steps, mean 34 measured on seed 0), the zero residual
    wedges (8/8 for 40 steps measured)."""
    loop = build_loop(load_robot("sim_xarm7"), _bridge_params(),
                      lambda robot, model: WrenchEKF(WrenchEKFConfig(), model))
    try:
        rng = np.random.default_rng(0)
        outcomes = [_episode(loop, pose, rng, 200) for pose in (0, 2)]
        assert all(success for success, _ in outcomes), outcomes
        jammed, _ = _episode(loop, 3, None, 15)
        assert not jammed
        depth = loop.ground_truth().insertion_depth
        assert 0.0 < depth < 0.005                         # wedged at the bore entrance
    finally:
        loop.simulation.scene.close()
