"""A minimal pybullet Panda under torque control, with known wrenches on the tool, for the EKF.

The wrench estimator is only as good as it is against a ground truth, and the full shaft/bearing
scene mixes real contacts (whose wrench is itself computed from contact points) into the picture.
Here the "contact" is mostly a wrench we apply ourselves with ``applyExternalForce`` and
``applyExternalTorque`` at the tool link, so the truth is exact; a fixed table adds one real
contact for comparison. The arm follows a joint reference under a Pinocchio computed-torque PD,
stepped at 1 kHz like the real control loop.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as p
from qg_common.panda_description import Q_READY, panda_urdf_path
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.wrench_ekf import WrenchEKF

N_JOINTS = 7

DT = 1e-3
#: Computed-torque PD: ~3 Hz joint bandwidth, critically damped, whatever the inertia.
KP = 400.0    # [1/s^2]
KD = 40.0     # [1/s]
TOOL_LINK = "panda_hand_tcp"

#: A wrench profile: time since start [s] -> wrench on the tool in tool-frame axes (6,) [N, Nm].
WrenchProfile = Callable[[float], np.ndarray]
#: A joint reference: time [s] -> (q_ref, dq_ref).
JointReference = Callable[[float], tuple[np.ndarray, np.ndarray]]


@dataclass
class Trace:
    """Per-step record of a run: true and estimated tool-frame wrenches, update times."""
    time: np.ndarray          # (T,) [s]
    truth: np.ndarray         # (T, 6)
    estimate: np.ndarray      # (T, 6)
    update_seconds: np.ndarray  # (T,) wall time of each estimator update [s]


class PandaTorqueHarness:
    """pybullet DIRECT Panda, fixed base, velocity motors off, torque control at 1 kHz.

    :param model: the Pinocchio model used for gravity compensation and ground-truth frames.
    :param measurement_noise: std of white noise added to (q, dq) fed to the estimator
        [rad, rad/s]; zero gives the simulator's exact state.
    :param seed: seed of the measurement noise.
    """

    def __init__(self, model: ArmModel, measurement_noise: tuple[float, float] = (0.0, 0.0),
                 seed: int = 0) -> None:
        self.model = model
        self.client = p.connect(p.DIRECT)
        p.setGravity(0.0, 0.0, -9.81, physicsClientId=self.client)
        p.setTimeStep(DT, physicsClientId=self.client)
        self.robot = p.loadURDF(str(panda_urdf_path()), useFixedBase=True,
                                flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=self.client)
        names = {p.getJointInfo(self.robot, j, physicsClientId=self.client)[12].decode(): j
                 for j in range(p.getNumJoints(self.robot, physicsClientId=self.client))}
        self.arm = [names[f"panda_link{i}"] for i in range(1, 8)]
        self.fingers = [names["panda_leftfinger"], names["panda_rightfinger"]]
        self.tool = names[TOOL_LINK]
        for j in range(-1, len(names)):
            p.changeDynamics(self.robot, j, linearDamping=0.0, angularDamping=0.0,
                             jointDamping=0.0, physicsClientId=self.client)
        p.setJointMotorControlArray(self.robot, self.arm, p.VELOCITY_CONTROL,
                                    forces=[0.0] * N_JOINTS, physicsClientId=self.client)
        p.setJointMotorControlArray(self.robot, self.fingers, p.POSITION_CONTROL,
                                    targetPositions=[0.0, 0.0], forces=[100.0, 100.0],
                                    physicsClientId=self.client)
        self.surface: int | None = None
        self._noise = np.asarray(measurement_noise, float)
        self._rng = np.random.default_rng(seed)
        self.reset(Q_READY)

    def reset(self, q: np.ndarray) -> None:
        """Put the arm at rest at ``q``."""
        for j, qj in zip(self.arm, q):
            p.resetJointState(self.robot, j, float(qj), 0.0, physicsClientId=self.client)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact joint positions and velocities."""
        states = p.getJointStates(self.robot, self.arm, physicsClientId=self.client)
        return np.array([s[0] for s in states]), np.array([s[1] for s in states])

    def measured_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint state with the configured measurement noise."""
        q, dq = self.state()
        return (q + self._noise[0] * self._rng.standard_normal(N_JOINTS),
                dq + self._noise[1] * self._rng.standard_normal(N_JOINTS))

    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Tool link frame (position, rotation) in the world, from pybullet."""
        ls = p.getLinkState(self.robot, self.tool, computeForwardKinematics=True,
                            physicsClientId=self.client)
        rot = np.array(p.getMatrixFromQuaternion(ls[5])).reshape(3, 3)
        return np.array(ls[4]), rot

    def add_surface(self, gap: float, friction: float = 0.5) -> None:
        """A fixed table whose top is ``gap`` [m] below the tool origin (at the current pose)."""
        pos, _ = self.tool_pose()
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.2, 0.2, 0.05],
                                       physicsClientId=self.client)
        self.surface = p.createMultiBody(0.0, shape, basePosition=[pos[0], pos[1],
                                                                   pos[2] - gap - 0.05],
                                         physicsClientId=self.client)
        p.changeDynamics(self.surface, -1, lateralFriction=friction, physicsClientId=self.client)

    def remove_surface(self) -> None:
        """Take the table away again."""
        if self.surface is not None:
            p.removeBody(self.surface, physicsClientId=self.client)
            self.surface = None

    def contact_wrench(self) -> np.ndarray:
        """Wrench the surface exerted on the arm over the last step, tool origin and axes.

        With the arm as body A, normal and friction forces on it are ``+f n + f1 d1 + f2 d2``;
        checked against the static balance ``pinv(J^T) (g - tau)`` at rest in contact, which
        this sign matches within 0.03 N on 8 N of friction (the opposite sign is off by 16 N).
        """
        if self.surface is None:
            return np.zeros(6)
        pos, rot = self.tool_pose()
        force, torque = np.zeros(3), np.zeros(3)
        for cp in p.getContactPoints(self.robot, self.surface, physicsClientId=self.client):
            f = cp[9] * np.asarray(cp[7]) + cp[10] * np.asarray(cp[11]) + \
                cp[12] * np.asarray(cp[13])
            force += f
            torque += np.cross(np.asarray(cp[5]) - pos, f)
        return np.concatenate([rot.T @ force, rot.T @ torque])

    def step(self, tau: np.ndarray, wrench_tool: np.ndarray) -> None:
        """Apply ``tau`` and the tool-frame wrench (about the tool origin) for one step."""
        pos, rot = self.tool_pose()
        force, torque = rot @ wrench_tool[:3], rot @ wrench_tool[3:]
        # WORLD_FRAME for both: the force acts at the tool origin given in world coordinates.
        p.applyExternalForce(self.robot, self.tool, force.tolist(), pos.tolist(), p.WORLD_FRAME,
                             physicsClientId=self.client)
        p.applyExternalTorque(self.robot, self.tool, torque.tolist(), p.WORLD_FRAME,
                              physicsClientId=self.client)
        p.setJointMotorControlArray(self.robot, self.arm, p.TORQUE_CONTROL,
                                    forces=np.asarray(tau, float).tolist(),
                                    physicsClientId=self.client)
        p.stepSimulation(physicsClientId=self.client)

    def control(self, q_ref: np.ndarray, dq_ref: np.ndarray) -> np.ndarray:
        """Computed-torque joint PD (from the exact state).

        Scaling the PD by ``M`` keeps it stable at 1 kHz where a plain joint PD is not: with
        joint 2 near 0, joints 1 and 3 are nearly collinear and their difference mode has tiny
        inertia.
        """
        q, dq = self.state()
        acc = KP * (q_ref - q) + KD * (dq_ref - dq)
        return self.model.nonlinear_effects(q, dq) + self.model.mass_matrix(q) @ acc

    def run(self, estimator: WrenchEKF, duration: float, wrench: WrenchProfile,
            reference: JointReference | None = None) -> Trace:
        """Run the closed loop for ``duration`` seconds and record truth and estimate.

        The estimator sees the measured state after each step and the torques of that step; the
        truth is the applied wrench plus the surface contact of that step.
        """
        q0, _ = self.state()
        reference = reference or (lambda t: (q0, np.zeros(N_JOINTS)))
        estimator.reset(self.measured_state()[0])
        steps = int(round(duration / DT))
        times, truth, est, cost = (np.zeros(steps), np.zeros((steps, 6)), np.zeros((steps, 6)),
                                   np.zeros(steps))
        for k in range(steps):
            t = k * DT
            tau = self.control(*reference(t))
            truth[k] = wrench(t)
            self.step(tau, truth[k])
            truth[k] += self.contact_wrench()
            q, dq = self.measured_state()
            start = time.perf_counter()
            est[k] = estimator.update(q, dq, tau, DT)
            cost[k] = time.perf_counter() - start
            times[k] = t + DT
        return Trace(times, truth, est, cost)

    def close(self) -> None:
        """Disconnect from pybullet."""
        p.disconnect(self.client)


def step_wrench(value: np.ndarray, onset: float, end: float = np.inf) -> WrenchProfile:
    """A constant wrench switched on at ``onset`` and off at ``end`` [s]."""
    value = np.asarray(value, float)
    return lambda t: value.copy() if onset <= t < end else np.zeros(6)


def sine_reference(q0: np.ndarray, amplitude: np.ndarray, period: float) -> JointReference:
    """A smooth joint-space oscillation starting at rest at ``q0`` [rad, s]."""
    w = 2.0 * np.pi / period

    def ref(t: float) -> tuple[np.ndarray, np.ndarray]:
        return q0 + amplitude * (1.0 - np.cos(w * t)), amplitude * w * np.sin(w * t)
    return ref


def descend_reference(model: ArmModel, q0: np.ndarray, depth: float, duration: float
                      ) -> JointReference:
    """Move the tool straight down by ``depth`` [m] at constant speed over ``duration`` [s].

    Linearised inverse kinematics at ``q0``; good enough for a few cm.
    """
    direction = np.linalg.pinv(model.kinematics(q0).jacobian) @ np.array([0, 0, -depth, 0, 0, 0])

    def ref(t: float) -> tuple[np.ndarray, np.ndarray]:
        s = min(t / duration, 1.0)
        return q0 + s * direction, direction / duration if t < duration else np.zeros(N_JOINTS)
    return ref


def rmse(error: np.ndarray) -> float:
    """Root mean square of the vector norm of ``error`` (T, 3)."""
    return float(np.sqrt(np.mean(np.sum(error ** 2, axis=1))))


def settling_time(trace: Trace, onset: float, tolerance: tuple[float, float],
                  window: int = 1) -> float:
    """Time after ``onset`` from which force and torque errors stay within ``tolerance``.

    :param window: average the error over this many steps first (for chattering contacts).
    """
    err = trace.estimate - trace.truth
    if window > 1:
        kernel = np.ones(window) / window
        err = np.stack([np.convolve(e, kernel, mode="same") for e in err.T], axis=1)
    bad = (np.linalg.norm(err[:, :3], axis=1) > tolerance[0]) | \
          (np.linalg.norm(err[:, 3:], axis=1) > tolerance[1])
    after = trace.time > onset
    last_bad = np.flatnonzero(bad & after)
    return 0.0 if last_bad.size == 0 else float(trace.time[last_bad[-1]] + DT - onset)
