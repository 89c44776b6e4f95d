"""The 1 kHz tick's faster formulas against the ones they replaced, on recorded ticks: equal to
the bit.

A loop on the default simulated Panda (MuJoCo, the realistic arm, the wrench EKF) runs a few
random-residual RL steps while every input of the rewritten parts is recorded; each recorded
input then goes through the replaced formula (written out here as it was) and through the code
the tick runs now. Equal means ``array_equal`` and equal sign bits, so a -0.0 for a 0.0 fails.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from arms import start
from qg_common.params import config_file, load_ros_params
from qg_common.rotations import tilt_from_down
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.arm_model import JointLimits
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from robot_bridge_node.core.safety import VELOCITY_BRAKE_DAMPING, SafetyFilter
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig
from sim_robot_node.core.arm_imperfections import NORMALS_DRAWN, ArmImperfections, ImperfectArm

#: RL steps recorded (each ends at rest or at its time limit; tick count printed on failure).
STEPS = 3
#: [s] each step's time limit: ~800 ticks a step.
MAX_TIME = 0.8
#: of the residuals' random stream
SEED = 4


@dataclass
class Recording:
    """Every input of the rewritten parts, tick by tick, in the order the loop made them."""
    torques: list[tuple] = field(default_factory=list)      # limit_torques(tau, dt, dq), reset
    tilts: list[tuple] = field(default_factory=list)        # limit_tilt(wrench, rotation)
    arm: list[tuple] = field(default_factory=list)          # the simulated arm's errors' calls
    tools: list = field(default_factory=list)               # the controller's tool states
    ticks: int = 0
    joints: JointLimits | None = None                       # the safety filter's
    imperfections: ArmImperfections | None = None           # the simulated arm's


def _record(loop: RobotLoop) -> Recording:
    """Wraps the loop's parts so that each call's inputs (copies) are recorded."""
    rec, safety = Recording(), loop.safety
    limit_torques, limit_tilt, reset = safety.limit_torques, safety.limit_tilt, safety.reset

    def torques(tau, dt, dq=None):
        rec.torques.append(("limit", np.array(tau), dt, None if dq is None else np.array(dq)))
        return limit_torques(tau, dt, dq)

    def tilt(wrench, rotation):
        rec.tilts.append((np.array(wrench), np.array(rotation)))
        return limit_tilt(wrench, rotation)

    def safety_reset(tau=None):
        rec.torques.append(("reset", None if tau is None else np.array(tau)))
        reset(tau)

    safety.limit_torques, safety.limit_tilt, safety.reset = torques, tilt, safety_reset
    errors = loop.simulation.scene.arm_errors
    apply_friction, measure, start_jitter = (errors.apply_friction, errors.measure,
                                             errors.start_jitter)

    def friction(tau, dq):
        rec.arm.append(("friction", np.array(tau), np.array(dq)))
        return apply_friction(tau, dq)

    def reading(q, dq, tau):
        rec.arm.append(("measure", np.concatenate([q, dq, tau])))
        return measure(q, dq, tau)

    def jitter():
        rec.arm.append(("jitter",))
        return start_jitter()

    errors.apply_friction, errors.measure, errors.start_jitter = friction, reading, jitter
    controller = loop.controller
    control = controller.step

    def step(q, dq, setpoint, dt):
        tau = control(q, dq, setpoint, dt)
        rec.tools.append(controller.tool)
        return tau

    controller.step = step
    return rec


def record(steps: int = STEPS, max_time: float = MAX_TIME, seed: int = SEED) -> Recording:
    """``steps`` random-residual RL steps of the default simulated Panda from a reset."""
    params = load_ros_params(config_file("bridge.yaml"))
    params["rest"] = {**params.get("rest", {}), "max_time": max_time}
    ekf = load_ros_params(config_file("wrench_estimator.yaml"))["ekf"]
    loop = build_loop(load_robot("sim_panda_mujoco"), params,
                      estimator=lambda robot, model: WrenchEKF(WrenchEKFConfig.from_dict(ekf),
                                                               model))
    rec = _record(loop)
    loop.begin()
    loop.reset(start(3))
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        loop.execute(WrenchSetpoint.residual(-15.0, *(3.0 * rng.uniform(-1.0, 1.0, 2))))
    rec.ticks, rec.joints = loop.ticks_run, loop.safety.joints
    rec.imperfections = loop.simulation.scene.config.imperfections
    loop.simulation.close()
    return rec


@pytest.fixture(scope="module")
def recording() -> Recording:
    """A reset, then random residuals: a few hundred ticks, some past the tilt cone's start."""
    return record()


def assert_bits_equal(got: np.ndarray, expected: np.ndarray, what: str) -> None:
    np.testing.assert_array_equal(got, expected, err_msg=what)
    assert np.array_equal(np.signbit(got), np.signbit(expected)), what


# --- the safety filter ---------------------------------------------------------------------
class PythonTorqueLimits:
    """``SafetyFilter.limit_torques`` as it was on Python floats (the formula replaced)."""

    def __init__(self, joints) -> None:
        self._torque = np.asarray(joints.torque, float).tolist()
        self._torque_floor = [-t for t in self._torque]
        self._rate = np.asarray(joints.torque_rate, float).tolist()
        self._velocity = np.asarray(joints.velocity, float).tolist()
        self._last_tau = None

    def reset(self, tau) -> None:
        self._last_tau = None if tau is None else np.asarray(tau, float).tolist()

    def limit_torques(self, tau, dt, dq=None) -> np.ndarray:
        torques = np.asarray(tau, float).tolist()
        if dq is not None:
            torques = self._brake(torques, np.asarray(dq, float).tolist())
        limited = []
        for t, floor, ceiling in zip(torques, self._torque_floor, self._torque):
            t = t if t >= floor or t != t else floor
            limited.append(t if t <= ceiling or t != t else ceiling)
        last = self._last_tau
        if last is not None:
            for i, (t, before, rate) in enumerate(zip(limited, last, self._rate)):
                step = rate * dt
                floor, ceiling = before - step, before + step
                t = t if t >= floor or t != t else floor
                limited[i] = t if t <= ceiling or t != t else ceiling
        self._last_tau = limited
        return np.array(limited)

    def _brake(self, torques, speeds):
        if all(-v <= s <= v for s, v in zip(speeds, self._velocity)):
            return torques
        braked = []
        for t, s, v in zip(torques, speeds, self._velocity):
            within = s if s >= -v or s != s else -v
            within = within if within <= v or within != within else v
            braked.append(t - VELOCITY_BRAKE_DAMPING * (s - within))
        return braked


def python_limit_tilt(limits, wrench: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``SafetyFilter.limit_tilt`` as it was (the angle computed on every call)."""
    angle, back = tilt_from_down(rotation)
    start_angle = limits.tilt_max - limits.tilt_margin
    if angle <= start_angle:
        return wrench
    applied = -(rotation @ wrench[3:])
    outward = float(applied @ back)
    if outward < 0.0:
        applied = applied - outward * back
    applied = applied + limits.tilt_stiffness * (angle - start_angle) * back
    return np.concatenate([wrench[:3], -(rotation.T @ applied)])


def test_the_recording_has_ticks_in_and_out_of_the_tilt_cone(recording: Recording) -> None:
    limits = SafetyFilter().limits
    angles = [tilt_from_down(rotation)[0] for _, rotation in recording.tilts]
    start_angle = limits.tilt_max - limits.tilt_margin
    assert len(recording.tilts) >= 300, recording.ticks
    assert sum(a > start_angle for a in angles) >= 10
    assert sum(a <= start_angle for a in angles) >= 10


def test_torque_limits_are_the_python_formulas_on_recorded_ticks(recording: Recording) -> None:
    """Every command the loop limited (the resets' joint law and the controller's, with the
    rate limit carried over and the resets' torques), through both."""
    joints = recording.joints
    new, old = SafetyFilter(joints=joints), PythonTorqueLimits(joints)
    limited = 0
    for call in recording.torques:
        if call[0] == "reset":
            new.reset(call[1])
            old.reset(call[1])
            continue
        _, tau, dt, dq = call
        assert_bits_equal(new.limit_torques(tau, dt, dq), old.limit_torques(tau, dt, dq),
                          f"command {limited}")
        limited += 1
    assert limited >= 300


def test_torque_limits_are_the_python_formulas_past_every_bound(recording: Recording) -> None:
    """Recorded ticks stay inside the limits: commands past the torque, rate and velocity
    limits, NaN and inf, through both (the recorded arm's limits)."""
    joints = recording.joints
    new, old = SafetyFilter(joints=joints), PythonTorqueLimits(joints)
    rng = np.random.default_rng(5)
    special = [np.nan, np.inf, -np.inf, 0.0, -0.0]
    for i in range(500):
        tau = rng.normal(0.0, 1.2, 7) * joints.torque
        dq = rng.normal(0.0, 0.8, 7) * joints.velocity
        if i % 7 == 0:
            tau[rng.integers(7)] = special[i % 5]
            dq[rng.integers(7)] = special[(i // 7) % 5]
        speeds = None if i % 4 == 0 else dq
        if i % 100 == 0:
            last = None if i % 200 == 0 else rng.normal(0.0, 0.3, 7) * joints.torque
            new.reset(last)
            old.reset(last)
        assert_bits_equal(new.limit_torques(tau, 0.001, speeds),
                          old.limit_torques(tau, 0.001, speeds), f"command {i}")


def test_tilt_limit_is_the_formula_on_recorded_ticks_and_at_the_cone(
        recording: Recording) -> None:
    """The recorded feed-forwards and tool rotations, then rotations within a billionth of a
    radian of the cone's wall on either side (where the quick inside test must defer to the
    angle): the same array back inside, the same numbers outside."""
    safety = SafetyFilter()
    cases = list(recording.tilts)
    wall = safety.limits.tilt_max - safety.limits.tilt_margin
    rng = np.random.default_rng(2)
    for offset in (-1e-9, -1e-12, 0.0, 1e-12, 1e-9):
        for _ in range(20):
            heading = rng.uniform(-math.pi, math.pi)
            tilt = wall + offset
            z = np.array([math.sin(tilt) * math.cos(heading), math.sin(tilt) * math.sin(heading),
                          -math.cos(tilt)])
            x = np.cross([0.0, 1.0, 0.0], z)
            x /= np.linalg.norm(x)
            cases.append((rng.normal(0.0, 3.0, 6), np.column_stack([x, np.cross(z, x), z])))
    for i, (wrench, rotation) in enumerate(cases):
        got = safety.limit_tilt(wrench, rotation)
        expected = python_limit_tilt(safety.limits, wrench, rotation)
        assert (got is wrench) == (expected is wrench), f"case {i}"
        assert_bits_equal(got, expected, f"case {i}")


# --- the loop ------------------------------------------------------------------------------
def test_the_rest_detectors_speeds_are_the_tool_states_on_recorded_ticks(
        recording: Recording) -> None:
    """``ToolState.speeds`` (one read of the twist, every tick) against the two properties
    (the formulas the tick used), on every recorded tool state."""
    assert len(recording.tools) >= 300
    for i, tool in enumerate(recording.tools):
        assert tool.speeds() == (tool.linear_speed, tool.angular_speed), i


# --- the simulated arm's errors ------------------------------------------------------------
class PythonArmErrors:
    """``ImperfectArm``'s friction and sensor errors as they were (the formulas replaced):
    the constants and the noise stream drawn from the seed the same way."""

    def __init__(self, config: ArmImperfections) -> None:
        n = self.n = config.n_joints
        self.config = config
        constants = np.random.default_rng([config.seed, 0])
        self.torque_bias = constants.normal(0.0, 1.0, n) * config.torque_bias
        self.encoder_bias = constants.normal(0.0, 1.0, n) * config.encoder_bias
        self._noise = np.random.default_rng([config.seed, 1])
        self._coulomb = np.array(config.joint_coulomb_friction, float)
        self._velocity = np.where(self._coulomb > 0.0,
                                  np.array(config.joint_friction_velocity, float), 1.0)
        self._viscous = np.array(config.joint_viscous_friction, float)
        self._sensor_noise = np.repeat([config.encoder_noise, config.velocity_noise,
                                        config.torque_noise], n)

    def friction(self, dq):
        return self._coulomb * np.tanh(dq / self._velocity) + self._viscous * dq

    def measure(self, q, dq, tau):
        n = self.n
        noise = self._noise.normal(0.0, 1.0, 3 * n) * self._sensor_noise
        return (q + self.encoder_bias + noise[:n], dq + noise[n:2 * n],
                tau + self.torque_bias + noise[2 * n:])

    def start_jitter(self):
        draw = self._noise.normal(0.0, 1.0, 4)
        return (draw[:2] * self.config.start_tilt_jitter,
                draw[2:] * self.config.start_position_jitter)


def test_arm_errors_are_the_python_formulas_on_recorded_steps(recording: Recording) -> None:
    """Every friction, sensor reading and start jitter of the recorded run, in its order (one
    noise stream for all), through both: the same numbers, the stream in step."""
    config = recording.imperfections
    assert config.has_friction and config.has_sensor_errors
    new, old = ImperfectArm(config), PythonArmErrors(config)
    counts = {"friction": 0, "measure": 0, "jitter": 0}
    for call in recording.arm:
        kind = call[0]
        what = f"{kind} {counts[kind]}"
        counts[kind] += 1
        if kind == "friction":
            _, tau, dq = call
            assert_bits_equal(new.apply_friction(tau, dq), tau - old.friction(dq), what)
        elif kind == "measure":
            q, dq, tau = np.split(call[1], 3)
            for got, expected in zip(vars(new.measure(q, dq, tau)).values(),
                                     old.measure(q, dq, tau)):
                assert_bits_equal(got, expected, what)
        else:
            for got, expected in zip(new.start_jitter(), old.start_jitter()):
                assert_bits_equal(got, expected, what)
    assert counts["friction"] >= 300 and counts["measure"] >= 300 and counts["jitter"] >= 1


def test_a_noiseless_velocity_keeps_the_sign_of_a_zero() -> None:
    """Without velocity noise a -0.0 joint velocity reads -0.0, as ``dq + 0 * noise`` did."""
    config = dataclasses.replace(ArmImperfections(seed=3), velocity_noise=0.0)
    new, old = ImperfectArm(config), PythonArmErrors(config)
    q, tau = np.zeros(7), np.ones(7)
    for _ in range(20):
        dq = np.array([-0.0, 0.0, -0.0, 1e-3, -0.0, -1e-3, -0.0])
        assert_bits_equal(new.measure(q, dq, tau).dq, old.measure(q, dq, tau)[1], "dq")


def test_the_noise_stream_is_in_step_across_its_draws_ahead() -> None:
    """Resets' jitters (4 normals) between steps' readings (3n) at random, over many of the
    stream's batches (``NORMALS_DRAWN`` steps each): the very numbers ``normal`` drew."""
    config = ArmImperfections(seed=8)
    new, old = ImperfectArm(config), PythonArmErrors(config)
    rng = np.random.default_rng(0)
    n = config.n_joints
    for i in range(NORMALS_DRAWN * 5):
        if rng.random() < 0.05:
            for got, expected in zip(new.start_jitter(), old.start_jitter()):
                assert_bits_equal(got, expected, f"jitter at {i}")
        q, dq, tau = np.split(rng.normal(0.0, 1.0, 3 * n), 3)
        for got, expected in zip(vars(new.measure(q, dq, tau)).values(),
                                 old.measure(q, dq, tau)):
            assert_bits_equal(got, expected, f"reading {i}")
