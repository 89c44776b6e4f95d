"""Tick timing of the composed robot process in realtime mode (wall-clock 1 kHz).

Runs the ``robot`` process's nodes (sim, bridge, wrench_estimator) and its loop thread in this
process, spun by the same executor as ``ros2 run robot_bridge_node robot`` in realtime mode,
while a fourth node plays the executor: a residual setpoint repeated every 4 ms, a new one every
0.5 s. Every tick's start is timestamped by a loop observer. Reports the tick period
p50/p99/max, the fraction of ticks on time, the realtime factor, CPU use, and (``--cost``) the
time of one loop tick and of publishing the 1 kHz topics once, measured without pacing. Goal: p99 <= 1.5 ms, >= 99.5 % on time.

"On time": a tick whose period (start to start) is at most 1.5 ms, i.e. at most half a period
late; ticks dropped by the pacer after falling a full period behind are counted as late too.

Usage: python benchmarks/realtime_bench.py [--seconds 30] [--publish-rate 1000] [--cost]
       [--priority 50] [--switch-interval 0.005]
(in the stack environment: eval "$(.venv/bin/python -m qg_learning_node.cli.ros_env)")
"""
from __future__ import annotations

import argparse
import gc
import json
import resource
import sys
import threading
import time

import numpy as np
import rclpy
from qg_interfaces.msg import WrenchSetpoint as WrenchSetpointMsg
from qg_common.callback_executor import CallbackThreadPool
from rclpy.node import Node
from rclpy.timer import Timer
from qg_common.conversions import setpoint_msg
from qg_common.conversions import time_msg
from qg_common.types import WrenchSetpoint
from robot_bridge_node.bridge_node import BridgeNode
from robot_bridge_node.estimator_node import WrenchEstimatorNode
from robot_bridge_node.robot_process import RobotProcess
from robot_bridge_node.simulation_node import SimulationNode

ON_TIME = 1.5e-3   # [s] largest tick period counted as on time


def start_process(mode: str, publish_rate: float, priority: int = 0
                  ) -> tuple[RobotProcess, list[Node]]:
    rclpy.init(args=[
        "realtime_bench", "--ros-args", "-p", f"sim.clock_mode:={mode}",
        "-p", f"sim.publish_rate:={float(publish_rate)}",
        "-p", f"sim.realtime_priority:={priority}"])
    sim = SimulationNode()
    nodes = [sim, BridgeNode(sim.plugin), WrenchEstimatorNode(sim.plugin)]
    return RobotProcess(*nodes), nodes


def executor_stand_in(node: Node, rng: np.random.Generator) -> Timer:
    """Repeat a residual setpoint every 4 ms; a new seq every 0.5 s."""
    publisher = node.create_publisher(WrenchSetpointMsg, "/wrench_setpoint", 10)
    state = {"seq": 0, "msg": None, "t": -1.0}

    def send() -> None:
        now = time.monotonic()
        if now - state["t"] > 0.5:
            state["seq"] += 1
            state["t"] = now
            state["msg"] = setpoint_msg(state["seq"], WrenchSetpoint.residual(
                -10.0, *(rng.uniform(-1.0, 1.0, 2))), time_msg(0))
        publisher.publish(state["msg"])

    return node.create_timer(0.004, send)


def realtime(seconds: float, publish_rate: float, switch_interval: float | None,
             priority: int) -> dict:
    process, nodes = start_process("realtime", publish_rate, priority)
    stand_in = Node("executor_stand_in")
    timer = executor_stand_in(stand_in, np.random.default_rng(0))
    starts: list[int] = []
    process.runner.loop_observers.append(lambda ns, loop: starts.append(time.perf_counter_ns()))
    executor = CallbackThreadPool(num_threads=3)
    for node in [*nodes, stand_in]:
        executor.add_node(node)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    cpu0, wall0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    stop = process.start()
    if switch_interval is not None:
        sys.setswitchinterval(switch_interval)
    time.sleep(seconds)
    stop()
    cpu1, wall1 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    ticks = process.runner.ticks
    stand_in.destroy_timer(timer)    # no callback may be running into the teardown
    executor.shutdown()
    spin.join()
    for node in [*nodes, stand_in]:
        node.destroy_node()
    rclpy.shutdown()
    gc.collect()   # rclpy reports callbacks cut short by the teardown now, not after the results
    periods = np.diff(np.asarray(starts, dtype=np.int64)) * 1e-9
    periods = periods[1:]   # the first tick of the pacer has no deadline
    missed = process.pacer.missed
    cpu = (cpu1.ru_utime + cpu1.ru_stime - cpu0.ru_utime - cpu0.ru_stime) / (wall1 - wall0)
    return {"ticks": int(periods.size + 1), "missed_ticks": int(missed),
            "period_p50_ms": float(np.percentile(periods, 50) * 1e3),
            "period_p99_ms": float(np.percentile(periods, 99) * 1e3),
            "period_max_ms": float(periods.max() * 1e3),
            "on_time_fraction": float(np.sum(periods <= ON_TIME) / (periods.size + missed)),
            "realtime_factor": float(ticks * process.loop.config.dt / (wall1 - wall0)),
            "cpu_fraction_of_one_core": float(cpu)}


def publishing_cost(ticks: int) -> dict:
    """Time of a loop tick and of publishing one sample of the 1 kHz topics [us], the ground
    truth at its own rate as in the process."""
    process, nodes = start_process("lockstep", 1000.0)
    loop, runner = process.loop, process.runner
    loop.command(WrenchSetpoint.residual(-10.0, 0.5, 0.0))
    start = time.perf_counter()
    for _ in range(ticks):
        loop.tick()
    tick = (time.perf_counter() - start) / ticks
    start = time.perf_counter()
    for k in range(ticks):
        runner.ticks = k     # what decides whether this sample carries the ground truth
        runner.publish_sample(time_msg(k))
    publish = (time.perf_counter() - start) / ticks
    for node in nodes:
        node.destroy_node()
    rclpy.shutdown()
    return {"tick_us": tick * 1e6, "publish_us_per_sample": publish * 1e6}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="wall seconds to run")
    parser.add_argument("--publish-rate", type=float, default=1000.0, help="[Hz] 1 kHz topics")
    parser.add_argument("--cost", action="store_true", help="also measure the publishing cost")
    parser.add_argument("--switch-interval", type=float, default=None,
                        help="[s] override the process's GIL switch interval (A/B test)")
    parser.add_argument("--priority", type=int, default=0,
                        help="SCHED_FIFO priority of the loop thread (sim.realtime_priority)")
    args = parser.parse_args()
    result = {"seconds": args.seconds, "publish_rate_hz": args.publish_rate}
    if args.cost:
        result.update(publishing_cost(3000))
    result.update(realtime(args.seconds, args.publish_rate, args.switch_interval, args.priority))
    result["priority"] = args.priority
    result["switch_interval_s"] = sys.getswitchinterval()
    print(f"on time = tick period <= {ON_TIME * 1e3:.1f} ms (start to start); ticks the pacer "
          f"dropped after falling a period behind count as late")
    print(f"ticks {result['ticks']} in {args.seconds:.0f} s, realtime factor "
          f"{result['realtime_factor']:.3f}, missed {result['missed_ticks']}")
    print(f"period p50 {result['period_p50_ms']:.3f} ms  p99 {result['period_p99_ms']:.3f} ms  "
          f"max {result['period_max_ms']:.3f} ms  on time {result['on_time_fraction']:.2%}  "
          f"(goal p99 <= 1.5 ms, >= 99.5 %)")
    print(f"CPU {result['cpu_fraction_of_one_core']:.0%} of one core")
    if args.cost:
        print(f"loop tick {result['tick_us']:.0f} us; publishing the 1 kHz topics "
              f"{result['publish_us_per_sample']:.0f} us per tick (ground truth at 100 Hz)")
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in result.items()}))


if __name__ == "__main__":
    main()
