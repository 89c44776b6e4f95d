"""``ros2 run sim_robot_node sim``: the simulated Panda as a process of its own.

The stack normally runs the simulation inside the ``robot`` process (the ``sim_panda`` plugin of
``robot_bridge_node``). Run on its own, ``SeparateSim`` steps the scene at wall-clock 1 kHz like
a torque-controlled arm: it applies the latest ``joint_commands`` efforts, and with no fresh
command it holds gravity-compensating torques, as the Panda's own firmware would. The node is
the bridge's ``SimulationNode`` (the same topics as in the composed process).
"""
from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import pybullet
from qg_common import topics
from qg_common.node_runtime import LoopThread, RealtimePacer, favour_loop_thread, run_nodes
from qg_common.types import JointState
from qg_interfaces.msg import AtRest
from rclpy.node import Node
from robot_bridge_node.simulation_node import SimulationNode, serve_reset
from sensor_msgs.msg import JointState as JointStateMsg
from std_msgs.msg import Header

from sim_robot_node.core.panda_scene import PandaSceneConfig, PandaShaftScene
from sim_robot_node.plugins import SIM_PANDA

__all__ = ["SeparateSim", "main"]


@dataclass
class _ResetJob:
    """A reset handed from the service thread to the loop thread."""
    initial_pose: int
    housing_yaw: float
    done: threading.Event
    due: float = math.inf                 # perf_counter time from which to answer
    observation: AtRest | None = None


class SeparateSim:
    """The scene stepped at wall-clock 1 kHz under ``/joint_commands`` (separate processes).

    Every tick applies the latest command if it is fresh (younger than ``command_timeout`` and
    sent after the last reset), else gravity compensation with joint damping; then it steps and
    publishes the new state (``effort`` = the torque just applied) and the ground truth. A reset
    teleports the arm and announces it on ``sim/restarted`` (stamped with the reset time), so
    the bridge and the estimator restart from the new state; the bridge settles under its
    controller and reports the settled state (``ee_at_rest`` with ``seq`` 0), and no earlier
    than ``reset_wait`` after the reset the service answers with that observation.
    """

    def __init__(self, node: SimulationNode, scene: PandaShaftScene) -> None:
        self.node = node
        self.scene = scene
        self.config = node.config
        self.pacer = RealtimePacer(scene.config.time_step)
        self._command: tuple[float, np.ndarray] | None = None   # (arrival, tau)
        self._settled: AtRest | None = None     # the bridge's observation after the last reset
        self._jobs: queue.Queue[_ResetJob] = queue.Queue()
        self._job: _ResetJob | None = None
        self._reset_time = -math.inf
        self.restarted = node.create_publisher(Header, topics.SIM_RESTARTED, topics.RESTARTED_QOS)
        node.create_subscription(JointStateMsg, topics.JOINT_COMMANDS, self._on_command,
                                 topics.SENSOR_QOS)
        node.create_subscription(AtRest, topics.EE_AT_REST, self._on_at_rest, topics.COMMAND_QOS)
        serve_reset(node, self)

    def _on_command(self, msg: JointStateMsg) -> None:
        tau = np.asarray(msg.effort, float)
        if tau.shape != (7,) or not np.all(np.isfinite(tau)):
            self.node.get_logger().error(f"ignoring joint_commands without 7 finite efforts: "
                                         f"{tau.tolist()}", throttle_duration_sec=1.0)
            return
        self._command = (time.perf_counter(), tau)

    def _on_at_rest(self, msg: AtRest) -> None:
        if msg.seq == 0:
            self._settled = msg

    def hold_torques(self, state: JointState) -> np.ndarray:
        """Gravity (with the shaft) compensated, motion damped: the arm floats in place."""
        zeros = [0.0] * 7
        gravity = np.asarray(pybullet.calculateInverseDynamics(
            self.scene.robot, state.q.tolist(), zeros, zeros, physicsClientId=self.scene.cid))
        return gravity - self.config.hold_damping * state.dq

    def reset(self, initial_pose: int, housing_yaw: float = 0.0, timeout: float = 5.0,
              session: str = "") -> AtRest:
        """Reset on the loop thread; the bridge's settled observation, ``reset_wait`` at the
        earliest.

        ``session`` is not enforced in this separate-process mode: the bridge learns of a reset
        only from the restarted state stream, so it serves any sender (the composed ``robot``
        process, the default, serves only the reset's session).
        :raises TimeoutError: if the bridge reports no settled state within ``timeout`` s more.
        """
        del session
        job = _ResetJob(initial_pose, housing_yaw, threading.Event())
        self._jobs.put(job)
        if not job.done.wait(timeout=self.config.reset_wait + timeout):
            raise TimeoutError("the bridge reported no settled state after the reset")
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
            if self._job is not None and now >= self._job.due and self._settled is not None:
                self._job.observation = self._settled
                self._job.done.set()
                self._job = None

    def _take_reset(self, now: float) -> None:
        try:
            job = self._jobs.get_nowait()
        except queue.Empty:
            return
        self.scene.reset(job.initial_pose, job.housing_yaw)
        self._settled = None
        self._reset_time = now
        job.due = now + self.config.reset_wait
        self._job = job
        self.restarted.publish(Header(stamp=self.node.get_clock().now().to_msg()))


def _start_separate_sim(nodes: list[Node]) -> Callable[[], None]:
    node = nodes[0]
    assert isinstance(node, SimulationNode)
    if not node.config.realtime:
        # The realtime rates follow, not only the pacing: published at lockstep's 100 Hz, the
        # states would clock the bridge's loop (one tick per state) ten times too slowly.
        node.get_logger().info("separate sim process: running in realtime (wall-clock 1 kHz)")
        node.config = replace(node.config, clock_mode="realtime")
    scene = PandaShaftScene(PandaSceneConfig.from_dict(node.params.get("panda_scene", {})))
    scene.reset(node.config.initial_pose)
    sim = SeparateSim(node, scene)
    favour_loop_thread()
    return LoopThread("sim", sim.run, node, node.config.realtime_priority).start().stop


def main(args: list[str] | None = None) -> int:
    return run_nodes([lambda: SimulationNode(SIM_PANDA)], args, background=_start_separate_sim)


if __name__ == "__main__":
    raise SystemExit(main())
