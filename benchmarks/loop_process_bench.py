"""What recording costs the 1 kHz loop now that it runs in a process of its own.

1. In this process, the loop's tick and the time it then spends writing the tick into the
   sample ring (``RingOutlet``, what the loop process does), timed around each call, over the
   same random residual steps, several rounds: everything publishing and recording take from
   the loop (goal: at most 2 %). Shown apart: computing the simulation's ground truth every
   10th tick for its topics and the bag (a real robot has none).
2. Through a real loop process (``LoopLink``, lockstep), the same steps with every tick recorded
   into an episode bag by the robot process's recording code (``record_ticks``, with the
   ``/tf`` of ``RobotFrames.tf_rows``) and with the ticks thrown away: the loop process's CPU
   time per tick (from /proc) and wall time per tick, the reading thread's CPU time per tick
   for recording, the ring's lost records, and the bag's ``/joint_states`` count against the
   ticks (goal: 0 dropped).

Usage: python benchmarks/loop_process_bench.py [--steps 40] [--rounds 3]
(in the stack environment: eval "$(.venv/bin/qgl env)"). The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from qg_common.params import config_file, load_ros_params
from qg_common.types import N_START_POSES, StartPose, WrenchSetpoint
from qg_learning_node.executor.parameters import load_geometry
from qg_recording.bag_reader import bag_info
from qg_recording.episode_recorder import EpisodeRecorder
from robot_bridge_node.core.hardware_interface import robot_plugin
from robot_bridge_node.core.interface_kinds import interface_kind
from robot_bridge_node.core.loop_link import LoopLink
from robot_bridge_node.core.loop_process import RingOutlet
from robot_bridge_node.core.loop_runner import SetpointCommand
from robot_bridge_node.core.robot_frames import RobotFrames, base_frame
from robot_bridge_node.core.robot_loop import RobotLoop
from robot_bridge_node.core.sample_ring import SampleRing
from robot_bridge_node.core.tick_messages import TickNames, record_ticks
from robot_bridge_node.robot_process import shipped_loop_spec


def setpoints(steps: int, seed: int = 0) -> list[tuple[StartPose, WrenchSetpoint]]:
    """(start pose, setpoint) of every step: uniform random residuals, a new pose of the
    shipped cell (``config/shaft_task.yaml``) every 5."""
    rng = np.random.default_rng(seed)
    geometry = load_geometry(load_ros_params(config_file("shaft_task.yaml")))
    starts = [geometry.start_pose(i) for i in range(N_START_POSES)]
    return [(starts[k // 5 % N_START_POSES],
             WrenchSetpoint.residual(-15.0, *rng.uniform(-3.0, 3.0, 2))) for k in range(steps)]


class _NoSocket:
    def send(self, message: object) -> None:
        del message


class _NoOutput:
    def sample(self, t_ns: int, loop: RobotLoop, publish: bool) -> None:
        del t_ns, loop, publish


def in_process(steps: int, rounds: int) -> dict:
    """The loop's time per tick spent in its output (timed around each ``sample`` call), with
    and without the ground truth, and per tick with no output at all; alternating, medians."""
    spec = shipped_loop_spec("sim_panda")
    plugin = robot_plugin(spec.robot)
    loop = interface_kind(plugin.interface).build_loop(
        plugin.create(spec.robot_params), spec.bridge_params, spec.estimator_params)
    ring = SampleRing.create(len(plugin.describe(spec.robot_params).joint_names))
    outlets = {"none": _NoOutput(), "ring": RingOutlet(ring, _NoSocket(), 10**9),
               "ring_and_truth": RingOutlet(ring, _NoSocket(),
                                             spec.truth_every // spec.publish_every)}
    tick_us: dict[str, list[float]] = {name: [] for name in outlets}
    output_us: dict[str, list[float]] = {name: [] for name in outlets}
    plan = setpoints(steps)
    clock = time.perf_counter
    for _ in range(rounds):
        for name, outlet in outlets.items():
            ticks, ticking, output, pose = 0, 0.0, 0.0, None
            for start, setpoint in plan:
                if start is not pose:
                    loop.reset(start)
                    pose = start
                loop.command(setpoint)
                while True:
                    t0 = clock()
                    at_rest = loop.tick()
                    t1 = clock()
                    ticks += 1
                    outlet.sample(ticks, loop, ticks % spec.publish_every == 0)
                    output += clock() - t1
                    ticking += t1 - t0
                    if at_rest:
                        break
            tick_us[name].append(ticking / ticks * 1e6)
            output_us[name].append(output / ticks * 1e6)
    ring.close()
    tick = statistics.median(tick_us["none"])
    out = {name: statistics.median(values) for name, values in output_us.items()}
    return {"us_per_tick": tick, "us_in_ring_output_per_tick": out["ring"],
            "us_in_output_with_truth_per_tick": out["ring_and_truth"],
            "ring_output_percent": 100.0 * out["ring"] / tick,
            "truth_percent": 100.0 * (out["ring_and_truth"] - out["ring"]) / tick,
            "tick_us_by_outlet": {name: statistics.median(v) for name, v in tick_us.items()}}


class _Keep:
    """The robot process's part: record every tick (``record_ticks``), with the ``/tf`` of the
    robot's frames (``RobotFrames.tf_rows``), or throw them away."""

    def __init__(self, recorder: EpisodeRecorder | None, names: TickNames,
                 frames: RobotFrames) -> None:
        self.recorder, self.names, self.frames, self.ticks, self.events = \
            recorder, names, frames, 0, 0
        self.cpu = 0.0             # [s] of this thread's CPU spent recording

    def samples(self, records: np.ndarray) -> None:
        self.ticks += len(records)
        if self.recorder is not None:
            start = time.thread_time()
            tf = self.frames.tf_rows(records)
            record_ticks(self.recorder, records, self.names, [] if tf is None else [tf])
            self.cpu += time.thread_time() - start

    def at_rest(self, event: object) -> None:
        self.events += 1

    def timing(self, snapshot: object) -> None:
        pass

    def log(self, level: str, message: str) -> None:
        print(level, message)

    def failed(self, message: str) -> None:
        raise SystemExit(message)


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def through_process(steps: int, record: bool) -> dict:
    """The loop process running ``steps`` steps, its ticks recorded or not."""
    spec = shipped_loop_spec("sim_panda")
    description = robot_plugin(spec.robot).describe(spec.robot_params)
    names = description.joint_names
    folder = Path(tempfile.mkdtemp(prefix="loop_bench_"))
    recorder = EpisodeRecorder(folder) if record else None
    keep = _Keep(recorder, TickNames(tuple(names), base_frame(description)),
                 RobotFrames(description))
    link = LoopLink(spec, len(names), keep)
    link.start()
    if recorder is not None:
        recorder.start("bench_episode")
    pose, seq = None, 0
    cpu0, t0 = _cpu_seconds(link.process.pid), time.perf_counter()
    for start, setpoint in setpoints(steps):
        if start is not pose:
            link.reset(start)
            pose = start
        seq += 1
        events = keep.events
        link.send_setpoint(SetpointCommand(seq, setpoint))
        while keep.events == events:
            time.sleep(0.0002)
    wall, cpu = time.perf_counter() - t0, _cpu_seconds(link.process.pid) - cpu0
    time.sleep(0.05)
    link.stop()
    result = {"ticks": keep.ticks, "lost": link.ring.lost,
              "loop_cpu_us_per_tick": cpu / keep.ticks * 1e6,
              "wall_us_per_tick": wall / keep.ticks * 1e6,
              "reader_cpu_us_per_tick": keep.cpu / keep.ticks * 1e6}
    if recorder is not None:
        recorder.stop()
        info = bag_info(folder / "bench_episode")
        result["bag_joint_states"] = info.count("/joint_states")
        result["bag_tf"] = info.count("/tf")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    result = {"in_process": in_process(args.steps, args.rounds)}
    r = result["in_process"]
    print(f"loop tick {r['us_per_tick']:.1f} us; writing it into the ring "
          f"{r['us_in_ring_output_per_tick']:.2f} us/tick = {r['ring_output_percent']:.2f} % of "
          f"the loop's time (goal <= 2 %); the simulation's ground truth every 10th tick for its "
          f"topics and the bag adds {r['truth_percent']:.2f} %", flush=True)
    runs: dict[str, list[dict]] = {"recorded": [], "not_recorded": []}
    for _ in range(args.rounds):
        for name, record in (("recorded", True), ("not_recorded", False)):
            runs[name].append(through_process(args.steps, record))
    for name, results in runs.items():
        cpu = statistics.median(x["loop_cpu_us_per_tick"] for x in results)
        wall = statistics.median(x["wall_us_per_tick"] for x in results)
        lost = sum(x["lost"] for x in results)
        extra = ""
        if name == "recorded":
            dropped = sum(x["ticks"] - x["bag_joint_states"] for x in results)
            reader = statistics.median(x["reader_cpu_us_per_tick"] for x in results)
            tf = sum(x["bag_tf"] for x in results)
            extra = (f", ticks missing from the bags {dropped}, /tf messages {tf}; the reader "
                     f"thread's recording (with /tf) {reader:.1f} us/tick")
        print(f"loop process, ticks {name.replace('_', ' ')}: loop CPU {cpu:.1f} us/tick, wall "
              f"{wall:.1f} us/tick, ring records lost {lost}{extra}", flush=True)
    result["through_process"] = runs
    print(json.dumps(result))


if __name__ == "__main__":
    main()
