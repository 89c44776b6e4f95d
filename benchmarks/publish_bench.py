"""CPU time per tick to publish the 1 kHz topics: message objects against serialized rows.

The robot process publishes every tick of its loop on six topics (seven in lockstep, with
``/clock``). Two ways are timed on the same block of ticks, with rclpy publishers on a private
domain and no subscriber:

- ``objects``: a message object per topic and tick, built by ``qg_common.conversions`` and
  serialized by rclpy (what the separate sim, bridge and estimator processes still do, and the
  robot process did before);
- ``serialized``: the block's rows of numbers per topic (``tick_messages.serialized_ticks``),
  encoded by numpy and published as bytes (what the robot process does).

The records are synthetic (the Panda's 7 joints, a tool pose and an estimate on every tick,
the ground truth every ``--truth-every`` ticks); the cost does not depend on the numbers.
The last line is one JSON object.

Usage: python benchmarks/publish_bench.py [--ticks 5000] [--block 250] [--truth-every 10]
"""
from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--ticks", type=int, default=5000)
    parser.add_argument("--block", type=int, default=250, help="ticks the reader takes at once")
    parser.add_argument("--truth-every", type=int, default=10)
    args = parser.parse_args()
    os.environ.setdefault("ROS_DOMAIN_ID", "97")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    import rclpy
    from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
    from qg_common.conversions import (
        ground_truth_msg,
        joint_state_msg,
        pose_stamped,
        time_msg,
        twist_stamped,
        wrench_stamped,
    )
    from qg_common.types import JointState
    from qg_interfaces.msg import GroundTruth
    from qg_recording.cdr import CdrBuffer
    from robot_bridge_node.core.sample_ring import (
        HAS_TOOL,
        HAS_TRUTH,
        HAS_WRENCH,
        PUBLISH,
        record_dtype,
        truth_from_array,
    )
    from robot_bridge_node.core.tick_messages import TickNames, serialized_ticks
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState as JointStateMsg

    rclpy.init()
    node = rclpy.create_node("publish_bench")
    types = {"/joint_states": JointStateMsg, "/sim/ground_truth": GroundTruth,
             "/sim/ground_truth_wrench": WrenchStamped, "/wrench_estimate": WrenchStamped,
             "/ee_pose": PoseStamped, "/ee_twist": TwistStamped, "/clock": Clock}
    pub = {topic: node.create_publisher(t, topic, 10) for topic, t in types.items()}
    names = tuple(f"joint{i}" for i in range(1, 8))
    base = "link0"

    rng = np.random.default_rng(0)
    records = np.zeros(args.ticks, record_dtype(len(names)))
    records["t_ns"] = 10**9 + np.arange(args.ticks) * 10**6
    records["flags"] = PUBLISH | HAS_WRENCH | HAS_TOOL
    records["flags"][::args.truth_every] |= HAS_TRUTH
    for field in ("q", "dq", "tau", "tau_cmd", "wrench", "tool_position", "tool_twist", "truth"):
        records[field] = rng.normal(size=records[field].shape)
    records["tool_rotation"] = np.eye(3)

    def objects(block: np.ndarray) -> None:
        for record in block:
            stamp = time_msg(int(record["t_ns"]))
            pub["/joint_states"].publish(joint_state_msg(
                JointState(record["q"], record["dq"], record["tau"]), stamp, names))
            if record["flags"] & HAS_TRUTH:
                truth = truth_from_array(record["truth"])
                pub["/sim/ground_truth"].publish(ground_truth_msg(truth, stamp))
                pub["/sim/ground_truth_wrench"].publish(wrench_stamped(truth.wrench, stamp))
            pub["/wrench_estimate"].publish(wrench_stamped(record["wrench"], stamp))
            pub["/ee_pose"].publish(pose_stamped(record["tool_position"],
                                                 record["tool_rotation"], stamp, base))
            pub["/ee_twist"].publish(twist_stamped(record["tool_twist"], stamp, base))
            pub["/clock"].publish(Clock(clock=stamp))

    def serialized(block: np.ndarray) -> None:
        for t_ns, messages in serialized_ticks(block, TickNames(names, base)):
            for topic, message in messages:
                pub[topic].publish(message)
            pub["/clock"].publish(CdrBuffer().stamp(t_ns).message())

    def per_tick(publish: Callable[[np.ndarray], None]) -> float:
        """[us] process CPU time per tick."""
        start = time.process_time()
        for first in range(0, args.ticks, args.block):
            publish(records[first:first + args.block])
        return (time.process_time() - start) / args.ticks * 1e6

    serialized(records[:args.block])            # warm up: imports, layouts, DDS writers
    objects(records[:args.block])
    result = {"ticks": args.ticks, "block": args.block, "truth_every": args.truth_every,
              "objects_us_per_tick": round(per_tick(objects), 1),
              "serialized_us_per_tick": round(per_tick(serialized), 1)}
    result["speedup"] = round(result["objects_us_per_tick"] / result["serialized_us_per_tick"], 2)
    print(f"objects: {result['objects_us_per_tick']} us per tick; serialized: "
          f"{result['serialized_us_per_tick']} us per tick ({result['speedup']}x)")
    node.destroy_node()
    rclpy.shutdown()
    print(json.dumps(result))


if __name__ == "__main__":
    main()
