"""The clearance-fit peg-in-hole task as a cell knows it, with no physics engine in it (SPEC 4).

A block with a round hole stands where the cell's fixture holds it; the peg is held upright by a
position-controlled arm (the Nextage) with the tool pointing down; positions of the task are in
the workspace frame: origin on the hole axis at the block's base, z up, the workspace a cube of
side ``workspace_side`` standing on that floor. From that alone this module gives the starts
(seeded free tip positions), and the distance of a measured tool pose's peg tip to the hole
bottom, the goal. The executor computes reward and success from the tool pose the arm measures;
a simulated cell builds its scene from the same numbers (``config/peg_task.yaml``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from qg_common.params import POSITIVE, ParameterSection, config_from_dict
from qg_common.types import StartPose

__all__ = ["PegHoleGeometry", "PegCell", "TOOL_DOWN", "sample_start", "PEG_TASK_SECTION",
           "PEG_TASK_FILE"]

#: Tool orientation (base frame) with the tool z axis (the peg) pointing down and the hand's back
#: (tool x) toward the robot: the Nextage's natural working pose.
TOOL_DOWN = np.diag([-1.0, 1.0, -1.0])


@dataclass(frozen=True)
class PegHoleGeometry:
    """Sizes of the clearance-fit task (SPEC 4: peg 1 cm, hole 2 cm, 20 cm workspace).

    :param peg_radius: [m]
    :param peg_length: [m]
    :param peg_mass: [kg]
    :param hole_radius: inradius of the polygonal hole [m]
    :param hole_depth: [m]
    :param block_width: side of the square block (the thesis's 5 cm) [m]
    :param block_height: [m]
    :param ring_segments: boxes forming the round hole's wall
    :param workspace_side: side of the cubic workspace [m]
    :param goal_tolerance: the peg counts as inserted when its tip is this close to the centre
        of the hole bottom; below ``hole_depth`` that is only possible inside the hole [m]
    :param friction: lateral friction coefficient of peg and block
    """
    peg_radius: float = 0.005
    peg_length: float = 0.08
    peg_mass: float = 0.05
    hole_radius: float = 0.01
    hole_depth: float = 0.03
    block_width: float = 0.05
    block_height: float = 0.04
    ring_segments: int = 16
    workspace_side: float = 0.2
    goal_tolerance: float = 0.0075
    friction: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            if not getattr(self, f.name) > 0:
                raise ValueError(f"{f.name} must be > 0, got {getattr(self, f.name)}")
        if not self.peg_radius < self.hole_radius < self.block_width / 2 - 0.005:
            raise ValueError("need peg_radius < hole_radius < block_width/2 - 5 mm, got "
                             f"{self.peg_radius}, {self.hole_radius}, {self.block_width}")
        if not self.hole_depth < self.block_height:
            raise ValueError(f"hole_depth {self.hole_depth} must be < block_height "
                             f"{self.block_height}")
        if not self.goal_tolerance < self.hole_depth:
            raise ValueError(f"goal_tolerance {self.goal_tolerance} must be < hole_depth "
                             f"{self.hole_depth}, or the peg could succeed without entering")
        if self.ring_segments < 8:
            raise ValueError(f"ring_segments must be >= 8, got {self.ring_segments}")
        if not self.block_height < self.workspace_side:
            raise ValueError("the block must fit in the workspace")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> PegHoleGeometry:
        """Build from a parameter dict (unknown keys are an error)."""
        return config_from_dict(cls, params)

    @property
    def goal(self) -> np.ndarray:
        """Peg tip position when fully inserted: the centre of the hole bottom (workspace frame)."""
        return np.array([0.0, 0.0, self.block_height - self.hole_depth])

    @property
    def workspace_low(self) -> np.ndarray:
        """Lower corner of the workspace cube (workspace frame) [m]."""
        return np.array([-self.workspace_side / 2, -self.workspace_side / 2, 0.0])

    @property
    def workspace_high(self) -> np.ndarray:
        """Upper corner of the workspace cube (workspace frame) [m]."""
        return np.array([self.workspace_side / 2, self.workspace_side / 2, self.workspace_side])

    def is_free(self, tip: np.ndarray, margin: float = 0.002) -> bool:
        """True if an upright peg with its tip at ``tip`` clears the block by ``margin``."""
        reach = self.block_width / 2 + self.peg_radius + margin
        return bool(tip[2] > self.block_height + margin or np.max(np.abs(tip[:2])) > reach)


def sample_start(geometry: PegHoleGeometry, rng: np.random.Generator) -> np.ndarray:
    """A tip position drawn uniformly from the part of the workspace where the peg is free."""
    margin = geometry.peg_radius + 0.002
    low = geometry.workspace_low + np.array([margin, margin, 0.002])
    high = geometry.workspace_high - np.array([margin, margin, 0.0])
    while True:
        tip = rng.uniform(low, high)
        if geometry.is_free(tip):
            return tip



@dataclass(frozen=True)
class PegCell:
    """The peg task's cell: where the workspace frame is, and the parts.

    :param workspace_origin: (3,) the workspace frame's origin (hole axis, block base) in the
        robot's base frame [m]; the default puts the whole 20 cm cube inside the Nextage's
        tool-down reach.
    :param geometry: the peg, the hole and the workspace.
    """
    workspace_origin: tuple[float, ...] = (0.4, -0.15, -0.15)
    geometry: PegHoleGeometry = field(default_factory=PegHoleGeometry)

    def __post_init__(self) -> None:
        if len(self.workspace_origin) != 3 or not all(map(math.isfinite, self.workspace_origin)):
            raise ValueError(f"workspace_origin needs 3 finite entries, got "
                             f"{self.workspace_origin!r}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> PegCell:
        """From the ``peg_task`` section of ``config/peg_task.yaml`` (``geometry`` nested)."""
        return config_from_dict(cls, params)

    @property
    def origin(self) -> np.ndarray:
        return np.asarray(self.workspace_origin, float)

    def tool_position_for_tip(self, tip: np.ndarray) -> np.ndarray:
        """The tool-down tool position (base frame) that puts the peg tip at ``tip``
        (workspace frame): the tool is the peg's length above its tip."""
        return self.origin + np.asarray(tip, float) + np.array([0.0, 0.0,
                                                                self.geometry.peg_length])

    def tip(self, tool_position: np.ndarray, tool_rotation: np.ndarray) -> np.ndarray:
        """The peg tip (workspace frame) of a tool pose (base frame): the peg's length along the
        tool's z axis."""
        return (np.asarray(tool_position, float)
                + np.asarray(tool_rotation, float)[:, 2] * self.geometry.peg_length - self.origin)

    def start_pose(self, index: int) -> StartPose:
        """Start ``index``: the tip at the free position the seed ``index`` draws (the same for
        every robot and run), the tool pointing down."""
        tip = sample_start(self.geometry, np.random.default_rng(index))
        return StartPose(self.tool_position_for_tip(tip), TOOL_DOWN.copy(), label=index)


#: The peg cell's parameters (``peg_task.*``), declared by the Nextage's sim and the executor of
#: the peg task. Sizes positive.
PEG_TASK_SECTION = ParameterSection("peg_task", PegCell, ranges={
    **{f"geometry.{f.name}": POSITIVE for f in fields(PegHoleGeometry) if f.type == "float"},
    "geometry.ring_segments": (8, 10000)})
#: Where its defaults are: ``(package, file)`` in ``share/<package>/config``.
PEG_TASK_FILE = ("qg_common", "peg_task.yaml")
