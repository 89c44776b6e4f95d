"""What every 1 kHz loop does, whatever its robot's control: the clock, resets, an RL step to rest.

An RL step is one setpoint, ticked until the rest detector says the arm is at rest or the step's
time is up; a reset puts the arm at a start (a simulation's teleport, or a motion) and holds it
there for ``settle_time``. The tick itself, how a setpoint becomes commands, is the robot's:
``robot_loop.RobotLoop`` writes torques through the hybrid controller and the safety filter,
``position_loop.PositionLoop`` joint targets through the task-space position controller.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from qg_common.params import config_from_dict
from qg_common.types import (
    NO_GROUND_TRUTH,
    GroundTruth,
    JointState,
    StartPose,
    StepResult,
    WrenchSetpoint,
)

from robot_bridge_node.core.hardware_interface import SimulationInterface
from robot_bridge_node.core.loop_clock import LoopClock, TickClock
from robot_bridge_node.core.rest_detector import RestDetector
from robot_bridge_node.core.start_motion import ResetConfig
from robot_bridge_node.core.wrench_source import WrenchEstimator

__all__ = ["LoopConfig", "LoopCore"]


@dataclass(frozen=True)
class LoopConfig:
    """Loop timing."""
    dt: float = 0.001              # [s] tick period (= the simulator step)
    settle_time: float = 0.1       # [s] holding the start pose after a reset
    realtime: bool = False         # watchdog on: hold the pose when no step follows a step

    def __post_init__(self) -> None:
        if not 0.0 < self.dt <= 0.01:
            raise ValueError(f"dt must be in (0, 0.01] s, got {self.dt}")
        if self.settle_time < 0.0:
            raise ValueError(f"settle_time must be >= 0, got {self.settle_time}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> LoopConfig:
        """From the ``loop`` section of ``config/bridge.yaml``."""
        return config_from_dict(cls, params)


class ReadsJoints(Protocol):
    """The hardware as the loop core needs it: the joints' state (both interfaces have it)."""

    def read(self) -> JointState: ...


class LoopCore(ABC):
    """One episode's 1 kHz control of a robot, but for the tick.

    :param hardware: read (and written by the tick) once per tick.
    :param controller: turns setpoints into commands; its ``tool`` is the tool's state the rest
        detector and the step's result read, its ``model.nv`` the number of joints.
    :param rest_detector: ends an RL step at rest or at its time limit.
    :param estimator: contact-wrench source updated every tick; ``None`` runs without one.
    :param config: the loop's timing.
    :param simulation: a simulation's extra powers (teleporting to a start, ground truth);
        ``None`` on real hardware, where a reset is always a motion and the ground truth reads
        as zeros.
    :param clock: the loop's time; default ``TickClock``: every tick one ``config.dt``.
    :param reset_config: how ``reset`` gets the arm to a start; default ``ResetConfig()``.
    """

    def __init__(self, hardware: ReadsJoints, controller: Any, rest_detector: RestDetector,
                 estimator: WrenchEstimator | None = None, config: LoopConfig | None = None,
                 simulation: SimulationInterface | None = None,
                 clock: LoopClock | None = None,
                 reset_config: ResetConfig | None = None) -> None:
        self.hardware = hardware
        self.simulation = simulation
        self.controller = controller
        self.rest = rest_detector
        self.estimator = estimator
        self.config = config or LoopConfig()
        self.reset_config = reset_config or ResetConfig()
        self.clock: LoopClock = clock or TickClock(self.config.dt)
        self.wrench_estimate: np.ndarray | None = None
        self.watchdog_holds = 0    # holds the realtime watchdog began (the commander was late)
        self.ticks = 0             # since the last reset
        self.ticks_run = 0         # since the loop was built (a reset's motion included)
        #: (n,) the torques last written (a position robot's loop writes targets: zeros)
        self.commanded = np.zeros(controller.model.nv)
        self.recovered = ""        # what the last recovery from a fault did

    @property
    def time(self) -> float:
        """[s] robot time since the last reset, on the loop's ``clock``."""
        return self.clock.time

    @property
    def teleports(self) -> bool:
        """Whether ``reset`` puts the arm at the start at once (a simulation's shortcut)."""
        return self.simulation is not None and self.reset_config.teleport

    @abstractmethod
    def begin(self) -> None:
        """Restart the clock where the arm is and hold it there until the first setpoint or
        reset: what the loop does when it starts (a robot is never moved at start-up)."""

    @abstractmethod
    def command(self, setpoint: WrenchSetpoint) -> None:
        """Start executing ``setpoint``.

        :raises SetpointRejected: if it is refused; the previous command stays.
        """

    @abstractmethod
    def feed_watchdog(self) -> None:
        """The running setpoint was repeated: keep it (no new step)."""

    @abstractmethod
    def tick(self) -> bool:
        """One control period. True when the current step has come to rest or timed out."""

    @abstractmethod
    def _move_to(self, start: StartPose) -> None:
        """Move the arm to ``start`` (a reset without a teleport).

        :raises RuntimeError: if the start is out of reach or not reached in time.
        """

    def reset(self, start: StartPose) -> None:
        """New episode: the arm at ``start``, settled there holding that pose.

        A simulation with ``reset.teleport`` puts it there at once; any other robot is moved
        there (``_move_to``).
        :raises RuntimeError: if the start is out of reach (the motion is not begun).
        """
        self.recover()
        if self.teleports:
            self.simulation.teleport(start)
        else:
            self._move_to(start)
        self.settle_here()

    def recover(self) -> str:
        """Take the robot out of a fault (``Recoverable``: a Franka's error recovery) before it
        is moved again; what was done ("" if there was no fault).

        :raises HardwareFault: if the robot refuses to recover.
        """
        if getattr(self.hardware, "fault", None) is None:
            return ""
        self.recovered = self.hardware.recover()
        return self.recovered

    def settle_here(self) -> None:
        """Restart the episode's clock and the estimator where the arm is and hold it there
        (``begin``) for ``settle_time``: the end of every reset; alone, after a separate
        simulation put the arm at its start. The first setpoint releases the hold."""
        self.begin()
        for _ in range(round(self.config.settle_time / self.config.dt)):
            self.tick()

    def execute(self, setpoint: WrenchSetpoint) -> StepResult:
        """Run one RL step: command ``setpoint`` and tick until at rest or the step times out."""
        start = self.time
        self.command(setpoint)
        while not self.tick():
            pass
        return self.result(start)

    def ground_truth(self) -> GroundTruth:
        """The simulation's truth now; zeros on real hardware."""
        return NO_GROUND_TRUTH if self.simulation is None else self.simulation.ground_truth()

    def result(self, start: float, fault: str = "") -> StepResult:
        """How the step that started at loop time ``start`` [s] ended (its at-rest event);
        ``fault``: the robot stopped it, and why."""
        tool = self.controller.tool
        return StepResult(duration=self.time - start, timed_out=self.rest.timed_out,
                          linear_speed=tool.linear_speed, angular_speed=tool.angular_speed,
                          ground_truth=self.ground_truth(),
                          wrench_estimate=None if self.wrench_estimate is None
                          else self.wrench_estimate.copy(), fault=fault)

    def _restart(self) -> JointState:
        """Restart the clock and the estimator at the arm's state now."""
        self.ticks = 0
        state = self.hardware.read()
        self.clock.restart()
        if self.estimator is not None:
            self.estimator.reset(state.q)
        return state

    def _sense(self, state: JointState) -> float:
        """The period of the tick under way (its ``state`` just read), and the wrench
        estimate updated with that state."""
        dt = self.clock.period()
        if self.estimator is not None and dt > 0.0:   # (0: the same state read again)
            self.wrench_estimate = self.estimator.update(state.q, state.dq, state.tau, dt)
        return dt

    def _count(self, dt: float) -> None:
        """The tick under way, of period ``dt``, is done: counted and on the clock."""
        self.ticks += 1
        self.ticks_run += 1
        self.clock.advance(dt)
