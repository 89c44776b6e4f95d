"""The ``bridge`` node: the robot-agnostic command interface in front of the (simulated) robot.

The bridge owns the 1 kHz loop (``core/robot_loop.py``), like a robot's controller process:
``LoopRunner`` drives it on a dedicated thread (not an rclpy timer, whose jitter is several ms),
takes ``wrench_setpoint`` in, and publishes the tool pose and twist and
the ``ee_at_rest`` event that ends an RL step. In the composed ``robot`` process the loop's
hardware is the robot plugin; run on its own (``ros2 run robot_bridge_node bridge``) it is
``RemoteRobot``, which reads ``joint_states`` from the separate sim and writes
``joint_commands``, one tick per received state, on the states' clock (``StateClock``). Which
loop, controller and parameters a robot gets is its interface kind's (``interface_kinds``), looked
up by the name its plugin gives: this module names no robot and no kind.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from qg_common import topics
from qg_common.conversions import (at_rest_msg, ground_truth_from_msg, joint_state_from_msg,
                                   pose_stamped, setpoint_from_msg, time_msg, time_ns,
                                   twist_stamped, wrench_from_msg)
from qg_common.node_parameters import declare_parameters, package_defaults
from qg_common.node_runtime import LoopThread, favour_loop_thread, run_nodes
from qg_common.types import NO_GROUND_TRUTH, GroundTruth, JointState
from qg_interfaces.msg import AtRest, GroundTruth as GroundTruthMsg
from qg_interfaces.msg import WrenchSetpoint as WrenchSetpointMsg
from rclpy.node import Node
from sensor_msgs.msg import JointState as JointStateMsg
from std_msgs.msg import Header

from robot_bridge_node.core.hardware_interface import (ROBOT_SECTION, Robot, RobotPlugin,
                                                       robot_plugin)
from robot_bridge_node.core.impedance import ToolState
from robot_bridge_node.core.interface_kinds import interface_kind
from robot_bridge_node.core.robot_loop import RobotLoop, StateClock
from robot_bridge_node.core.safety import SetpointRejected

__all__ = ["BridgeNode", "LoopRunner", "LoopObserver", "RemoteRobot", "LatestWrench",
           "MAX_STATE_GAP", "main"]

#: Called after every tick with the simulated time [ns] (e.g. an MCAP recorder).
LoopObserver = Callable[[int, RobotLoop], None]


class BridgeNode(Node):
    """Takes wrench setpoints (``setpoint_handler``), reports the EEF state and rest.

    Its parameters are the controller's of the robot's interface kind
    (``InterfaceKind.controller_sections``: the controller and its limits, the rest detector
    that ends an RL step, the loop timing; defaults from ``config/bridge.yaml``, a position
    robot's gains from the robot's own files); the robot is the plugin named by its ``robot``
    parameter unless ``plugin`` is given.
    """

    def __init__(self, plugin: RobotPlugin | None = None) -> None:
        super().__init__("bridge")
        if plugin is None:
            plugin = robot_plugin(declare_parameters(self, [ROBOT_SECTION])["robot"])
        self.plugin = plugin
        self.kind = interface_kind(plugin.interface)
        self.params = declare_parameters(self, self.kind.controller_sections,
                                         (("robot_bridge_node", "bridge.yaml"),
                                          *plugin.config_files))
        self.ee_pose = self.create_publisher(PoseStamped, topics.EE_POSE, topics.SENSOR_QOS)
        self.ee_twist = self.create_publisher(TwistStamped, topics.EE_TWIST, topics.SENSOR_QOS)
        self.ee_at_rest = self.create_publisher(AtRest, topics.EE_AT_REST, topics.COMMAND_QOS)
        self.setpoint_handler: Callable[[WrenchSetpointMsg], None] | None = None
        self.create_subscription(WrenchSetpointMsg, topics.WRENCH_SETPOINT, self._on_setpoint,
                                 topics.COMMAND_QOS)

    def _on_setpoint(self, msg: WrenchSetpointMsg) -> None:
        if self.setpoint_handler is None:
            self.get_logger().warn(f"setpoint {msg.seq} ignored: the loop is not running yet")
            return
        self.setpoint_handler(msg)

    def publish_tool(self, stamp: Time, tool: ToolState) -> None:
        """``/ee_pose`` and ``/ee_twist`` (base frame)."""
        self.ee_pose.publish(pose_stamped(tool.position, tool.rotation, stamp))
        self.ee_twist.publish(twist_stamped(tool.twist, stamp))


@dataclass
class _ResetJob:
    """A reset handed to the loop thread; ``done`` is set with the observation or the error."""
    initial_pose: int
    housing_yaw: float
    session: str
    done: threading.Event
    observation: AtRest | None = None
    error: Exception | None = None


class LoopRunner:
    """Drives one ``RobotLoop`` on its own thread: setpoints and resets in, ticks, events out.

    Everything that touches the loop runs on that thread; the ROS callbacks only leave work in
    a mailbox (the latest setpoint, a pending reset). A setpoint with a new ``seq`` starts a
    step; one with the ``seq`` of the last accepted command only feeds the watchdog (the
    executor repeats the current setpoint every few ms in realtime mode). A rejected setpoint
    (NaN/inf) is logged and the previous command stays.

    Only the session being served steers the arm: a reset names a session (the executor's
    episode), and from then on a setpoint of any other session is dropped before it reaches the
    mailbox, logged and counted (``foreign_setpoints`` in every ``AtRest``). A reset with the
    empty session serves any sender (manual use).

    :param loop: the loop; its ``config.realtime`` turns the watchdog on.
    :param bridge: publishes the tool state and ``/ee_at_rest``.
    :param lockstep: tick only while a step runs, as fast as possible, stamped with simulated
        time; otherwise tick continuously, stamped with the wall clock.
    :param pace: not lockstep: called before every tick, returns once the tick is due; False
        skips the tick (nothing to do yet).
    :param publish_every: publish the 1 kHz topics every this many ticks.
    :param publish: extra outputs of a published tick, given its stamp (the composed process
        publishes the sim's and the estimator's topics and ``/clock`` there).
    """

    def __init__(self, loop: RobotLoop, bridge: BridgeNode, *, lockstep: bool,
                 pace: Callable[[], bool] | None = None, publish_every: int = 1,
                 publish: Callable[[Time], None] | None = None) -> None:
        if not lockstep and pace is None:
            raise ValueError("a free-running (realtime) loop needs a pace")
        self.loop = loop
        self.bridge = bridge
        self.lockstep = lockstep
        self.pace = pace
        self.publish_every = max(1, publish_every)
        self.publish = publish
        #: The per-tick hook: each is called after every tick (and once a reset has settled)
        #: with its stamp [ns] (``now_ns``), the one its published messages carry.
        self.loop_observers: list[LoopObserver] = []
        self._dt_ns = round(loop.config.dt * 1e9)
        self._settle_ticks = round(loop.config.settle_time / loop.config.dt)
        self.clock_ns = 0          # simulated time: ticks run since start, resets included
        self.ticks = 0
        self._mail = threading.Condition()
        self._setpoint: WrenchSetpointMsg | None = None
        self._reset: _ResetJob | None = None
        self._seq: int | None = None        # last accepted setpoint
        self._step_start: float | None = None   # loop time of the running step's start
        self._session = ""                  # the served session ("" = any sender)
        self.foreign_setpoints = 0          # setpoints of other sessions since the last reset

    # --- called from ROS callbacks -----------------------------------------------------------
    def submit_setpoint(self, msg: WrenchSetpointMsg) -> None:
        """Hand a setpoint of the served session to the loop (the latest one wins); drop and
        count one of another session."""
        with self._mail:
            if not self._serves(msg):
                self.foreign_setpoints += 1
                served = self._session
            else:
                self._setpoint = msg
                self._mail.notify()
                return
        self.bridge.get_logger().warning(
            f"setpoint {msg.seq} of session '{msg.session}' ignored: serving '{served}'",
            throttle_duration_sec=1.0)

    def _serves(self, msg: WrenchSetpointMsg) -> bool:
        """Whether ``msg`` belongs to the served session (any does while that is "")."""
        return not self._session or msg.session == self._session

    def request_reset(self, initial_pose: int, housing_yaw: float = 0.0,
                      session: str = "") -> _ResetJob:
        """Ask the loop thread to reset and settle, then serve ``session``; returns at once."""
        job = _ResetJob(initial_pose, housing_yaw, session, threading.Event())
        with self._mail:
            self._reset = job
            self._session = session
            self.foreign_setpoints = 0
            self._mail.notify()
        return job

    def reset(self, initial_pose: int, housing_yaw: float = 0.0, timeout: float = 30.0,
              session: str = "") -> AtRest:
        """Reset and settle on the loop thread; the settled observation (also on /ee_at_rest).
        From then on only setpoints of ``session`` are executed ("" = any).

        :raises TimeoutError: if the loop thread does not finish in ``timeout`` seconds.
        :raises RuntimeError, ValueError: what the simulation raised (e.g. IK out of reach).
        :raises TimeoutError: also when a remote robot sends no state after its restart.
        """
        job = self.request_reset(initial_pose, housing_yaw, session)
        if not job.done.wait(timeout):
            raise TimeoutError(f"the loop did not reset within {timeout:.0f} s")
        if job.error is not None:
            raise job.error
        assert job.observation is not None
        return job.observation

    # --- the loop thread ---------------------------------------------------------------------
    def run(self, stop: threading.Event) -> None:
        """Body of the loop thread (see ``LoopThread``)."""
        while not stop.is_set():
            if self.lockstep:
                if not self._wait_for_work(stop):
                    continue
            elif not self.pace():
                continue
            self._take_mail()
            if self.lockstep and self._step_start is None:
                continue
            at_rest = self.loop.tick()
            self._after_tick(at_rest)

    def _wait_for_work(self, stop: threading.Event) -> bool:
        """Lockstep: a step runs or mail is waiting (else wait a little and say no)."""
        if self._step_start is not None:
            return True
        with self._mail:
            if self._setpoint is None and self._reset is None:
                self._mail.wait(timeout=0.05)
            return self._setpoint is not None or self._reset is not None

    def _take_mail(self) -> None:
        with self._mail:
            setpoint, self._setpoint = self._setpoint, None
            job, self._reset = self._reset, None
        if job is not None:
            self._do_reset(job)
        # A command of another session that was waiting when the reset came must not run in it.
        if setpoint is not None and self._serves(setpoint):
            self._take_setpoint(setpoint)

    def _take_setpoint(self, msg: WrenchSetpointMsg) -> None:
        loop = self.loop
        if msg.seq == self._seq:
            loop.feed_watchdog()
            return
        try:
            loop.command(setpoint_from_msg(msg))
        except SetpointRejected as exc:
            self.bridge.get_logger().error(
                f"setpoint {msg.seq} rejected: {exc}; keeping the previous command",
                throttle_duration_sec=1.0)
            return
        self._seq = msg.seq
        self._step_start = loop.time

    def _do_reset(self, job: _ResetJob) -> None:
        try:
            self.loop.reset(job.initial_pose, job.housing_yaw)
        except (RuntimeError, ValueError, TimeoutError) as exc:
            self.bridge.get_logger().error(f"reset failed: {exc}")
            job.error = exc
            job.done.set()
            return
        self._seq = None
        self._step_start = None
        self.clock_ns += self._settle_ticks * self._dt_ns
        t_ns = self.now_ns()
        self._observe(t_ns)  # the settled start state is published: it is recorded too
        stamp = time_msg(t_ns)
        job.observation = self._event(0, self.loop.time - self.loop.config.settle_time, stamp)
        self.publish_sample(stamp)
        self.bridge.ee_at_rest.publish(job.observation)
        job.done.set()

    def _after_tick(self, at_rest: bool) -> None:
        self.ticks += 1
        self.clock_ns += self._dt_ns
        t_ns = self.now_ns()  # the tick's one stamp: observers record what is published
        self._observe(t_ns)
        stamp: Time | None = None
        if self.ticks % self.publish_every == 0:
            stamp = time_msg(t_ns)
            self.publish_sample(stamp)
        if at_rest and self._step_start is not None:
            event = self._event(self._seq or 0, self._step_start, stamp or time_msg(t_ns))
            self._step_start = None
            self.bridge.ee_at_rest.publish(event)

    def _observe(self, t_ns: int) -> None:
        for observer in self.loop_observers:
            observer(t_ns, self.loop)

    def now_ns(self) -> int:
        """The loop's clock [ns], which stamps its messages: simulated time in lockstep (it
        stands still between steps), the bridge node's clock (wall clock) otherwise."""
        return self.clock_ns if self.lockstep else self.bridge.get_clock().now().nanoseconds

    def publish_sample(self, stamp: Time) -> None:
        """Publish the loop's current state on the 1 kHz topics."""
        tool = self.loop.controller.tool
        if tool is not None:
            self.bridge.publish_tool(stamp, tool)
        if self.publish is not None:
            self.publish(stamp)

    def _event(self, seq: int, start: float, stamp: Time) -> AtRest:
        """The ``AtRest`` of the step that started at loop time ``start``."""
        tool = self.loop.controller.tool
        return at_rest_msg(seq, self.loop.result(start), tool.position, tool.rotation, stamp,
                           self.foreign_setpoints)



# --- separate-process mode ------------------------------------------------------------------
#: [s] The most one tick of the separate bridge counts (``StateClock``): the sim's
#: ``command_timeout``, after which it holds the arm itself rather than following the bridge.
MAX_STATE_GAP = 0.02


class RemoteRobot:
    """The loop's hardware and simulation over topics: the arm is the separate sim process.

    ``read`` is the latest ``joint_states`` and ``state_time`` its stamp; ``write`` publishes
    ``joint_commands`` (the command in the interface kind's ``command_field``: torques in
    ``effort``, targets in ``position``) and waits (up to ``timeout``) for the next state, so
    the loop ticks once per state it takes, and a tick covers the time since the previous state
    it took, however many it missed. The first state and every ``sim/restarted`` call
    ``on_restart``; ``reset`` then waits for a state from after the restart, so the loop
    settles from the new pose.

    A command's stamp names the restart it follows: the ``sim/restarted`` stamp the loop last
    reset from (0 before any). Until the loop has taken a restart, its commands still aim at
    the pose before it, and the sim, which applies only commands of its latest restart, holds
    the new pose instead (before this, the first reset after start-up dragged a Nextage 69 deg
    of a joint back toward its old pose for 90 ms, and the reply's pose was 0.02-8.6 mm off).
    """

    def __init__(self, node: Node, n_joints: int, command_field: str,
                 on_restart: Callable[[], None], timeout: float = 0.05) -> None:
        self.node = node
        self.n_joints = n_joints
        self.command_field = command_field
        self.on_restart = on_restart
        self.timeout = timeout
        self._stamp = 0.0
        self._read_stamp = 0.0
        self._state: JointState | None = None
        self._truth: GroundTruthMsg | None = None
        self._restart_ns = 0       # the latest sim/restarted stamp [ns]
        self._epoch_ns = 0         # the one the loop last reset from: stamps its commands
        self._fresh = threading.Condition()
        self._received = 0
        self._used = 0
        self.commands = node.create_publisher(JointStateMsg, topics.JOINT_COMMANDS,
                                              topics.SENSOR_QOS)
        node.create_subscription(JointStateMsg, topics.JOINT_STATES, self._on_state,
                                 topics.SENSOR_QOS)
        node.create_subscription(GroundTruthMsg, topics.GROUND_TRUTH, self._on_truth,
                                 topics.SENSOR_QOS)
        node.create_subscription(Header, topics.SIM_RESTARTED, self._on_restarted,
                                 topics.RESTARTED_QOS)

    def _on_state(self, msg: JointStateMsg) -> None:
        try:
            state = joint_state_from_msg(msg, self.n_joints)
        except ValueError as exc:
            self.node.get_logger().error(f"bad joint_states: {exc}", throttle_duration_sec=1.0)
            return
        first = self._state is None
        with self._fresh:
            self._state = state
            self._stamp = time_ns(msg.header.stamp) * 1e-9
            self._received += 1
            self._fresh.notify()
        if first:
            self.on_restart()

    def _on_restarted(self, msg: Header) -> None:
        self.node.get_logger().info("the sim restarted: settling under control")
        with self._fresh:
            self._restart_ns = time_ns(msg.stamp)
        self.on_restart()

    def _on_truth(self, msg: GroundTruthMsg) -> None:
        self._truth = msg

    def wait_ready(self) -> bool:
        """True once the sim has published a state (waits up to ``timeout`` for one)."""
        with self._fresh:
            if self._state is None:
                self._fresh.wait(self.timeout)
            return self._state is not None

    # --- torque or position interface ------------------------------------------------------
    def read(self) -> JointState:
        with self._fresh:
            assert self._state is not None, "no joint_states yet (wait_ready first)"
            self._read_stamp = self._stamp
            return self._state

    def state_time(self) -> float:
        """[s] the stamp of the state ``read`` returned last (the sim's clock)."""
        return self._read_stamp

    def write(self, command: np.ndarray) -> None:
        msg = JointStateMsg(**{self.command_field: np.asarray(command, float).tolist()})
        msg.header.stamp = time_msg(self._epoch_ns)
        self.commands.publish(msg)
        with self._fresh:
            if self._received == self._used:
                self._fresh.wait(self.timeout)
            self._used = self._received

    # --- simulation interface --------------------------------------------------------------
    def reset(self, initial_pose: int, housing_yaw: float = 0.0) -> None:
        """The sim resets itself (``sim/reset``): wait for its first state after that.

        :raises TimeoutError: if the sim publishes none within a second.
        """
        del initial_pose, housing_yaw
        with self._fresh:
            restart = self._restart_ns
            if not self._fresh.wait_for(lambda: self._stamp >= restart * 1e-9, timeout=1.0):
                raise TimeoutError("no joint_states after the sim restarted")
            self._epoch_ns = restart

    def ground_truth(self) -> GroundTruth:
        return NO_GROUND_TRUTH if self._truth is None else ground_truth_from_msg(self._truth)

    def contact_wrench(self) -> np.ndarray:
        return self.ground_truth().wrench


class LatestWrench:
    """The loop's wrench in separate-process mode: the last ``/wrench_estimate`` received (the
    separate estimator's EKF, or the separate sim's wrist sensor)."""

    def __init__(self, node: Node) -> None:
        self._wrench = np.zeros(6)
        node.create_subscription(WrenchStamped, topics.WRENCH_ESTIMATE, self._on_wrench,
                                 topics.SENSOR_QOS)

    def _on_wrench(self, msg: WrenchStamped) -> None:
        self._wrench = wrench_from_msg(msg.wrench)

    def reset(self, q: np.ndarray) -> None:
        del q

    def update(self, q: np.ndarray, dq: np.ndarray, tau_cmd: np.ndarray,
               dt: float) -> np.ndarray:
        del q, dq, tau_cmd, dt
        return self._wrench.copy()


def _start_separate_bridge(nodes: list[Node]) -> Callable[[], None]:
    bridge = nodes[0]
    assert isinstance(bridge, BridgeNode)
    p = bridge.params
    runner: LoopRunner | None = None

    def restart() -> None:
        if runner is not None:
            runner.request_reset(0)

    # The robot's own parameters belong to the separate sim process: describe it by its defaults.
    description = bridge.plugin.describe(package_defaults("sim", bridge.plugin.config_files))
    remote = RemoteRobot(bridge, len(description.joint_names), bridge.kind.command_field, restart)
    params = {**p, "loop": {**p.get("loop", {}), "realtime": True}}
    loop = bridge.kind.build_loop(Robot(remote, remote, description), params, {},
                                  wrench=LatestWrench(bridge),
                                  clock=StateClock(remote, MAX_STATE_GAP))
    runner = LoopRunner(loop, bridge, lockstep=False, pace=remote.wait_ready)
    bridge.setpoint_handler = runner.submit_setpoint
    favour_loop_thread()
    return LoopThread("bridge loop", runner.run, bridge).start().stop


def main(args: list[str] | None = None) -> int:
    # Its callbacks only store the latest message for the loop thread.
    return run_nodes([BridgeNode], args, background=_start_separate_bridge,
                     blocking_callbacks=False)


if __name__ == "__main__":
    raise SystemExit(main())
