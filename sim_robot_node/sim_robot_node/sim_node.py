"""``ros2 run sim_robot_node sim``: a simulated robot as a process of its own.

The stack normally runs the simulation inside the ``robot`` process (the plugin named by its
``robot`` parameter, in ``robot_bridge_node``). Run on its own, ``SeparateSim`` steps the same
plugin's robot (``-p robot:=<name>``, ``sim_panda`` by default) at wall-clock 1 kHz: it applies
the latest ``joint_commands`` (the field its interface kind names: torques in ``effort``, joint
targets in ``position``), and with no fresh command what the kind's ``hold`` gives (a torque arm
floats under gravity compensation, as its own firmware would; a position arm keeps its last
target). A robot with a wrist force-torque sensor also publishes the sensor's reading on
``wrench_estimate``, as its driver would. The node is the bridge's ``SimulationNode`` (the same
topics as in the composed process).
"""
from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from geometry_msgs.msg import WrenchStamped
from qg_common import topics
from qg_common.conversions import time_ns, wrench_stamped
from qg_common.node_runtime import LoopThread, favour_loop_thread, run_nodes
from qg_common.realtime_pacer import RealtimePacer
from qg_common.types import StartPose
from qg_interfaces.msg import AtRest
from rclpy.node import Node
from robot_bridge_node.core.hardware_interface import Robot
from robot_bridge_node.core.interface_kinds import InterfaceKind, interface_kind
from robot_bridge_node.simulation_node import SimulationNode
from robot_bridge_node.start_service import serve_move_to_start
from sensor_msgs.msg import JointState as JointStateMsg
from std_msgs.msg import Header

__all__ = ["SeparateSim", "main"]


#: [s] The bridge's commands may follow an earlier restart this long in a row (it is taking
#: the new one) before the sim warns that they still do.
STALE_COMMANDS_WARNING = 1.0


@dataclass
class _ResetJob:
    """A start handed from the service thread to the loop thread."""
    start: StartPose
    done: threading.Event
    due: float = math.inf                 # perf_counter time from which to answer
    observation: AtRest | None = None


class SeparateSim:
    """A robot plugin's robot stepped at wall-clock 1 kHz under ``/joint_commands`` (separate
    processes).

    Every tick applies the latest command if it is fresh (younger than ``command_timeout``) and
    follows the last restart (its stamp is that restart's ``sim/restarted`` stamp: the bridge has
    restarted from the new pose), else the interface kind's hold; then it steps (the hardware's
    ``write``) and publishes the new state and the ground truth. It serves ``move_to_start`` by
    teleporting (its simulation's shortcut). Its start and every such reset are restarts: the sim announces each on ``sim/restarted`` (stamped with its time, latched), so
    the bridge and the estimator restart from the new state, and a bridge sends no command
    before it has taken one. After a reset (which teleports the arm) the bridge settles under
    its controller and reports the settled state (``ee_at_rest`` with ``seq`` 0); no earlier
    than ``reset_wait`` after the reset the service answers with the first such report stamped
    after the restart. (A report of the bridge's previous settling, still on its way when the
    reset was taken, once answered a reset with the pose before it: 168 mm off.)

    :param robot: from the plugin; it needs a simulation (``teleport``, ``ground_truth``).
    :param kind: its interface kind (``robot_bridge_node.interfaces``).
    """

    def __init__(self, node: SimulationNode, robot: Robot, kind: InterfaceKind) -> None:
        if robot.simulation is None:
            raise ValueError("the separate sim needs a simulated robot (simulation is None)")
        self.node = node
        self.robot = robot
        self.simulation = robot.simulation
        self.kind = kind
        self.config = node.config
        self.n_joints = len(robot.description.joint_names)
        self.hold = kind.hold(robot.description, self.config.hold_damping)
        self.pacer = RealtimePacer(robot.description.dt)
        self._command: tuple[float, int, np.ndarray] | None = None  # (arrival, stamp, command)
        self._settled: AtRest | None = None     # the bridge's latest settled report
        self._jobs: queue.Queue[_ResetJob] = queue.Queue()
        self._job: _ResetJob | None = None
        self._restart_ns = 0                    # the stamp of the last sim/restarted
        self._stale_since: float | None = None  # since when fresh commands follow an old restart
        self.restarted = node.create_publisher(Header, topics.SIM_RESTARTED, topics.RESTARTED_QOS)
        self.wrench = None if robot.wrist_sensor is None else node.create_publisher(
            WrenchStamped, topics.WRENCH_ESTIMATE, topics.SENSOR_QOS)
        node.create_subscription(JointStateMsg, topics.JOINT_COMMANDS, self._on_command,
                                 topics.SENSOR_QOS)
        node.create_subscription(AtRest, topics.EE_AT_REST, self._on_at_rest, topics.COMMAND_QOS)
        serve_move_to_start(node, self)
        self.hold.reset(robot.hardware.read())
        self._announce_restart()

    def _on_command(self, msg: JointStateMsg) -> None:
        command = np.asarray(getattr(msg, self.kind.command_field), float)
        if command.shape != (self.n_joints,) or not np.all(np.isfinite(command)):
            self.node.get_logger().error(
                f"ignoring joint_commands without {self.n_joints} finite "
                f"{self.kind.command_field} values: {command.tolist()}", throttle_duration_sec=1.0)
            return
        self._command = (time.perf_counter(), time_ns(msg.header.stamp), command)

    def _on_at_rest(self, msg: AtRest) -> None:
        if msg.seq == 0:
            self._settled = msg     # the loop thread checks that it follows the last restart

    def move_to_start(self, start: StartPose, timeout: float = 5.0, session: str = "") -> AtRest:
        """Teleport to ``start`` on the loop thread; the bridge's settled observation,
        ``reset_wait`` at the earliest.

        ``session`` is not enforced in this separate-process mode: the bridge learns of a reset
        only from the restarted state stream, so it serves any sender (the composed ``robot``
        process, the default, serves only the reset's session).
        :raises TimeoutError: if the bridge reports no settled state within ``timeout`` s more.
        """
        del session
        job = _ResetJob(start, threading.Event())
        self._jobs.put(job)
        if not job.done.wait(timeout=self.config.reset_wait + timeout):
            raise TimeoutError("the bridge reported no settled state after the reset")
        assert job.observation is not None
        return job.observation

    def run(self, stop: threading.Event) -> None:
        """The 1 kHz loop (body of a ``LoopThread``)."""
        dt = self.robot.description.dt
        every = self.config.publish_every(dt)
        truth_every = self.config.ground_truth_every(dt)
        hardware = self.robot.hardware
        tick = 0
        while not stop.is_set():
            self.pacer.wait()
            now = time.perf_counter()
            self._take_reset(now)
            state = hardware.read()
            command = self._command
            since_reset = command if command is not None and command[1] >= self._restart_ns \
                else None
            fresh = since_reset is not None and now - since_reset[0] < self.config.command_timeout
            self._watch_stale(now, command is not None and since_reset is None
                              and now - command[0] < self.config.command_timeout)
            hardware.write(since_reset[2] if fresh else self.hold.command(
                state, None if since_reset is None else since_reset[2]))
            tick += 1
            if tick % every == 0:
                stamp = self.node.get_clock().now().to_msg()
                self.node.publish_state(stamp, hardware.read(),
                                        self.simulation.ground_truth() if tick % truth_every == 0
                                        else None)
                if self.wrench is not None:
                    self.wrench.publish(wrench_stamped(self.robot.wrist_sensor.read_wrench(),
                                                       stamp))
            settled = self._settled
            if self._job is not None and now >= self._job.due and settled is not None \
                    and time_ns(settled.header.stamp) >= self._restart_ns:
                self._job.observation = settled
                self._job.done.set()
                self._job = None

    def _watch_stale(self, now: float, stale: bool) -> None:
        """Warn when the bridge keeps sending commands of an earlier restart (it has not taken
        ``sim/restarted``): a few are normal while it settles from the new pose."""
        if not stale:
            self._stale_since = None
        elif self._stale_since is None:
            self._stale_since = now
        elif now - self._stale_since > STALE_COMMANDS_WARNING:
            self.node.get_logger().warning(
                "joint_commands follow an earlier restart (the bridge has not taken "
                "sim/restarted): holding the arm", throttle_duration_sec=5.0)

    def _take_reset(self, now: float) -> None:
        try:
            job = self._jobs.get_nowait()
        except queue.Empty:
            return
        self.simulation.teleport(job.start)
        self.hold.reset(self.robot.hardware.read())
        self._announce_restart()
        job.due = now + self.config.reset_wait
        self._job = job

    def _announce_restart(self) -> None:
        """Commands and settled reports stamped before now belong to an earlier restart."""
        stamp = self.node.get_clock().now()
        self._restart_ns = stamp.nanoseconds
        self.restarted.publish(Header(stamp=stamp.to_msg()))


def _start_separate_sim(nodes: list[Node]) -> Callable[[], None]:
    node = nodes[0]
    assert isinstance(node, SimulationNode)
    if not node.config.realtime:
        # The realtime rates follow, not only the pacing: published at lockstep's 100 Hz, the
        # states would clock the bridge's loop (one tick per state) ten times too slowly.
        node.get_logger().info("separate sim process: running in realtime (wall-clock 1 kHz)")
        node.config = replace(node.config, clock_mode="realtime")
    robot = node.plugin.create(node.params)
    sim = SeparateSim(node, robot, interface_kind(node.plugin.interface))
    favour_loop_thread()
    return LoopThread("sim", sim.run, node, node.config.realtime_priority).start().stop


def main(args: list[str] | None = None) -> int:
    # The node loads the plugin its `robot` parameter names.
    return run_nodes([SimulationNode], args, background=_start_separate_sim)


if __name__ == "__main__":
    raise SystemExit(main())
