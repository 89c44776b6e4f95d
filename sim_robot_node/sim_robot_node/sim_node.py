"""The ``sim`` node: the simulated robot as ROS sees it (joint states, ground truth, reset).

``SimNode`` is only the ROS face: it publishes what it is handed and forwards ``/sim/reset`` to
whoever steps the physics. In the composed ``robot`` process that is the one 1 kHz loop shared
with the bridge and the estimator (``robot_bridge_node.robot_process``). Run on its own
(``ros2 run sim_robot_node sim``), ``SeparateSim`` steps the scene at wall-clock 1 kHz like a
torque-controlled arm: it applies the latest ``/joint_commands`` efforts, and with no fresh
command it holds gravity-compensating torques, as the Panda's own firmware would.
"""
from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pybullet
import rclpy.qos
from builtin_interfaces.msg import Time
from geometry_msgs.msg import WrenchStamped
from qg_interfaces.msg import AtRest, GroundTruth
from qg_interfaces.srv import ResetSim
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from sim_robot_node.conversions import (at_rest_msg, ground_truth_msg, joint_state_msg,
                                        wrench_from_msg, wrench_stamped)
from sim_robot_node.core import types
from sim_robot_node.core.types import StepResult
from sim_robot_node.core.panda_scene import N_START_POSES, PandaSceneConfig, PandaShaftScene
from sim_robot_node.core.params import config_from_dict
from sim_robot_node.node_runtime import LoopThread, RealtimePacer, node_params, run_nodes

__all__ = ["SENSOR_QOS", "RESTARTED_TOPIC", "RESTARTED_QOS", "SimConfig", "SimNode", "SeparateSim", "main"]

SENSOR_QOS = rclpy.qos.QoSProfile(depth=1, reliability=rclpy.qos.ReliabilityPolicy.BEST_EFFORT)

#: Separate processes only: the sim teleported the arm (a reset); header stamp = when.
RESTARTED_TOPIC = "/sim/restarted"
RESTARTED_QOS = 10

#: What a reset handler does: reset to (initial_pose, housing_yaw), settle, return the observation.
ResetHandler = Callable[[int, float], AtRest]


@dataclass(frozen=True)
class SimConfig:
    """The ``sim`` section of ``config/sim.yaml``: clock mode and the separate-process sim.

    :param clock_mode: ``lockstep`` (the loop runs as fast as it can while a setpoint executes,
        publishes ``/clock``) or ``realtime`` (wall-clock 1 kHz). Separate processes are always
        realtime.
    :param publish_rate: [Hz] rate of the 1 kHz topics; 0 picks 1000 in realtime and 100 (of
        simulated time) in lockstep, where publishing would otherwise dominate the tick.
    :param ground_truth_rate: [Hz] rate of ``/sim/ground_truth(_wrench)``, at most
        ``publish_rate``: computing the ground truth costs about a third of a tick.
    :param realtime_priority: realtime: ``SCHED_FIFO`` priority (1..99) of the 1 kHz loop
        thread; 0 keeps the normal scheduler.
    :param initial_pose: start pose (0..7) taken when the process starts.
    :param command_timeout: [s] separate sim: a ``/joint_commands`` older than this is stale.
    :param hold_damping: [Nms/rad] separate sim: joint damping added to the gravity hold.
    :param reset_wait: [s] separate sim: wall time the bridge gets to settle after a reset
        before ``/sim/reset`` answers.
    """
    clock_mode: str = "lockstep"
    publish_rate: float = 0.0
    ground_truth_rate: float = 100.0
    realtime_priority: int = 0
    initial_pose: int = 0
    command_timeout: float = 0.02
    hold_damping: float = 1.0
    reset_wait: float = 0.2

    def __post_init__(self) -> None:
        if self.clock_mode not in ("lockstep", "realtime"):
            raise ValueError(f"clock_mode must be 'lockstep' or 'realtime', got {self.clock_mode!r}")
        if not (math.isfinite(self.publish_rate) and 0.0 <= self.publish_rate <= 1000.0):
            raise ValueError(f"publish_rate must be in [0, 1000] Hz (0: mode default), "
                             f"got {self.publish_rate}")
        if not (math.isfinite(self.ground_truth_rate) and 0.0 < self.ground_truth_rate <= 1000.0):
            raise ValueError(f"ground_truth_rate must be in (0, 1000] Hz, "
                             f"got {self.ground_truth_rate}")
        if not 0 <= self.realtime_priority <= 99:
            raise ValueError(f"realtime_priority must be in 0..99 (0: normal scheduling), "
                             f"got {self.realtime_priority}")
        if not 0 <= self.initial_pose < N_START_POSES:
            raise ValueError(f"initial_pose must be in 0..{N_START_POSES - 1}, "
                             f"got {self.initial_pose}")
        for name in ("command_timeout", "reset_wait"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0 s, got {getattr(self, name)}")
        if self.hold_damping < 0.0:
            raise ValueError(f"hold_damping must be >= 0, got {self.hold_damping}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> SimConfig:
        """From the ``sim`` section of ``config/sim.yaml``."""
        return config_from_dict(cls, params)

    @property
    def realtime(self) -> bool:
        return self.clock_mode == "realtime"

    def publish_every(self, dt: float) -> int:
        """Publish the 1 kHz topics every this many ticks of ``dt`` seconds."""
        rate = self.publish_rate or (1000.0 if self.realtime else 100.0)
        return max(1, round(1.0 / (rate * dt)))

    def ground_truth_every(self, dt: float) -> int:
        """Publish the ground truth every this many ticks (a multiple of ``publish_every``)."""
        every = self.publish_every(dt)
        return every * max(1, round(1.0 / (self.ground_truth_rate * dt * every)))


class SimNode(Node):
    """Publishes the simulated hardware's state; serves ``/sim/reset`` through ``reset_handler``.

    The handler runs in its own callback group, so it may block until the loop thread has
    reset and settled the scene while the node's other callbacks keep running.
    """

    def __init__(self) -> None:
        super().__init__("sim", automatically_declare_parameters_from_overrides=True)
        self.params = node_params(self)
        self.config = SimConfig.from_dict(self.params.get("sim", {}))
        self.scene_config = PandaSceneConfig.from_dict(self.params.get("panda_scene", {}))
        self.joint_states = self.create_publisher(JointState, "/joint_states", SENSOR_QOS)
        self.ground_truth = self.create_publisher(GroundTruth, "/sim/ground_truth", SENSOR_QOS)
        self.ground_truth_wrench = self.create_publisher(
            WrenchStamped, "/sim/ground_truth_wrench", SENSOR_QOS)
        self.clock = self.create_publisher(Clock, "/clock", SENSOR_QOS)
        self.reset_handler: ResetHandler | None = None
        self.create_service(ResetSim, "/sim/reset", self._on_reset,
                            callback_group=MutuallyExclusiveCallbackGroup())

    def publish_state(self, stamp: Time, state: types.JointState,
                      truth: types.GroundTruth | None = None) -> None:
        """``/joint_states``, and with ``truth`` ``/sim/ground_truth(_wrench)``."""
        self.joint_states.publish(joint_state_msg(state, stamp))
        if truth is not None:
            self.ground_truth.publish(ground_truth_msg(truth, stamp))
            self.ground_truth_wrench.publish(wrench_stamped(truth.wrench, stamp))

    def publish_clock(self, stamp: Time) -> None:
        self.clock.publish(Clock(clock=stamp))

    def _on_reset(self, request: ResetSim.Request, response: ResetSim.Response) -> ResetSim.Response:
        if not 0 <= request.initial_pose < N_START_POSES:
            response.success = False
            response.message = (f"initial_pose must be 0..{N_START_POSES - 1}, "
                                f"got {request.initial_pose}")
            return response
        if not math.isfinite(request.housing_yaw):
            response.success = False
            response.message = f"housing_yaw must be finite, got {request.housing_yaw}"
            return response
        if self.reset_handler is None:
            response.success = False
            response.message = "the simulation is not running yet"
            return response
        try:
            response.observation = self.reset_handler(request.initial_pose, request.housing_yaw)
        except (RuntimeError, ValueError, TimeoutError) as exc:
            self.get_logger().error(f"reset to pose {request.initial_pose} failed: {exc}")
            response.success = False
            response.message = f"reset failed: {exc}"
            return response
        response.success = True
        response.message = f"reset to pose {request.initial_pose}, yaw {request.housing_yaw:.3f} rad"
        return response


@dataclass
class _ResetJob:
    """A reset handed from the service thread to the loop thread."""
    initial_pose: int
    housing_yaw: float
    done: threading.Event
    due: float = math.inf                 # perf_counter time at which to answer
    observation: AtRest | None = None


class SeparateSim:
    """The scene stepped at wall-clock 1 kHz under ``/joint_commands`` (separate processes).

    Every tick applies the latest command if it is fresh (younger than ``command_timeout`` and
    sent after the last reset), else gravity compensation with joint damping; then it steps and
    publishes the new state (``effort`` = the torque just applied) and the ground truth. A reset
    teleports the arm and announces it on ``/sim/restarted`` (stamped with the reset time), so
    the bridge and the estimator restart from the new state; the bridge settles under its
    controller, and after ``reset_wait`` the service answers with the settled observation (the
    last ``/wrench_estimate`` as its estimate).
    """

    def __init__(self, node: SimNode, scene: PandaShaftScene) -> None:
        self.node = node
        self.scene = scene
        self.config = node.config
        self.pacer = RealtimePacer(scene.config.time_step)
        self._command: tuple[float, np.ndarray] | None = None   # (arrival, tau)
        self._estimate = np.zeros(6)
        self._jobs: queue.Queue[_ResetJob] = queue.Queue()
        self._job: _ResetJob | None = None
        self._reset_time = -math.inf
        self.restarted = node.create_publisher(Header, RESTARTED_TOPIC, RESTARTED_QOS)
        node.create_subscription(JointState, "/joint_commands", self._on_command, SENSOR_QOS)
        node.create_subscription(WrenchStamped, "/wrench_estimate", self._on_estimate, SENSOR_QOS)
        node.reset_handler = self.reset

    def _on_command(self, msg: JointState) -> None:
        tau = np.asarray(msg.effort, float)
        if tau.shape != (7,) or not np.all(np.isfinite(tau)):
            self.node.get_logger().error(f"ignoring /joint_commands without 7 finite efforts: "
                                         f"{tau.tolist()}", throttle_duration_sec=1.0)
            return
        self._command = (time.perf_counter(), tau)

    def _on_estimate(self, msg: WrenchStamped) -> None:
        self._estimate = wrench_from_msg(msg.wrench)

    def hold_torques(self, state: types.JointState) -> np.ndarray:
        """Gravity (with the shaft) compensated, motion damped: the arm floats in place."""
        zeros = [0.0] * 7
        gravity = np.asarray(pybullet.calculateInverseDynamics(
            self.scene.robot, state.q.tolist(), zeros, zeros, physicsClientId=self.scene.cid))
        return gravity - self.config.hold_damping * state.dq

    def reset(self, initial_pose: int, housing_yaw: float) -> AtRest:
        """Reset on the loop thread, wait ``reset_wait``, return the settled observation."""
        job = _ResetJob(initial_pose, housing_yaw, threading.Event())
        self._jobs.put(job)
        if not job.done.wait(timeout=self.config.reset_wait + 5.0):
            raise TimeoutError("the simulation loop did not complete the reset")
        assert job.observation is not None
        return job.observation

    def run(self, stop: threading.Event) -> None:
        """The 1 kHz loop (body of a ``LoopThread``)."""
        every = self.config.publish_every(self.scene.config.time_step)
        truth_every = self.config.ground_truth_every(self.scene.config.time_step)
        tick = 0
        while not stop.is_set():
            self.pacer.wait()
            now = time.perf_counter()
            self._take_reset(now)
            state = self.scene.joint_state()
            command = self._command
            fresh = (command is not None and command[0] > self._reset_time
                     and now - command[0] < self.config.command_timeout)
            self.scene.apply_torques(command[1] if fresh else self.hold_torques(state))
            self.scene.step()
            tick += 1
            if tick % every == 0:
                stamp = self.node.get_clock().now().to_msg()
                self.node.publish_state(stamp, self.scene.joint_state(),
                                        self.scene.ground_truth() if tick % truth_every == 0
                                        else None)
            if self._job is not None and now >= self._job.due:
                self._job.observation = self._observation()
                self._job.done.set()
                self._job = None

    def _take_reset(self, now: float) -> None:
        try:
            job = self._jobs.get_nowait()
        except queue.Empty:
            return
        self.scene.reset(job.initial_pose, job.housing_yaw)
        self._reset_time = now
        job.due = now + self.config.reset_wait
        self._job = job
        self.restarted.publish(Header(stamp=self.node.get_clock().now().to_msg()))

    def _observation(self) -> AtRest:
        scene = self.scene
        link = pybullet.getLinkState(scene.robot, scene.shaft_link, computeLinkVelocity=True,
                                     physicsClientId=scene.cid)
        position, rotation = scene.tool_pose()
        result = StepResult(duration=self.config.reset_wait, timed_out=False,
                            linear_speed=float(np.linalg.norm(link[6])),
                            angular_speed=float(np.linalg.norm(link[7])),
                            ground_truth=scene.ground_truth(), wrench_estimate=self._estimate)
        return at_rest_msg(0, result, position, rotation, self.node.get_clock().now().to_msg())


def _start_separate_sim(nodes: list[Node]) -> Callable[[], None]:
    node = nodes[0]
    assert isinstance(node, SimNode)
    if not node.config.realtime:
        node.get_logger().info("separate sim process: running in realtime (wall-clock 1 kHz)")
    scene = PandaShaftScene(node.scene_config)
    scene.reset(node.config.initial_pose)
    sim = SeparateSim(node, scene)
    return LoopThread("sim", sim.run, node, node.config.realtime_priority).start().stop


def main(args: list[str] | None = None) -> int:
    return run_nodes([SimNode], ["panda_scene.yaml", "sim.yaml"], args,
                     background=_start_separate_sim)


if __name__ == "__main__":
    raise SystemExit(main())
