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
- a wall-clock 1 kHz run: ticks that missed their deadline with and without recording.

Usage: .venv/bin/python benchmarks/recording_bench.py [--ticks 5000] [--work-us 300] [--realtime-s 2]
The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from qg_recording.bag_reader import bag_info
from qg_recording.episode_recorder import EpisodeRecorder

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=5000)
    parser.add_argument("--work-us", type=float, default=300.0, help="CPU work per tick standing in for the loop")
    parser.add_argument("--realtime-s", type=float, default=2.0)
    args = parser.parse_args()
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
