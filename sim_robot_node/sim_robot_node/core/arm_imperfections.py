"""What separates a real arm from the model the bridge controls it with (the Panda's figures as
defaults; any arm: the per-joint ones have one entry a joint of the arm).

The simulated arm is otherwise ideal: the bridge's Pinocchio model is the very URDF pybullet
loads, the joint state is exact and the measured torque is the command. At rest the EKF then
reads back exactly the commanded wrench (``docs/learning.md``, section 1), so the thesis's 4-D
wrench state cannot show where the shaft is. A real arm differs in ways its driver cannot tell
the bridge about; each is one parameter here, in the units a datasheet or an identification
paper gives, with 0 switching it off:

- **payload error**: mass the gravity model does not know (adapter, cables, a misentered load)
  and its centre of mass;
- **joint friction**: what the Panda's own friction compensation leaves. libfranka's torque
  commands are "joint-level torques without gravity and friction": the robot compensates its
  joint friction itself, by a model, and the error of that model reaches the links. We take a
  share of the smooth Coulomb friction Gaz et al. (2019) identified on the Panda, plus a small
  viscous part. It acts between the torque the drive realises (and the sensor reads) and the
  link, so the driver's measured torque does not contain it;
- **joint-torque and encoder noise and bias**: what the driver's ``tau_J``, ``q`` and ``dq`` carry;
- **start-pose jitter**: a taught start is reached within the arm's repeatability, not exactly;
- **housing pose error**: the fixture holds the bore a little off the axis the cell was
  configured with; the executor's ``task.push_axis`` is the configured one.

Constants (biases, the housing's error) are drawn once per ``seed``: one seed is one robot in one
cell. Noise is drawn once per physics step, jitter once per reset, from a second stream of the
same seed, so a run is a pure function of the seed and the sequence of resets and steps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from qg_common.params import config_from_dict
from qg_common.types import JointState
from robot_bridge_node.core.native import ArmErrors

__all__ = ["GAZ_2019_COULOMB", "GAZ_2019_VELOCITY", "RESIDUAL_FRICTION_SHARE", "RESIDUAL_COULOMB",
           "ArmImperfections", "ImperfectArm"]

#: The Panda's joint count: the length of the per-joint defaults.
N_ARM_JOINTS = 7
#: Steps of sensor noise drawn from the noise stream at a time (``ImperfectArm._next_normals``).
NORMALS_DRAWN = 64

#: [Nm] Coulomb level of each joint's friction, Gaz et al. (2019), "Dynamic Identification of the
#: Franka Emika Panda Robot With Retrieval of Feasible Parameters Using Penalty-Based
#: Optimization", IEEE RA-L 4(4): their sigmoid ``phi1 / (1 + exp(-phi2 (dq + phi3)))`` minus its
#: value at rest tends to ``+-phi1 / 2``; ``phi1 = (0.546, 0.872, 0.641, 1.279, 0.839, 0.303,
#: 0.565) Nm``.
GAZ_2019_COULOMB = (0.27308, 0.43612, 0.32034, 0.63970, 0.41952, 0.15151, 0.28245)
#: The share of that friction the robot's own compensation leaves (the default): 20 %. Franka
#: publishes no figure; Universal Robots' direct torque control compensates 70-80 % of the
#: Coulomb and 80-90 % of the viscous friction at its defaults (ur_msgs
#: FrictionModelParameters: coulomb_scale 0.7-0.8, viscous_scale 0.8-0.9).
RESIDUAL_FRICTION_SHARE = 0.2
#: [Nm] the default: :data:`RESIDUAL_FRICTION_SHARE` of :data:`GAZ_2019_COULOMB`.
RESIDUAL_COULOMB = tuple(round(RESIDUAL_FRICTION_SHARE * c, 5) for c in GAZ_2019_COULOMB)
#: [rad/s] velocity scale of the same sigmoid written as ``coulomb * tanh(dq / v)``:
#: ``v = 2 / phi2`` with ``phi2 = (5.12, 9.07, 10.14, 5.59, 8.35, 17.13, 10.34) s/rad``.
GAZ_2019_VELOCITY = (0.39077, 0.22061, 0.19732, 0.35776, 0.23961, 0.11673, 0.19350)


@dataclass(frozen=True)
class ArmImperfections:
    """The real arm's departures from the model, each 0 for the ideal arm.

    :param payload_mass_error: [kg] mass on the hand that the bridge's model does not carry.
        Default 0.1 kg: an adapter and cables, about 14 % of the Franka Hand's 0.73 kg, within
        the error of a load entered by hand (Franka's Desk asks for the end effector's mass and
        centre of mass; libfranka ``setLoad``).
    :param payload_com_error: (3,) [m] that mass's centre in the tool frame (z along the shaft).
        Default 2 cm beside the flange and 3 cm towards it.
    :param joint_coulomb_friction: (n,) [Nm] Coulomb level per joint that reaches the links:
        20 % of Gaz et al.'s identified friction (:data:`RESIDUAL_COULOMB`) on the Panda.
    :param joint_friction_velocity: (n,) [rad/s] velocity at which the Coulomb part reaches 76 %
        of its level (``tanh(1)``); Gaz et al.'s sigmoid slope. Must be > 0 where friction is on.
    :param joint_viscous_friction: (n,) [Nms/rad] viscous friction per joint that reaches the
        links. Gaz et al. fitted none beyond the sigmoid, whose slope at rest (0.7-2.0 Nms/rad)
        acts viscous at the task's speeds; default 0.02 Nms/rad, a residual of the same order.
    :param torque_noise: [Nm] std of the joint-torque sensor's noise per sample. Default 0.02 Nm,
        the Panda datasheet's torque resolution (< 0.02 Nm).
    :param torque_bias: [Nm] std of each joint-torque sensor's offset (drawn once per seed).
        Default 0.15 Nm, the datasheet's relative torque accuracy.
    :param encoder_noise: [rad] std of the joint position's noise per sample. Default 1e-5 rad.
    :param encoder_bias: [rad] std of each joint's calibration offset (drawn once per seed).
        Default 1e-4 rad: about the datasheet's pose repeatability (+-0.1 mm) over the 0.85 m reach.
    :param velocity_noise: [rad/s] std of the joint velocity's noise per sample. Default 1e-3
        rad/s, the noise the wrench estimator assumes (``wrench_estimator.yaml``).
    :param start_tilt_jitter: [rad] std of each component of the start tilt vector, drawn per
        reset. Default 0.5 deg: a taught start reached again by an impedance controller.
    :param start_position_jitter: [m] std of the shaft tip's lateral start position per reset.
        Default 0.05 mm, half the datasheet's pose repeatability.
    :param housing_tilt_error: [rad] std of each component of the bore axis' tilt from the
        configured axis (drawn once per seed). Default 0.5 deg, ISO 2768-1 class m angular
        tolerance for 10-50 mm features (+-0.5 deg).
    :param housing_position_error: [m] std of the bore centre's lateral offset from the
        configured position (drawn once per seed). Default 0.05 mm.
    :param seed: which robot and cell: the constants above and the noise streams.
    """

    payload_mass_error: float = 0.1
    payload_com_error: tuple[float, ...] = (0.02, 0.0, -0.03)
    joint_coulomb_friction: tuple[float, ...] = RESIDUAL_COULOMB
    joint_friction_velocity: tuple[float, ...] = GAZ_2019_VELOCITY
    joint_viscous_friction: tuple[float, ...] = (0.02,) * N_ARM_JOINTS
    torque_noise: float = 0.02
    torque_bias: float = 0.15
    encoder_noise: float = 1e-5
    encoder_bias: float = 1e-4
    velocity_noise: float = 1e-3
    start_tilt_jitter: float = math.radians(0.5)
    start_position_jitter: float = 5e-5
    housing_tilt_error: float = math.radians(0.5)
    housing_position_error: float = 5e-5
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "seed":
                if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                    raise ValueError(f"seed must be an integer >= 0, got {value!r}")
                continue
            values = value if isinstance(value, tuple) else (value,)
            signed = f.name == "payload_com_error"     # a position, any sign
            if any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                   or (v < 0.0 and not signed) for v in values):
                raise ValueError(f"{f.name} must be finite{'' if signed else ' and >= 0'}, "
                                 f"got {value!r}")
        if len(self.payload_com_error) != 3:
            raise ValueError(f"payload_com_error needs 3 entries, got {self.payload_com_error}")
        n = self.n_joints
        for name in ("joint_friction_velocity", "joint_viscous_friction"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} needs {n} entries (one a joint, as "
                                 f"joint_coulomb_friction), got {getattr(self, name)}")
        if any(c > 0.0 and v <= 0.0 for c, v in zip(self.joint_coulomb_friction,
                                                    self.joint_friction_velocity)):
            raise ValueError("joint_friction_velocity must be > 0 on every joint with friction")

    @property
    def n_joints(self) -> int:
        """The joint count the per-joint figures are for."""
        return len(self.joint_coulomb_friction)

    @classmethod
    def ideal(cls, seed: int = 0, n_joints: int = N_ARM_JOINTS) -> ArmImperfections:
        """The arm of ``n_joints`` joints exactly as the bridge models it (every imperfection 0)."""
        zeros = (0.0,) * n_joints
        return cls(payload_mass_error=0.0, payload_com_error=(0.0, 0.0, 0.0),
                   joint_coulomb_friction=zeros, joint_friction_velocity=zeros,
                   joint_viscous_friction=zeros, torque_noise=0.0, torque_bias=0.0,
                   encoder_noise=0.0, encoder_bias=0.0, velocity_noise=0.0,
                   start_tilt_jitter=0.0, start_position_jitter=0.0, housing_tilt_error=0.0,
                   housing_position_error=0.0, seed=seed)

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ArmImperfections:
        """From the ``panda_scene.imperfections`` section (unknown keys are an error)."""
        return config_from_dict(cls, params)

    @property
    def has_friction(self) -> bool:
        return any(self.joint_coulomb_friction) or any(self.joint_viscous_friction)

    @property
    def has_sensor_errors(self) -> bool:
        return any((self.torque_noise, self.torque_bias, self.encoder_noise, self.encoder_bias,
                    self.velocity_noise))


class ImperfectArm:
    """The drawn constants and the noise streams of one :class:`ArmImperfections`.

    ``friction`` is applied by the scene between the command and the links; ``measure`` turns
    the true joint state and the command into what the driver reads, once per physics step;
    ``start_jitter`` perturbs each start; ``housing_rotation_error`` and
    ``housing_position_error`` are the fixture's constant misplacement (housing frame).

    :param n_joints: the arm's joint count (its model's), which the per-joint figures must
        match; ``None``: theirs.
    :raises ValueError: if they do not.
    """

    def __init__(self, config: ArmImperfections, n_joints: int | None = None) -> None:
        n_joints = config.n_joints if n_joints is None else n_joints
        if config.n_joints != n_joints:
            raise ValueError(f"the imperfections' per-joint figures have {config.n_joints} "
                             f"entries, the arm has {n_joints} joints")
        self.config = config
        self.n_joints = n = n_joints
        constants = np.random.default_rng([config.seed, 0])
        self.torque_bias = constants.normal(0.0, 1.0, n) * config.torque_bias
        self.encoder_bias = constants.normal(0.0, 1.0, n) * config.encoder_bias
        tilt = constants.normal(0.0, 1.0, 2) * config.housing_tilt_error
        offset = constants.normal(0.0, 1.0, 2) * config.housing_position_error
        #: (3,) rotation vector of the true bore axis against the configured one (housing frame)
        self.housing_rotation_error = np.array([tilt[0], tilt[1], 0.0])
        #: (3,) the true bore centre against the configured one (housing frame) [m]
        self.housing_position_error = np.array([offset[0], offset[1], 0.0])
        self._noise = np.random.default_rng([config.seed, 1])
        self._coulomb = np.array(config.joint_coulomb_friction, float)
        self._velocity = np.where(self._coulomb > 0.0,
                                  np.array(config.joint_friction_velocity, float), 1.0)
        self._viscous = np.array(config.joint_viscous_friction, float)
        self._sensor_noise = np.repeat([config.encoder_noise, config.velocity_noise,
                                        config.torque_noise], n)
        # (3n,) the biases of [q, dq, tau]; dq's is -0.0, the sum's identity (x + -0.0 == x,
        # -0.0 included), so one addition biases all three as ``measure`` always did.
        self._bias = np.concatenate([self.encoder_bias, np.full(n, -0.0), self.torque_bias])
        # The noise stream's next normals, drawn NORMALS_DRAWN steps' worth at a time (a draw
        # of 3n costs ~1 us, mostly the call): ``_next_normals`` hands them out in order.
        self._normals_drawn = np.empty(NORMALS_DRAWN * 3 * n)
        self._normals_used = self._normals_drawn.size
        self._scaled, self._smooth = np.empty(n), np.empty(n)   # ``apply_friction``'s buffers
        # The exactly rounded arithmetic of both, compiled, with the constants and the buffers
        # NumPy writes (``tanh``, the normals) held from here on.
        self._arithmetic = ArmErrors(self._coulomb, self._viscous, self._smooth,
                                     self._sensor_noise, self._bias, self._normals_drawn)

    def friction(self, dq: np.ndarray) -> np.ndarray:
        """(n,) [Nm] the joints' friction torque at true velocities ``dq`` (opposes motion)."""
        return self._coulomb * np.tanh(dq / self._velocity) + self._viscous * dq

    def apply_friction(self, tau: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """(n,) [Nm] ``tau - friction(dq)``, to the bit (NumPy's tanh into preallocated buffers,
        the rest compiled: ``native.ArmErrors``): what reaches the links of a command ``tau`` at
        true velocities ``dq``, every step."""
        np.divide(dq, self._velocity, self._scaled)       # (outputs passed by position:
        np.tanh(self._scaled, self._smooth)               # faster; NumPy's tanh, its rounding)
        return self._arithmetic.friction_applied(tau, dq)

    def measure(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray) -> JointState:
        """The driver's reading of the true ``q``, ``dq`` and the realised torque ``tau``:
        ``q`` plus its bias and noise, ``dq`` plus its noise, ``tau`` plus its bias and noise
        (one standard normal draw of 3n, in that order, per call)."""
        n = self.n_joints
        reading = self._arithmetic.reading(q, dq, tau, self._next_normals(3 * n))
        return JointState(q=reading[:n], dq=reading[n:2 * n], tau=reading[2 * n:])

    def start_jitter(self) -> tuple[np.ndarray, np.ndarray]:
        """One reset's ``(tilt vector change [rad] (2,), tip offset [m] (2,))``, housing frame."""
        first = self._next_normals(4)
        draw = self._normals_drawn[first:first + 4]
        return (draw[:2] * self.config.start_tilt_jitter,
                draw[2:] * self.config.start_position_jitter)

    def _next_normals(self, k: int) -> int:
        """Where the noise stream's next ``k`` standard normals start in ``_normals_drawn`` (valid
        until the next call). The numbers and their order are those of ``normal(0, 1, k)`` drawn
        each time (``standard_normal`` fills an array one normal after the other, as ``normal``
        draws them, and ``0 + 1 z`` is ``z``); only the generator runs ahead of what was used."""
        drawn, used = self._normals_drawn, self._normals_used
        if used + k > drawn.size:
            left = drawn.size - used
            drawn[:left] = drawn[used:]
            self._noise.standard_normal(out=drawn[left:])
            used = 0
        self._normals_used = used + k
        return used
