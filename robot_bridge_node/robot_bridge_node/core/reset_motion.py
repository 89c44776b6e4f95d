"""A torque loop's reset by motion: the part out of its fixture, then the start motion, ticked.

``start_motion`` plans the path (back out, a joint motion, the approach) and the joint law that
tracks it; here the loop runs them tick by tick. First the held part comes out compliantly,
under the task's controller, along the start's approach axis; then the joints follow the plan
and hold the start until they are there and still.
"""
from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from qg_common.types import JointState, StartPose, WrenchSetpoint

from robot_bridge_node.core.hardware_interface import TorqueInterface
from robot_bridge_node.core.impedance import HybridImpedanceController
from robot_bridge_node.core.loop_core import LoopConfig
from robot_bridge_node.core.safety import SafetyFilter
from robot_bridge_node.core.start_motion import JointHold, ResetConfig, StartMotion

__all__ = ["TorqueTicks", "move_to_start", "retreat"]


class TorqueTicks(Protocol):
    """What the reset motion drives: a torque loop (``robot_loop.RobotLoop``)."""

    hardware: TorqueInterface
    controller: HybridImpedanceController
    safety: SafetyFilter
    config: LoopConfig
    reset_config: ResetConfig
    setpoint: WrenchSetpoint
    holding: bool

    @property
    def time(self) -> float: ...

    def begin(self) -> None: ...

    def tick(self) -> bool: ...

    def command(self, setpoint: WrenchSetpoint) -> None: ...

    def feed_watchdog(self) -> None: ...

    def joint_tick(self, law: JointHold, q_target: np.ndarray,
                   dq_target: np.ndarray) -> JointState: ...


def move_to_start(loop: TorqueTicks, start: StartPose) -> None:
    """Tick through the motion to ``start`` under the joint impedance law, then hold its
    joints until they are there and still (see ``start_motion``).

    :raises RuntimeError: if the start is out of reach (nothing moved), or not reached in
        ``reset.arrive_timeout`` after the path.
    """
    config = loop.reset_config
    retreat(loop, start)
    motion = StartMotion(loop.controller.model, loop.hardware.read().q, start, config)
    law = JointHold(loop.controller.model, config)
    loop.holding = True                  # the watchdog leaves a moving arm alone
    dt = loop.config.dt
    began, target = loop.time, motion.at(0.0)
    while loop.time - began <= motion.duration:
        following = motion.at(loop.time - began + dt)
        loop.joint_tick(law, target, (following - target) / dt)
        target = following
    # Holding the start: its joint targets moved by the integral of the joints' error, which
    # takes out what the model does not know (an unknown payload's weight: 1 mm at the tool).
    began, still, shift = loop.time, np.zeros_like(target), np.zeros_like(target)
    while loop.time - began < config.arrive_timeout:
        state = loop.joint_tick(law, motion.q_start + shift, still)
        shift += config.arrive_gain * dt * (motion.q_start - state.q)
        off, turned = motion.error(state.q)
        if (off < config.arrive_tolerance and turned < config.arrive_angle
                and np.max(np.abs(state.dq)) < config.arrive_speed):
            return
    raise RuntimeError(f"the arm did not arrive at the start within {config.arrive_timeout} "
                       f"s ({off * 1e3:.2f} mm, {math.degrees(turned):.2f} deg off)")


def retreat(loop: TorqueTicks, start: StartPose) -> None:
    """Pull the held part out of its fixture along the start's approach axis under the task's
    compliant controller, until the tool is level with ``start``'s approach point. The pull is
    ``reset.withdraw_force`` and grows to ``reset.withdraw_force_max`` (at most the safety
    filter's ``force_max``) over the first half of ``reset.withdraw_timeout`` while the part
    stays in.

    Along the fixture's axis, not the tool's own: a tilted part pulled along itself presses
    sideways into the fixture's rim and jams. The rotation stays free (zero torques): the part
    aligns with the fixture as it comes out.

    :raises RuntimeError: if it is not out within ``reset.withdraw_timeout``.
    """
    config = loop.reset_config
    approach = np.asarray(start.approach, float)
    length = float(np.linalg.norm(approach))
    if length == 0.0:
        return
    axis, entry = approach / length, np.asarray(start.position, float) - approach
    outwards = -axis             # from the start towards the approach point, base frame

    def inside() -> float:
        """[m] how far the tool is short of the approach point's level."""
        return float(np.dot(loop.controller.tool.position - entry, axis))

    loop.begin()
    loop.tick()                                      # holding: the tool pose of the arm now
    if inside() <= 0.0:
        return
    began = loop.time
    strongest = max(min(loop.safety.limits.force_max, config.withdraw_force_max),
                    config.withdraw_force)
    ramp = 0.5 * config.withdraw_timeout
    loop.command(WrenchSetpoint(np.zeros(6)))
    while inside() > 0.0:
        elapsed = loop.time - began
        if elapsed > config.withdraw_timeout:
            loop.begin()                             # hold it where it stuck
            raise RuntimeError(f"the part did not come out of the fixture within "
                               f"{config.withdraw_timeout} s ({inside() * 1e3:.1f} mm short "
                               f"of the approach point)")
        pull = config.withdraw_force + (strongest - config.withdraw_force) * min(
            1.0, elapsed / ramp)
        # The setpoint's force is the contact's on the tool, in the tool's frame: a pull
        # outwards is the opposite of that direction.
        force = -pull * (loop.controller.tool.rotation.T @ outwards)
        loop.setpoint = WrenchSetpoint(np.concatenate([force, np.zeros(3)]))
        # The pull is the loop's own motion, not a commander's step: a jammed part rests for
        # the rest detector's 20 ms before it breaks free, and the realtime watchdog would then
        # hold it stiffly.
        loop.feed_watchdog()
        loop.tick()
    loop.begin()
