"""The ``bridge`` node: the robot-agnostic command interface in front of the (simulated) robot.

The bridge owns the 1 kHz loop (``core/robot_loop.py``), like a robot's controller process:
it takes ``wrench_setpoint`` in, and publishes the tool pose and twist and the ``ee_at_rest``
event that ends an RL step. In the composed ``robot`` process the loop runs in a process of its
own with the robot plugin as its hardware (``robot_process.py``); run on its own (``ros2 run
robot_bridge_node bridge``) a ``LoopRunner`` drives it on a dedicated thread (not an rclpy
timer, whose jitter is several ms) with ``RemoteRobot`` as its hardware, which reads
``joint_states`` from the separate sim and writes ``joint_commands``, one tick per received
state, on the states' clock (``StateClock``). Which
loop, controller and parameters a robot gets is its interface kind's (``interface_kinds``), looked
up by the name its plugin gives: this module names no robot and no kind.
"""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from qg_common import topics
from qg_common.conversions import (
    at_rest_msg,
    ground_truth_from_msg,
    joint_state_from_msg,
    pose_stamped,
    setpoint_from_msg,
    time_msg,
    time_ns,
    twist_stamped,
    wrench_from_msg,
)
from qg_common.node_parameters import declare_parameters, package_defaults
from qg_common.node_runtime import LoopThread, favour_loop_thread, run_nodes
from qg_common.types import NO_GROUND_TRUTH, GroundTruth, JointState, StartPose
from qg_interfaces.msg import AtRest
from qg_interfaces.msg import GroundTruth as GroundTruthMsg
from qg_interfaces.msg import WrenchSetpoint as WrenchSetpointMsg
from rclpy.node import Node
from sensor_msgs.msg import JointState as JointStateMsg
from std_msgs.msg import Header

from robot_bridge_node.core.frame_kinematics import base_frame
from robot_bridge_node.core.hardware_interface import (
    ROBOT_SECTION,
    Robot,
    RobotPlugin,
    robot_plugin,
)
from robot_bridge_node.core.impedance import ToolState
from robot_bridge_node.core.interface_kinds import interface_kind
from robot_bridge_node.core.loop_clock import MAX_STATE_GAP, StateClock
from robot_bridge_node.core.loop_core import LoopCore
from robot_bridge_node.core.loop_runner import (
    LoopRunner,
    ResetCommand,
    SetpointCommand,
    StepEvent,
    ThreadMailbox,
)

__all__ = ["BridgeNode", "RosOutlet", "log_at", "RemoteRobot", "LatestWrench",
           "main"]


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
        #: The frame of the tool's pose and twist: the root link of the robot's URDF.
        self.base_frame = base_frame(plugin.describe(package_defaults("bridge",
                                                                      plugin.config_files)))
        self.ee_pose = self.create_publisher(PoseStamped, topics.EE_POSE, topics.SENSOR_QOS)
        self.ee_twist = self.create_publisher(TwistStamped, topics.EE_TWIST, topics.SENSOR_QOS)
        self.ee_at_rest = self.create_publisher(AtRest, topics.EE_AT_REST, topics.COMMAND_QOS)
        #: The loop's commands (a torque robot's torques in ``effort``): the separate sim's input,
        #: and in the composed process the commanded torques beside the measured ones.
        self.joint_commands = self.create_publisher(JointStateMsg, topics.JOINT_COMMANDS,
                                                    topics.SENSOR_QOS)
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
        self.ee_pose.publish(pose_stamped(tool.position, tool.rotation, stamp, self.base_frame))
        self.ee_twist.publish(twist_stamped(tool.twist, stamp, self.base_frame))


class RosOutlet:
    """A ``LoopRunner``'s output as the separate bridge's topics: the tool pose and twist of
    the publishing ticks and the at-rest events, from the loop's thread."""

    def __init__(self, bridge: BridgeNode) -> None:
        self.bridge = bridge

    def sample(self, t_ns: int, loop: LoopCore, publish: bool) -> None:
        tool = loop.controller.tool
        if publish and tool is not None:
            self.bridge.publish_tool(time_msg(t_ns), tool)

    def at_rest(self, event: StepEvent) -> None:
        self.bridge.ee_at_rest.publish(at_rest_msg(event.seq, event.result, event.position,
                                                   event.rotation, time_msg(event.t_ns),
                                                   self.bridge.base_frame))

    def reset_done(self, job: int, event: StepEvent | None, error: str | None) -> None:
        del job, event, error     # the sim restarted on its own: nobody waits for an answer

    def log(self, level: str, message: str) -> None:
        log_at(self.bridge, level, message)


#: [s] The same line from the loop is logged at most this often.
LOG_REPEAT = 1.0
_logged: dict[tuple[str, str], float] = {}


def log_at(node: Node, level: str, message: str) -> None:
    """Log a line the loop reported (``info``, ``warning``, else error), the same line at most
    once a second (a loop can repeat a complaint every tick). Throttled by its text, not by
    rclpy's call site: every line comes through here, and a rejected setpoint's line once
    went unlogged because a failed reset's had been logged the moment before."""
    now, key = time.monotonic(), (level, message)
    if now - _logged.get(key, -math.inf) < LOG_REPEAT:
        return
    _logged[key] = now
    if len(_logged) > 1000:              # lines carrying numbers: forget the old ones
        for old in [k for k, t in _logged.items() if now - t >= LOG_REPEAT]:
            del _logged[old]
    # Each severity from a call site of its own: rclpy refuses a call site that changes it.
    logger = node.get_logger()
    if level == "info":
        logger.info(message)
    elif level == "warning":
        logger.warning(message)
    else:
        logger.error(message)


# --- separate-process mode ------------------------------------------------------------------


class RemoteRobot:
    """The loop's hardware and simulation over topics: the arm is the separate sim process.

    ``read`` is the latest ``joint_states`` and ``state_time`` its stamp; ``write`` publishes
    ``joint_commands`` (the command in the interface kind's ``command_field``: torques in
    ``effort``, targets in ``position``) and waits (up to ``timeout``) for the next state, so
    the loop ticks once per state it takes, and a tick covers the time since the previous state
    it took, however many it missed. The first state and every ``sim/restarted`` call
    ``on_restart``; ``take_restart`` then waits for a state from after the restart, so the loop
    settles from the new pose.

    A command's stamp names the restart it follows: the ``sim/restarted`` stamp the loop last
    reset from. Until the loop has taken a restart, its commands still aim at the pose before
    it, and the sim, which applies only commands of its latest restart, holds the new pose
    instead (before this, the first reset after start-up dragged a Nextage 69 deg of a joint
    back toward its old pose for 90 ms, and the reply's pose was 0.02-8.6 mm off). The sim
    announces its start as a restart too, so a loop that has taken none sends nothing: a bridge
    started beside a running sim waits for the latched ``sim/restarted`` (on a loaded host it
    once came 1.1 s after the first state, and the sim warned of stale commands meanwhile).
    """

    def __init__(self, node: BridgeNode, n_joints: int, command_field: str,
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
        self.commands = node.joint_commands
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
        if self._epoch_ns:              # else no restart taken yet: the sim holds the arm
            msg = JointStateMsg(**{self.command_field: np.asarray(command, float).tolist()})
            msg.header.stamp = time_msg(self._epoch_ns)
            self.commands.publish(msg)
        with self._fresh:
            if self._received == self._used:
                self._fresh.wait(self.timeout)
            self._used = self._received

    def take_restart(self) -> None:
        """The sim teleported the arm (it serves ``move_to_start``): wait for its first state
        after that, and stamp the commands from then on with that restart.

        :raises TimeoutError: if the sim publishes none within a second.
        """
        with self._fresh:
            restart = self._restart_ns
            if not self._fresh.wait_for(lambda: self._stamp >= restart * 1e-9, timeout=1.0):
                raise TimeoutError("no joint_states after the sim restarted")
            self._epoch_ns = restart

    # --- simulation interface --------------------------------------------------------------
    def teleport(self, start: StartPose) -> None:
        """Not the bridge's to do here: the separate sim serves ``move_to_start`` itself."""
        raise RuntimeError("in separate-process mode the sim moves the arm to its start "
                           "(its move_to_start service); the bridge only settles it")

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
    mailbox = ThreadMailbox()

    def restart() -> None:
        mailbox.post_reset(ResetCommand(None))

    # The robot's own parameters belong to the separate sim process: describe it by its defaults.
    description = bridge.plugin.describe(package_defaults("sim", bridge.plugin.config_files))
    remote = RemoteRobot(bridge, len(description.joint_names), bridge.kind.command_field, restart)
    params = {**p, "loop": {**p.get("loop", {}), "realtime": True}}
    loop = bridge.kind.build_loop(Robot(remote, remote, description), params, {},
                                  wrench=LatestWrench(bridge),
                                  clock=StateClock(remote, MAX_STATE_GAP))
    runner = LoopRunner(loop, mailbox, RosOutlet(bridge), lockstep=False, pace=remote.wait_ready,
                        take_restart=remote.take_restart)
    bridge.setpoint_handler = lambda msg: mailbox.post_setpoint(
        SetpointCommand(int(msg.seq), setpoint_from_msg(msg)))
    favour_loop_thread()
    return LoopThread("bridge loop", runner.run, bridge).start().stop


def main(args: list[str] | None = None) -> int:
    # Its callbacks only store the latest message for the loop thread.
    return run_nodes([BridgeNode], args, background=_start_separate_bridge,
                     blocking_callbacks=False)


if __name__ == "__main__":
    raise SystemExit(main())
