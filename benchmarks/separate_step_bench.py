"""RL step time with sim, bridge and estimator as separate processes (``ros2 run`` each).

Starts ``sim``, ``bridge`` and ``wrench_estimator`` as three processes, resets, and runs RL steps
the way the executor does (a new setpoint, then waiting for its ``ee_at_rest``). Per step:
the wall time from the setpoint to its event, and the step's duration on the bridge loop's clock
(the states' stamps; at most ``rest.max_time``, 0.25 s, plus one state's gap). Measured on
2 cores (docs/design.md, the 1 kHz path): median 0.25 s idle and loaded; 0.7-1.7 s idle
before the loop took its clock from the stamps and the separate processes handed the GIL over
every 0.1 ms. The last line is one JSON object.

Usage: python benchmarks/separate_step_bench.py [--steps 8]
(in the stack environment: eval "$(.venv/bin/python -m qg_bringup.ros_env)")
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

#: The residual setpoints the steps alternate between (tool-frame wrench).
WRENCHES = ((0.0, 0.0, -8.0, 0.0, 0.3, 0.0), (0.0, 0.0, -8.0, 0.3, 0.0, 0.0),
            (0.0, 0.0, -8.0, 0.0, -0.3, 0.0), (0.0, 0.0, -8.0, -0.3, 0.0, 0.0))


def run(steps: int, domain_id: str) -> dict:
    from qg_bringup.launcher import Launcher
    from qg_bringup.ros_env import stack_env
    from qg_bringup.stack_file import ProcessSpec
    from qg_common.conversions import setpoint_msg, start_pose_request, time_msg
    from qg_common.params import config_file, load_ros_params
    from qg_common.ros_client import CliNode, call_service
    from qg_common.shaft_task import ShaftTaskGeometry
    from qg_common.types import WrenchSetpoint as Setpoint
    from qg_interfaces.msg import AtRest, WrenchSetpoint
    from qg_interfaces.srv import MoveToStart

    work = Path(tempfile.mkdtemp(prefix="separate_step_"))
    env = stack_env(domain_id=domain_id, log_dir=work / "ros_log")
    launcher = Launcher(env=env, out=None, log_dir=work / "logs")
    launcher.start([ProcessSpec("sim", "sim_robot_node", "sim"),
                    ProcessSpec("bridge", "robot_bridge_node", "bridge"),
                    ProcessSpec("wrench_estimator", "robot_bridge_node", "wrench_estimator")])
    walls: list[float] = []
    durations: list[float] = []
    timeouts = 0
    try:
        with CliNode("separate_step_bench", domain_id=int(domain_id)) as cli:
            events: list[AtRest] = []
            cli.node.create_subscription(AtRest, "/ee_at_rest", events.append, 100)
            publisher = cli.node.create_publisher(WrenchSetpoint, "/wrench_setpoint", 10)
            geometry = ShaftTaskGeometry.from_dict(
                load_ros_params(config_file("shaft_task.yaml"))["shaft_task"])
            reply = call_service(cli, MoveToStart, "/move_to_start",
                                 start_pose_request(geometry.start_pose(1)), timeout=60.0)
            if not reply.success:
                raise RuntimeError(f"reset failed: {reply.message}")
            cli.spin_until(lambda: publisher.get_subscription_count() > 0, 30.0)
            for seq in range(1, steps + 1):
                msg = setpoint_msg(seq, Setpoint(np.array(WRENCHES[seq % len(WRENCHES)])),
                                   time_msg(0))
                start = time.monotonic()
                publisher.publish(msg)
                while not any(e.seq == seq for e in events):
                    cli.executor.spin_once(timeout_sec=0.001)
                    if time.monotonic() - start > 30.0:
                        raise TimeoutError(f"step {seq}: no ee_at_rest within 30 s")
                walls.append(time.monotonic() - start)
                event = next(e for e in events if e.seq == seq)
                durations.append(event.duration)
                timeouts += event.timed_out
                print(f"step {seq}: {walls[-1]:.3f} s wall, {event.duration:.3f} s loop time"
                      f"{' (timed out)' if event.timed_out else ''}", flush=True)
    finally:
        codes = launcher.stop(5.0)
    return {"steps": steps, "wall_s": walls, "wall_median_s": float(np.median(walls)),
            "wall_min_s": min(walls), "wall_max_s": max(walls), "loop_s": durations,
            "timed_out": timeouts, "exit_codes": codes, "logs": str(work / "logs")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=8)
    args = parser.parse_args()
    print(json.dumps(run(args.steps, os.environ.get("ROS_DOMAIN_ID", "93"))))


if __name__ == "__main__":
    main()
