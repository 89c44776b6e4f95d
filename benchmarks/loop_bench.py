"""Speed of the 1 kHz loop in lockstep against the raw pybullet steps inside it.

Runs random-residual steps (the shaft in contact with the bore, the expensive case) through the
full loop: state read, ground-truth wrench as the estimator, controller, safety, rest detector,
physics step. The time spent in pybullet's step alone, on exactly the same trajectory, gives the
raw rate (an open-loop replay of the torques would drift into other contact states). Goals:
>= 5x real time and >= 50 % of the raw rate. The last line is one JSON object.

Usage: python benchmarks/loop_bench.py [--seconds 5] [--pose 0]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.robot_loop import build_loop
from robot_bridge_node.core.wrench_source import MeasuredWrench


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated seconds")
    parser.add_argument("--pose", type=int, default=0, help="start pose 0..7")
    args = parser.parse_args()
    loop = build_loop(load_robot("sim_panda"),
                      estimator=lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench))
    scene = loop.simulation.scene
    ticks = round(args.seconds / loop.config.dt)
    rng = np.random.default_rng(0)
    loop.reset(args.pose)

    physics = 0.0
    step = scene.step

    def timed_step() -> None:
        nonlocal physics
        t = time.perf_counter()
        step()
        physics += time.perf_counter() - t

    scene.step = timed_step
    done = steps = 0
    start = time.perf_counter()
    while done < ticks:
        loop.command(WrenchSetpoint.residual(-15.0, *(3.0 * rng.uniform(-1.0, 1.0, 2))))
        steps += 1
        while done < ticks:
            done += 1
            if loop.tick():
                break
    total = time.perf_counter() - start
    loop_rate, raw_rate = ticks / total, ticks / physics
    gt = scene.ground_truth()
    print(f"{args.seconds:.1f} s simulated from start {args.pose}, {steps} random-residual steps,"
          f" final depth {gt.insertion_depth * 1e3:.1f} mm")
    print(f"full loop     : {loop_rate:7.0f} steps/s ({loop_rate / 1000:.2f}x real time)")
    print(f"pybullet alone: {raw_rate:7.0f} steps/s ({raw_rate / 1000:.2f}x real time)")
    overhead = 1e6 * (total - physics) / ticks
    print(f"loop / raw    : {loop_rate / raw_rate:.0%}; {overhead:.0f} us per tick outside pybullet"
          f" (goals: >= 5x real time, >= 50 % of raw)")
    print(json.dumps({"loop_steps_per_s": round(loop_rate), "raw_steps_per_s": round(raw_rate),
                      "loop_realtime_factor": round(loop_rate / 1000, 2),
                      "loop_fraction_of_raw": round(loop_rate / raw_rate, 3),
                      "overhead_us_per_tick": round(overhead),
                      "sim_seconds": args.seconds}))


if __name__ == "__main__":
    main()
