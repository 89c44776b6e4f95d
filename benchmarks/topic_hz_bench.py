"""What ``ros2 topic hz /joint_states`` counts with the realtime robot up.

There is no ros2cli wheel, so this subscribes as ``ros2 topic hz`` does: its own process, one
node spun by ``rclpy.spin`` on a single thread, a raw subscription with the sensor-data QoS
(best effort, depth 5, volatile), every arrival timed on receipt; its rate is one over the mean
gap between arrivals over the window, as ``ros2 topic hz`` reports it. Also printed: the share
of the window's ticks that arrived (the header stamps say which), and the gaps' spread.

Starts the composed robot process in realtime mode (``sim.clock_mode:=realtime``; the loop
holds the start pose, ticking at 1 kHz), waits ``--warmup`` seconds, then counts for
``--seconds``. Goal: >= 990 Hz on ``/joint_states`` (the loop keeps 1 kHz).

Usage: python benchmarks/topic_hz_bench.py [--seconds 10] [--topics /joint_states /tf]
(in the stack environment: eval "$(.venv/bin/qgl env)"). The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="counted wall seconds")
    parser.add_argument("--warmup", type=float, default=3.0)
    parser.add_argument("--topics", nargs="+", default=["/joint_states", "/tf"])
    parser.add_argument("--set", action="append", default=[], metavar="NAME:=VALUE",
                        help="a robot process parameter, e.g. sim.realtime_priority:=0")
    args = parser.parse_args()

    import rclpy
    from qg_bringup.launcher import Launcher
    from qg_bringup.ros_env import stack_env
    from qg_bringup.stack_file import ProcessSpec
    from qg_recording.episode_recorder import TOPICS
    from qg_recording.player import message_class
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message

    run_dir = Path(tempfile.mkdtemp(prefix="topic_hz_bench_"))
    domain = os.environ.get("ROS_DOMAIN_ID", "79")
    env = stack_env(domain_id=domain, log_dir=run_dir / "ros_log")
    env["QG_RUNS_DIR"] = str(run_dir)
    launcher = Launcher(env=env, out=None, log_dir=run_dir / "logs")
    extra = tuple(x for item in args.set for x in ("-p", item))
    launcher.start([ProcessSpec("robot", "robot_bridge_node", "robot",
                                ("--ros-args", "-p", "sim.clock_mode:=realtime", *extra))])
    arrivals: dict[str, list[tuple[float, bytes]]] = {t: [] for t in args.topics}
    counting = [False]
    try:
        rclpy.init(domain_id=int(domain))
        node = rclpy.create_node("topic_hz_bench")
        for topic in args.topics:
            def received(data: bytes, topic: str = topic) -> None:
                if counting[0]:
                    arrivals[topic].append((time.monotonic(), data))
            node.create_subscription(message_class(TOPICS[topic].type_name), topic, received,
                                     qos_profile_sensor_data, raw=True)
        executor = SingleThreadedExecutor()      # what rclpy.spin(node) spins
        executor.add_node(node)
        deadline = time.monotonic() + 120.0        # the robot process starts (1-3 s)
        while not node.count_publishers(args.topics[0]) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        start = time.monotonic() + args.warmup
        while time.monotonic() < start:
            executor.spin_once(timeout_sec=0.05)
        pid = launcher.pids()["robot"]
        counting[0] = True
        cpu0, end = _cpu_seconds(pid), time.monotonic() + args.seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        counting[0] = False
        robot_cpu = 100.0 * (_cpu_seconds(pid) - cpu0) / args.seconds
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
    finally:
        codes = launcher.stop()
    result: dict = {"seconds": args.seconds, "set": args.set, "exit_codes": codes,
                    "robot_process_cpu_percent": robot_cpu, "topics": {}}
    print(f"robot process (its loop process not counted): {robot_cpu:.0f} % of a core")
    for topic, received in arrivals.items():
        if len(received) < 2:
            result["topics"][topic] = {"messages": len(received)}
            print(f"{topic}: {len(received)} messages in {args.seconds:.0f} s")
            continue
        times = np.array([t for t, _ in received])
        gaps = np.diff(times)
        cls = message_class(TOPICS[topic].type_name)
        first, last = (deserialize_message(received[k][1], cls) for k in (0, -1))
        header = (lambda m: m.header) if topic != "/tf" else (lambda m: m.transforms[0].header)
        stamp_span = ((header(last).stamp.sec - header(first).stamp.sec)
                      + (header(last).stamp.nanosec - header(first).stamp.nanosec) * 1e-9)
        stats = {"messages": len(received), "rate_hz": 1.0 / gaps.mean(),
                 "gap_min_ms": 1e3 * gaps.min(), "gap_max_ms": 1e3 * gaps.max(),
                 "gap_std_ms": 1e3 * gaps.std(),
                 "gap_p99_ms": 1e3 * float(np.percentile(gaps, 99)),
                 "stamp_span_s": stamp_span}
        result["topics"][topic] = stats
        print(f"{topic}: average rate {stats['rate_hz']:.1f} Hz (as ros2 topic hz), "
              f"{stats['messages']} messages in {args.seconds:.0f} s; gaps min "
              f"{stats['gap_min_ms']:.2f} ms, max {stats['gap_max_ms']:.2f} ms, std "
              f"{stats['gap_std_ms']:.2f} ms, p99 {stats['gap_p99_ms']:.2f} ms")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
