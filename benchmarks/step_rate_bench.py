"""RL steps per wall second: the in-process runner against the ROS stack, same learning episodes.

Both paths run QG-DDPG training episodes with the demo's settings (the default state, critic lr
1e-4, 50 iterations per 20-step cycle, episodes capped at 50 steps) from the repo's config/:
first in this process (``RunSpec.run``: sim + bridge + EKF + learner on one core), then through
the real stack (robot, executor and learner processes, episodes started by service call).
Printed per path: RL steps, wall time, RL steps per wall second, the fraction of steps that end
at the rest detector's time limit (``rest.max_time``) and simulated seconds per step. The ROS
path also splits its wall time, from the arrival times of ``/wrench_setpoint`` and
``/ee_at_rest`` at this process: the robot's part of a step (setpoint to its at-rest event) and
the turnaround (an at-rest event to the next setpoint: executor, actor and two messages).
Goals (issue 12): <= 10 % of steps at the time limit; >= 20 RL steps/s in process; the stack
>= 80 % of the in-process rate. The last line is one JSON object.

Usage: python benchmarks/step_rate_bench.py [--episodes 8] [--skip-ros]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import torch
from qg_experiments.runner import RunSpec

CRITIC_LR, ITERATIONS, CAP = 1e-4, 50, 50


def in_process(episodes: int) -> dict:
    torch.set_num_threads(1)
    result = RunSpec("qgddpg", CRITIC_LR, ITERATIONS, seed=0, train_episodes=episodes,
                     test_episodes=0, train_max_steps=CAP).run()
    steps = result["rl_steps"]
    return {"rl_steps": steps, "wall_time": result["wall_time"],
            "steps_per_second": steps / result["wall_time"],
            "timeout_fraction": result["step_timeouts"] / steps,
            "sim_seconds_per_step": result["sim_time"] / steps}


def step_time_split(setpoints: list[tuple[float, int]], rests: list[tuple[float, int]]) -> dict:
    """Split the ROS path's steps into the robot's part and the turnaround, in milliseconds.

    :param setpoints: (arrival time [s], seq) of every ``/wrench_setpoint`` seen (re-sends too).
    :param rests: (arrival time [s], seq) of every ``/ee_at_rest`` seen; seq 0 is a reset's.
    :returns: median and 90th percentile of each part, and the turnaround's share of the time
        from the first setpoint to the last at-rest event. A turnaround across a reset (the
        next episode's first setpoint) is left out: it holds the reset, not a step.
    """
    sent: dict[int, float] = {}
    for t, seq in setpoints:
        sent.setdefault(seq, t)                   # the first send starts the step
    robot, turnaround = [], []
    previous: tuple[float, int] | None = None
    for t, seq in sorted(rests):
        if seq in sent:
            robot.append(t - sent[seq])
        if previous is not None and previous[1] > 0 and seq == previous[1] + 1 and seq in sent:
            turnaround.append(sent[seq] - previous[0])
        previous = (t, seq)
    span = max(t for t, _ in rests) - min(sent.values()) if sent and rests else float("nan")

    def ms(values: list[float]) -> dict:
        ordered = sorted(values)
        if not ordered:
            return {"median": float("nan"), "p90": float("nan"), "n": 0}
        return {"median": 1e3 * statistics.median(ordered),
                "p90": 1e3 * ordered[int(0.9 * (len(ordered) - 1))], "n": len(ordered)}
    return {"robot_ms": ms(robot), "turnaround_ms": ms(turnaround),
            "turnaround_share": sum(turnaround) / span}


def through_ros(episodes: int) -> dict:
    from qg_interfaces.msg import AtRest, WrenchSetpoint

    from qg_learning_node.cli.demo import (DemoSettings, run_episode_by_service, start_stack,
                                           wait_for_stack)
    from qg_learning_node.cli.ros_client import CliNode
    from qg_common.params import config_file

    settings = DemoSettings(train_max_steps=CAP, critic_lr=CRITIC_LR, iterations=ITERATIONS)
    launcher, env = start_stack(Path(tempfile.mkdtemp(prefix="step_rate_")), settings,
                                config_file("stack.yaml"),
                                os.environ.get("ROS_DOMAIN_ID", "77"))
    events: list[AtRest] = []
    rests: list[tuple[float, int]] = []
    setpoints: list[tuple[float, int]] = []

    def on_at_rest(msg: AtRest) -> None:
        rests.append((time.monotonic(), msg.seq))
        events.append(msg)
    try:
        with CliNode("step_rate_bench", domain_id=int(env["ROS_DOMAIN_ID"])) as cli:
            wait_for_stack(cli, timeout=180.0)
            cli.node.create_subscription(AtRest, "/ee_at_rest", on_at_rest, 100)
            cli.node.create_subscription(WrenchSetpoint, "/wrench_setpoint",
                                         lambda m: setpoints.append((time.monotonic(), m.seq)), 100)
            start = time.monotonic()
            outcomes = [run_episode_by_service(cli, i, "train", -1, seed=i, timeout=600.0)
                        for i in range(episodes)]
            wall = time.monotonic() - start
    finally:
        launcher.stop()
    steps = sum(o.steps for o in outcomes)
    step_events = [e for e in events if e.seq > 0]       # seq 0: the reset's settled state
    return {"rl_steps": steps, "wall_time": wall, "steps_per_second": steps / wall,
            "timeout_fraction": sum(e.timed_out for e in step_events) / max(1, len(step_events)),
            "sim_seconds_per_step": sum(e.duration for e in step_events) / max(1, len(step_events)),
            **step_time_split(setpoints, rests)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--skip-ros", action="store_true", help="only the in-process runner")
    args = parser.parse_args()
    result = {"in_process": in_process(args.episodes)}
    print("in process:", json.dumps(result["in_process"]), flush=True)
    if not args.skip_ros:
        result["ros"] = through_ros(args.episodes)
        print("ROS stack: ", json.dumps(result["ros"]), flush=True)
        result["ros_over_in_process"] = (result["ros"]["steps_per_second"]
                                         / result["in_process"]["steps_per_second"])
    ip = result["in_process"]
    result["goals"] = {"timeouts_at_most_10_percent": ip["timeout_fraction"] <= 0.10,
                       "in_process_at_least_20_steps_per_s": ip["steps_per_second"] >= 20.0,
                       "ros_at_least_80_percent": result.get("ros_over_in_process", 0.0) >= 0.8}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
