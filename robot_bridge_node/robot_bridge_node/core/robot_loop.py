"""The torque robot's 1 kHz loop: read, estimate the contact wrench, control, limit, write.

One plain Python method per millisecond (``tick``) composes the hardware interface, the wrench
estimator, the hybrid controller and the safety filter; the loop core (``loop_core``) runs the
ticks of an RL step until the rest detector ends it, and resets. The ROS nodes only publish what
the loop produced, so the same loop runs in tests, benchmarks, lockstep training and realtime
mode. The loop sees the robot only through ``core/hardware_interface.py``: which robot it is
was decided by the plugin loaded.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from qg_common.types import JointState, StartPose, WrenchSetpoint

from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import Robot, SimulationInterface, TorqueInterface
from robot_bridge_node.core.impedance import HybridImpedanceController, ImpedanceConfig
from robot_bridge_node.core.loop_clock import LoopClock
from robot_bridge_node.core.loop_core import LoopConfig, LoopCore
from robot_bridge_node.core.reset_motion import move_to_start
from robot_bridge_node.core.rest_detector import RestConfig, RestDetector
from robot_bridge_node.core.safety import SafetyFilter, SafetyLimits
from robot_bridge_node.core.start_motion import JointHold, ResetConfig
from robot_bridge_node.core.wrench_source import WrenchEstimator

__all__ = ["RobotLoop", "build_loop"]

_HOLD = WrenchSetpoint(np.zeros(6))


class RobotLoop(LoopCore):
    """One episode's 1 kHz torque control of the robot.

    :param hardware: read and written once per tick.
    :param controller: the hybrid force/impedance law: setpoint in, torques out.
    :param safety: limits every setpoint and every torque written (never optional).
    :param rest_detector: ends an RL step at rest or at its time limit.
    :param estimator: contact-wrench estimator updated every tick; ``None`` runs without one.
    :param simulation: a simulation's extra powers (teleporting to a start, ground truth);
        ``None`` on real hardware, where a reset is always a motion (``reset_motion``).
    :param clock: the loop's time; default ``TickClock``: every tick one ``config.dt``.
    :param reset_config: how ``reset`` gets the arm to a start; default ``ResetConfig()``.
    """

    hardware: TorqueInterface
    controller: HybridImpedanceController

    def __init__(self, hardware: TorqueInterface, controller: HybridImpedanceController,
                 safety: SafetyFilter, rest_detector: RestDetector,
                 estimator: WrenchEstimator | None = None, config: LoopConfig | None = None,
                 simulation: SimulationInterface | None = None,
                 clock: LoopClock | None = None,
                 reset_config: ResetConfig | None = None) -> None:
        super().__init__(hardware, controller, rest_detector, estimator, config, simulation,
                         clock, reset_config)
        self.safety = safety
        self.setpoint = _HOLD
        self.holding = False
        self.stepping = False      # a step is under way (commanded, not yet at rest)

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

    def _move_to(self, start: StartPose) -> None:
        """Out of the fixture, then the start motion (``reset_motion.move_to_start``)."""
        move_to_start(self, start)

    def joint_tick(self, law: JointHold, q_target: np.ndarray,
                   dq_target: np.ndarray) -> JointState:
        """One control period under a reset's joint law (the safety filter's torque limits
        still apply); the state it acted on."""
        state = self.hardware.read()
        dt = self.clock.period()
        self.commanded = self.safety.limit_torques(law.torque(state.q, state.dq, q_target,
                                                             dq_target), dt, state.dq)
        self.hardware.write(self.commanded)
        self._count(dt)
        return state

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
        dt = self._sense(state)
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
        self._count(dt)
        done = self.rest.update(*self.controller.tool.speeds(), dt)
        if done and self.stepping:
            # The step is over: the watchdog's window for the next setpoint opens now. During a
            # step its setpoint holds (the rest detector's time limit bounds it), so a
            # commander sends one message per RL step, not a keep-alive stream.
            self.stepping = False
            self.safety.feed_watchdog(self.time)
        return done


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
