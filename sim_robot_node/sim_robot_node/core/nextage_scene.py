"""The clearance-fit peg-in-hole scene in pybullet: a Nextage arm holding a peg above a holed block.

The thesis ran this task (ch. 3.1.1) on a Nextage Open behind the manufacturer's task-space
position interface, with a sensor at the wrist; this scene gives the bridge the same hardware
shape: joint position targets in (motors with force limits), joint state and the wrist
force-torque sensor out. Ground truth (peg tip, distance to the hole bottom, success) is for
evaluation and rewards only.

The peg/hole geometry is the cell's (``qg_common.peg_task``); the builders of the block and the
peg live here, because the free peg environment (``peg_env``) uses the same task without the arm. Positions of the task are given
in the workspace frame: origin on the hole axis at the block's base, z up, the workspace a cube
of side ``workspace_side`` standing on that floor.
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
from qg_common.params import config_from_dict
from qg_common.peg_task import TOOL_DOWN, PegCell, PegHoleGeometry, sample_start
from qg_common.types import JointState

__all__ = ["PegGroundTruth", "NextageSceneConfig", "NextagePegScene", "nextage_urdf_path",
           "build_hole_block", "build_peg", "INIT_POSE"]

#: The published Nextage "init pose" of the right arm [rad]: forearm forward, hand down.
INIT_POSE = np.deg2rad([-0.6, 0.0, -100.0, 15.2, 9.4, 3.2])


def _quaternion(rotation: np.ndarray) -> list[float]:
    """pybullet quaternion (x, y, z, w) of a rotation matrix, with scipy's sign (the start
    poses' IK was tuned with it). Imported here: scipy costs every process that loads the
    robot plugins 0.18 s, and only a Nextage reset needs it."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(np.asarray(rotation, float)).as_quat().tolist()


def nextage_urdf_path() -> Path:
    """Path of our Nextage Open arm URDF (package data of ``sim_robot_node``)."""
    return Path(str(files("sim_robot_node") / "assets" / "nextage" / "nextage_arm.urdf"))


def build_hole_block(client: int, geometry: PegHoleGeometry, origin: np.ndarray) -> int:
    """A static block with a round hole (a ring of boxes in a square frame) on a floor plate.

    :param origin: position of the workspace frame origin (hole axis, block base) in the world.
    :returns: the pybullet body id.
    """
    g = geometry
    half = g.block_width / 2
    bottom = g.block_height - g.hole_depth
    ring_outer = g.hole_radius * np.sqrt(2) + 0.003    # the ring covers the frame's corners
    frame_inner = g.hole_radius + 0.003                # half-side of the frame's square opening
    wall_mid = bottom + g.hole_depth / 2
    boxes: list[tuple[np.ndarray, np.ndarray, float]] = [   # (half extents, centre, yaw)
        (np.array([half, half, bottom / 2]), np.array([0.0, 0.0, bottom / 2]), 0.0)]
    frame_thickness = half - frame_inner
    for yaw in (0.0, np.pi / 2, np.pi, 3 * np.pi / 2):
        centre = (frame_inner + frame_thickness / 2) * np.array([np.cos(yaw), np.sin(yaw), 0.0])
        centre[2] = wall_mid
        boxes.append((np.array([frame_thickness / 2, half, g.hole_depth / 2]), centre, yaw))
    ring_thickness = ring_outer - g.hole_radius
    tangential = ring_outer * np.tan(np.pi / g.ring_segments)
    for k in range(g.ring_segments):
        yaw = 2 * np.pi * k / g.ring_segments
        radius = g.hole_radius + ring_thickness / 2
        centre = np.array([radius * np.cos(yaw), radius * np.sin(yaw), wall_mid])
        boxes.append((np.array([ring_thickness / 2, tangential, g.hole_depth / 2]), centre, yaw))
    shape = p.createCollisionShapeArray(
        [p.GEOM_BOX] * len(boxes), halfExtents=[b[0].tolist() for b in boxes],
        collisionFramePositions=[b[1].tolist() for b in boxes],
        collisionFrameOrientations=[p.getQuaternionFromEuler([0, 0, b[2]]) for b in boxes],
        physicsClientId=client)
    # No visual shape: createVisualShapeArray crashes pybullet 3.2.x; DIRECT mode needs none.
    body = p.createMultiBody(0.0, shape, basePosition=np.asarray(origin, float).tolist(),
                             physicsClientId=client)
    p.changeDynamics(body, -1, lateralFriction=g.friction, physicsClientId=client)
    return body


def build_peg(client: int, geometry: PegHoleGeometry) -> int:
    """An upright cylindrical peg, its base frame at its centre (tip ``peg_length/2`` below)."""
    g = geometry
    shape = p.createCollisionShape(p.GEOM_CYLINDER, radius=g.peg_radius, height=g.peg_length,
                                   physicsClientId=client)
    body = p.createMultiBody(g.peg_mass, shape, physicsClientId=client)
    p.changeDynamics(body, -1, lateralFriction=g.friction, physicsClientId=client)
    return body


@dataclass(frozen=True)
class PegGroundTruth:
    """Simulator-only truth of the peg task (workspace frame)."""
    tip: np.ndarray        # (3,) peg tip position [m]
    distance: float        # [m] tip distance to the goal at the hole bottom
    success: bool          # tip within ``goal_tolerance`` of the goal


@dataclass(frozen=True)
class NextageSceneConfig:
    """The Nextage peg scene.

    :param time_step: physics step [s] (1 kHz like the control loop).
    :param position_gain: pybullet POSITION_CONTROL gain (fraction of the position error
        corrected per step).
    :param velocity_gain: pybullet POSITION_CONTROL velocity gain.
    :param effort_scale: multiplies the URDF effort limits to give the motor force limits.
    :param solver_iterations: pybullet constraint solver iterations.
    """
    time_step: float = 1e-3
    position_gain: float = 0.2
    velocity_gain: float = 1.0
    effort_scale: float = 1.0
    solver_iterations: int = 50

    def __post_init__(self) -> None:
        for name in ("time_step", "position_gain", "velocity_gain", "effort_scale"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.solver_iterations < 1:
            raise ValueError(f"solver_iterations must be >= 1, got {self.solver_iterations}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> NextageSceneConfig:
        """Build from a parameter dict (unknown keys are an error)."""
        return config_from_dict(cls, params)


class NextagePegScene:
    """pybullet DIRECT world: the Nextage arm (fixed chest) holding the peg, the holed block.

    The peg hangs from the tool frame by a rigid constraint, so contact forces on it travel
    through the hand into the wrist force-torque sensor. Joint targets are held between calls of
    ``set_joint_targets``; ``step`` advances one ``time_step``. A new scene starts with the peg
    tip 3 cm above the hole, motors holding.
    """

    TOOL_LINK = "RARM_TOOL"
    SENSOR_JOINT = "RARM_FT_JOINT"

    def __init__(self, config: NextageSceneConfig | None = None,
                 cell: PegCell | None = None) -> None:
        self.config = config or NextageSceneConfig()
        self.cell = cell or PegCell()
        self.geometry = self.cell.geometry
        self.origin = self.cell.origin
        self.client = p.connect(p.DIRECT)
        p.setGravity(0, 0, -9.81, physicsClientId=self.client)
        p.setPhysicsEngineParameter(fixedTimeStep=self.config.time_step,
                                    numSolverIterations=self.config.solver_iterations,
                                    physicsClientId=self.client)
        self.robot = p.loadURDF(str(nextage_urdf_path()), useFixedBase=True,
                                flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=self.client)
        infos = [p.getJointInfo(self.robot, j, physicsClientId=self.client)
                 for j in range(p.getNumJoints(self.robot, physicsClientId=self.client))]
        self.joints = [i[0] for i in infos if i[2] == p.JOINT_REVOLUTE]
        self.joint_names = tuple(infos[j][1].decode() for j in self.joints)
        self.q_lower = np.array([infos[j][8] for j in self.joints])
        self.q_upper = np.array([infos[j][9] for j in self.joints])
        self.force_limits = self.config.effort_scale * np.array([infos[j][10] for j in self.joints])
        self.tool_link = next(i[0] for i in infos if i[12].decode() == self.TOOL_LINK)
        self.sensor_joint = next(i[0] for i in infos if i[1].decode() == self.SENSOR_JOINT)
        p.enableJointForceTorqueSensor(self.robot, self.sensor_joint, True,
                                       physicsClientId=self.client)
        table_top = self.origin - np.array([0.0, 0.0, 0.01])
        table = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.2, 0.2, 0.01],
                                       physicsClientId=self.client)
        p.createMultiBody(0.0, table, basePosition=table_top.tolist(), physicsClientId=self.client)
        self.block = build_hole_block(self.client, self.geometry, self.origin)
        self.peg = build_peg(self.client, self.geometry)
        half = self.geometry.peg_length / 2
        # The peg's frame has z up; the tool's z points down: a half turn about x joins them.
        self._peg_constraint = p.createConstraint(
            self.robot, self.tool_link, self.peg, -1, p.JOINT_FIXED, [0, 0, 0],
            parentFramePosition=[0, 0, half], childFramePosition=[0, 0, 0],
            childFrameOrientation=p.getQuaternionFromEuler([np.pi, 0, 0]),
            physicsClientId=self.client)
        p.changeConstraint(self._peg_constraint, maxForce=1000.0, physicsClientId=self.client)
        self._q_target = np.zeros(len(self.joints))
        self.reset(start=self.geometry.goal + [0.0, 0.0, self.geometry.hole_depth + 0.03])

    # --- hardware interface -----------------------------------------------------------------
    def set_joint_targets(self, q: np.ndarray) -> None:
        """Joint position targets for the motors (held until the next call) [rad]."""
        q = np.asarray(q, float)
        if q.shape != self._q_target.shape or not np.all(np.isfinite(q)):
            raise ValueError(f"joint targets must be {len(self.joints)} finite values, got {q}")
        q = np.clip(q, self.q_lower, self.q_upper)
        self._q_target = q
        p.setJointMotorControlArray(
            self.robot, self.joints, p.POSITION_CONTROL, targetPositions=q.tolist(),
            forces=self.force_limits.tolist(),
            positionGains=[self.config.position_gain] * len(self.joints),
            velocityGains=[self.config.velocity_gain] * len(self.joints),
            physicsClientId=self.client)

    def step(self) -> None:
        """Advance the physics by one ``time_step``."""
        p.stepSimulation(physicsClientId=self.client)

    def joint_state(self) -> JointState:
        """Measured positions [rad], velocities [rad/s] and motor torques [Nm]."""
        states = p.getJointStates(self.robot, self.joints, physicsClientId=self.client)
        return JointState(q=np.array([s[0] for s in states]), dq=np.array([s[1] for s in states]),
                          tau=np.array([s[3] for s in states]))

    def wrist_wrench(self) -> np.ndarray:
        """Wrist force-torque sensor reading (Fx, Fy, Fz, Tx, Ty, Tz) [N, Nm], sensor frame.

        The wrench the arm exerts on everything beyond the sensor (sensor disc, hand, peg), in
        the sensor frame (z along the tool axis). As on a real uncompensated sensor it includes
        their weight: in free air with the tool down Fz = -m g; pressing the peg onto something
        raises Fz by the contact force. Subtract a free-air reading to get the contact wrench.
        """
        return np.array(p.getJointState(self.robot, self.sensor_joint,
                                        physicsClientId=self.client)[2])

    def tool_pose(self) -> np.ndarray:
        """Tool frame pose (4x4) in the robot's base frame."""
        state = p.getLinkState(self.robot, self.tool_link, computeForwardKinematics=True,
                               physicsClientId=self.client)
        pose = np.eye(4)
        pose[:3, :3] = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        pose[:3, 3] = state[4]
        return pose

    # --- task -------------------------------------------------------------------------------
    def tool_pose_for_tip(self, tip: np.ndarray) -> np.ndarray:
        """Tool-down pose (base frame) that puts the peg tip at ``tip`` (workspace frame)."""
        pose = np.eye(4)
        pose[:3, :3] = TOOL_DOWN
        pose[:3, 3] = self.origin + np.asarray(tip, float) + [0, 0, self.geometry.peg_length]
        return pose

    def peg_tip(self) -> np.ndarray:
        """Peg tip position in the workspace frame [m]."""
        position, orientation = p.getBasePositionAndOrientation(self.peg,
                                                                physicsClientId=self.client)
        axis = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)[:, 2]
        return np.asarray(position) - axis * self.geometry.peg_length / 2 - self.origin

    def ground_truth(self) -> PegGroundTruth:
        """Peg tip, its distance to the hole bottom and success (evaluation only)."""
        tip = self.peg_tip()
        distance = float(np.linalg.norm(tip - self.geometry.goal))
        return PegGroundTruth(tip, distance, distance < self.geometry.goal_tolerance)

    def reset(self, start: np.ndarray | None = None, seed: int | None = None) -> np.ndarray:
        """Put the peg tip at ``start`` with the arm at rest there, motors holding that pose.

        :param start: tip position in the workspace frame [m]; None draws a free position
            uniformly from the workspace with ``seed``.
        :returns: the joint configuration the arm was put in [rad].
        """
        tip = sample_start(self.geometry, np.random.default_rng(seed)) if start is None \
            else np.asarray(start, float)
        q = self._inverse_kinematics(self.tool_pose_for_tip(tip))
        pose = self.tool_pose()
        peg_centre = pose[:3, 3] + pose[:3, 2] * self.geometry.peg_length / 2
        peg_rotation = pose[:3, :3] @ np.diag([1.0, -1.0, -1.0])    # the half turn about x
        p.resetBasePositionAndOrientation(self.peg, peg_centre.tolist(),
                                          _quaternion(peg_rotation), physicsClientId=self.client)
        p.resetBaseVelocity(self.peg, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        self.set_joint_targets(q)
        return q

    def _inverse_kinematics(self, pose: np.ndarray, tolerance: float = 1e-5) -> np.ndarray:
        """Joints for a tool pose by pybullet's IK (used only to place the arm at reset).

        Starts from ``INIT_POSE``; the joints are left at the solution, at rest. (pybullet's
        null-space variant with joint limits did not converge here, so limits are checked after.)
        The controller's IK lives in the bridge
        (``robot_bridge_node``), which depends on this package, not the reverse.
        :raises ValueError: if the pose is out of reach.
        """
        for joint, angle in zip(self.joints, INIT_POSE):
            p.resetJointState(self.robot, joint, angle, 0.0, physicsClientId=self.client)
        for _ in range(20):
            q = p.calculateInverseKinematics(
                self.robot, self.tool_link, pose[:3, 3].tolist(), _quaternion(pose[:3, :3]),
                maxNumIterations=100, residualThreshold=1e-7, physicsClientId=self.client)
            for joint, angle in zip(self.joints, q):
                p.resetJointState(self.robot, joint, angle, 0.0, physicsClientId=self.client)
            reached = self.tool_pose()
            if np.any(q < self.q_lower) or np.any(q > self.q_upper):
                break
            if (np.linalg.norm(reached[:3, 3] - pose[:3, 3]) < tolerance
                    and np.linalg.norm(reached[:3, :3] - pose[:3, :3]) < 10 * tolerance):
                return q
        raise ValueError(f"tool pose out of reach within the joint limits: position {pose[:3, 3]}")

    def close(self) -> None:
        """Disconnect the physics client."""
        if p.isConnected(self.client):
            p.disconnect(self.client)
