"""Hybrid force/impedance law: the pure mapping, gravity compensation, x/y stiffness."""
from __future__ import annotations

import numpy as np
import pytest
from robot_bridge_node.core.impedance import HybridImpedanceController, ImpedanceConfig
from robot_bridge_node.core.panda_model import Q_READY, PandaModel
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from qg_common.types import WrenchSetpoint

from arms import ideal


@pytest.fixture(scope="module")
def loop() -> RobotLoop:
    # The ideal arm: these tests hold the control law against the model it was built on (the
    # realistic arm's unknown payload sinks along the force-controlled z axis by design).
    loop = build_loop(load_robot("sim_panda", ideal()))
    yield loop
    loop.simulation.scene.close()


def test_at_the_reference_and_still_the_law_is_gravity_plus_jt_feedforward() -> None:
    model = PandaModel()
    controller = HybridImpedanceController(ImpedanceConfig(), model)
    controller.reset(Q_READY)
    wrench = np.array([1.0, -2.0, -15.0, 0.5, -0.3, 0.1])
    tau = controller.step(Q_READY, np.zeros(7), WrenchSetpoint(wrench), 0.001)
    kin = model.kinematics(Q_READY)
    applied = -np.concatenate([kin.rotation @ wrench[:3], kin.rotation @ wrench[3:]])
    np.testing.assert_allclose(tau, kin.jacobian.T @ applied + model.gravity(Q_READY), atol=1e-9)


def test_velocity_is_damped_in_every_direction() -> None:
    model = PandaModel()
    controller = HybridImpedanceController(ImpedanceConfig(), model)
    controller.reset(Q_READY)
    rng = np.random.default_rng(0)
    for _ in range(5):
        dq = rng.normal(scale=0.2, size=7)
        tau = controller.step(Q_READY, dq, WrenchSetpoint(np.zeros(6)), 0.001)
        power = float(dq @ (tau - model.nonlinear_effects(Q_READY, dq)))
        assert power < 0.0  # the controller only removes energy around the reference


def lift(loop: RobotLoop, seconds: float = 0.3) -> None:
    """Pull the shaft up out of the counterbore (contact convention: +Fz pulls), then stop."""
    loop.command(WrenchSetpoint.residual(8.0, 0.0, 0.0))
    for _ in range(round(seconds / loop.config.dt)):
        loop.tick()
    loop.execute(WrenchSetpoint(np.zeros(6)))
    assert loop.simulation.scene.ground_truth().insertion_depth < -0.02


def test_gravity_compensation_holds_the_pose_for_two_seconds(loop: RobotLoop) -> None:
    loop.reset(0)
    start, _ = loop.simulation.scene.tool_pose()
    loop.command(WrenchSetpoint(np.zeros(6)))
    for _ in range(2000):
        loop.tick()
    end, _ = loop.simulation.scene.tool_pose()
    assert np.linalg.norm(end - start) < 0.001


@pytest.mark.parametrize("axis", [0, 1])
def test_measured_lateral_stiffness_is_the_configured_one(loop: RobotLoop, axis: int) -> None:
    loop.reset(0)
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
