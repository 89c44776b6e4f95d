"""Hybrid force/impedance law: the pure mapping, gravity compensation, x/y stiffness."""
from __future__ import annotations

import numpy as np
import pytest
from arms import ideal, start
from qg_common.panda_description import Q_READY, panda_arm
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.impedance import HybridImpedanceController, ImpedanceConfig
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop


@pytest.fixture(scope="module")
def loop() -> RobotLoop:
    # The ideal arm: these tests hold the control law against the model it was built on (the
    # realistic arm's unknown payload sinks along the force-controlled z axis by design).
    loop = build_loop(load_robot("sim_panda", ideal()))
    yield loop
    loop.simulation.scene.close()


def test_at_the_reference_and_still_the_law_is_gravity_plus_jt_feedforward() -> None:
    model = ArmModel.of_arm(panda_arm())
    controller = HybridImpedanceController(ImpedanceConfig(), model)
    controller.reset(Q_READY)
    wrench = np.array([1.0, -2.0, -15.0, 0.5, -0.3, 0.1])
    tau = controller.step(Q_READY, np.zeros(7), WrenchSetpoint(wrench), 0.001)
    kin = model.kinematics(Q_READY)
    applied = -np.concatenate([kin.rotation @ wrench[:3], kin.rotation @ wrench[3:]])
    np.testing.assert_allclose(tau, kin.jacobian.T @ applied + model.gravity(Q_READY), atol=1e-9)


def test_velocity_is_damped_in_every_direction() -> None:
    model = ArmModel.of_arm(panda_arm())
    controller = HybridImpedanceController(ImpedanceConfig(), model)
    controller.reset(Q_READY)
    rng = np.random.default_rng(0)
    for _ in range(5):
        dq = rng.normal(scale=0.2, size=7)
        tau = controller.step(Q_READY, dq, WrenchSetpoint(np.zeros(6)), 0.001)
        power = float(dq @ (tau - model.nonlinear_effects(Q_READY, dq)))
        assert power < 0.0  # the controller only removes energy around the reference



def test_matches_the_law_written_out_in_numpy() -> None:
    """The compiled law is the module docstring's, term by term, away from the reference and
    the posture (spring, damping, feed-forward, null-space projection, C dq + g)."""
    import pinocchio as pin

    model, config = ArmModel.of_arm(panda_arm()), ImpedanceConfig()
    controller = HybridImpedanceController(config, model)
    rng = np.random.default_rng(1)
    controller.reset(Q_READY + 0.05 * rng.standard_normal(7))       # the posture: elsewhere
    stiffness = np.r_[config.k_trans, config.k_rot]
    damping = np.r_[config.d_trans, config.d_rot]
    for _ in range(20):
        q, dq = Q_READY + 0.1 * rng.standard_normal(7), 0.3 * rng.standard_normal(7)
        wrench = rng.uniform(-5.0, 5.0, 6)
        tau = controller.step(q, dq, WrenchSetpoint(wrench), 0.001)
        kin, ref = model.kinematics(q), controller.reference
        rot6 = np.kron(np.eye(2), kin.rotation)            # EEF frame -> base frame, both parts
        error = np.r_[ref.position - kin.position, pin.log3(ref.rotation @ kin.rotation.T)]
        eef_wrench = (stiffness * (rot6.T @ error) - damping * (rot6.T @ kin.jacobian @ dq)
                      - wrench)
        posture = config.k_null * (controller.q_null - q) - config.d_null * dq
        jac = kin.jacobian
        null = posture - jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), jac @ posture)
        expected = (jac.T @ rot6 @ eef_wrench + null - config.d_joint * dq
                    + model.nonlinear_effects(q, dq))
        np.testing.assert_allclose(tau, expected, rtol=0.0, atol=1e-9)
        np.testing.assert_allclose(controller.tool.twist, jac @ dq, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(controller.tool.rotation, kin.rotation, rtol=0.0, atol=1e-12)

def lift(loop: RobotLoop, seconds: float = 0.3) -> None:
    """Pull the shaft up out of the counterbore (contact convention: +Fz pulls), then stop."""
    loop.command(WrenchSetpoint.residual(8.0, 0.0, 0.0))
    for _ in range(round(seconds / loop.config.dt)):
        loop.tick()
    loop.execute(WrenchSetpoint(np.zeros(6)))
    assert loop.simulation.scene.ground_truth().insertion_depth < -0.02


def test_gravity_compensation_holds_the_pose_for_two_seconds(loop: RobotLoop) -> None:
    loop.reset(start(0))
    began, _ = loop.simulation.scene.tool_pose()
    loop.command(WrenchSetpoint(np.zeros(6)))
    for _ in range(2000):
        loop.tick()
    end, _ = loop.simulation.scene.tool_pose()
    assert np.linalg.norm(end - began) < 0.001


@pytest.mark.parametrize("axis", [0, 1])
def test_measured_lateral_stiffness_is_the_configured_one(loop: RobotLoop, axis: int) -> None:
    loop.reset(start(0))
    lift(loop)
    loop.command(WrenchSetpoint(np.zeros(6)))
    reference = loop.controller.reference
    wrench = np.zeros(6)
    wrench[axis] = 3.0  # contact force on the tool along EEF x or y: the arm gives way
    loop.command(WrenchSetpoint(wrench, reference))
    for _ in range(1500):
        loop.tick()
    position, _ = loop.simulation.scene.tool_pose()
    displacement = reference.rotation.T @ (position - reference.position)
    stiffness = 3.0 / -displacement[axis]
    configured = loop.controller.config.k_trans[axis]
    assert stiffness == pytest.approx(configured, rel=0.10)
    assert abs(displacement[1 - axis]) < 0.1 * abs(displacement[axis])


def test_the_panda_from_its_plugin_is_the_model_of_its_description_bit_for_bit():
    """The generic model of the sim_panda plugin's description is the Panda with its shaft, as
    the description in qg_common builds it: the same serialised model the kernels load."""
    from qg_common.panda_description import JOINT_NAMES, TOOL_MOUNT
    from robot_bridge_node.core.hardware_interface import load_robot
    description = load_robot("sim_panda", ideal()).description
    assert description.joint_names == JOINT_NAMES and description.tool_frame == TOOL_MOUNT
    tool = description.tool
    assert ArmModel.from_description(description).serialised() == ArmModel.of_arm(
        panda_arm(), tool.offset, tool.payload_mass, tool.payload_com).serialised()
    assert ArmModel.of_arm(panda_arm()).nv == 7        # the fingers are locked


def test_holding_makes_every_axis_stiff_and_a_release_restores_the_task_gains():
    """A pose error along z (force-controlled, 0 N/m in the task) pulls back while holding."""
    model = ArmModel.of_arm(panda_arm())
    controller = HybridImpedanceController(ImpedanceConfig(), model)
    controller.reset(Q_READY)
    kin = model.kinematics(Q_READY)
    down = Q_READY + np.linalg.pinv(kin.jacobian) @ np.array([0, 0, -0.001, 0, 0, 0])
    free = controller.step(down, np.zeros(7), WrenchSetpoint(np.zeros(6)), 0.001)
    np.testing.assert_allclose(free, model.gravity(down) + ImpedanceConfig().k_null
                               * _null_space_pull(model, down), atol=0.05)
    controller.hold(Q_READY)
    held = controller.step(down, np.zeros(7), WrenchSetpoint(np.zeros(6)), 0.001)
    # 1 mm below the held pose: the hold pushes up with about 3000 N/m x 1 mm = 3 N.
    force = np.linalg.lstsq(model.kinematics(down).jacobian.T, held - free, rcond=None)[0]
    assert force[2] == pytest.approx(3.0, abs=0.3)
    controller.release()
    np.testing.assert_allclose(controller.step(down, np.zeros(7), WrenchSetpoint(np.zeros(6)),
                                               0.001), free, atol=1e-9)


def _null_space_pull(model: ArmModel, q: np.ndarray) -> np.ndarray:
    """The posture spring's torque direction per unit stiffness at ``q`` (towards Q_READY)."""
    J = model.kinematics(q).jacobian
    projector = np.eye(7) - J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), J)
    return projector @ (Q_READY - q)
