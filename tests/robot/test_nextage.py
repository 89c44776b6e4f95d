"""Our Nextage arm: the URDF in both engines, the IK position controller, the peg scene."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest
from qg_common.params import config_file, load_ros_params
from robot_bridge_node.core.position_control import (
    PositionControlConfig,
    TaskSpacePositionController,
)
from sim_robot_node.core.nextage_scene import (
    INIT_POSE,
    NextagePegScene,
    NextageSceneConfig,
    PegHoleGeometry,
    nextage_urdf_path,
)

TOOL = "RARM_TOOL"
#: Published joint limits of the right arm [deg] (the URDF comment's table).
PUBLISHED_LIMITS_DEG = [(-88, 88), (-140, 45), (-158, 0), (-165, 165), (-100, 100), (-163, 163)]


@pytest.fixture(scope="module")
def nextage_params() -> dict:
    return load_ros_params(config_file("nextage.yaml"))


@pytest.fixture(scope="module")
def controller(nextage_params: dict) -> TaskSpacePositionController:
    config = PositionControlConfig.from_dict(nextage_params["position_control"])
    return TaskSpacePositionController(nextage_urdf_path(), TOOL, config)


@pytest.fixture
def scene(nextage_params: dict):
    s = NextagePegScene(NextageSceneConfig.from_dict(nextage_params["scene"]))
    yield s
    s.close()


def test_urdf_loads_in_both_engines_with_the_published_limits():
    model = pin.buildModelFromUrdf(str(nextage_urdf_path()))
    assert model.nq == 6
    assert model.existFrame(TOOL) and model.existFrame("RARM_FT_LINK")
    np.testing.assert_allclose(np.rad2deg(model.lowerPositionLimit),
                               [lo for lo, _ in PUBLISHED_LIMITS_DEG], atol=0.01)
    np.testing.assert_allclose(np.rad2deg(model.upperPositionLimit),
                               [hi for _, hi in PUBLISHED_LIMITS_DEG], atol=0.01)
    client = p.connect(p.DIRECT)
    try:
        robot = p.loadURDF(str(nextage_urdf_path()), useFixedBase=True, physicsClientId=client)
        kinds = [p.getJointInfo(robot, j, physicsClientId=client)[2]
                 for j in range(p.getNumJoints(robot, physicsClientId=client))]
        assert kinds.count(p.JOINT_REVOLUTE) == 6 and kinds.count(p.JOINT_FIXED) == 3
    finally:
        p.disconnect(client)


def test_forward_kinematics_of_pybullet_and_pinocchio_agree(
        scene: NextagePegScene, controller: TaskSpacePositionController):
    rng = np.random.default_rng(0)
    worst_position, worst_rotation = 0.0, 0.0
    for _ in range(20):
        q = rng.uniform(scene.q_lower, scene.q_upper)
        for joint, angle in zip(scene.joints, q):
            p.resetJointState(scene.robot, joint, angle, physicsClientId=scene.client)
        bullet, pinocchio_pose = scene.tool_pose(), controller.forward(q)
        worst_position = max(worst_position,
                             np.linalg.norm(bullet[:3, 3] - pinocchio_pose[:3, 3]))
        worst_rotation = max(worst_rotation,
                             np.linalg.norm(pin.log3(bullet[:3, :3].T @ pinocchio_pose[:3, :3])))
    assert worst_position < 1e-3
    assert worst_rotation < 1e-3


def test_ik_reaches_twenty_tool_down_poses_in_the_workspace(
        scene: NextagePegScene, controller: TaskSpacePositionController):
    rng = np.random.default_rng(1)
    g = scene.geometry
    for _ in range(20):
        tip = rng.uniform(g.workspace_low, g.workspace_high)
        pose = scene.tool_pose_for_tip(tip)
        result = controller.solve(INIT_POSE, pose)
        reached = controller.forward(result.q)
        assert np.linalg.norm(reached[:3, 3] - pose[:3, 3]) < 1e-3, tip
        assert np.linalg.norm(pin.log3(reached[:3, :3].T @ pose[:3, :3])) < 1e-3, tip
        assert np.all(result.q >= controller.q_lower) and np.all(result.q <= controller.q_upper)


def test_controller_is_rate_limited_rejects_nan_and_clamps_to_the_workspace(
        controller: TaskSpacePositionController):
    cfg = controller.config
    controller.reset(INIT_POSE)
    start = controller.forward(INIT_POSE)
    far = start.copy()
    far[:3, 3] += [0.5, 0.0, 0.0]                         # 50 cm: beyond the workspace box
    q_previous = INIT_POSE.copy()
    for _ in range(100):
        q_target = controller.step(INIT_POSE, far)
        assert np.max(np.abs(q_target - q_previous)) <= cfg.joint_speed_limit * cfg.dt + 1e-12
        q_previous = q_target
    moved = controller.pose_command[:3, 3] - start[:3, 3]
    assert np.linalg.norm(moved) == pytest.approx(100 * cfg.linear_speed_limit * cfg.dt, rel=1e-6)
    for _ in range(3000):
        controller.step(INIT_POSE, far)
    assert controller.pose_command[0, 3] == pytest.approx(cfg.workspace_max[0])
    rejected = controller.rejected_references
    held = controller.pose_command
    nan_pose = far.copy()
    nan_pose[0, 3] = np.nan
    controller.step(INIT_POSE, nan_pose)
    assert controller.rejected_references == rejected + 1
    np.testing.assert_array_equal(controller.pose_command, held)
    with pytest.raises(ValueError, match="not finite"):
        controller.step(np.full(6, np.nan), far)


def test_bad_configs_fail_loudly():
    with pytest.raises(ValueError, match="damping"):
        PositionControlConfig(damping=0.0)
    with pytest.raises(ValueError, match="workspace_min"):
        PositionControlConfig(workspace_min=(0.0, 0.0, 0.0), workspace_max=(1.0, -1.0, 1.0))
    with pytest.raises(ValueError, match="unknown"):
        PositionControlConfig.from_dict({"dampin": 0.1})
    with pytest.raises(ValueError, match="hole_radius"):
        PegHoleGeometry(hole_radius=0.004)
    with pytest.raises(ValueError, match="unknown"):
        NextageSceneConfig.from_dict({"geometry": {"peg_radiu": 0.005}})


def _descend(scene: NextagePegScene, controller: TaskSpacePositionController, start: np.ndarray,
             steps: int) -> tuple[bool, float]:
    """Move the tip straight down from ``start`` to the hole-bottom height.

    :returns: success at any time, and the largest rise of the wrist's vertical force over its
        free-air reading [N].
    """
    q = scene.reset(start=start)
    controller.reset(q)
    for _ in range(50):
        scene.step()
    free_air = scene.wrist_wrench()[2]
    goal_height = start.copy()
    goal_height[2] = scene.geometry.goal[2]
    reference = scene.tool_pose_for_tip(goal_height)
    success, peak = False, 0.0
    for _ in range(steps):
        scene.set_joint_targets(controller.step(scene.joint_state().q, reference))
        scene.step()
        success |= scene.ground_truth().success
        peak = max(peak, scene.wrist_wrench()[2] - free_air)
    return success, peak


def test_wrist_sensor_reads_the_weight_beyond_it_in_free_air(scene: NextagePegScene):
    scene.reset(start=np.array([0.0, 0.0, 0.1]))
    for _ in range(200):
        scene.step()
    # sensor disc 0.2 kg + hand 0.4 kg + tool 0.001 kg + peg; the arm holds it up (-z: tool down)
    mass = 0.601 + scene.geometry.peg_mass
    np.testing.assert_allclose(scene.wrist_wrench()[:3], [0.0, 0.0, -mass * 9.81], atol=0.05)


def test_straight_down_over_the_hole_inserts(scene: NextagePegScene,
                                             controller: TaskSpacePositionController):
    success, _ = _descend(scene, controller, np.array([0.0, 0.0, 0.07]), steps=900)
    assert success
    assert scene.ground_truth().distance < scene.geometry.goal_tolerance


def test_straight_down_with_a_15_mm_offset_hits_the_block(scene: NextagePegScene,
                                                          controller: TaskSpacePositionController):
    success, peak = _descend(scene, controller, np.array([0.015, 0.0, 0.07]), steps=900)
    assert not success
    assert peak > 50.0     # the block pushes back through peg and hand (~200 N at the motor limits)
