"""The shaft task's world in pybullet (``shaft_world.ShaftWorld``).

The arm is its package's URDF with the shaft welded to the flange (``shaft_urdfs``: a fixed
joint in the multibody is exact, unlike a soft constraint), loaded with implicit cylinders and the
file's inertias; only the shaft collides. The housing is one fixed body of boxes (the bore's ring
and the counterbore's wall) with the plunger on a prismatic joint below the bore, whose velocity
motor at target 0 with the fit's force limit is the Coulomb friction of the fit.
"""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np
import pybullet as p
from qg_common.arm_description import ArmDescription
from qg_common.rotations import quaternion_from_matrix
from qg_common.shaft_task import Fixture, ShaftTaskGeometry

from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig
from sim_robot_node.core.shaft_urdfs import SHAFT_JOINT, arm_with_shaft_urdf, housing_urdf

__all__ = ["PybulletShaftWorld", "build"]


class PybulletShaftWorld:
    """The arm holding the shaft, and the housing, in a pybullet client of its own (DIRECT)."""

    def __init__(self, arm: ArmDescription, geometry: ShaftTaskGeometry,
                 config: ShaftSceneConfig) -> None:
        self.geometry = geometry
        self.config = config
        self.n_joints = arm.n_joints
        self._tmp = Path(tempfile.mkdtemp(prefix="shaft_world_"))
        self.cid: int | None = p.connect(p.DIRECT)
        c = config
        p.setGravity(0.0, 0.0, -c.gravity, physicsClientId=self.cid)
        p.setPhysicsEngineParameter(
            fixedTimeStep=c.time_step, numSolverIterations=c.pybullet.solver_iterations,
            contactBreakingThreshold=c.pybullet.contact_breaking_threshold,
            physicsClientId=self.cid)
        flags = p.URDF_USE_IMPLICIT_CYLINDER | p.URDF_USE_INERTIA_FROM_FILE
        robot_urdf, housing_file = self._tmp / "arm_shaft.urdf", self._tmp / "housing.urdf"
        arm_with_shaft_urdf(arm, geometry, config).write(robot_urdf)
        housing_file.write_text(housing_urdf(geometry, config))
        self.robot = p.loadURDF(str(robot_urdf), useFixedBase=True, flags=flags,
                                physicsClientId=self.cid)
        self.housing = p.loadURDF(str(housing_file), useFixedBase=True,
                                  basePosition=geometry.hole_position, flags=flags,
                                  physicsClientId=self.cid)
        names = {p.getJointInfo(self.robot, j, physicsClientId=self.cid)[1].decode(): j
                 for j in range(p.getNumJoints(self.robot, physicsClientId=self.cid))}
        self.arm = [names[n] for n in arm.joint_names]
        self.shaft_link = names[SHAFT_JOINT]
        self._setup_dynamics()
        self._plunger_weight = (0.0, 0.0, c.plunger_mass * c.gravity)

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

    # --- ShaftWorld ---------------------------------------------------------------------
    def set_arm_state(self, q: np.ndarray, dq: np.ndarray) -> None:
        for j, qj, dqj in zip(self.arm, q, dq):
            p.resetJointState(self.robot, j, float(qj), float(dqj), physicsClientId=self.cid)

    def arm_state(self) -> tuple[np.ndarray, np.ndarray]:
        states = p.getJointStates(self.robot, self.arm, physicsClientId=self.cid)
        return np.array([s[0] for s in states]), np.array([s[1] for s in states])

    def set_arm_torques(self, tau: np.ndarray) -> None:
        p.setJointMotorControlArray(self.robot, self.arm, p.TORQUE_CONTROL, forces=tau.tolist(),
                                    physicsClientId=self.cid)

    def step(self) -> None:
        p.applyExternalForce(self.housing, 0, self._plunger_weight, (0.0, 0.0, 0.0),
                             p.LINK_FRAME, physicsClientId=self.cid)
        p.stepSimulation(physicsClientId=self.cid)

    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        state = p.getLinkState(self.robot, self.shaft_link, computeForwardKinematics=True,
                               physicsClientId=self.cid)
        rotation = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return np.array(state[4]), rotation

    def place_housing(self, fixture: Fixture) -> None:
        p.resetBasePositionAndOrientation(self.housing, np.asarray(fixture.position).tolist(),
                                          quaternion_from_matrix(fixture.rotation),
                                          physicsClientId=self.cid)

    def plunger_travel(self) -> float:
        return float(p.getJointState(self.housing, 0, physicsClientId=self.cid)[0])

    def set_plunger_travel(self, travel: float) -> None:
        p.resetJointState(self.housing, 0, float(travel), 0.0, physicsClientId=self.cid)

    def contact_wrench(self) -> np.ndarray:
        """Measured like a wrist force/torque sensor between hand and shaft: the reaction of the
        shaft's fixed joint minus the shaft's weight (its inertial forces, under 0.1 N at the
        accelerations of the task, are neglected). Summing ``getContactPoints`` instead fails
        where the shaft is pinched in the bore: the reported lateral forces there violate the
        arm's static balance by tens of newtons."""
        c = self.config
        # pybullet reports the hand's force on the shaft and its moment about the shaft's centre
        # of mass, in the tool frame.
        hand = p.getJointState(self.robot, self.shaft_link, physicsClientId=self.cid)[2]
        _, rotation = self.tool_pose()
        weight = rotation.T @ np.array([0.0, 0.0, -c.shaft_mass * c.gravity])
        force = -(np.asarray(hand[:3]) + weight)
        lever = self.geometry.shaft_centre[2]  # the centre of mass is on the tool z axis
        torque = [-hand[3] - lever * force[1], -hand[4] + lever * force[0], -hand[5]]
        return np.concatenate([force, torque])

    def close(self) -> None:
        """Disconnect pybullet and delete the generated URDFs."""
        if self.cid is not None:
            p.disconnect(physicsClientId=self.cid)
            self.cid = None
        shutil.rmtree(self._tmp, ignore_errors=True)


def build(arm: ArmDescription, geometry: ShaftTaskGeometry,
          config: ShaftSceneConfig) -> PybulletShaftWorld:
    """The shaft task's world in pybullet (``shaft_world.build_world`` calls it by name)."""
    return PybulletShaftWorld(arm, geometry, config)
