"""The shaft-into-bearing task as a robot cell knows it, with no physics engine in it.

A cell is described by where its fixture holds the housing, the sizes of the parts, the tilted
start poses and the tolerance of a finished fit. From that alone this module gives the start
poses an episode moves to, the inserted target pose, and how far any tool pose is from the goal
(``ShaftTaskGeometry.measure``). Both sides of the stack read it:

- the executor computes reward, success and "left the bore" from the tool pose the robot
  *measures* (forward kinematics of its joints, the ``ee_pose`` of every at-rest event) against
  the fixture pose of its task parameters, so a real arm runs exactly the task a simulated one
  does;
- a simulated cell builds its scene from the same numbers and, for evaluation only, measures its
  *true* tool pose against its *true* housing (the configured pose plus the fixture's error).

The numbers are ``config/shaft_task.yaml``'s (section ``shaft_task``). Frames: the housing
frame's origin is the bearing face centre, its z axis points out of the bore; the tool frame is
at the grasp point on the shaft axis, its z axis along the shaft towards the tip.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from qg_common.params import POSITIVE, ParameterSection, config_from_dict
from qg_common.rotations import axis_angle_matrix, housing_rotation, tilt_from_down
from qg_common.types import N_START_POSES, StartPose

__all__ = ["ShaftTaskGeometry", "TaskMeasure", "Fixture", "TOOL_DOWN", "SHAFT_TASK_SECTION",
           "SHAFT_TASK_FILE"]

#: The tool pointing straight down with its x axis along the base's x: the untilted grasp.
TOOL_DOWN = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class Fixture:
    """Where a housing is: its bearing face centre and orientation in the base frame."""
    position: np.ndarray
    rotation: np.ndarray


@dataclass(frozen=True)
class TaskMeasure:
    """How far a tool pose is from the inserted pose (what reward and success are made of).

    :param insertion_depth: [m] the shaft tip below the bearing face, along the bore axis
        (negative above it).
    :param lateral_offset: [m] the tip's distance from the bore axis.
    :param position_error: [m] tool position to the inserted tool position.
    :param orientation_error: (2,) [rad] the x/y angle-axis rotation, in the tool frame, that
        turns the shaft onto the bore axis (its z part is zero: the fit does not care about the
        turn about the shaft).
    :param tilt: [rad] the shaft's angle from the bore axis.
    :param inserted: the tip is within ``success_tolerance`` of the full depth.
    """
    insertion_depth: float
    lateral_offset: float
    position_error: float
    orientation_error: np.ndarray
    tilt: float
    inserted: bool

    @property
    def orientation_error_norm(self) -> float:
        """dR of the dense reward [rad]."""
        return float(np.linalg.norm(self.orientation_error))


@dataclass(frozen=True)
class ShaftTaskGeometry:
    """The cell and its parts (SPEC section 1). Lengths in m, angles in rad.

    :param hole_position: (3,) the bearing face centre in the robot's base frame: where the
        cell's fixture holds the housing, as the cell measured it.
    :param housing_yaw: the housing turned about the vertical.
    :param housing_tilt: the fixture's tilt of the bore axis, about the housing's x axis after
        its yaw.
    :param hole_radius: the bore's radius.
    :param bore_depth: the free slide below the bearing face before the fit begins.
    :param counterbore_depth: the recess above the bearing face.
    :param counterbore_extra_radius: the recess's radius minus the bore's.
    :param plunger_travel: how far the fit goes on after the free slide: the inner ring's travel.
    :param success_tolerance: the fit is finished when the tip is this close to the full depth.
        It must exceed what the robot's kinematics and the fixture are off by (the realistic
        Panda: up to 0.2 mm, encoder biases, and 0.15 mm, the housing's position error).
    :param shaft_radius: the shaft (its clearance in the bore is ``hole_radius - shaft_radius``).
    :param shaft_length: the shaft's length.
    :param grasp_height: the grasp point (tool frame origin) above the shaft's tip.
    :param start_tilt: every start tilts the shaft this much, start ``k`` towards k * 45 deg of
        the housing frame.
    :param start_clearance: at a start, the shaft's lowest rim point is this far above the
        bearing face, its tip on the bore axis.
    :param approach_distance: a reset by motion reaches the start along the bore axis from this
        far above it (clear of the counterbore).
    :param max_lateral_offset: the episode ends when the tip leaves the bore axis this far.
    """
    hole_position: tuple[float, ...] = (0.45, 0.0, 0.25)
    housing_yaw: float = 0.0
    housing_tilt: float = 0.0
    hole_radius: float = 0.006
    bore_depth: float = 0.012
    counterbore_depth: float = 0.006
    counterbore_extra_radius: float = 0.004
    plunger_travel: float = 0.004
    success_tolerance: float = 0.0005
    shaft_radius: float = 0.0059
    shaft_length: float = 0.1
    grasp_height: float = 0.06
    start_tilt: float = math.radians(15.0)
    start_clearance: float = 0.0005
    approach_distance: float = 0.03
    max_lateral_offset: float = 0.015

    def __post_init__(self) -> None:
        if len(self.hole_position) != 3 or not all(map(math.isfinite, self.hole_position)):
            raise ValueError(f"hole_position needs 3 finite entries, got {self.hole_position}")
        if not 0.0 < self.shaft_radius < self.hole_radius:
            raise ValueError(f"shaft_radius {self.shaft_radius} must be in (0, hole_radius "
                             f"{self.hole_radius})")
        if not 0.0 < self.grasp_height < self.shaft_length:
            raise ValueError(f"grasp_height {self.grasp_height} must be in (0, shaft_length "
                             f"{self.shaft_length})")
        for name in ("bore_depth", "counterbore_depth", "counterbore_extra_radius",
                     "plunger_travel", "success_tolerance", "max_lateral_offset"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not self.success_tolerance < self.plunger_travel:
            raise ValueError(f"success_tolerance {self.success_tolerance} must be below the "
                             f"plunger_travel {self.plunger_travel}")
        for name in ("start_clearance", "approach_distance"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.start_tilt < math.pi / 4:
            raise ValueError(f"start_tilt must be in [0, pi/4) rad, got {self.start_tilt}")
        if not abs(self.housing_tilt) <= math.radians(20.0):
            raise ValueError(f"housing_tilt must be within +-20 deg (the arm's reach around the "
                             f"start poses), got {self.housing_tilt} rad")
        if not math.isfinite(self.housing_yaw):
            raise ValueError(f"housing_yaw must be finite, got {self.housing_yaw}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ShaftTaskGeometry:
        """From the ``shaft_task`` section of ``config/shaft_task.yaml``."""
        return config_from_dict(cls, params)

    # --- the fixture and the target ----------------------------------------------------------
    @property
    def full_depth(self) -> float:
        """[m] the tip's depth below the bearing face when fully inserted."""
        return self.bore_depth + self.plunger_travel

    @property
    def shaft_centre(self) -> np.ndarray:
        """(3,) the shaft's centre (of mass) in the tool frame [m]: on its axis, half its length
        above the tip."""
        return np.array([0.0, 0.0, self.grasp_height - self.shaft_length / 2])

    def fixture(self) -> Fixture:
        """Where the cell believes the housing is."""
        return Fixture(np.asarray(self.hole_position, float),
                       housing_rotation(self.housing_yaw, self.housing_tilt))

    def bore_axis(self) -> np.ndarray:
        """(3,) unit vector, base frame: the bore's axis, pointing into the bore (tip first)."""
        return -self.fixture().rotation[:, 2]

    def target_tool_position(self, fixture: Fixture | None = None) -> np.ndarray:
        """(3,) the tool position with the shaft on the bore axis and fully inserted."""
        f = fixture or self.fixture()
        return f.position + f.rotation @ np.array([0.0, 0.0, self.grasp_height - self.full_depth])

    # --- the starts --------------------------------------------------------------------------
    def start_pose(self, index: int, jitter: tuple[np.ndarray, np.ndarray] | None = None
                   ) -> StartPose:
        """Start ``index`` (0..7): the shaft tilted by ``start_tilt`` towards index * 45 deg in
        the housing frame, its tip on the bore axis, its lowest rim point ``start_clearance``
        above the bearing face; reached along the bore axis from ``approach_distance`` above.

        :param jitter: ``(tilt vector change [rad], tip offset [m])`` in the housing's x/y: how far
            a simulated arm misses the taught start (its imperfections), ``None``: none.
        """
        if not 0 <= index < N_START_POSES:
            raise ValueError(f"start index must be in 0..{N_START_POSES - 1}, got {index}")
        angle, phi = self.start_tilt, index * 2.0 * math.pi / N_START_POSES
        tip = np.zeros(3)
        if jitter is not None:
            vector = angle * np.array([math.cos(phi), math.sin(phi)]) + jitter[0]
            angle, phi = math.hypot(*vector.tolist()), math.atan2(vector[1], vector[0])
            tip[:2] = jitter[1]
        axis_up = np.array([math.sin(angle) * math.cos(phi),
                            math.sin(angle) * math.sin(phi), math.cos(angle)])
        tip[2] = self.start_clearance + self.shaft_radius * math.sin(angle)
        tilt = axis_angle_matrix(np.array([-math.sin(phi), math.cos(phi), 0.0]), angle)
        fixture = self.fixture()
        housing = fixture.rotation
        tip = fixture.position + housing @ tip
        return StartPose(position=tip + self.grasp_height * (housing @ axis_up),
                         rotation=housing @ tilt @ TOOL_DOWN,
                         approach=self.approach_distance * self.bore_axis(), label=index)

    # --- how far a pose is from the goal -------------------------------------------------------
    def measure(self, position: np.ndarray, rotation: np.ndarray,
                fixture: Fixture | None = None) -> TaskMeasure:
        """The task's errors of the tool pose ``position``, ``rotation`` (base frame).

        :param fixture: the housing's pose to measure against; ``None``: the cell's
            (``fixture()``). A simulation passes its true housing for the ground truth.
        """
        f = fixture or self.fixture()
        position = np.asarray(position, float)
        rotation = np.asarray(rotation, float)
        tip = position + self.grasp_height * rotation[:, 2]
        tip_in_housing = f.rotation.T @ (tip - f.position)
        tilt, axis = tilt_from_down(f.rotation.T @ rotation)
        error = rotation.T @ (f.rotation @ axis * tilt)
        depth = float(-tip_in_housing[2])
        return TaskMeasure(
            insertion_depth=depth,
            lateral_offset=float(math.hypot(tip_in_housing[0], tip_in_housing[1])),
            position_error=float(np.linalg.norm(position - self.target_tool_position(f))),
            orientation_error=error[:2].copy(), tilt=float(tilt),
            inserted=bool(depth >= self.full_depth - self.success_tolerance))


#: The task's parameters (``shaft_task.*``), declared by every node that needs the cell: the
#: simulated robot (its scene) and the executor (its target and starts). Sizes positive.
SHAFT_TASK_SECTION = ParameterSection("shaft_task", ShaftTaskGeometry, ranges={
    **{name: POSITIVE for name in ("hole_radius", "bore_depth", "counterbore_depth",
                                   "counterbore_extra_radius", "plunger_travel",
                                   "success_tolerance", "shaft_radius", "shaft_length",
                                   "grasp_height", "start_clearance", "approach_distance",
                                   "max_lateral_offset")},
    "start_tilt": (0.0, math.pi / 4), "housing_tilt": (-math.radians(20.0), math.radians(20.0))})
#: Where its defaults are: ``(package, file)`` in ``share/<package>/config``.
SHAFT_TASK_FILE = ("qg_common", "shaft_task.yaml")
