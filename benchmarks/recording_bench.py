"""Cost of recording the five 1 kHz messages of the robot loop into an episode bag.

Simulates the 1 kHz loop of `RobotLoop.tick()` (a fixed amount of CPU work per tick stands in
for physics, estimator and controller) and records joint states, wrench estimate, EE pose,
EE twist and ground truth every tick with `EpisodeRecorder`. CPU times (not wall times) are
the measure, so the figures hold on a machine shared with other jobs. Reports per tick

- loop-thread CPU inside the record calls (encoding + queueing) and writer-thread CPU (MCAP
  records, zstd, metadata.yaml); both hold the interpreter lock, so their sum is what
  recording takes from the loop, also given as a share of the 1 ms period,
- for comparison, the loop-thread CPU of filling rclpy messages and serializing them with rclpy,
- messages produced vs. written (must be equal), bag size per recorded second,
- a wall-clock 1 kHz run: ticks that missed their deadline with and without recording,
- bytes per training episode with `recording.mode` `all` and `rl_rate`: a training episode of
  the robot process's shape (``--steps`` RL steps of ``--ticks-per-step`` 1 kHz ticks through
  the robot process's `record_ticks`, its `/tf`, the Panda's latched description, frames and
  scene, a status, setpoint, at-rest event and transition per step), or, with ``--bags``, the
  recorded bags of a run: each bag's bytes against its RL-rate copy's (`compact_bag`, which
  writes what `rl_rate` records). Needs the ROS environment (`eval "$(.venv/bin/qgl env)"`).

Usage: .venv/bin/python benchmarks/recording_bench.py [--ticks 5000] [--work-us 300] [--realtime-s 2]
       [--episode-only] [--steps 36] [--ticks-per-step 460] [--bags RUN/episodes]
The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from qg_recording.bag_reader import bag_info
from qg_recording.disk_keeper import RecordingPolicy, compact_bag, disk_bytes
from qg_recording.episode_recorder import EpisodeRecorder
from qg_recording.rosbag2_metadata import read_metadata

NAMES = [f"panda_joint{i}" for i in range(1, 8)]
PERIOD_NS = 1_000_000


class FakeLoop:
    """Numbers shaped like one robot tick, updated in place (as the real loop does) after a
    fixed amount of CPU work that stands in for physics, estimator and controller."""

    def __init__(self, work_us: float) -> None:
        self.work_s = work_us * 1e-6
        self.rng = np.random.default_rng(0)
        self.q, self.dq, self.tau = np.zeros(7), np.zeros(7), np.zeros(7)
        self.force, self.torque = np.zeros(3), np.zeros(3)
        self.pos, self.quat = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
        self.lin, self.ang = np.zeros(3), np.zeros(3)
        self.wrench, self.tilt_xy = np.zeros(6), np.zeros(2)

    def tick(self) -> None:
        end = time.perf_counter() + self.work_s
        while time.perf_counter() < end:
            pass
        self.q += 1e-3
        self.dq[:] = self.rng.standard_normal(7)
        self.tau[:] = self.dq * 2.0
        self.force[:] = self.dq[:3]
        self.torque[:] = self.tau[:3]
        self.wrench[:] = self.tau[:6]


def record_tick(rec: EpisodeRecorder, loop: FakeLoop, t_ns: int) -> None:
    rec.record_joint_state(t_ns, NAMES, loop.q, loop.dq, loop.tau)
    rec.record_wrench(t_ns, loop.force, loop.torque)
    rec.record_pose(t_ns, loop.pos, loop.quat)
    rec.record_twist(t_ns, loop.lin, loop.ang)
    rec.record_ground_truth(t_ns, loop.wrench, 0.01, 0.002, False, 0.002, loop.tilt_xy, 0.001, 0.02)


def run_lockstep(runs: Path, ticks: int, work_us: float, record: bool) -> dict[str, float]:
    """Ticks back to back; CPU time of the record calls on the loop thread and of the process."""
    loop, rec = FakeLoop(work_us), EpisodeRecorder(runs)
    if record:
        rec.start(f"bench_{time.monotonic_ns()}")
    wall, cpu_in_calls = np.zeros(ticks), 0.0
    cpu0, thread0 = time.process_time(), time.thread_time()
    for i in range(ticks):
        loop.tick()
        w, c = time.perf_counter(), time.thread_time()
        record_tick(rec, loop, i * PERIOD_NS)
        cpu_in_calls += time.thread_time() - c
        wall[i] = time.perf_counter() - w
    loop_thread = time.thread_time() - thread0
    bag = rec.stop()  # the writer thread's remaining work counts too
    other_threads = time.process_time() - cpu0 - loop_thread
    out = {"loop_calls_us": cpu_in_calls / ticks * 1e6, "other_threads_us": other_threads / ticks * 1e6,
           "wall_mean_us": float(wall.mean() * 1e6), "wall_p99_us": float(np.percentile(wall, 99) * 1e6)}
    if bag is not None:
        info = bag_info(bag)
        out.update(produced=5 * ticks, written=info.message_count,
                   bytes_per_s=info.size_bytes / (ticks * PERIOD_NS * 1e-9), complete=info.complete)
    return out


def rclpy_cost(ticks: int) -> tuple[float, int]:
    """Loop-thread CPU µs per tick of the alternative: fill rclpy messages and serialize them with
    `rclpy.serialization.serialize_message` (GroundTruth only if qg_interfaces is importable)."""
    from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    try:
        from qg_interfaces.msg import GroundTruth
    except ImportError:
        GroundTruth = None  # noqa: N806
    loop = FakeLoop(0.0)
    t0 = time.thread_time()
    for i in range(ticks):
        sec, nanosec = divmod(i * PERIOD_NS, 1_000_000_000)
        js = JointState(name=NAMES, position=loop.q.tolist(), velocity=loop.dq.tolist(), effort=loop.tau.tolist())
        w, p, tw = WrenchStamped(), PoseStamped(), TwistStamped()
        w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = loop.force.tolist()
        w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = loop.torque.tolist()
        p.pose.position.x, p.pose.position.y, p.pose.position.z = loop.pos.tolist()
        p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z, p.pose.orientation.w = loop.quat.tolist()
        tw.twist.linear.x, tw.twist.linear.y, tw.twist.linear.z = loop.lin.tolist()
        tw.twist.angular.x, tw.twist.angular.y, tw.twist.angular.z = loop.ang.tolist()
        msgs = [js, w, p, tw]
        if GroundTruth is not None:
            gt = GroundTruth(insertion_depth=0.01, plunger_travel=0.002, success=False, position_error=0.002,
                             orientation_error=loop.tilt_xy, lateral_offset=0.001, tilt=0.02)
            gt.contact_wrench.force.x, gt.contact_wrench.force.y, gt.contact_wrench.force.z = loop.force.tolist()
            msgs.append(gt)
        for m in msgs:
            m.header.stamp.sec, m.header.stamp.nanosec = sec, nanosec
            serialize_message(m)
    return (time.thread_time() - t0) / ticks * 1e6, len(msgs)


def run_realtime(runs: Path, seconds: float, work_us: float, record: bool) -> dict[str, float]:
    """Wall-clock 1 kHz: sleep to each deadline; count ticks that finished after it."""
    loop, rec = FakeLoop(work_us), EpisodeRecorder(runs)
    if record:
        rec.start(f"rt_{time.monotonic_ns()}")
    ticks, late = int(seconds * 1000), 0
    worst = 0.0
    start = time.perf_counter()
    for i in range(ticks):
        deadline = start + (i + 1) * 1e-3
        loop.tick()
        record_tick(rec, loop, i * PERIOD_NS)
        now = time.perf_counter()
        if now > deadline:
            late += 1
            worst = max(worst, now - deadline)
        else:
            time.sleep(max(0.0, deadline - now - 50e-6))
            while time.perf_counter() < deadline:
                pass
    rec.stop()
    return {"late_ticks": late, "ticks": ticks, "worst_overrun_us": worst * 1e6}


def _latched_and_ticks(steps: int, ticks_per_step: int) -> tuple[dict[str, bytes], object, object, list]:
    """The Panda's latched messages, its tick names, its frames and the episode's ticks as
    blocks of sample-ring records (smooth motion with sensor noise, the truth every 10th tick)."""
    from qg_common.conversions import marker_array_msg, time_msg
    from rclpy.serialization import serialize_message
    from robot_bridge_node.core.hardware_interface import robot_plugin
    from robot_bridge_node.core.robot_frames import RobotFrames, base_frame, task_scene
    from robot_bridge_node.core.sample_ring import HAS_TOOL, HAS_TRUTH, HAS_WRENCH, record_dtype
    from robot_bridge_node.core.tick_messages import TickNames
    from robot_bridge_node.robot_process import shipped_loop_spec
    from std_msgs.msg import String

    spec = shipped_loop_spec("sim_panda")
    plugin = robot_plugin("sim_panda")
    description = plugin.describe(spec.robot_params)
    frames = RobotFrames(description)
    scene = task_scene("sim_panda", spec.robot_params)
    latched = {"/robot_description": serialize_message(String(data=frames.urdf)),
               "/scene_markers": serialize_message(marker_array_msg(scene, frames.base, time_msg(0))),
               "/tf_static": frames.static_message(0, scene)}
    names = TickNames(tuple(description.joint_names), base_frame(description), plugin.own_wrench_topic)
    n, rng = steps * ticks_per_step, np.random.default_rng(0)
    records = np.zeros(n, dtype=record_dtype(len(names.joint_names)))
    t = np.arange(n) * 1e-3
    records["t_ns"] = np.arange(n, dtype=np.int64) * PERIOD_NS + 10**9
    records["tick"] = np.arange(n)
    records["flags"] = HAS_WRENCH | HAS_TOOL | np.where(np.arange(n) % 10 == 0, HAS_TRUTH, 0)
    wave = np.sin(2 * np.pi * t / 2.0)[:, None]
    records["q"] = 0.3 + 0.01 * wave + rng.normal(0.0, 1e-6, (n, 7))
    records["dq"] = 0.03 * np.cos(2 * np.pi * t / 2.0)[:, None] + rng.normal(0.0, 1e-4, (n, 7))
    records["tau"] = 2.0 + 0.5 * wave + rng.normal(0.0, 0.05, (n, 7))
    records["tau_cmd"] = records["tau"] + rng.normal(0.0, 0.01, (n, 7))
    records["wrench"] = -5.0 * wave + rng.normal(0.0, 0.3, (n, 6))
    records["tool_position"] = np.array([0.5, 0.0, 0.3]) + 1e-3 * wave + rng.normal(0.0, 1e-6, (n, 3))
    angle = 0.01 * wave[:, 0]
    rot = np.zeros((n, 3, 3))
    rot[:, 0, 0] = rot[:, 1, 1] = np.cos(angle)
    rot[:, 0, 1], rot[:, 1, 0], rot[:, 2, 2] = -np.sin(angle), np.sin(angle), 1.0
    records["tool_rotation"] = rot
    records["tool_twist"] = rng.normal(0.0, 1e-3, (n, 6))
    records["truth"] = rng.normal(0.0, 0.1, (n, 14))
    blocks = [records[i:i + 200] for i in range(0, n, 200)]
    return latched, names, frames, blocks


def training_episode_bytes(folder: Path, mode: str, steps: int, ticks_per_step: int) -> dict[str, float]:
    """Record one training episode of the robot process's shape with ``recording.mode``
    ``mode``; its bag's bytes on disk and messages."""
    from qg_interfaces.msg import AtRest, EpisodeStatus, WrenchSetpoint
    from rclpy.serialization import serialize_message
    from robot_bridge_node.core.tick_messages import record_ticks

    latched, names, frames, blocks = _latched_and_ticks(steps, ticks_per_step)
    rec = EpisodeRecorder(folder / mode, policy=RecordingPolicy(mode=mode))
    episode_id = "20261128_000000_0000_train_p0"
    rec.start(episode_id, {"mode": "train", "initial_pose": 0, "reward": "dense"})
    t0 = int(blocks[0]["t_ns"][0])
    for topic, data in latched.items():
        rec.record_raw(topic, t0, data)
    rng = np.random.default_rng(1)
    per_step = max(1, len(blocks) // steps)
    step = 0
    for k, block in enumerate(blocks):
        t = int(block["t_ns"][0])
        if k % per_step == 0 and step < steps:
            rec.record_raw("/episode_status", t, serialize_message(EpisodeStatus(
                episode_id=episode_id, state="running", mode="train", step=step, max_steps=steps)))
            rec.record_raw("/wrench_setpoint", t, serialize_message(WrenchSetpoint(seq=step + 1)))
        tf = frames.tf_rows(block)
        record_ticks(rec, block, names, [] if tf is None else [tf])
        if k % per_step == per_step - 1 and step < steps:
            t = int(block["t_ns"][-1])
            rec.record_raw("/ee_at_rest", t, serialize_message(AtRest(seq=step + 1)))
            rec.record_transition(t, step, rng.normal(size=3), rng.normal(size=6), -1.0,
                                  rng.normal(size=3), False)
            step += 1
    rec.record_raw("/episode_status", int(blocks[-1]["t_ns"][-1]), serialize_message(EpisodeStatus(
        episode_id=episode_id, state="done", mode="train", step=steps, max_steps=steps)))
    bag = rec.stop()
    info = bag_info(bag)
    return {"bytes": rec.last_bytes, "file_bytes": info.size_bytes, "messages": info.message_count,
            "transitions": info.count("/transitions"), "topics": len([t for t in info.topics if t.message_count])}


def recorded_bags_bytes(episodes: Path, scratch: Path) -> dict[str, float]:
    """The recorded training bags of a run (custom data ``mode: train``): bytes on disk as
    recorded against their RL-rate copies (made in ``scratch``), summed."""
    bags = [p for p in sorted(episodes.iterdir()) if (p / "metadata.yaml").is_file()
            and (read_metadata(p).get("custom_data") or {}).get("mode") == "train"]
    full = rl = 0
    for bag in bags:
        copy = scratch / bag.name
        shutil.copytree(bag, copy)
        full += disk_bytes(copy)
        rl += compact_bag(copy, "recording_bench")
        shutil.rmtree(copy)
    return {"bags": len(bags), "all_bytes": full, "rl_rate_bytes": rl}


def episode_main(args: argparse.Namespace) -> dict[str, float]:
    """Bytes per training episode, ``all`` against ``rl_rate``, printed; the figures."""
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        full = training_episode_bytes(Path(tmp), "all", args.steps, args.ticks_per_step)
        rl = training_episode_bytes(Path(tmp), "rl_rate", args.steps, args.ticks_per_step)
        print(f"training episode of {args.steps} steps, {args.steps * args.ticks_per_step} ticks: "
              f"all {full['bytes'] / 1e6:.2f} MB ({full['messages']} messages, {full['topics']} topics), "
              f"rl_rate {rl['bytes'] / 1e3:.1f} kB ({rl['messages']} messages, {rl['topics']} topics) "
              f"= {100 * rl['bytes'] / full['bytes']:.2f} % of all; transitions {full['transitions']} "
              f"and {rl['transitions']}")
        out.update(episode_steps=args.steps, episode_ticks=args.steps * args.ticks_per_step,
                   all_bytes_per_episode=full["bytes"], rl_rate_bytes_per_episode=rl["bytes"],
                   rl_rate_pct_of_all=100 * rl["bytes"] / full["bytes"],
                   transitions_all=full["transitions"], transitions_rl_rate=rl["transitions"])
        if args.bags:
            real = recorded_bags_bytes(Path(args.bags), Path(tmp))
            if real["bags"]:
                n = real["bags"]
                print(f"{n} recorded training bags of {args.bags}: all {real['all_bytes'] / n / 1e6:.2f} MB "
                      f"per episode, their RL-rate copies {real['rl_rate_bytes'] / n / 1e3:.1f} kB "
                      f"= {100 * real['rl_rate_bytes'] / real['all_bytes']:.2f} %")
                out.update(recorded_bags=n, recorded_all_bytes_per_episode=real["all_bytes"] / n,
                           recorded_rl_rate_bytes_per_episode=real["rl_rate_bytes"] / n,
                           recorded_rl_rate_pct_of_all=100 * real["rl_rate_bytes"] / real["all_bytes"])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=5000)
    parser.add_argument("--work-us", type=float, default=300.0, help="CPU work per tick standing in for the loop")
    parser.add_argument("--realtime-s", type=float, default=2.0)
    parser.add_argument("--episode-only", action="store_true",
                        help="only the bytes per training episode (no timing)")
    parser.add_argument("--steps", type=int, default=36, help="RL steps of the training episode")
    parser.add_argument("--ticks-per-step", type=int, default=460,
                        help="1 kHz ticks per RL step (a demo run's bags: 23,051 ticks for 50 steps)")
    parser.add_argument("--bags", default="", help="a run's episodes folder: its training bags too")
    args = parser.parse_args()
    if args.steps < 1 or args.ticks_per_step < 1:
        parser.error("--steps and --ticks-per-step must be >= 1")
    episode = episode_main(args)
    if args.episode_only:
        print(json.dumps(episode))
        return
    with tempfile.TemporaryDirectory() as tmp:
        runs = Path(tmp)
        run_lockstep(runs, 500, args.work_us, True)  # warm-up: imports, caches
        base = run_lockstep(runs, args.ticks, args.work_us, False)
        rec = run_lockstep(runs, args.ticks, args.work_us, True)
        rclpy_us, rclpy_messages = rclpy_cost(min(args.ticks, 2000))
        rt_base = run_realtime(runs, args.realtime_s, args.work_us, False)
        rt_rec = run_realtime(runs, args.realtime_s, args.work_us, True)
    total = rec["loop_calls_us"] + rec["other_threads_us"] - base["other_threads_us"]
    result = {
        "ticks": args.ticks,
        "loop_thread_cpu_us": rec["loop_calls_us"],
        "writer_thread_cpu_us": rec["other_threads_us"] - base["other_threads_us"],
        "total_cpu_us": total,
        "total_pct_of_1ms": total / 10.0,
        "record_wall_mean_us": rec["wall_mean_us"],
        "record_wall_p99_us": rec["wall_p99_us"],
        "rclpy_serialize_loop_thread_cpu_us": rclpy_us,
        "rclpy_serialize_messages": rclpy_messages,
        "messages_produced": rec["produced"],
        "messages_written": rec["written"],
        "bag_complete": rec["complete"],
        "bag_kib_per_s": rec["bytes_per_s"] / 1024,
        "realtime_ticks": rt_rec["ticks"],
        "realtime_late_ticks_without": rt_base["late_ticks"],
        "realtime_late_ticks_with": rt_rec["late_ticks"],
        "realtime_worst_overrun_us_with": rt_rec["worst_overrun_us"],
        **episode,
    }
    print(f"per 1 kHz tick, five messages: loop thread {result['loop_thread_cpu_us']:.1f} µs CPU "
          f"(numbers into row buffers), writer thread {result['writer_thread_cpu_us']:.1f} µs CPU, "
          f"total {total:.1f} µs = {result['total_pct_of_1ms']:.2f} % of 1 ms")
    print(f"wall time inside the record calls: {rec['wall_mean_us']:.1f} µs mean, {rec['wall_p99_us']:.1f} µs p99 "
          "(includes preemption on a shared machine)")
    print(f"instead, rclpy messages + serialize_message: {rclpy_us:.1f} µs loop-thread CPU per tick "
          f"for {rclpy_messages} messages")
    print(f"messages produced {result['messages_produced']}, written {result['messages_written']}, "
          f"summary present: {result['bag_complete']}")
    print(f"bag size: {result['bag_kib_per_s']:.1f} KiB per recorded second")
    print(f"wall-clock 1 kHz, {rt_rec['ticks']} ticks: late {rt_base['late_ticks']} without recording, "
          f"{rt_rec['late_ticks']} with (worst overrun {rt_rec['worst_overrun_us']:.0f} µs)")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
