"""The realtime loop's timing with the whole stack up and training (goal: p99 <= 1.5 ms).

Starts the stack of ``config/stack.yaml`` (robot process, learner, executor; ``--robots 2``: two
robots and one learner) with every robot in realtime mode (``sim.clock_mode:=realtime``; a
step's setpoint holds until the step ends, no keep-alive), runs QG-DDPG training episodes (the demo's
settings, at most 50 steps) on every robot for ``--seconds``, and reads each loop's own timing
from its ``diagnostics`` (``loop_diagnostics``): the counts and histogram at the start and the
end of the measured window give the tick period p50/p99/max and the share of ticks on time (a
period of at most 1.5 ms; ticks the pacer dropped count as late). Also printed: RL steps, and
the CPU each process used. Goal: p99 <= 1.5 ms and >= 99.5 % on time, one robot and two.
The last line is one JSON object.

Usage: python benchmarks/realtime_bench.py [--seconds 60] [--robots 1] [--warmup 10]
(in the stack environment: eval "$(.venv/bin/qgl env)")
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from qg_bringup.episode_schedule import EpisodeJob, run_lanes
from qg_bringup.fleet import fleet_specs, robot_namespace
from qg_bringup.launcher import Launcher
from qg_bringup.ros_env import stack_env
from qg_bringup.stack_file import load_stack_config
from qg_bringup.stack_start import DemoSettings, wait_for_stack, with_run_settings
from qg_common.params import config_file
from qg_common.ros_client import CliNode
from robot_bridge_node.core.tick_timing import TimingSnapshot

REALTIME = {("robot_bridge_node", "robot"): ("-p", "sim.clock_mode:=realtime")}


def realtime_specs(robots: int, robot_args: tuple[str, ...]) -> list:
    """The stack's processes with the demo's learning settings, every robot in realtime (with
    ``robot_args``, ``-p name:=value`` pairs, added to the robot process's parameters)."""
    specs = []
    for spec in load_stack_config(config_file("stack.yaml")):
        spec = with_run_settings(spec, DemoSettings(train_max_steps=50))
        extra = REALTIME.get((spec.package, spec.executable))
        if extra:
            if spec.executable == "robot":
                extra = (*extra, *robot_args)
            spec = replace(spec, args=(*spec.args, "--ros-args", *extra))
        specs.append(spec)
    return fleet_specs(specs, robots)


def _stat(pid: int) -> list[str]:
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


def process_cpu(pids: dict[str, int]) -> dict[str, float]:
    """[s] user + system CPU time of each process so far, its children's (a robot process's
    loop process) under ``<name>/child``."""
    tick = os.sysconf("SC_CLK_TCK")
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                children.setdefault(int(_stat(int(entry))[1]), []).append(int(entry))
            except (OSError, IndexError, ValueError):
                pass
    cpu = {}
    for name, pid in pids.items():
        for key, proc in ((name, pid), *((f"{name}/child", c) for c in children.get(pid, []))):
            try:
                fields = _stat(proc)
                cpu[key] = (int(fields[11]) + int(fields[12])) / tick
            except (OSError, IndexError, ValueError):
                cpu[key] = float("nan")
    return cpu


def main() -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from robot_bridge_node.loop_diagnostics import STATUS_NAME, snapshot_from_status
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="measured wall seconds")
    parser.add_argument("--robots", type=int, default=1)
    parser.add_argument("--warmup", type=float, default=10.0,
                        help="[s] of training before the window opens")
    parser.add_argument("--set", action="append", default=[], metavar="NAME:=VALUE",
                        help="a robot process parameter, e.g. sim.realtime_priority:=0")
    args = parser.parse_args()
    robots = [robot_namespace(k) for k in range(args.robots)] if args.robots > 1 else [""]
    run_dir = Path(tempfile.mkdtemp(prefix="realtime_bench_"))
    env = stack_env(log_dir=run_dir / "ros_log")
    env["QG_RUNS_DIR"] = str(run_dir)
    env["ROS_DOMAIN_ID"] = os.environ.get("ROS_DOMAIN_ID", "78")
    launcher = Launcher(env=env, out=None, log_dir=run_dir / "logs")
    launcher.start(realtime_specs(args.robots,
                                  tuple(x for item in args.set for x in ("-p", item))))
    latest: dict[str, TimingSnapshot] = {}

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith(STATUS_NAME):
                latest[status.name] = snapshot_from_status(status)

    try:
        with CliNode("realtime_bench", domain_id=int(env["ROS_DOMAIN_ID"])) as cli:
            wait_for_stack(cli, timeout=180.0, robots=robots)
            for robot in robots:
                cli.node.create_subscription(DiagnosticArray,
                                             f"/{robot}/diagnostics".replace("//", "/"),
                                             on_diagnostics, 10)
            marks: dict[str, tuple[float, dict, dict]] = {}
            pids = launcher.pids()

            def check() -> None:
                now = time.monotonic()
                if "start" not in marks and now - t0 >= args.warmup \
                        and len(latest) == len(robots):
                    marks["start"] = (now, dict(latest), process_cpu(pids))
                if "start" in marks and now - marks["start"][0] >= args.seconds:
                    marks["end"] = (now, dict(latest), process_cpu(pids))
                    raise StopIteration

            jobs = {robot: [EpisodeJob(i, "train", -1, seed=i) for i in range(10_000)]
                    for robot in robots}
            t0 = time.monotonic()
            try:
                run_lanes(cli, jobs, timeout=600.0, check=check)
            except StopIteration:
                pass
    finally:
        codes = launcher.stop()
    (t_start, start, cpu0), (t_end, end, cpu1) = marks["start"], marks["end"]
    wall = t_end - t_start
    result: dict = {"seconds": wall, "robots": args.robots, "set": args.set, "loops": {},
                    "exit_codes": codes,
                    "cpu_percent": {name: 100.0 * (cpu1[name] - cpu0[name]) / wall
                                    for name in cpu1}}
    for name in sorted(end):
        window = end[name].since(start[name])
        result["loops"][name] = {k: round(v, 4) for k, v in window.summary().items()}
        s = result["loops"][name]
        print(f"{name}: {s['ticks']} ticks + {s['missed']} dropped in {wall:.0f} s; period p50 "
              f"{s['period_p50_ms']:.2f} ms, p99 {s['period_p99_ms']:.2f} ms, max (whole run) "
              f"{s['period_max_ms']:.2f} ms; {s['on_time_percent']:.2f} % on time "
              f"(goal: p99 <= 1.5 ms, >= 99.5 %)")
    print("CPU % of one core: " + ", ".join(f"{k} {v:.0f}" for k, v in
                                            result["cpu_percent"].items()))
    print(json.dumps(result))


if __name__ == "__main__":
    main()
