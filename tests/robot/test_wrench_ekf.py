"""The EKF wrench estimator against wrenches applied in pybullet with applyExternalForce/Torque.

Accuracy targets from the issue: ~0 in free motion; RMSE <= 0.3 N and 0.03 Nm in quasi-static
contact. The noisy runs add the measurement noise the config assumes (1e-5 rad, 1e-3 rad/s);
with the simulator's exact state the inverse dynamics are trivial and the error is ~0.
"""
from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from ekf_harness import (
    PandaTorqueHarness,
    descend_reference,
    rmse,
    settling_time,
    sine_reference,
    step_wrench,
)
from qg_common.panda_description import Q_READY, panda_arm
from qg_common.params import config_file, load_ros_params
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig

W = np.array([5.0, -3.0, -15.0, 0.5, -0.3, 0.2])     # tool frame [N, Nm]
NOISE = (1e-5, 1e-3)                                 # [rad, rad/s]
Q_TILTED = Q_READY + np.array([0.4, 0.2, -0.3, 0.3, 0.5, -0.4, 0.6])


@pytest.fixture(scope="module")
def model() -> ArmModel:
    return ArmModel.of_arm(panda_arm())


@pytest.fixture(scope="module")
def exact(model: ArmModel) -> Iterator[PandaTorqueHarness]:
    h = PandaTorqueHarness(model)
    yield h
    h.close()


@pytest.fixture(scope="module")
def noisy(model: ArmModel) -> Iterator[PandaTorqueHarness]:
    h = PandaTorqueHarness(model, measurement_noise=NOISE, seed=3)
    yield h
    h.close()


def errors(trace, start: float) -> tuple[float, float]:
    err = (trace.estimate - trace.truth)[trace.time >= start]
    return rmse(err[:, :3]), rmse(err[:, 3:])


# --- config -------------------------------------------------------------------------------------
def test_yaml_config_is_the_default_config() -> None:
    params = load_ros_params(config_file("wrench_estimator.yaml"))
    assert WrenchEKFConfig.from_dict(params["ekf"]) == WrenchEKFConfig()


@pytest.mark.parametrize("params, match", [
    ({"process_noise_forse": 1.0}, "unknown"),
    ({"process_noise_force": 0.0}, "process_noise_force"),
    ({"measurement_noise_dq": -1e-3}, "measurement_noise_dq"),
    ({"lowpass_cutoff_hz": -1.0}, "lowpass_cutoff_hz"),
    ({"initial_std_q": float("nan")}, "initial_std_q"),
    ({"process_noise_torque": "fast"}, "process_noise_torque"),
])
def test_bad_config_is_rejected(params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        WrenchEKFConfig.from_dict(params)


# --- accuracy -----------------------------------------------------------------------------------
@pytest.mark.parametrize("q0", [Q_READY, Q_TILTED], ids=["ready", "tilted"])
def test_converges_to_applied_wrench_in_tool_frame(noisy: PandaTorqueHarness,
                                                   model: ArmModel, q0: np.ndarray) -> None:
    noisy.reset(q0)
    ekf = WrenchEKF(WrenchEKFConfig(), model)
    trace = noisy.run(ekf, 0.8, step_wrench(W, 0.1))
    force_rmse, torque_rmse = errors(trace, 0.3)
    assert force_rmse <= 0.3 and torque_rmse <= 0.03, (force_rmse, torque_rmse)
    mean = trace.estimate[trace.time >= 0.3].mean(axis=0)
    np.testing.assert_allclose(mean, W, atol=0.05)
    # The base-frame estimate is the same wrench rotated by the tool orientation.
    q, _ = noisy.state()
    rot = model.kinematics(q).rotation
    np.testing.assert_allclose(ekf.wrench_base, np.concatenate([rot @ W[:3], rot @ W[3:]]),
                               atol=0.6)


def test_free_motion_estimate_is_near_zero(exact: PandaTorqueHarness, noisy: PandaTorqueHarness,
                                           model: ArmModel) -> None:
    motion = sine_reference(Q_READY, np.array([0.3, -0.2, 0.3, 0.3, 0.4, 0.3, 0.4]), 2.0)
    no_wrench = lambda t: np.zeros(6)  # noqa: E731
    exact.reset(Q_READY)
    trace = exact.run(WrenchEKF(WrenchEKFConfig(), model), 1.0, no_wrench, motion)
    assert np.abs(trace.estimate).max() < 1e-3
    noisy.reset(Q_READY)
    trace = noisy.run(WrenchEKF(WrenchEKFConfig(), model), 1.0, no_wrench, motion)
    force_rmse, torque_rmse = errors(trace, 0.0)
    assert force_rmse <= 0.3 and torque_rmse <= 0.03, (force_rmse, torque_rmse)


def test_settles_within_50_ms_of_contact_onset(exact: PandaTorqueHarness,
                                               model: ArmModel) -> None:
    """Measured: 28 ms to stay within 0.3 N / 0.03 Nm of a 16 N, 0.6 Nm step."""
    exact.reset(Q_READY)
    trace = exact.run(WrenchEKF(WrenchEKFConfig(), model), 0.3, step_wrench(W, 0.1))
    settle = settling_time(trace, 0.1, (0.3, 0.03))
    assert 0.01 < settle < 0.05, settle


def test_recovers_from_an_impact(exact: PandaTorqueHarness, model: ArmModel) -> None:
    """A 60 N, 5 ms pulse is mostly missed (the filter averages over ~30 ms), then forgotten."""
    exact.reset(Q_READY)
    pulse = np.array([0.0, 0.0, 60.0, 0.0, 0.0, 0.0])
    trace = exact.run(WrenchEKF(WrenchEKFConfig(), model), 0.3, step_wrench(pulse, 0.1, 0.105))
    assert trace.estimate[:, 2].max() < 30.0
    assert settling_time(trace, 0.105, (0.3, 0.03)) < 0.08


def test_matches_a_real_table_contact_on_average(exact: PandaTorqueHarness,
                                                 model: ArmModel) -> None:
    """Fingertips pressed onto a pybullet table: the truth is the contact-point wrench.

    The contact chatters at ~145 Hz (+-0.4 N), so the comparison is on the mean over 0.5 s.
    """
    exact.reset(Q_READY)
    exact.add_surface(gap=0.02)
    try:
        trace = exact.run(WrenchEKF(WrenchEKFConfig(), model), 1.2, lambda t: np.zeros(6),
                          descend_reference(model, Q_READY, 0.025, 0.4))
    finally:
        exact.remove_surface()
    late = trace.time >= 0.7
    assert np.linalg.norm(trace.truth[late, :3].mean(axis=0)) > 20.0
    bias = (trace.estimate - trace.truth)[late].mean(axis=0)
    assert np.linalg.norm(bias[:3]) < 0.05 and np.linalg.norm(bias[3:]) < 0.005, bias


def test_lowpass_delays_but_keeps_the_level(exact: PandaTorqueHarness, model: ArmModel) -> None:
    runs = []
    for cutoff in (0.0, 5.0):
        exact.reset(Q_READY)
        ekf = WrenchEKF(WrenchEKFConfig(lowpass_cutoff_hz=cutoff), model)
        runs.append(exact.run(ekf, 0.6, step_wrench(W, 0.05)))
    raw, smooth = runs
    at = np.searchsorted(raw.time, 0.1)
    assert abs(smooth.estimate[at, 2]) < 0.8 * abs(raw.estimate[at, 2])
    np.testing.assert_allclose(smooth.estimate[-1], W, atol=0.01)


# --- state handling -----------------------------------------------------------------------------
def test_reset_clears_the_estimate(exact: PandaTorqueHarness, model: ArmModel) -> None:
    ekf = WrenchEKF(WrenchEKFConfig(), model)
    exact.reset(Q_READY)
    exact.run(ekf, 0.2, step_wrench(W, 0.0))
    assert np.linalg.norm(ekf.wrench_base[:3]) > 10.0
    p0 = WrenchEKF(WrenchEKFConfig(), model).covariance
    ekf.reset(Q_READY)
    np.testing.assert_array_equal(ekf.wrench_base, np.zeros(6))
    np.testing.assert_array_equal(ekf.covariance, p0)
    exact.reset(Q_READY)
    trace = exact.run(ekf, 0.05, step_wrench(np.zeros(6), 0.0))
    assert np.abs(trace.estimate).max() < 1e-3


@pytest.mark.parametrize("field", ["q", "dq", "tau_cmd"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_input_is_rejected(model: ArmModel, field: str, bad: float) -> None:
    ekf = WrenchEKF(WrenchEKFConfig(), model)
    ekf.reset(Q_READY)
    args = {"q": Q_READY.copy(), "dq": np.zeros(7), "tau_cmd": model.gravity(Q_READY)}
    args[field][3] = bad
    with pytest.raises(ValueError, match=field):
        ekf.update(args["q"], args["dq"], args["tau_cmd"], 1e-3)
    np.testing.assert_array_equal(ekf.wrench_base, np.zeros(6))   # state untouched


@pytest.mark.parametrize("dt", [0.0, -1e-3, np.nan])
def test_bad_time_step_is_rejected(model: ArmModel, dt: float) -> None:
    ekf = WrenchEKF(WrenchEKFConfig(), model)
    ekf.reset(Q_READY)
    with pytest.raises(ValueError, match="dt"):
        ekf.update(Q_READY, np.zeros(7), model.gravity(Q_READY), dt)


def test_wrong_shape_is_rejected(model: ArmModel) -> None:
    ekf = WrenchEKF(WrenchEKFConfig(), model)
    with pytest.raises(ValueError, match=r"shape \(7,\)"):
        ekf.reset(np.zeros(6))


@pytest.mark.filterwarnings("ignore:overflow encountered")
def test_large_finite_input_is_accepted(model: ArmModel) -> None:
    """The combined finiteness test (u.u) overflows here; the per-input checks must then pass."""
    ekf = WrenchEKF(WrenchEKFConfig(), model)
    ekf.reset(Q_READY)
    tau = model.gravity(Q_READY)
    tau[0] = 1e200
    ekf.update(Q_READY, np.zeros(7), tau, 1e-3)     # no ValueError


def test_matches_step_by_step_reference(model: ArmModel) -> None:
    """Same estimate as the textbook form of the filter: dense F P F^T and explicit Euler step."""
    import pinocchio as pin
    from scipy.linalg import lapack

    cfg = WrenchEKFConfig()
    ekf = WrenchEKF(cfg, model)
    rng = np.random.default_rng(0)
    n, dt = 7, 1e-3
    x = np.concatenate([Q_READY, np.zeros(13)])
    p = ekf.covariance
    data = model.model.createData()
    ekf.reset(Q_READY)
    q_rate = np.diag(np.r_[np.full(n, cfg.process_noise_q ** 2),
                           np.full(n, cfg.process_noise_dq ** 2),
                           np.full(3, cfg.process_noise_force ** 2),
                           np.full(3, cfg.process_noise_torque ** 2)])
    r = np.diag(np.r_[np.full(n, cfg.measurement_noise_q ** 2),
                      np.full(n, cfg.measurement_noise_dq ** 2)])
    for _ in range(200):
        q_meas = Q_READY + 1e-3 * rng.standard_normal(n)
        dq_meas = 1e-2 * rng.standard_normal(n)
        tau = model.gravity(q_meas) + rng.standard_normal(n)
        est = ekf.update(q_meas, dq_meas, tau, dt)
        # reference
        q, dq, w = x[:n], x[n:14], x[14:]
        m_inv = pin.computeMinverse(model.model, data, q)
        m_inv = np.triu(m_inv) + np.triu(m_inv, 1).T
        nle = pin.nonLinearEffects(model.model, data, q, dq)
        jac = pin.computeFrameJacobian(model.model, data, q, model.tool_frame,
                                       pin.LOCAL_WORLD_ALIGNED)
        a = m_inv @ jac.T
        dq_next = dq + dt * (m_inv @ (tau - nle) + a @ w)
        x = np.concatenate([q + dt * dq_next, dq_next, w])
        f = np.eye(20)
        f[:n, n:14] = dt * np.eye(n)
        f[n:14, 14:] = dt * a
        f[:n, 14:] = dt * dt * a
        p = f @ p @ f.T + dt * q_rate
        _, k_t, info = lapack.dposv(p[:14, :14] + r, p[:14])
        assert info == 0
        x = x + k_t.T @ (np.r_[q_meas, dq_meas] - x[:14])
        p = p - k_t.T @ p[:14]
        p = 0.5 * (p + p.T)
        pin.forwardKinematics(model.model, data, x[:n])
        rot = pin.updateFramePlacement(model.model, data, model.tool_frame).rotation
        ref = np.r_[rot.T @ x[14:17], rot.T @ x[17:]]
        np.testing.assert_allclose(est, ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ekf.covariance, p, rtol=1e-9, atol=1e-15)
