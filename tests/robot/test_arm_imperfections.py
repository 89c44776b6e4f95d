"""The simulated Panda's imperfections each change what they should, by the expected amount, and
switched off they give back the ideal arm bit for bit."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from arms import cell, start
from qg_common.panda_description import panda_arm, panda_urdf_path
from robot_bridge_node.core.arm_model import ArmModel
from sim_robot_node.core.arm_imperfections import GAZ_2019_COULOMB, ArmImperfections, ImperfectArm
from sim_robot_node.core.shaft_scene import ShaftScene, ShaftSceneConfig
from sim_robot_node.core.shaft_world import build_world

IDEAL = ArmImperfections.ideal()


def only(**changes) -> ArmImperfections:
    """The ideal arm with the named imperfections on."""
    return dataclasses.replace(IDEAL, **changes)


def scene_with(imperfections: ArmImperfections, cell_changes: dict | None = None,
               **config) -> ShaftScene:
    return ShaftScene(ShaftSceneConfig(imperfections=imperfections, **config),
                      cell(**(cell_changes or {})), panda_arm())


def test_the_ideal_arm_is_the_bare_world_bit_for_bit():
    """With every imperfection off the scene adds nothing to its engine's world: 300 steps under
    varying torques from start 5 read exactly the states of a bare world stepped with the same
    torques from the same joints (the driver's reading is the truth, the links get the
    command), and the measured torque is the command."""
    scene = scene_with(IDEAL)
    scene.teleport(start(5))
    bare = build_world(panda_arm(), scene.geometry, scene.config)
    bare.place_housing(scene.fixture)
    bare.set_arm_state(*scene.world.arm_state())
    tau = np.array([0.0, -30.0, 0.0, 20.0, 1.0, 2.0, 0.0])
    try:
        for k in range(300):
            state = scene.joint_state()
            q, dq = bare.arm_state()
            np.testing.assert_array_equal(state.q, q)
            np.testing.assert_array_equal(state.dq, dq)
            command = tau + 0.5 * np.sin(0.05 * k)
            scene.apply_torques(command)
            np.testing.assert_array_equal(scene.joint_state().tau, command)
            bare.set_arm_torques(command)
            scene.step()
            bare.step()
        assert np.linalg.norm(scene.joint_state().q - scene.world.arm_state()[0]) == 0.0
        assert np.linalg.norm(q - scene.joint_state().q) > 1e-3      # the arm did move
    finally:
        bare.close()
        scene.close()


def test_the_realistic_arm_is_the_default_and_every_imperfection_is_on():
    default = ShaftSceneConfig().imperfections
    assert default.payload_mass_error > 0 and default.torque_bias > 0
    np.testing.assert_allclose(default.joint_coulomb_friction,
                               0.2 * np.array(GAZ_2019_COULOMB), atol=1e-5)
    assert all(getattr(default, f.name) for f in dataclasses.fields(default)
               if f.name != "seed")
    zeroed = [f.name for f in dataclasses.fields(IDEAL)
              if f.name != "seed" and np.any(getattr(IDEAL, f.name))]
    assert zeroed == []


def test_a_payload_error_of_m_kg_at_tilt_theta_gives_its_gravity_torque():
    """The arm's true gravity torque (pybullet's inverse dynamics of the simulated arm) exceeds
    the bridge model's by the unknown mass's: ``J_com^T (0, 0, m g)`` at the start tilt."""
    import pybullet as p
    mass, com = 0.3, np.array([0.02, 0.0, -0.03])
    scene = scene_with(only(payload_mass_error=mass, payload_com_error=tuple(com)),
                       engine="pybullet")             # its API's inverse dynamics
    model = ArmModel.of_arm(panda_arm(), payload_mass=scene.config.shaft_mass,
                            payload_com=scene.geometry.shaft_centre)
    for pose in (0, 3):
        scene.teleport(start(pose))
        q = scene.joint_state().q
        true = np.array(p.calculateInverseDynamics(scene.world.robot, q.tolist(), [0.0] * 7,
                                                   [0.0] * 7, physicsClientId=scene.world.cid))
        kin = model.kinematics(q)
        lever = kin.rotation @ com                     # tool origin -> the mass, base frame
        jac_com = kin.jacobian[:3] - _skew(lever) @ kin.jacobian[3:]
        expected = jac_com.T @ np.array([0.0, 0.0, mass * scene.config.gravity])
        assert math.degrees(scene.ground_truth().tilt) == pytest.approx(15.0, abs=0.1)
        np.testing.assert_allclose(true - model.gravity(q), expected, atol=1e-3)
        assert np.abs(expected).max() > 0.5            # a real signal, not rounding


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def test_joint_friction_is_what_the_links_lose_and_the_driver_does_not_see():
    """Without gravity, a constant command accelerates the arm; the torque the links actually
    got (``M ddq``) falls short of the command by the Gaz et al. friction at that velocity,
    while the driver's torque reading is the command."""
    scene = scene_with(only(joint_coulomb_friction=GAZ_2019_COULOMB,
                            joint_friction_velocity=ArmImperfections().joint_friction_velocity,
                            joint_viscous_friction=(0.05,) * 7),
                       {"start_clearance": 0.05}, gravity=0.0)
    model = ArmModel.of_arm(panda_arm(), payload_mass=scene.config.shaft_mass,
                            payload_com=scene.geometry.shaft_centre)
    tau = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3])
    scene.teleport(start(0, start_clearance=0.05))
    for _ in range(60):                      # spin up joint 7 to a few tenths of rad/s
        scene.apply_torques(tau)
        scene.step()
    before = scene.true_joint_state()
    scene.apply_torques(tau)
    scene.step()
    after = scene.true_joint_state()
    ddq = (after.dq - before.dq) / scene.config.time_step
    realised = model.mass_matrix(before.q) @ ddq + \
        model.nonlinear_effects(before.q, before.dq)
    friction = scene.arm_errors.friction(before.dq)
    assert abs(before.dq[6]) > 0.2
    assert friction[6] > 0.1                 # of the order of Gaz et al.'s 0.28 Nm level
    np.testing.assert_allclose(realised[6], tau[6] - friction[6], atol=0.03)
    np.testing.assert_array_equal(scene.joint_state().tau, tau)


def test_friction_level_and_sign():
    arm = ImperfectArm(only(joint_coulomb_friction=GAZ_2019_COULOMB,
                            joint_friction_velocity=ArmImperfections().joint_friction_velocity,
                            joint_viscous_friction=(0.05,) * 7))
    fast = arm.friction(np.full(7, 10.0))
    expected = np.array(GAZ_2019_COULOMB) + 0.05 * 10.0
    np.testing.assert_allclose(fast, expected, rtol=1e-6)
    np.testing.assert_allclose(arm.friction(-np.full(7, 10.0)), -expected, rtol=1e-6)
    assert np.all(arm.friction(np.zeros(7)) == 0.0)


def test_sensor_noise_and_bias_have_their_configured_size():
    config = only(torque_noise=0.02, torque_bias=0.15, encoder_noise=1e-5, encoder_bias=1e-4,
                  velocity_noise=1e-3, seed=3)
    arm = ImperfectArm(config)
    q, dq, tau = np.ones(7), np.zeros(7), np.full(7, 2.0)
    samples = [arm.measure(q, dq, tau) for _ in range(4000)]
    tau_error = np.array([s.tau for s in samples]) - tau
    q_error = np.array([s.q for s in samples]) - q
    dq_error = np.array([s.dq for s in samples])
    np.testing.assert_allclose(tau_error.mean(axis=0), arm.torque_bias, atol=2e-3)
    np.testing.assert_allclose(tau_error.std(axis=0), 0.02, rtol=0.08)
    np.testing.assert_allclose(q_error.mean(axis=0), arm.encoder_bias, atol=1e-6)
    np.testing.assert_allclose(q_error.std(axis=0), 1e-5, rtol=0.08)
    np.testing.assert_allclose(dq_error.std(axis=0), 1e-3, rtol=0.08)
    # The biases are draws of their std: 7 joints, none zero, about the right size.
    assert 0.03 < np.abs(arm.torque_bias).mean() < 0.3
    assert 2e-5 < np.abs(arm.encoder_bias).mean() < 2e-4


def test_the_driver_reads_each_step_once_with_the_sensor_errors():
    scene = scene_with(only(torque_noise=0.02, torque_bias=0.15, encoder_noise=1e-5))
    first, again = scene.joint_state(), scene.joint_state()
    assert first is again                        # one reading per step
    truth = scene.true_joint_state()
    assert not np.array_equal(first.q, truth.q)
    np.testing.assert_allclose(first.q, truth.q, atol=1e-4)
    scene.apply_torques(np.zeros(7))
    scene.step()
    assert scene.joint_state() is not first


def test_start_jitter_and_the_housing_error_have_their_size_and_the_bore_moves():
    jitter, housing = math.radians(0.5), math.radians(0.5)
    tilts = []
    for seed in range(6):
        scene = scene_with(only(start_tilt_jitter=jitter, start_position_jitter=5e-5,
                                housing_tilt_error=housing, housing_position_error=5e-5,
                                seed=seed))
        error = scene.arm_errors.housing_rotation_error
        assert error[2] == 0.0 and 0.0 < np.linalg.norm(error) < 5 * housing
        # The bore really is where the error puts it: the fully inserted tool position lies
        # on the true axis, off the configured one by the position error.
        target = scene.geometry.target_tool_position(scene.fixture)
        configured = scene.geometry.target_tool_position()
        assert 0.0 < np.linalg.norm(target - configured) < 1e-3
        for pose in range(4):
            scene.teleport(start(pose))
            tilts.append(scene.ground_truth().tilt)
    spread = np.std(np.degrees(tilts))
    # Tilt against the true bore: 15 deg, spread by the jitter and the housing's error.
    assert np.mean(np.degrees(tilts)) == pytest.approx(15.0, abs=0.5)
    assert 0.2 < spread < 1.5


def test_a_seeded_arm_is_identical_twice_and_another_seed_differs():
    def run(seed: int) -> np.ndarray:
        scene = scene_with(dataclasses.replace(ArmImperfections(), seed=seed))
        scene.teleport(start(2))
        out = []
        for _ in range(50):
            state = scene.joint_state()
            scene.apply_torques(np.zeros(7))
            scene.step()
            out.append(np.concatenate([state.q, state.dq, state.tau]))
        return np.array(out)

    np.testing.assert_array_equal(run(1), run(1))
    assert not np.allclose(run(1), run(2))


def test_imperfections_are_validated():
    with pytest.raises(ValueError, match="torque_noise"):
        only(torque_noise=-0.1)
    with pytest.raises(ValueError, match="joint_coulomb_friction"):
        only(joint_coulomb_friction=(0.1,) * 6)
    with pytest.raises(ValueError, match="joint_friction_velocity"):
        only(joint_coulomb_friction=(0.1,) * 7)
    with pytest.raises(ValueError, match="seed"):
        only(seed=-1)
    assert panda_urdf_path().is_file()


def test_the_imperfections_fit_any_joint_count_and_refuse_another_arms():
    """Six joints (a UR arm's) as well as seven: one figure a joint, drawn and applied per joint;
    figures for another joint count are refused when the arm is built."""
    six = dataclasses.replace(ArmImperfections.ideal(n_joints=6), torque_noise=0.02,
                              torque_bias=0.15, joint_coulomb_friction=(0.1,) * 6,
                              joint_friction_velocity=(0.2,) * 6, seed=4)
    arm = ImperfectArm(six, 6)
    assert arm.torque_bias.shape == (6,) and np.all(arm.torque_bias != 0.0)
    reading = arm.measure(np.zeros(6), np.zeros(6), np.ones(6))
    assert reading.tau.shape == (6,) and not np.array_equal(reading.tau, np.ones(6))
    np.testing.assert_allclose(arm.friction(np.full(6, 10.0)), np.full(6, 0.1), rtol=1e-6)
    with pytest.raises(ValueError, match="7 joints"):
        ImperfectArm(six, 7)
    with pytest.raises(ValueError, match="joint_friction_velocity needs 6"):
        dataclasses.replace(six, joint_friction_velocity=(0.2,) * 7)
