"""The ``robot`` process: sim, bridge, estimator and recorder nodes around one 1 kHz loop.

Sending joint states between processes at 1 kHz costs more than the loop itself, so the robot
(the plugin named by the ``robot`` parameter, ``sim_panda`` by default), the controller and the
EKF run as one ``RobotLoop`` on one thread (``bridge_node.LoopRunner``), and the nodes only
publish what it produced and serve its services, under their own names, parameters and topics.

The reset path, end to end: the executor calls ``sim/reset`` -> ``serve_reset`` validates ->
``LoopRunner.reset`` hands the job to the loop thread -> ``RobotLoop.reset`` resets the plugin's
simulation and settles -> the settled ``AtRest`` is the answer. Clock modes (``sim.clock_mode``):

- ``lockstep``: the loop ticks as fast as it can while a setpoint executes and pauses once the
  step is at rest until the next setpoint or reset; messages carry simulated time and ``/clock``
  is published, so a run is reproducible.
- ``realtime``: the loop ticks at wall-clock 1 kHz, holds the last command like hardware, and
  the safety watchdog holds the pose when setpoints stop coming for 10 ms.
"""
from __future__ import annotations

import time
from collections.abc import Callable

from builtin_interfaces.msg import Time
from qg_common.node_runtime import LoopThread, favour_loop_thread, run_nodes
from qg_common.realtime_pacer import RealtimePacer
from rclpy.node import Node

from robot_bridge_node.bridge_node import BridgeNode, LoopRunner
from robot_bridge_node.core.robot_loop import RobotLoop
from robot_bridge_node.core.tick_timing import TickTiming
from robot_bridge_node.estimator_node import WrenchEstimatorNode
from robot_bridge_node.loop_diagnostics import LoopDiagnostics
from robot_bridge_node.recorder_node import RecorderNode
from robot_bridge_node.simulation_node import SimulationNode, serve_reset

__all__ = ["RobotProcess", "main"]


class RobotProcess:
    """One ``RobotLoop`` (robot plugin, controller, safety, rest detector, EKF) and its nodes.

    The loop is the robot's interface kind's (``InterfaceKind.build_loop``): a torque robot's
    runs the hybrid force/impedance controller and the EKF; a position robot's
    (``position_loop.PositionLoop``) the task-space IK and reads the wrist sensor.

    The loop is built from the nodes' parameters: the robot plugin the sim node loaded (its
    ``robot`` parameter) from the sim node's sections. ``runner.loop_observers`` is where a per-tick
    recorder attaches. The start pose (``sim.initial_pose``) is taken before the loop thread
    starts, so every run has the same history (lockstep runs repeat exactly).
    """

    def __init__(self, sim: SimulationNode, bridge: BridgeNode,
                 estimator: WrenchEstimatorNode) -> None:
        self.sim = sim
        self.bridge = bridge
        self.estimator = estimator
        config = sim.config
        robot = sim.plugin.create(sim.params)
        bridge_params = {**bridge.params,
                         "loop": {**bridge.params.get("loop", {}), "realtime": config.realtime}}
        self.loop: RobotLoop = bridge.kind.build_loop(robot, bridge_params, estimator.params)
        #: Realtime: holds the wall-clock tick period (``missed`` counts dropped ticks).
        self.pacer = RealtimePacer(self.loop.config.dt) if config.realtime else None
        pacer = self.pacer
        #: Realtime: how the ticks were spaced (published on ``diagnostics``).
        self.timing = TickTiming(self.loop.config.dt)
        timing = self.timing

        def pace() -> bool:
            timing.drop(pacer.wait())
            timing.tick(time.perf_counter_ns())
            return True
        self.runner = LoopRunner(self.loop, bridge, lockstep=not config.realtime,
                                 pace=pace if pacer is not None else None,
                                 publish_every=config.publish_every(self.loop.config.dt),
                                 publish=self._publish)
        self.truth_every = config.ground_truth_every(self.loop.config.dt)
        bridge.setpoint_handler = self.runner.submit_setpoint
        serve_reset(sim, self.runner)
        self.loop.reset(config.initial_pose)     # before the loop thread exists

    def _publish(self, stamp: Time) -> None:
        """The sim's and the estimator's share of a published tick (and ``/clock``)."""
        loop = self.loop
        self.sim.publish_state(stamp, loop.hardware.read(),
                               loop.ground_truth() if self.runner.ticks % self.truth_every == 0
                               else None)
        if self.loop.wrench_estimate is not None:
            self.estimator.publish(stamp, self.loop.wrench_estimate)
        if self.runner.lockstep:
            self.sim.publish_clock(stamp)

    def start(self) -> Callable[[], None]:
        """Start the loop thread; returns the function that stops it."""
        if not self.runner.lockstep:
            favour_loop_thread()
        priority = 0 if self.runner.lockstep else self.sim.config.realtime_priority
        return LoopThread("robot loop", self.runner.run, self.bridge, priority).start().stop


def _start(nodes: list[Node]) -> Callable[[], None]:
    sim, bridge, estimator, recorder = nodes
    assert isinstance(sim, SimulationNode) and isinstance(bridge, BridgeNode) \
        and isinstance(estimator, WrenchEstimatorNode) and isinstance(recorder, RecorderNode)
    process = RobotProcess(sim, bridge, estimator)
    process.runner.loop_observers.append(recorder.observe)
    recorder.clock_ns = process.runner.now_ns
    if sim.config.realtime:
        LoopDiagnostics(bridge, process.timing.snapshot, str(sim.get_parameter("robot").value))
    return process.start()


def main(args: list[str] | None = None) -> int:
    sim: list[SimulationNode] = []   # the sim node loads the plugin its `robot` names

    def make_sim() -> SimulationNode:
        sim.append(SimulationNode())
        return sim[0]

    return run_nodes([make_sim, lambda: BridgeNode(sim[0].plugin),
                      lambda: WrenchEstimatorNode(sim[0].plugin), RecorderNode], args,
                     background=_start)


if __name__ == "__main__":
    raise SystemExit(main())
