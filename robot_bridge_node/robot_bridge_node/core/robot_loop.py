"""The 1 kHz loop: read the robot, estimate the contact wrench, control, limit, apply, step.

One plain Python method per millisecond (``tick``) composes the hardware interface, the wrench
estimator, the hybrid controller and the safety filter; ``execute`` runs ticks for one RL step
until the rest detector ends it. The ROS nodes only publish what the loop produced, so the same
loop runs in tests, benchmarks, lockstep training and realtime mode. The loop sees the robot only
through ``core/hardware_interface.py``: which robot it is was decided by the plugin loaded.
"""
from __future__ import annotations

import math
from collections.abc import Callable
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

from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import (
    Robot,
    SimulationInterface,
    StampedStates,
    TorqueInterface,
)
from robot_bridge_node.core.impedance import HybridImpedanceController, ImpedanceConfig
from robot_bridge_node.core.rest_detector import RestConfig, RestDetector
from robot_bridge_node.core.safety import SafetyFilter, SafetyLimits
from robot_bridge_node.core.start_motion import JointHold, ResetConfig, StartMotion

__all__ = ["WrenchEstimator", "MeasuredWrench", "LoopConfig", "LoopClock", "TickClock",
           "StateClock", "MAX_STATE_GAP", "RobotLoop", "build_loop"]


class WrenchEstimator(Protocol):
    """Plug-in contact-wrench estimator (the EKF in ``wrench_ekf``)."""

    def reset(self, q: np.ndarray) -> None: ...

    def update(self, q: np.ndarray, dq: np.ndarray, tau_cmd: np.ndarray,
               dt: float) -> np.ndarray:
        """(6,) contact wrench ``(Fx, Fy, Fz, Tx, Ty, Tz)`` on the tool, tool frame."""
        ...


class MeasuredWrench:
    """A wrench source that reads a measurement instead of estimating one: a wrist force-torque
    sensor (``sensor.read_wrench``), or in simulation the true contact wrench
    (``simulation.contact_wrench``), a perfect sensor for tests and for comparing with the EKF.

    :param read: returns the (6,) wrench ``(Fx, Fy, Fz, Tx, Ty, Tz)`` on the tool, tool frame.
    """

    def __init__(self, read: Callable[[], np.ndarray]) -> None:
        self.read = read

    def reset(self, q: np.ndarray) -> None:
        del q

    def update(self, q: np.ndarray, dq: np.ndarray, tau_cmd: np.ndarray,
               dt: float) -> np.ndarray:
        del q, dq, tau_cmd, dt
        return self.read()


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


class LoopClock(Protocol):
    """The loop's time since the last reset, which the controller's, the safety filter's and the
    rest detector's ``dt``, the watchdog and a step's time limit all run on."""

    @property
    def time(self) -> float:
        """[s] since the last reset, up to the last tick ``advance``d."""
        ...

    def restart(self) -> None:
        """Time 0 is now (the hardware's state was just read after a reset)."""
        ...

    def period(self) -> float:
        """[s] how much time the tick under way covers (its state was just read)."""
        ...

    def advance(self, dt: float) -> None:
        """The tick under way, of ``period`` ``dt``, is done."""
        ...


class TickClock:
    """Every tick is one control period: the robot's state advances by exactly ``dt`` between
    reads (an in-process simulation steps in ``write``; a real arm's 1 kHz loop)."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.ticks = 0

    @property
    def time(self) -> float:
        return self.ticks * self.dt

    def restart(self) -> None:
        self.ticks = 0

    def period(self) -> float:
        return self.dt

    def advance(self, dt: float) -> None:
        del dt
        self.ticks += 1


#: [s] The most one tick on a ``StateClock`` counts: a longer gap between states (the loop, the
#: robot or the link between them stalled) counts as this long, so one hiccup cannot end a step.
#: It is the separate sim's ``command_timeout``, after which that sim holds the arm itself.
MAX_STATE_GAP = 0.02


class StateClock:
    """The time of the states read: a tick covers the time from the previous state's stamp to
    its own. A loop that misses states (a busy machine, states over topics) still ends a step
    at its time limit of the robot's time instead of after that many ticks.

    :param hardware: reports when the state it returned was measured.
    :param max_period: [s] the most one tick counts: a longer gap (the robot's process stalled,
        or the loop did) is counted as this long, so one hiccup cannot end a step.
    """

    def __init__(self, hardware: StampedStates, max_period: float) -> None:
        if max_period <= 0.0:
            raise ValueError(f"max_period must be > 0, got {max_period}")
        self.hardware = hardware
        self.max_period = max_period
        self.time = 0.0
        self._last = 0.0       # stamp of the last tick's state
        self._current = 0.0    # stamp of the state the tick under way read

    def restart(self) -> None:
        self.time = 0.0
        self._last = self._current = self.hardware.state_time()

    def period(self) -> float:
        """The stamp difference, in ``[0, max_period]`` (0: the same state read again)."""
        self._current = max(self._last, self.hardware.state_time())
        return min(self._current - self._last, self.max_period)

    def advance(self, dt: float) -> None:
        self.time += dt
        self._last = self._current


_HOLD = WrenchSetpoint(np.zeros(6))


class RobotLoop:
    """Owns one episode's 1 kHz control of the robot.

    :param hardware: read and written once per tick.
    :param estimator: contact-wrench estimator updated every tick; ``None`` runs without one.
    :param simulation: a simulation's extra powers (teleporting to a start, ground truth);
        ``None`` on real hardware, where a reset is always a motion and the ground truth reads
        as zeros.
    :param clock: the loop's time; default ``TickClock``: every tick one ``config.dt``.
    :param reset_config: how ``reset`` gets the arm to a start; default ``ResetConfig()``.
    """

    def __init__(self, hardware: TorqueInterface, controller: HybridImpedanceController,
                 safety: SafetyFilter, rest_detector: RestDetector,
                 estimator: WrenchEstimator | None = None, config: LoopConfig | None = None,
                 simulation: SimulationInterface | None = None,
                 clock: LoopClock | None = None,
                 reset_config: ResetConfig | None = None) -> None:
        self.hardware = hardware
        self.simulation = simulation
        self.controller = controller
        self.safety = safety
        self.rest = rest_detector
        self.estimator = estimator
        self.config = config or LoopConfig()
        self.reset_config = reset_config or ResetConfig()
        self.clock: LoopClock = clock or TickClock(self.config.dt)
        self.setpoint = _HOLD
        self.wrench_estimate: np.ndarray | None = None
        self.holding = False
        self.stepping = False      # a step is under way (commanded, not yet at rest)
        self.watchdog_holds = 0    # holds the watchdog began (the commander was late)
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

    def begin(self) -> None:
        """Take the arm where it is and hold it there, stiffly (the holding gains: the task's
        leave z free), until the first setpoint or reset: what the loop does when it starts (a
        robot is never moved at start-up), and after a reset."""
        state = self._restart()
        self.controller.reset(state.q)
        self.safety.reset(self.controller.model.gravity(state.q))
        self.setpoint = _HOLD
        self.controller.hold(state.q)
        self.holding = True
        self.stepping = False

    def reset(self, start: StartPose) -> None:
        """New episode: the arm at ``start``, settled there holding that pose.

        A simulation with ``reset.teleport`` puts it there at once; any other robot is moved
        there (``start_motion``: out along the approach axis, a joint motion, in along it).
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
        self._settle()

    def _move_to(self, start: StartPose) -> None:
        """Tick through the motion to ``start`` under the joint impedance law, then hold its
        joints until they are there and still (see ``start_motion``).

        :raises RuntimeError: if the start is out of reach (nothing moved), or not reached in
            ``reset.arrive_timeout`` after the path.
        """
        config = self.reset_config
        self._withdraw(start)
        motion = StartMotion(self.controller.model, self.hardware.read().q, start, config)
        law = JointHold(self.controller.model, config)
        self.holding = True                  # the watchdog leaves a moving arm alone
        began, target = self.time, motion.at(0.0)
        while self.time - began <= motion.duration:
            following = motion.at(self.time - began + self.config.dt)
            self._joint_tick(law, target, (following - target) / self.config.dt)
            target = following
        # Holding the start: its joint targets moved by the integral of the joints' error, which
        # takes out what the model does not know (an unknown payload's weight: 1 mm at the tool).
        began, still, shift = self.time, np.zeros_like(target), np.zeros_like(target)
        while self.time - began < config.arrive_timeout:
            state = self._joint_tick(law, motion.q_start + shift, still)
            shift += config.arrive_gain * self.config.dt * (motion.q_start - state.q)
            off, turned = motion.error(state.q)
            if (off < config.arrive_tolerance and turned < config.arrive_angle
                    and np.max(np.abs(state.dq)) < config.arrive_speed):
                return
        raise RuntimeError(f"the arm did not arrive at the start within {config.arrive_timeout} "
                           f"s ({off * 1e3:.2f} mm, {math.degrees(turned):.2f} deg off)")

    def _withdraw(self, start: StartPose) -> None:
        """Pull the part out of the fixture along the bore's axis (the start's approach) under
        the task's compliant controller, until the tool is level with ``start``'s approach
        point (see ``start_motion``). The pull is ``reset.withdraw_force`` and grows to
        ``reset.withdraw_force_max`` (at most the safety filter's ``force_max``) over the first
        half of ``reset.withdraw_timeout`` while the part stays in.

        Along the bore, not the tool's own axis: a tilted shaft pulled along itself presses
        sideways into the counterbore. On franky-sim a demo's resets failed 13 times in its
        first 15 episodes with a 10 N pull along the shaft, and in 2 of 48 with this pull. The
        rotation stays free (zero torques): the shaft aligns with the bore as it comes out.

        :raises RuntimeError: if it is not out within ``reset.withdraw_timeout``.
        """
        config = self.reset_config
        approach = np.asarray(start.approach, float)
        length = float(np.linalg.norm(approach))
        if length == 0.0:
            return
        axis, entry = approach / length, np.asarray(start.position, float) - approach
        out_of_bore = -axis          # from the start towards the approach point, base frame

        def inside() -> float:
            """[m] how far the tool is short of the approach point's level."""
            return float(np.dot(self.controller.tool.position - entry, axis))

        self.begin()
        self.tick()                                      # holding: the tool pose of the arm now
        if inside() <= 0.0:
            return
        began = self.time
        strongest = max(min(self.safety.limits.force_max, config.withdraw_force_max),
                        config.withdraw_force)
        ramp = 0.5 * config.withdraw_timeout
        self.command(WrenchSetpoint(np.zeros(6)))
        while inside() > 0.0:
            elapsed = self.time - began
            if elapsed > config.withdraw_timeout:
                self.begin()                             # hold it where it stuck
                raise RuntimeError(f"the part did not come out of the fixture within "
                                   f"{config.withdraw_timeout} s ({inside() * 1e3:.1f} mm short "
                                   f"of the approach point)")
            pull = config.withdraw_force + (strongest - config.withdraw_force) * min(
                1.0, elapsed / ramp)
            # The setpoint's force is the contact's on the tool, in the tool's frame: a pull
            # out of the bore is the opposite of that direction.
            force = -pull * (self.controller.tool.rotation.T @ out_of_bore)
            self.setpoint = WrenchSetpoint(np.concatenate([force, np.zeros(3)]))
            # The pull is the loop's own motion, not a commander's step: a jammed part rests
            # for the rest detector's 20 ms before it breaks free, and the realtime watchdog
            # then held it stiffly 0.1 s later (franky-sim: every reset after a jam failed).
            self.feed_watchdog()
            self.tick()
        self.begin()

    def _joint_tick(self, law: JointHold, q_target: np.ndarray,
                    dq_target: np.ndarray) -> JointState:
        """One control period under the reset's joint law (the safety filter's torque limits
        still apply); the state it acted on."""
        state = self.hardware.read()
        dt = self.clock.period()
        self.commanded = self.safety.limit_torques(law.torque(state.q, state.dq, q_target,
                                                             dq_target), dt, state.dq)
        self.hardware.write(self.commanded)
        self.ticks += 1
        self.ticks_run += 1
        self.clock.advance(dt)
        return state

    def _restart(self) -> JointState:
        """Restart the clock and the estimator at the arm's state now."""
        self.ticks = 0
        state = self.hardware.read()
        self.clock.restart()
        if self.estimator is not None:
            self.estimator.reset(state.q)
        return state

    def _settle(self) -> None:
        """Hold the start for ``settle_time``."""
        for _ in range(round(self.config.settle_time / self.config.dt)):
            self.tick()

    def command(self, setpoint: WrenchSetpoint) -> None:
        """Start executing ``setpoint`` (the residual policy's reference is the current pose).

        :raises SetpointRejected: if the safety filter refuses it; the previous command stays.
        """
        checked = self.safety.check_setpoint(setpoint)
        if checked.reference is None:
            self.controller.set_reference_to_current(self.hardware.read().q)
        self.setpoint = checked
        if self.holding:
            self.controller.release()
            self.holding = False
        self.safety.feed_watchdog(self.time)
        self.rest.reset()
        self.stepping = True

    def feed_watchdog(self) -> None:
        """The running setpoint was repeated: the realtime watchdog keeps it (no new step)."""
        self.safety.feed_watchdog(self.time)

    def tick(self) -> bool:
        """One control period. True when the current step has come to rest or timed out."""
        state = self.hardware.read()
        dt = self.clock.period()
        if self.estimator is not None and dt > 0.0:   # (0: the same state read again)
            self.wrench_estimate = self.estimator.update(state.q, state.dq, state.tau, dt)
        if (self.config.realtime and not self.holding and not self.stepping
                and self.safety.watchdog_expired(self.time)):
            # No step followed the last one in time: the commander is late or gone. Hold the
            # pose, stiff along every axis (the task's force-controlled z included; see
            # HybridImpedanceController.hold) until its next setpoint.
            self.controller.hold(state.q)
            self.setpoint = _HOLD
            self.holding = True
            self.watchdog_holds += 1
        setpoint = self.setpoint
        tool = self.controller.tool
        if tool is not None:
            wrench = self.safety.limit_tilt(setpoint.wrench, tool.rotation)
            if wrench is not setpoint.wrench:      # (inside the cone it is the same array)
                setpoint = WrenchSetpoint(wrench, setpoint.reference)
        tau = self.safety.limit_torques(self.controller.step(state.q, state.dq, setpoint, dt), dt,
                                        state.dq)
        self.hardware.write(tau)
        self.commanded = tau
        self.ticks += 1
        self.ticks_run += 1
        self.clock.advance(dt)
        tool = self.controller.tool
        done = self.rest.update(tool.linear_speed, tool.angular_speed, dt)
        if done and self.stepping:
            # The step is over: the watchdog's window for the next setpoint opens now. During a
            # step its setpoint holds (the rest detector's time limit bounds it), so a
            # commander sends one message per RL step, not a keep-alive stream.
            self.stepping = False
            self.safety.feed_watchdog(self.time)
        return done

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


def build_loop(robot: Robot, bridge_params: dict[str, Any] | None = None,
               estimator: Callable[[Robot, ArmModel], WrenchEstimator] | None = None,
               clock: LoopClock | None = None) -> RobotLoop:
    """The loop of a torque-controlled robot with controller, safety and rest detector.

    The controller's, the safety filter's and the estimator's model is the robot's own
    (``ArmModel.from_description``: its URDF, joints, flange, tool and limits).
    :param robot: from a plugin (``hardware_interface.load_robot``).
    :param bridge_params: the ``ros__parameters`` of ``config/bridge.yaml`` (sections
        ``impedance``, ``safety``, ``rest``, ``loop``, ``reset``); missing sections keep the
        defaults.
    :param estimator: builds the wrench estimator from the robot and the controller's model,
        e.g. ``lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench)``; ``None``: none.
    :param clock: the loop's time; ``None``: one ``loop.dt`` per tick (``TickClock``).
    """
    params = bridge_params or {}
    model = ArmModel.from_description(robot.description)
    controller = HybridImpedanceController(ImpedanceConfig.from_dict(params.get("impedance", {})),
                                           model)
    safety = SafetyFilter(SafetyLimits.from_dict(params.get("safety", {})), model.limits)
    return RobotLoop(robot.hardware, controller, safety,
                     RestDetector(RestConfig.from_dict(params.get("rest", {}))),
                     None if estimator is None else estimator(robot, model),
                     LoopConfig.from_dict(params.get("loop", {})), robot.simulation, clock,
                     ResetConfig.from_dict(params.get("reset", {})))
