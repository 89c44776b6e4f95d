"""A torque-controlled arm pressing a shaft into a tight bearing at 1 kHz: the shaft task's
simulated cell, for any arm its URDF describes and any engine ``shaft_world`` builds.

A rigid-body engine cannot simulate an interference fit, so the fit is modelled by its effect:
the shaft slides with 0.1 mm radial clearance through a bore (a ring of boxes) and then pushes a
heavy "inner ring" plunger whose sliding joint is resisted by Coulomb friction of ~11 N. The tight
clearance makes a tilted shaft wedge, so the constant base push jams while torques that
straighten the shaft let it slide in; the last millimetres need a sustained push above the
friction. Above the bore a counterbore keeps random torques from levering the shaft out.

What is the cell's and the arm's, whatever engine steps them, is here: the task's geometry
(``qg_common.shaft_task``: where the fixture holds the housing, the starts, the target), the
arm's imperfections (``arm_imperfections``: unmodelled payload, joint friction, sensor errors,
start jitter, the fixture's error), placing the arm at a start (inverse kinematics of the
bridge's own model of the arm), and the ground truth. The engine contributes a ``ShaftWorld``:
the bodies, one physics step, and what only it can tell (the true joint state, the tool pose,
the plunger and the contact wrench). ``config/panda_scene.yaml`` holds the physics of the
Panda's cell (``shaft_scene_config``; ``engine`` picks the world), ``config/shaft_task.yaml`` its
geometry.

Withdrawing the shaft from the bore undoes the fit, as in the real task, where the robot pulls
the shaft back out of the bearing's inner ring: whenever the tip is above the bearing face, the
inner ring is back at the start of its travel. So a reset by motion (the bridge backing out and
moving to the next start) leaves the cell ready as a teleport does.
"""
from __future__ import annotations

import math

import numpy as np
from qg_common.arm_description import ArmDescription
from qg_common.rotations import axis_angle_matrix
from qg_common.shaft_task import Fixture, ShaftTaskGeometry
from qg_common.types import GroundTruth, JointState, StartPose
from robot_bridge_node.core.arm_model import ArmModel

from sim_robot_node.core.arm_imperfections import ImperfectArm
from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig
from sim_robot_node.core.shaft_world import ShaftWorld, build_world

__all__ = ["ShaftSceneConfig", "ShaftScene"]


def _all_finite(values: np.ndarray) -> bool:
    """Whether every entry is finite: their sum is (a float sum, ~5x faster than
    ``np.isfinite`` and ``np.all`` on a few entries), or, should finite entries overflow it,
    each is."""
    return math.isfinite(sum(values.tolist())) or bool(np.all(np.isfinite(values)))


class ShaftScene:
    """The simulated cell: an arm holding the shaft above the bearing, in one engine's world.

    Usage: ``teleport(start)`` at each episode's start (or let the bridge move the arm there),
    then every millisecond ``joint_state()``, ``apply_torques(tau)``, ``step()``;
    ``ground_truth()`` when evaluation needs it. The arm starts parked above start 0, ready
    for its first reset.

    :param arm: the arm (its URDF, driven joints, flange and ready pose).
    """

    def __init__(self, config: ShaftSceneConfig, geometry: ShaftTaskGeometry,
                 arm: ArmDescription) -> None:
        self.config = config
        self.geometry = geometry
        self.arm_description = arm
        self.n_joints = arm.n_joints
        self._shape = (arm.n_joints,)
        imperfections = config.imperfections
        self.arm_errors = ImperfectArm(imperfections, self.n_joints)
        self._friction = imperfections.has_friction
        self._sensor_errors = imperfections.has_sensor_errors
        self._jitter = bool(imperfections.start_tilt_jitter or imperfections.start_position_jitter)
        self._kinematics = ArmModel.of_arm(arm)      # the flange is the tool frame (grasp point)
        self.world: ShaftWorld = build_world(arm, geometry, config)
        self.fixture = self._true_fixture()
        self._bore_axis = self.fixture.rotation[:, 2].copy()   # out of the bore, housing z
        self.world.place_housing(self.fixture)
        self._tau = np.zeros(self.n_joints)
        self._steps = 0
        self._q, self._dq = np.zeros(self.n_joints), np.zeros(self.n_joints)   # true, this step
        self._measured: JointState | None = None
        parked = geometry.start_pose(0)
        self.teleport(StartPose(parked.position - parked.approach, parked.rotation))

    def _true_fixture(self) -> Fixture:
        """Where the fixture really holds the bore: the configured pose, then its error (one per
        arm seed: ``housing_*_error``)."""
        nominal, errors = self.geometry.fixture(), self.arm_errors
        if not (self.config.imperfections.housing_tilt_error
                or self.config.imperfections.housing_position_error):
            return nominal
        return Fixture(nominal.position + nominal.rotation @ errors.housing_position_error,
                       nominal.rotation @ axis_angle_matrix(errors.housing_rotation_error, 1.0))

    # --- episode ------------------------------------------------------------------------
    def teleport(self, start: StartPose) -> None:
        """Put the arm at rest with its tool at ``start`` (missed by the arm's start jitter, as a
        real arm misses a taught pose) and the bearing's inner ring back at the start of its
        travel; the caller settles the arm under its controller.

        :raises RuntimeError: if the pose is out of the arm's reach.
        """
        position, rotation = np.asarray(start.position, float), np.asarray(start.rotation, float)
        if self._jitter:
            position, rotation = self._jittered(position, rotation)
        q0 = np.array(self.arm_description.ready, float)
        q0[-1] += self.geometry.housing_yaw      # the flange turned with the housing
        q = self._kinematics.inverse_kinematics(position, rotation, q0)
        self.world.set_arm_state(q, np.zeros(self.n_joints))
        self.world.set_plunger_travel(0.0)
        self._tau = np.zeros(self.n_joints)
        self._steps = 0
        self._after_step()

    def _jittered(self, position: np.ndarray, rotation: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """The start as the arm reaches it: the shaft turned about its tip by the reset's tilt
        jitter and the tip moved by its position jitter (both across the bore axis)."""
        tilt, offset = self.arm_errors.start_jitter()
        housing = self.geometry.fixture().rotation
        tip = position + self.geometry.grasp_height * rotation[:, 2]
        turn = axis_angle_matrix(housing @ np.array([-tilt[1], tilt[0], 0.0]), 1.0)
        rotation = turn @ rotation
        tip = tip + housing @ np.array([offset[0], offset[1], 0.0])
        return tip - self.geometry.grasp_height * rotation[:, 2], rotation

    # --- 1 kHz interface ----------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time since the last teleport [s]."""
        return self._steps * self.config.time_step

    def true_joint_state(self) -> JointState:
        """The joints as they are (evaluation only), with the last torque command."""
        return JointState(self._q, self._dq, self._tau.copy())

    def joint_state(self) -> JointState:
        """What the driver reports: joint positions, velocities and measured torques (the last
        command as the torque sensors read it), with the arm's encoder and sensor errors."""
        return self.true_joint_state() if self._measured is None else self._measured

    def apply_torques(self, tau: np.ndarray) -> None:
        """Joint torques for the next step [Nm]; the caller enforces limits. With joint
        friction, the links get the command minus the friction at their true velocities."""
        tau = np.array(tau, float)                    # the scene's own copy
        if tau.shape != self._shape or not (math.isfinite(sum(tau.tolist()))
                                            or _all_finite(tau)):
            raise ValueError(f"tau must be {self.n_joints} finite torques, got {tau}")
        self._tau = tau
        if self._friction:
            tau = self.arm_errors.apply_friction(tau, self._dq)
        self.world.set_arm_torques(tau)

    def step(self) -> None:
        """One physics step; a shaft withdrawn from the bore undoes the fit."""
        self.world.step()
        self._steps += 1
        if self.world.plunger_travel() > 0.0 and self._tip_depth() < 0.0:
            self.world.set_plunger_travel(0.0)
        self._after_step()

    def _after_step(self) -> None:
        """Take this step's true state and the driver's reading of it (once per step, so every
        ``joint_state`` of the step agrees)."""
        self._q, self._dq = q, dq = self.world.arm_state()
        if self._sensor_errors:
            self._measured = self.arm_errors.measure(q, dq, self._tau)

    def _tip_depth(self) -> float:
        """The tip's insertion depth (``ShaftTaskGeometry.measure``'s, against the true
        housing), written out: the full measure costs ~15 us, and this runs every step while
        the inner ring is off its start."""
        position, rotation = self.world.tool_pose()
        tip = position + self.geometry.grasp_height * rotation[:, 2]
        return -float(self._bore_axis @ (tip - self.fixture.position))

    # --- ground truth -------------------------------------------------------------------
    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Tool position and rotation matrix in the base frame (true)."""
        return self.world.tool_pose()

    def plunger_travel(self) -> float:
        """How far the inner ring has been pushed down [m]."""
        return self.world.plunger_travel()

    def contact_wrench(self) -> np.ndarray:
        """(6,) the wrench the housing exerts on the shaft, about the tool origin, tool frame."""
        return self.world.contact_wrench()

    def ground_truth(self) -> GroundTruth:
        """Contact wrench, insertion state and the errors the dense reward uses, measured on the
        true tool pose against the true housing (evaluation only)."""
        g = self.geometry
        position, rotation = self.world.tool_pose()
        m = g.measure(position, rotation, self.fixture)
        travel = self.world.plunger_travel()
        return GroundTruth(
            wrench=self.world.contact_wrench(), insertion_depth=m.insertion_depth,
            plunger_travel=travel,
            success=bool(travel >= g.plunger_travel - g.success_tolerance),
            position_error=m.position_error, orientation_error=m.orientation_error,
            lateral_offset=m.lateral_offset, tilt=m.tilt)

    def close(self) -> None:
        """Release the engine's world."""
        self.world.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # interpreter shutdown: nothing left to clean reliably
            pass

