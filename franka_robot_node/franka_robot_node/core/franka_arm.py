"""A Franka arm as the bridge's torque hardware interface, through libfranka (``franky``).

libfranka runs its own 1 kHz control thread: every millisecond it receives the robot's state
and must answer with a torque, or the robot stops the motion. Python must never be that answer:
a garbage collection or a busy core would miss it. So the plugin starts one
``franky.SimpleTorqueMotion`` (its C++ loop sends the last torque it was given) and our loop hands
it a new torque each tick with ``set_torque``; if our loop stalls for longer than
``signal_timeout``, the motion ends itself (``TorqueSignalTimeoutException``) instead of leaving a
stale torque on the arm.

- ``read`` returns the state of the robot's next millisecond (it waits for it, as libfranka's
  ``readOnce`` does, at most ``state_timeout``), so the loop's clock follows the robot's:
  ``state_time`` is the state's own stamp (libfranka's ``time``).
- ``write`` takes the loop's full joint torque (the bridge's law includes gravity from its model)
  and sends what libfranka expects: without gravity, which the robot adds itself. The gravity
  subtracted is libfranka's model's (``franky.Model.gravity`` with the state's end-effector and
  load), exactly what the robot adds: against franky-sim the two agree to 1e-7 Nm. A torque
  that is not finite or beyond the URDF's limits is refused (``TorqueRejected``) and never
  reaches libfranka; the change from one command to the next is held to libfranka's rate limit.
- Anything that ends the motion (a reflex, a missed signal timeout, a lost connection) raises
  ``FrankaFault`` with libfranka's reason from the next ``read`` or ``write``; the arm then
  refuses torques until ``recover`` has run libfranka's automatic error recovery.
"""
from __future__ import annotations

import logging
import socket
import threading
import time

import numpy as np
import pinocchio as pin
from qg_common.types import JointState
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import HardwareFault, RobotDescription

from franka_robot_node.core.fr3_description import FR3_FLANGE
from franka_robot_node.core.franka_config import FrankaConfig

__all__ = ["FrankaArm", "FrankaFault", "FrankaConnectError", "TorqueRejected", "FCI_PORT",
           "connect_robot", "load_in_flange"]

log = logging.getLogger(__name__)

#: libfranka's command port on the robot (franky-sim binds the same).
FCI_PORT = 1337
#: [s] How often ``read`` looks for the robot's next state while it waits.
_POLL = 5e-5
#: [kg m^2] the load's inertia for ``setLoad`` (column-major), the small one the bridge's model
#: gives a payload (``ArmModel``): gravity, which is what the robot uses it for, needs none.
_PAYLOAD_INERTIA = [1e-5, 0.0, 0.0, 0.0, 1e-5, 0.0, 0.0, 0.0, 1e-5]
#: [s] How often a refused connection is tried again until ``connect_timeout``.
_RETRY = 0.2
#: Why a connection failed, after the address.
_NO_ANSWER = "no answer within {} s (wrong address, robot off, or its network unreachable)"
_REFUSED = ("connection refused: nothing serves libfranka there (robot off, FCI not enabled in "
            "Desk, or franky-sim not started)")


class FrankaFault(HardwareFault):
    """libfranka ended the torque motion (a reflex, a missed signal timeout, the connection),
    or the robot stopped sending states: the step under way is over. The message is the reason;
    ``FrankaArm.recover`` must run before the arm takes torques again (the bridge's reset does)."""


class FrankaConnectError(ConnectionError):
    """The robot could not be reached or set up; the message names the address and why."""


class TorqueRejected(ValueError):
    """A torque command that must not reach libfranka (not finite, or beyond the joints'
    limits); nothing was sent."""


def connect_robot(config: FrankaConfig):  # -> franky.Robot (franky is imported here only)
    """``franky.Robot`` at ``config.address``, or ``FrankaConnectError`` within
    ``connect_timeout``.

    libfranka waits 60 s for an address that does not answer, spinning a whole core all the
    while, and calls a refused connection a missing FCI feature. So the command port is first
    reached with a TCP connection of our own (``_reach``), which can time out: libfranka is
    only called for an address that answers. A refused connection is retried (franky-sim may
    still be starting), the whole attempt is bounded, and the reason says which address failed
    how.
    """
    import franky
    policy = {"ignore": franky.RealtimeConfig.Ignore,
              "enforce": franky.RealtimeConfig.Enforce}[config.realtime]
    deadline = time.monotonic() + config.connect_timeout
    where = f"the Franka at {config.address} (TCP port {FCI_PORT})"
    while True:
        reached = _reach(config.address, deadline, where, config.connect_timeout)
        if not reached:                       # refused, with time left to try again
            time.sleep(_RETRY)
            continue
        outcome: dict[str, object] = {}

        def attempt() -> None:
            try:
                outcome["robot"] = franky.Robot(config.address, realtime_config=policy)
            except Exception as exc:  # noqa: BLE001 - reported below, whatever libfranka raised
                outcome["error"] = exc

        # libfranka's connect cannot be interrupted: a thread of its own, abandoned on timeout
        # (the port answered, so only a robot that stops answering midway leaves it behind).
        worker = threading.Thread(target=attempt, name="franka connect", daemon=True)
        worker.start()
        worker.join(max(0.0, deadline - time.monotonic()))
        if "robot" in outcome:
            return outcome["robot"]
        error = outcome.get("error")
        if error is None:
            raise FrankaConnectError(f"{where}: " + _NO_ANSWER.format(config.connect_timeout))
        refused = "refused" in str(error)
        if not refused or time.monotonic() + _RETRY >= deadline:
            reason = _REFUSED if refused else f"{type(error).__name__}: {error}"
            raise FrankaConnectError(f"{where}: {reason}") from error
        time.sleep(_RETRY)


def _reach(address: str, deadline: float, where: str, timeout: float) -> bool:
    """Whether the command port at ``address`` takes a TCP connection (closed again at once,
    before any handshake: franky-sim logs a client that disconnected and takes the next one);
    False when it is refused and there is time to try again before ``deadline``
    (``time.monotonic``).

    :raises FrankaConnectError: if it does not answer by ``deadline``, is refused with no time
        left, or cannot be reached at all (no route, a name that does not resolve).
    """
    try:
        with socket.create_connection((address, FCI_PORT),
                                      timeout=max(1e-3, deadline - time.monotonic())):
            return True
    except TimeoutError as exc:
        raise FrankaConnectError(f"{where}: " + _NO_ANSWER.format(timeout)) from exc
    except ConnectionRefusedError as exc:
        if time.monotonic() + _RETRY < deadline:
            return False
        raise FrankaConnectError(f"{where}: {_REFUSED}") from exc
    except OSError as exc:
        raise FrankaConnectError(f"{where}: {exc.strerror or exc}") from exc


def load_in_flange(model: ArmModel, tool_frame: str, com: np.ndarray) -> np.ndarray:
    """(3,) [m] a point given in ``tool_frame`` (the hand's tool centre point) in libfranka's
    flange frame ``fr3_link8``, where ``setLoad`` takes the load's centre of mass."""
    data = model.model.createData()
    pin.framesForwardKinematics(model.model, data, pin.neutral(model.model))
    flange = data.oMf[model.model.getFrameId(FR3_FLANGE)]
    tool = data.oMf[model.model.getFrameId(tool_frame)]
    return (flange.actInv(tool)).act(np.asarray(com, float))


class FrankaArm:
    """The bridge's ``TorqueInterface`` (and ``StampedStates``) over a connected ``franky.Robot``.

    :param robot: a connected ``franky.Robot`` (``connect_robot``).
    :param config: the plugin's parameters.
    :param model: the bridge's model of the arm: its torque limits guard ``write``.
    """

    def __init__(self, robot, config: FrankaConfig, model: ArmModel) -> None:
        self.robot = robot
        self.config = config
        self.joint_names = model.joint_names
        self.torque_limits = model.limits.torque.copy()
        self.rate_limits = model.limits.torque_rate.copy()
        self._model = robot.model           # libfranka's: the gravity the robot adds
        self._motion = None                 # the running franky.SimpleTorqueMotion
        self._fault: str | None = None      # why the last motion ended, until ``recover``
        self._state = None                  # the franky.RobotState last returned by ``read``
        self._consumed = -1                 # [ms] stamp of the state the last write answered
        self._last_sent = np.zeros(len(self.joint_names))
        self._last_sent_stamp = 0
        self.commanded = np.zeros(len(self.joint_names))   # the loop's last full torque

    @classmethod
    def connect(cls, config: FrankaConfig, description: RobotDescription) -> FrankaArm:
        """Connect to the arm, set its collision behaviour and the held part as its load.

        :raises FrankaConnectError: naming the address and the reason, within
            ``config.connect_timeout`` (plus the set-up calls' own answers).
        """
        model = ArmModel.from_description(description)
        robot = connect_robot(config)
        try:
            robot.set_collision_behavior(
                list(config.lower_torque_thresholds), list(config.upper_torque_thresholds),
                list(config.lower_force_thresholds), list(config.upper_force_thresholds))
            tool = description.tool
            com = load_in_flange(model, description.tool_frame, tool.payload_com)
            robot.set_load(float(tool.payload_mass), com.tolist(), _PAYLOAD_INERTIA)
            arm = cls(robot, config, model)
            arm.read()
        except Exception as exc:
            raise FrankaConnectError(f"the Franka at {config.address} connected but could not be "
                                     f"set up: {type(exc).__name__}: {exc}") from exc
        return arm

    # --- the torque interface --------------------------------------------------------------
    def read(self) -> JointState:
        """The robot's state: the first one after the state the last ``write`` answered (waiting
        for it, at most ``state_timeout``); ``tau`` is the measured joint torque ``tau_J``.

        :raises FrankaFault: if the motion ended (libfranka's reason) or no state came in time.
        """
        state = self._next_state()
        self._state = state
        return JointState(state.q, state.dq, state.tau_J)

    def state_time(self) -> float:
        """[s] the robot's stamp of the state ``read`` returned (libfranka's ``time``)."""
        return 0.0 if self._state is None else self._state.time.to_sec()

    def write(self, tau: np.ndarray) -> None:
        """Send the loop's full joint torque ``tau`` [Nm] (gravity included) as libfranka's
        command: gravity subtracted, the change since the last command within the rate limit.

        :raises TorqueRejected: ``tau`` is not 7 finite values within the joints' torque limits
            (nothing is sent; the motion's watchdog stops the arm if no good torque follows).
        :raises FrankaFault: the motion has ended and ``recover`` has not run since.
        """
        tau = np.asarray(tau, dtype=float)
        if tau.shape != self.torque_limits.shape or not np.all(np.isfinite(tau)):
            raise TorqueRejected(f"torque must be {len(self.torque_limits)} finite values, "
                                 f"got {tau.tolist()}")
        over = np.abs(tau) > self.torque_limits
        if np.any(over):
            raise TorqueRejected(f"torque beyond the joint limits on joints "
                                 f"{(np.flatnonzero(over) + 1).tolist()}: {tau.tolist()} "
                                 f"(limits {self.torque_limits.tolist()})")
        if self._fault is not None:
            raise FrankaFault(f"the arm stopped ({self._fault}); recover() first")
        if self._state is None:
            raise RuntimeError("write before the first read: no state to answer")
        state = self._state
        stamp = state.time.to_msec()
        sent = tau - self.robot_gravity()
        starting = self._motion is None
        if starting:                       # the robot held gravity alone until now
            self._last_sent = np.zeros_like(sent)
        periods = 1 if starting else max(1, stamp - self._last_sent_stamp)
        step = self.rate_limits * 1e-3 * periods
        sent = np.clip(sent, self._last_sent - step, self._last_sent + step)
        if starting:
            self._start(sent)
        else:
            self._motion.set_torque(sent)
        self._last_sent = sent
        self._last_sent_stamp = stamp
        self._consumed = stamp
        self.commanded = tau

    # --- what libfranka tells beside the seam --------------------------------------------------
    def robot_gravity(self) -> np.ndarray:
        """(7,) [Nm] the gravity torque the robot adds to every command at the last state read:
        libfranka's model with the state's end effector and load (``m_total``, ``F_x_Ctotal``)."""
        state = self._state
        if state is None:
            raise RuntimeError("no state read yet")
        return self._model.gravity(state.q, state.m_total, state.F_x_Ctotal)

    def external_wrench(self) -> np.ndarray:
        """(6,) libfranka's estimate of the external wrench on the end effector
        (``O_F_ext_hat_K``: base frame, at the stiffness frame K) in the last state read."""
        return np.zeros(6) if self._state is None else np.array(self._state.O_F_ext_hat_K)

    def command_success_rate(self) -> float:
        """libfranka's share of the last 100 commands the robot received in time."""
        return 0.0 if self._state is None else float(self._state.control_command_success_rate)

    @property
    def fault(self) -> str | None:
        """Why the last motion ended, until ``recover`` (``None``: running or idle)."""
        return self._fault

    def recover(self) -> str:
        """Run libfranka's automatic error recovery after a fault; the next ``write`` starts a
        new torque motion. Logged; returns what it did.

        :raises FrankaFault: if the robot refused to recover.
        """
        cause = self._fault or "no fault"
        ok = self.robot.recover_from_errors()
        message = (f"libfranka's automatic error recovery at {self.config.address} "
                   f"{'succeeded' if ok else 'FAILED'} (after: {cause})")
        (log.warning if ok else log.error)(message)
        if not ok:
            raise FrankaFault(message)
        self._fault = None
        self._motion = None
        return message

    def close(self) -> None:
        """Stop the torque motion (libfranka then holds the arm) and forget it, and how it
        ended: franky keeps a motion's exception for the next ``move`` otherwise."""
        if self._motion is not None:
            if self.robot.is_in_control:
                self.robot.stop()
            try:
                self.robot.join_motion(1.0)
            except Exception:  # noqa: BLE001 - the stop preempts the motion with an exception
                pass
        self._motion = None

    # --- the motion ---------------------------------------------------------------------------
    def _start(self, first: np.ndarray) -> None:
        """A torque motion, moved asynchronously: libfranka's thread sends the last torque."""
        import franky
        motion = franky.SimpleTorqueMotion(initial_torque=first,
                                           signal_timeout=self.config.signal_timeout)
        self.robot.move(motion, asynchronous=True)
        self._motion = motion

    def _check_motion(self) -> None:
        """Raise ``FrankaFault`` once with libfranka's reason if the motion has ended."""
        if self._motion is None or self.robot.is_in_control:
            return
        self._motion = None
        try:
            self.robot.join_motion(0.0)
            reason = "the torque motion ended"
        except Exception as exc:  # noqa: BLE001 - libfranka's and franky's exceptions alike
            reason = f"{type(exc).__name__}: {exc}"
        # Whether commands were reaching the robot in time before it ended: below 1, the
        # control thread was late (on a real arm, the network or a kernel without realtime).
        reason += f" (command success rate {self.command_success_rate():.2f} at the last state)"
        self._fault = reason
        log.error("Franka at %s: %s", self.config.address, reason)
        raise FrankaFault(reason)

    def _next_state(self):
        """The first state newer than the one the last ``write`` answered."""
        deadline = None
        while True:
            self._check_motion()
            state = self.robot.state
            if state.time.to_msec() > self._consumed:
                return state
            now = time.monotonic()
            if deadline is None:
                deadline = now + self.config.state_timeout
            elif now > deadline:
                reason = (f"no new state from the Franka at {self.config.address} for "
                          f"{self.config.state_timeout} s (last stamped "
                          f"{state.time.to_sec():.3f} s)")
                self._fault = reason
                raise FrankaFault(reason)
            time.sleep(_POLL)
