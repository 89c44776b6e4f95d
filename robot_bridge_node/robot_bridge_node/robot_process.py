"""The ``robot`` process: sim, bridge, estimator and recorder nodes around one 1 kHz loop.

The loop (the robot plugin named by the ``robot`` parameter, ``sim_panda`` by default, the
controller and the EKF) runs in a loop process of its own (``core/loop_process.py``), where no
ROS thread competes with it for Python's interpreter lock; this process keeps the nodes. Every
tick reaches it through a shared-memory ring (``core/sample_ring.py``), read by one thread
(``core/loop_link.py``) that publishes the ticks of the publishing rate under the nodes' names,
hands every tick to the recorder, and publishes the at-rest events. Nothing crosses a process
boundary at 1 kHz as a message.

The reset path, end to end: the executor calls ``move_to_start`` (the bridge node serves it)
-> ``serve_move_to_start`` validates -> ``RobotProcess.move_to_start`` opens the session and sends
the start to the loop process -> its ``LoopRunner`` has ``RobotLoop.reset`` teleport the plugin's
simulation there (or move the arm there) and settle -> the settled event is the answer. The
process moves nothing at start-up: the loop holds the arm where it is.
Clock modes (``sim.clock_mode``):

- ``lockstep``: the loop ticks as fast as it can while a setpoint executes and pauses once the
  step is at rest until the next setpoint or reset; messages carry simulated time and ``/clock``
  is published, so a run is reproducible.
- ``realtime``: the loop ticks at wall-clock 1 kHz, holds the last command like hardware, and
  the safety watchdog holds the pose when setpoints stop coming for 10 ms; its timing is on
  ``diagnostics``.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import rclpy
from qg_common.conversions import at_rest_msg, setpoint_from_msg, time_msg
from qg_common.node_parameters import package_defaults
from qg_common.node_runtime import run_nodes
from qg_common.types import StartPose
from qg_interfaces.msg import AtRest
from qg_interfaces.msg import WrenchSetpoint as WrenchSetpointMsg
from qg_recording.cdr import CdrBuffer
from rclpy.node import Node

from robot_bridge_node.bridge_node import BridgeNode, log_at
from robot_bridge_node.core.hardware_interface import robot_defaults, robot_plugin
from robot_bridge_node.core.loop_core import LoopConfig
from robot_bridge_node.core.loop_link import ForkedLoopProcess, LoopLink
from robot_bridge_node.core.loop_process import LoopSpec
from robot_bridge_node.core.loop_runner import SetpointCommand, StepEvent
from robot_bridge_node.core.paced_publisher import PacedPublisher
from robot_bridge_node.core.robot_frames import RobotFrames, base_frame, task_scene
from robot_bridge_node.core.sample_ring import PUBLISH
from robot_bridge_node.core.tick_messages import TickNames, TopicRows, serialized_ticks
from robot_bridge_node.core.tick_timing import TimingSnapshot
from robot_bridge_node.estimator_node import WrenchEstimatorNode
from robot_bridge_node.hardware_node import HardwareConfig, HardwareNode
from robot_bridge_node.loop_diagnostics import LoopDiagnostics
from robot_bridge_node.recorder_node import RecorderNode
from robot_bridge_node.robot_state import RobotStatePublisher
from robot_bridge_node.simulation_node import SimConfig, SimulationNode
from robot_bridge_node.start_service import serve_move_to_start

__all__ = ["RobotProcess", "loop_spec", "shipped_loop_spec", "main"]

#: [s] A reset waits at most this long for its episode's bag to open (``wait_for_episode``).
EPISODE_STATUS_WAIT = 1.0


class RobotProcess:
    """The nodes of one robot and the link to its loop process (``LoopListener``).

    The loop is the robot's interface kind's (``InterfaceKind.build_loop``): a torque robot's
    runs the hybrid force/impedance controller and the EKF; a position robot's the task-space IK
    and reads the wrist sensor. It is built from the nodes' parameters and holds the arm where it
    is until the first reset (lockstep runs repeat exactly).

    Only the session being served steers the arm: a reset names a session (the executor's
    episode), and from then on a setpoint of any other session is dropped before it reaches the
    loop, logged and counted (``foreign_setpoints`` in every ``AtRest``). A reset with the empty
    session serves any sender (manual use).

    :param forked: the loop process, forked before ROS started (``ForkedLoopProcess``: ``main``
        does so); None starts a new interpreter for it.
    """

    def __init__(self, state: SimulationNode | HardwareNode, bridge: BridgeNode,
                 estimator: WrenchEstimatorNode, recorder: RecorderNode | None = None,
                 forked: ForkedLoopProcess | None = None) -> None:
        self.state = state
        self.bridge = bridge
        self.estimator = estimator
        self.recorder = recorder
        config = state.config
        robot = str(bridge.get_parameter("robot").value)
        description = state.plugin.describe(state.params)
        self.names = TickNames(tuple(state.joint_names), base_frame(description),
                               state.plugin.own_wrench_topic)
        self.lockstep = not config.realtime
        spec = loop_spec(robot, config, state.params, bridge.params, estimator.params)
        self.link = LoopLink(spec, len(self.names.joint_names), self, forked=forked)
        self._lock = threading.Lock()
        self._session = ""                  # the served session ("" = any sender)
        self.foreign_setpoints = 0          # setpoints of other sessions since the last reset
        self._timing: TimingSnapshot | None = None
        # The 1 kHz topics' publishers, by the topic names of ``tick_messages``; the truth's
        # only where there is a simulation.
        self._publishers = {"/joint_states": state.joint_states,
                            "/joint_commands": bridge.joint_commands,
                            "/wrench_estimate": estimator.wrench,
                            "/ee_pose": bridge.ee_pose, "/ee_twist": bridge.ee_twist}
        if isinstance(state, SimulationNode):
            self._publishers.update({"/sim/ground_truth": state.ground_truth,
                                     "/sim/ground_truth_wrench": state.ground_truth_wrench})
        elif state.own_wrench is not None:
            self._publishers[f"/{self.names.own_wrench_topic}"] = state.own_wrench
        bridge.setpoint_handler = self.submit_setpoint
        if recorder is not None:
            recorder.clock_ns = self.link.now_ns
        # The robot as viewers draw it (robot_description, tf_static, scene_markers, tf).
        self.frames: RobotFrames | None = None
        self.robot_state: RobotStatePublisher | None = None
        if description.urdf and description.tool_frame:
            self.frames = RobotFrames(description)
            self.robot_state = RobotStatePublisher(
                bridge, self.frames, task_scene(robot, state.params),
                self.link.now_ns, recorder)
            self._publishers["/tf"] = self.robot_state.tf
        self._paced: PacedPublisher | None = None
        if config.realtime:
            # Realtime ticks leave evenly spaced, as the loop ticked (``paced_publisher``), from
            # a thread below the loop's priority, so they leave on time on a busy machine.
            self._paced = PacedPublisher(self._publish_message,
                                         priority=max(0, config.realtime_priority - 10))
            LoopDiagnostics(bridge, lambda: self._timing, robot)
        serve_move_to_start(bridge, self)

    def start(self) -> Callable[[], None]:
        """Start the loop process; returns the function that stops it."""
        self.link.start()
        return self.stop

    def stop(self) -> None:
        """Stop the loop process, then publish what it sent last."""
        try:
            self.link.stop()
        finally:
            if self._paced is not None:
                self._paced.stop()

    # --- commands (ROS callbacks) --------------------------------------------------------------
    def submit_setpoint(self, msg: WrenchSetpointMsg) -> None:
        """Hand a setpoint of the served session to the loop; drop and count one of another."""
        with self._lock:
            served = self._session
            if served and msg.session != served:
                self.foreign_setpoints += 1
            else:
                self.link.send_setpoint(SetpointCommand(int(msg.seq), setpoint_from_msg(msg)))
                return
        self.bridge.get_logger().warning(
            f"setpoint {msg.seq} of session '{msg.session}' ignored: serving '{served}'",
            throttle_duration_sec=1.0)

    def move_to_start(self, start: StartPose, timeout: float = 30.0, session: str = "") -> AtRest:
        """Get the robot to ``start`` and settle, in the loop process; the settled observation
        (also on ``ee_at_rest``). From then on only setpoints of ``session`` are executed ("" =
        any).

        :raises TimeoutError: if the loop does not settle in ``timeout`` seconds.
        :raises RuntimeError: what the reset failed with (e.g. a start out of reach).
        """
        with self._lock:
            self._session = session
            self.foreign_setpoints = 0
        if self.recorder is not None \
                and not self.recorder.wait_for_episode(session, EPISODE_STATUS_WAIT):
            self.bridge.get_logger().warning(
                f"no /episode_status of episode '{session}' within {EPISODE_STATUS_WAIT} s: "
                f"its bag, if any, begins after the reset's settled start")
        return self._at_rest_msg(self.link.reset(start, timeout))

    # --- the loop's output (the link's reader thread) ------------------------------------------
    def samples(self, records: np.ndarray) -> None:
        tf = None if self.frames is None else self.frames.tf_rows(records)
        extra = [] if tf is None else [tf]
        publish = (records["flags"] & PUBLISH) != 0
        if publish.any() or extra:
            self._publish(records, publish, extra)
        if self.recorder is not None:
            self.recorder.record_samples(records, self.names, extra)

    def _publish(self, records: np.ndarray, publish: np.ndarray, extra: list[TopicRows]) -> None:
        """The ticks on the 1 kHz topics (those ``publish`` marks) and ``/tf`` under the nodes'
        names, tick by tick, each message published serialized (``tick_messages``: the bytes
        the recorder writes); realtime ticks paced, lockstep ones at once with ``/clock``."""
        ticks = serialized_ticks(records, self.names, publish, extra)
        if self._paced is not None:
            self._paced.put(ticks)
            return
        for t_ns, messages in ticks:
            for topic, message in messages:
                self._publishers[topic].publish(message)
            # rosgraph_msgs/Clock: the stamp alone
            self.state.clock.publish(CdrBuffer().stamp(t_ns).message())

    def _publish_message(self, topic: str, message: bytes) -> None:
        self._publishers[topic].publish(message)

    def at_rest(self, event: StepEvent) -> None:
        self.bridge.ee_at_rest.publish(self._at_rest_msg(event))

    def _at_rest_msg(self, event: StepEvent) -> AtRest:
        return at_rest_msg(event.seq, event.result, event.position, event.rotation,
                           time_msg(event.t_ns), self.names.base_frame, self.foreign_setpoints)

    def timing(self, snapshot: TimingSnapshot) -> None:
        self._timing = snapshot

    def log(self, level: str, message: str) -> None:
        log_at(self.bridge, level, message)

    def failed(self, message: str) -> None:
        self.bridge.get_logger().fatal(message)
        rclpy.try_shutdown()      # the process ends; run_nodes reports the exit


def loop_spec(robot: str, clock: SimConfig | HardwareConfig, robot_params: dict[str, Any],
              bridge_params: dict[str, Any], estimator_params: dict[str, Any]) -> LoopSpec:
    """What the robot process sends its loop process, from the nodes' parameters: the clock
    mode, priority and rates are the ``sim`` node's (``hardware``'s for a real robot), the tick
    the bridge's."""
    dt = LoopConfig.from_dict(bridge_params.get("loop", {})).dt
    return LoopSpec(
        robot=robot, robot_params=robot_params, bridge_params=bridge_params,
        estimator_params=estimator_params, realtime=clock.realtime,
        priority=clock.realtime_priority,
        publish_every=clock.publish_every(dt), truth_every=clock.ground_truth_every(dt))


def shipped_loop_spec(robot: str) -> LoopSpec:
    """The ``loop_spec`` of ``ros2 run robot_bridge_node robot`` with no overrides: ``robot``'s
    plugin and the installed config files (a simulation: the shipped ``sim.yaml``, lockstep).
    Tests and benchmarks start a loop process with it."""
    plugin = robot_plugin(robot)
    if plugin.simulated:
        params = package_defaults("sim", (("robot_bridge_node", "sim.yaml"),
                                          *plugin.config_files))
        clock: SimConfig | HardwareConfig = SimConfig.from_dict(params["sim"])
    else:
        params = package_defaults("hardware", plugin.config_files)
        clock = HardwareConfig.from_dict(params.get("hardware", {}))
    return loop_spec(
        robot, clock, params,
        robot_defaults(plugin, (("robot_bridge_node", "bridge.yaml"),), "bridge"),
        package_defaults("wrench_estimator", (("robot_bridge_node", "wrench_estimator.yaml"),)))


def main(args: list[str] | None = None) -> int:
    # The loop process is forked first, while this process has no threads (ROS starts some).
    forked = ForkedLoopProcess()
    bridge: list[BridgeNode] = []   # the bridge loads the plugin its `robot` names

    def make_bridge() -> BridgeNode:
        bridge.append(BridgeNode())
        return bridge[0]

    def make_state() -> SimulationNode | HardwareNode:
        """The robot's state node: ``sim`` for a simulated robot, ``hardware`` for a real one
        (no truth, no simulated clock)."""
        plugin = bridge[0].plugin
        return SimulationNode(plugin) if plugin.simulated else HardwareNode(plugin)

    def start(nodes: list[Node]) -> Callable[[], None]:
        bridge_node, state, estimator, recorder = nodes
        assert isinstance(bridge_node, BridgeNode) and isinstance(estimator, WrenchEstimatorNode) \
            and isinstance(recorder, RecorderNode)
        return RobotProcess(state, bridge_node, estimator, recorder, forked).start()

    return run_nodes([make_bridge, make_state, lambda: WrenchEstimatorNode(bridge[0].plugin),
                      RecorderNode], args, background=start)


if __name__ == "__main__":
    raise SystemExit(main())
