"""A torque-controlled arm pressing a shaft into a tight bearing, at 1 kHz: the shaft task's scene
for any arm described by its URDF (``qg_common.arm_description``).

A rigid-body engine cannot simulate an interference fit, so the fit is modelled by its effect:
the shaft slides with 0.1 mm radial clearance through a bore (a ring of boxes) and then pushes a
heavy "inner ring" plunger whose prismatic joint is resisted by Coulomb friction (a velocity motor
at target 0 with a force limit of ~11 N). The tight clearance makes a tilted shaft wedge, so the
constant base push jams while torques that straighten the shaft let it slide in; the last
millimetres need a sustained push above the friction. Above the bore a counterbore keeps random
torques from levering the shaft out of the hole.

The arm is its package's URDF (the file Pinocchio reads for the bridge's controller), joints
other than the driven ones fixed, with the shaft welded to the flange (``shaft_urdfs``). Only the
shaft collides. Frames: the tool frame is at the grasp point on the shaft axis with the
orientation of the flange (z along the shaft towards its tip, i.e. into the bore). What belongs
to one arm is its ``ArmDescription`` (URDF, joints, flange, ready pose) and its config file's
imperfections: ``panda_scene.py`` and ``config/panda_scene.yaml`` make the Panda's scene,
``config/xarm_scene.yaml`` the xArm 7's.
"""
from __future__ import annotations

import math
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
from qg_common.arm_description import ArmDescription
from qg_common.params import config_from_dict
from qg_common.rotations import (axis_angle_matrix, housing_rotation,
                                 quaternion_from_matrix, rotation_log, tilt_from_down)
from qg_common.types import N_START_POSES, GroundTruth, JointState

from sim_robot_node.core.arm_imperfections import ArmImperfections, ImperfectArm
from sim_robot_node.core.shaft_urdfs import SHAFT_JOINT, arm_with_shaft_urdf, housing_urdf

__all__ = ["ShaftSceneConfig", "ShaftScene"]


@dataclass(frozen=True)
class ShaftSceneConfig:
    """Geometry and physics of the shaft/bearing task (SPEC section 1), and the arm's
    imperfections. Lengths in m. The defaults are the Panda's (``config/panda_scene.yaml``);
    another arm's config file names what differs."""
    time_step: float = 0.001                    # [s] one physics step = one control tick
    solver_iterations: int = 50
    contact_breaking_threshold: float = 0.001   # [m] (default 0.02: idle contacts, 5x slower)
    gravity: float = 9.81                       # [m/s^2]
    hole_position: tuple[float, ...] = (0.45, 0.0, 0.25)  # bearing face centre, base frame [m]
    hole_radius: float = 0.006
    bore_depth: float = 0.012                   # free slide before the inner ring
    bore_segments: int = 48
    counterbore_segments: int = 32
    counterbore_depth: float = 0.006
    counterbore_extra_radius: float = 0.004
    plunger_mass: float = 2.0                   # [kg] heavy, so the friction motor stays Coulomb
    plunger_travel: float = 0.004
    plunger_friction: float = 11.0              # [N] friction force of the fit
    success_tolerance: float = 0.0002           # success: plunger this close to full travel
    shaft_radius: float = 0.0059
    shaft_length: float = 0.1
    shaft_mass: float = 0.086                   # [kg] steel, 11.8 mm x 100 mm
    grasp_height: float = 0.06                  # grasp point above the shaft tip
    friction: float = 0.5                       # combined lateral friction shaft/housing
    start_tilt: float = math.radians(15.0)      # [rad]
    start_clearance: float = 0.0005             # lowest rim point above the bearing face
    max_lateral_offset: float = 0.015           # episode ends if the tip leaves the axis by more
    housing_tilt: float = 0.0                   # [rad] fixture tilt of the bore axis (about the
                                                # housing's x axis, after its yaw)
    imperfections: ArmImperfections = field(default_factory=ArmImperfections)  # the real arm

    def __post_init__(self) -> None:
        if not 0.0 < self.time_step <= 0.01:
            raise ValueError(f"time_step must be in (0, 0.01] s, got {self.time_step}")
        if len(self.hole_position) != 3:
            raise ValueError(f"hole_position needs 3 entries, got {len(self.hole_position)}")
        if not 0.0 < self.shaft_radius < self.hole_radius:
            raise ValueError(f"shaft_radius {self.shaft_radius} must be in (0, hole_radius "
                             f"{self.hole_radius})")
        if not 0.0 < self.grasp_height < self.shaft_length:
            raise ValueError(f"grasp_height {self.grasp_height} must be in (0, shaft_length)")
        positive = ("solver_iterations", "contact_breaking_threshold", "bore_depth",
                    "bore_segments", "counterbore_segments", "counterbore_depth",
                    "counterbore_extra_radius",
                    "plunger_mass", "plunger_travel", "plunger_friction", "success_tolerance",
                    "shaft_mass", "friction")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.start_tilt < math.pi / 4:
            raise ValueError(f"start_tilt must be in [0, pi/4) rad, got {self.start_tilt}")
        if not abs(self.housing_tilt) <= math.radians(20.0):
            raise ValueError(f"housing_tilt must be within +-20 deg (the arm's reach around the "
                             f"start poses), got {self.housing_tilt} rad")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ShaftSceneConfig:
        """From a scene section (``panda_scene`` of ``config/panda_scene.yaml``, ``xarm_scene``
        of ``config/xarm_scene.yaml``; ``imperfections`` nested)."""
        values = dict(params)
        if isinstance(values.get("imperfections"), dict):
            values["imperfections"] = ArmImperfections.from_dict(values["imperfections"])
        return config_from_dict(cls, values)

    @property
    def full_depth(self) -> float:
        """Tip depth below the bearing face when fully inserted [m]."""
        return self.bore_depth + self.plunger_travel

    @property
    def tool_offset(self) -> np.ndarray:
        """Grasp point relative to the flange in its frame: the shaft is held there."""
        return np.zeros(3)

    @property
    def shaft_com(self) -> np.ndarray:
        """Shaft centre of mass in the tool frame (z towards the tip)."""
        return np.array([0.0, 0.0, self.shaft_length / 2 - (self.shaft_length - self.grasp_height)])


class ShaftScene:
    """pybullet world: a torque-controlled arm holding a shaft above a bearing in a housing.

    Usage per episode: ``reset(k)``, then every millisecond ``joint_state()``,
    ``apply_torques(tau)``, ``step()``; ``ground_truth()`` when evaluation needs it.

    :param arm: the arm (its URDF, driven joints, flange and ready pose).
    """

    def __init__(self, config: ShaftSceneConfig, arm: ArmDescription) -> None:
        self.config = config
        self.arm_description = arm
        self.n_joints = arm.n_joints
        imperfections = self.config.imperfections
        self.arm_errors = ImperfectArm(imperfections, self.n_joints)
        self._friction = imperfections.has_friction
        self._sensor_errors = imperfections.has_sensor_errors
        self._measured: JointState | None = None   # the driver's reading of the current step
        self._tmp = Path(tempfile.mkdtemp(prefix="shaft_scene_"))
        self.cid: int | None = p.connect(p.DIRECT)
        c = self.config
        p.setGravity(0.0, 0.0, -c.gravity, physicsClientId=self.cid)
        p.setPhysicsEngineParameter(
            fixedTimeStep=c.time_step, numSolverIterations=c.solver_iterations,
            contactBreakingThreshold=c.contact_breaking_threshold, physicsClientId=self.cid)
        flags = p.URDF_USE_IMPLICIT_CYLINDER | p.URDF_USE_INERTIA_FROM_FILE
        self.robot = p.loadURDF(str(self._write_robot_urdf()), useFixedBase=True, flags=flags,
                                physicsClientId=self.cid)
        self.housing = p.loadURDF(str(self._write_housing_urdf()), useFixedBase=True,
                                  basePosition=c.hole_position, flags=flags,
                                  physicsClientId=self.cid)
        names = {p.getJointInfo(self.robot, j, physicsClientId=self.cid)[1].decode(): j
                 for j in range(p.getNumJoints(self.robot, physicsClientId=self.cid))}
        self.arm = [names[n] for n in arm.joint_names]
        self.shaft_link = names[SHAFT_JOINT]
        self._setup_dynamics()
        self._tau = np.zeros(self.n_joints)
        self._steps = 0
        self.housing_yaw = 0.0
        self._housing = housing_rotation(0.0, c.housing_tilt)   # base frame <- housing frame
        self._hole = np.asarray(c.hole_position, float)          # bearing face centre, true
        self.reset(0)

    # --- construction -------------------------------------------------------------------
    def _write_robot_urdf(self) -> Path:
        """The arm's URDF with the shaft (``shaft_urdfs.arm_with_shaft_urdf``), for pybullet."""
        path = self._tmp / "arm_shaft.urdf"
        arm_with_shaft_urdf(self.arm_description, self.config).write(path)
        return path

    def _write_housing_urdf(self) -> Path:
        """The housing (``shaft_urdfs.housing_urdf``), for pybullet."""
        path = self._tmp / "housing.urdf"
        path.write_text(housing_urdf(self.config))
        return path

    def _setup_dynamics(self) -> None:
        c = self.config
        for j in range(-1, p.getNumJoints(self.robot, physicsClientId=self.cid)):
            p.changeDynamics(self.robot, j, linearDamping=0.0, angularDamping=0.0,
                             jointDamping=0.0, physicsClientId=self.cid)
        p.setJointMotorControlArray(self.robot, self.arm, p.VELOCITY_CONTROL,
                                    forces=[0.0] * self.n_joints, physicsClientId=self.cid)
        # pybullet multiplies the two bodies' coefficients: the housing carries the combined one.
        p.changeDynamics(self.robot, self.shaft_link, lateralFriction=1.0, physicsClientId=self.cid)
        for j in (-1, 0):
            p.changeDynamics(self.housing, j, lateralFriction=c.friction, linearDamping=0.0,
                             angularDamping=0.0, jointDamping=0.0, physicsClientId=self.cid)
        p.setJointMotorControl2(self.housing, 0, p.VELOCITY_CONTROL, targetVelocity=0.0,
                                force=c.plunger_friction, physicsClientId=self.cid)
        p.enableJointForceTorqueSensor(self.robot, self.shaft_link, True, physicsClientId=self.cid)
        for j in range(-1, p.getNumJoints(self.robot, physicsClientId=self.cid)):
            if j != self.shaft_link:  # only the shaft touches the world
                p.setCollisionFilterGroupMask(self.robot, j, 0, 0, physicsClientId=self.cid)

    # --- episode ------------------------------------------------------------------------
    def start_tool_pose(self, initial_pose: int, housing_yaw: float = 0.0,
                        jitter: tuple[np.ndarray, np.ndarray] | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Tool position and rotation (base frame) of start ``initial_pose`` (0..7).

        The shaft is tilted by ``start_tilt`` towards direction k * 45 deg (in the housing frame),
        its tip on the hole axis, its lowest rim point ``start_clearance`` above the bearing face.
        The housing is the configured one (where the cell believes the bore is). ``jitter``:
        ``(tilt vector change [rad], tip offset [m])`` in the housing's x/y, how far a real arm
        misses the taught start.
        """
        if not 0 <= initial_pose < N_START_POSES:
            raise ValueError(f"initial_pose must be in 0..{N_START_POSES - 1}, got {initial_pose}")
        c = self.config
        angle, phi = c.start_tilt, initial_pose * 2.0 * math.pi / N_START_POSES
        tip = np.zeros(3)
        if jitter is not None:
            vector = angle * np.array([math.cos(phi), math.sin(phi)]) + jitter[0]
            angle, phi = math.hypot(*vector.tolist()), math.atan2(vector[1], vector[0])
            tip[:2] = jitter[1]
        axis_up = np.array([math.sin(angle) * math.cos(phi),
                            math.sin(angle) * math.sin(phi), math.cos(angle)])
        tip[2] = c.start_clearance + c.shaft_radius * math.sin(angle)
        down = np.diag([1.0, -1.0, -1.0])  # tool z pointing down, hand x along base x
        tilt = axis_angle_matrix(np.array([-math.sin(phi), math.cos(phi), 0.0]), angle)
        # The start in the housing frame, then the housing's pose (yaw, fixture tilt).
        housing = housing_rotation(housing_yaw, c.housing_tilt)
        tip = np.asarray(c.hole_position, float) + housing @ tip
        return tip + c.grasp_height * (housing @ axis_up), housing @ tilt @ down

    def reset(self, initial_pose: int, housing_yaw: float = 0.0) -> None:
        """Start an episode: housing rotated by ``housing_yaw``, arm at start ``initial_pose``.

        The arm is placed by inverse kinematics at rest; the caller settles it under its
        controller. The plunger goes back to the top of its travel.
        """
        c, errors = self.config, self.arm_errors
        jitter = None
        if c.imperfections.start_tilt_jitter or c.imperfections.start_position_jitter:
            jitter = errors.start_jitter()
        position, rotation = self.start_tool_pose(initial_pose, housing_yaw, jitter)
        # The bore where the fixture really holds it: the configured pose, then its error.
        self._housing = housing_rotation(housing_yaw, c.housing_tilt)
        self._hole = np.asarray(c.hole_position, float)
        orientation = p.getQuaternionFromEuler([c.housing_tilt, 0.0, housing_yaw])
        if c.imperfections.housing_tilt_error or c.imperfections.housing_position_error:
            self._hole = self._hole + self._housing @ errors.housing_position_error
            self._housing = self._housing @ axis_angle_matrix(errors.housing_rotation_error, 1.0)
            orientation = quaternion_from_matrix(self._housing)
        p.resetBasePositionAndOrientation(self.housing, self._hole.tolist(), orientation,
                                          physicsClientId=self.cid)
        p.resetJointState(self.housing, 0, 0.0, 0.0, physicsClientId=self.cid)
        self.housing_yaw = housing_yaw
        q = self._inverse_kinematics(position, rotation)
        for j, qj in zip(self.arm, q):
            p.resetJointState(self.robot, j, qj, 0.0, physicsClientId=self.cid)
        self._tau = np.zeros(self.n_joints)
        self._steps = 0
        self._measure()

    def _inverse_kinematics(self, position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """Joint angles putting the tool exactly at the pose (damped least squares from the
        arm's ready pose, its last joint, which turns the flange about the tool axis, turned
        with the housing).

        :raises RuntimeError: if the pose is out of reach.
        """
        q = np.array(self.arm_description.ready, float)
        q[-1] += self.housing_yaw
        zeros = [0.0] * self.n_joints
        for _ in range(200):
            for j, qj in zip(self.arm, q):
                p.resetJointState(self.robot, j, qj, 0.0, physicsClientId=self.cid)
            pos, rot = self.tool_pose()
            error = np.concatenate([position - pos, rotation_log(rotation @ rot.T)])
            if np.linalg.norm(error) < 1e-7:
                return q
            lin, ang = p.calculateJacobian(self.robot, self.shaft_link, [0.0, 0.0, 0.0],
                                           q.tolist(), zeros, zeros, physicsClientId=self.cid)
            jac = np.vstack([np.array(lin), np.array(ang)])
            q = q + jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), error)
        if np.linalg.norm(error) < 1e-6:
            # Some rotated-housing starts (yaw 90 deg, pose 7) stall at ~2.5e-7 near the wrist's
            # limit; 1 um / 1 urad is far below the 0.5 mm start clearance.
            return q
        raise RuntimeError(
            f"inverse kinematics did not converge (error {np.linalg.norm(error):.2e})")

    # --- 1 kHz interface ----------------------------------------------------------------
    @property
    def tool_offset(self) -> np.ndarray:
        """Grasp point relative to the flange (the controller's model uses the same)."""
        return self.config.tool_offset

    @property
    def time(self) -> float:
        """Simulated time since the last reset [s]."""
        return self._steps * self.config.time_step

    def true_joint_state(self) -> JointState:
        """The joints as they are (evaluation only), with the torque the drives realised."""
        states = p.getJointStates(self.robot, self.arm, physicsClientId=self.cid)
        return JointState(q=np.array([s[0] for s in states]), dq=np.array([s[1] for s in states]),
                          tau=self._tau.copy())

    def joint_state(self) -> JointState:
        """What the driver reports: joint positions, velocities and measured torques (the last
        command as the torque sensors read it), with the arm's encoder and sensor errors."""
        if self._measured is None:
            return self.true_joint_state()
        return self._measured

    def _measure(self) -> None:
        """Take this step's reading (once per step, so every ``joint_state`` agrees)."""
        if not self._sensor_errors:
            return
        true = self.true_joint_state()
        m = self.arm_errors.measure(true.q, true.dq, true.tau)
        self._measured = JointState(q=m.q, dq=m.dq, tau=m.tau)

    def apply_torques(self, tau: np.ndarray) -> None:
        """Joint torques for the next step [Nm]; the caller enforces limits. With joint
        friction, the links get the command minus the friction at their true velocities."""
        tau = np.asarray(tau, float)
        if tau.shape != (self.n_joints,) or not np.all(np.isfinite(tau)):
            raise ValueError(f"tau must be {self.n_joints} finite torques, got {tau}")
        self._tau = tau.copy()
        if self._friction:
            tau = tau - self.arm_errors.friction(self.true_joint_state().dq)
        p.setJointMotorControlArray(self.robot, self.arm, p.TORQUE_CONTROL, forces=tau.tolist(),
                                    physicsClientId=self.cid)

    def step(self) -> None:
        """One physics step. The plunger's weight is carried (only the fit friction holds it)."""
        c = self.config
        p.applyExternalForce(self.housing, 0, (0.0, 0.0, c.plunger_mass * c.gravity),
                             (0.0, 0.0, 0.0), p.LINK_FRAME, physicsClientId=self.cid)
        p.stepSimulation(physicsClientId=self.cid)
        self._steps += 1
        self._measure()

    # --- ground truth -------------------------------------------------------------------
    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Tool position and rotation matrix in the base frame."""
        state = p.getLinkState(self.robot, self.shaft_link, computeForwardKinematics=True,
                               physicsClientId=self.cid)
        rotation = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return np.array(state[4]), rotation

    def plunger_travel(self) -> float:
        """How far the inner ring has been pushed down [m]."""
        return float(p.getJointState(self.housing, 0, physicsClientId=self.cid)[0])

    def contact_wrench(self) -> np.ndarray:
        """Wrench the housing exerts on the shaft, about the tool origin, in the tool frame.

        Measured like a wrist force/torque sensor between hand and shaft: the reaction of the
        shaft's fixed joint minus the shaft's weight (its inertial forces, under 0.1 N at the
        accelerations of the task, are neglected). Summing ``getContactPoints`` instead fails
        where the shaft is pinched in the bore: the reported lateral forces there violate the
        arm's static balance by tens of newtons.
        """
        c = self.config
        # pybullet reports the hand's force on the shaft and its moment about the shaft's centre
        # of mass, in the tool frame.
        hand = p.getJointState(self.robot, self.shaft_link, physicsClientId=self.cid)[2]
        _, rotation = self.tool_pose()
        weight = rotation.T @ np.array([0.0, 0.0, -c.shaft_mass * c.gravity])
        force = -(np.asarray(hand[:3]) + weight)
        lever = c.shaft_com[2]  # the centre of mass is on the tool z axis
        torque = [-hand[3] - lever * force[1], -hand[4] + lever * force[0], -hand[5]]
        return np.concatenate([force, torque])

    def target_tool_position(self) -> np.ndarray:
        """Tool position with the shaft on the bore axis and fully inserted [m]."""
        c = self.config
        return self._hole + self._housing @ np.array([0.0, 0.0, c.grasp_height - c.full_depth])

    def ground_truth(self) -> GroundTruth:
        """Contact wrench, insertion state and the errors the dense reward uses."""
        c = self.config
        position, rotation = self.tool_pose()
        z_tool = rotation[:, 2]
        tip = position + c.grasp_height * z_tool
        # The rotation turning the shaft onto the bore axis, as angle-axis in the tool frame: its
        # z part is zero, the insertion does not care about the rotation about the shaft.
        housing = self._housing
        tilt, axis = tilt_from_down(housing.T @ rotation)
        error = rotation.T @ (housing @ axis * tilt)
        tip_in_housing = housing.T @ (tip - self._hole)
        travel = self.plunger_travel()
        return GroundTruth(
            wrench=self.contact_wrench(),
            insertion_depth=float(-tip_in_housing[2]),
            plunger_travel=travel,
            success=bool(travel >= c.plunger_travel - c.success_tolerance),
            position_error=float(np.linalg.norm(position - self.target_tool_position())),
            orientation_error=error[:2].copy(),
            lateral_offset=float(math.hypot(tip_in_housing[0], tip_in_housing[1])),
            tilt=tilt)

    def close(self) -> None:
        """Disconnect pybullet and delete the generated URDFs."""
        if self.cid is not None:
            p.disconnect(physicsClientId=self.cid)
            self.cid = None
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # interpreter shutdown: nothing left to clean reliably
            pass

