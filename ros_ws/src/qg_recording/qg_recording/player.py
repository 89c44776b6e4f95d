"""Republishing a bag with its original timing, like `ros2 bag play` (node side: uses rclpy).

Messages are published as the recorded CDR bytes (rclpy publishes serialized messages as they
are), on publishers of the recorded types with the recorded offered QoS (reliability and
durability: a transient-local subscriber such as the learner's `/episode_status` one only matches
a transient-local publisher), each at
`first_publish + (t - t_first) / rate` on the monotonic clock. Sleeping happens between messages
only; a publisher that falls behind (slow machine, high rate) catches up without sleeping rather
than drifting.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .bag_reader import bag_info, read_raw
from .rosbag2_metadata import parse_qos_profiles

__all__ = ["PlayResult", "message_class", "offered_qos", "play"]

#: [s] at the end, how long to wait for subscribers to acknowledge the last reliable messages.
ACK_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class PlayResult:
    messages: int
    bag_duration_s: float  # between the first and the last played message
    wall_s: float  # from the first to the last publish


def message_class(type_name: str) -> type:
    """The rclpy message class of `pkg/msg/Type`.

    :raises ValueError: if the name is malformed; ImportError/AttributeError if not installed.
    """
    parts = type_name.split("/")
    if len(parts) != 3 or parts[1] != "msg":
        raise ValueError(f"not a message type name: {type_name!r} (expected pkg/msg/Type)")
    return getattr(importlib.import_module(f"{parts[0]}.msg"), parts[2])


def offered_qos(offered_yaml: str) -> QoSProfile:
    """The publisher QoS replay offers: the recorded profile's reliability and durability.

    A volatile topic gets at least depth 10, so a burst of replayed messages is not cut short;
    a transient-local one keeps its recorded depth, which is what a late joiner receives live.
    """
    reliability, durability, depth = parse_qos_profiles(offered_yaml)
    latched = durability == "transient_local"
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth if latched else max(10, depth),
        reliability=ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort" else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def play(
    path: Path,
    rate: float = 1.0,
    topics: Iterable[str] | None = None,
    node: Node | None = None,
    start_delay_s: float = 0.0,
    wait_for_subscribers_s: float = 0.0,
) -> PlayResult:
    """Publish the bag's messages with their recorded spacing divided by `rate`.

    :param node: node to publish from; a `qgl_replay` node is created (rclpy must be
        initialised) and destroyed if None.
    :param topics: only these topics (all if None).
    :param start_delay_s: wait after creating the publishers (and after the subscribers were
        seen), so subscribers can match them; messages published before are lost to them.
    :param wait_for_subscribers_s: first wait up to this long until every publisher has a
        subscriber.
    :raises ValueError: for a non-positive rate.
    """
    if rate <= 0.0:
        raise ValueError(f"rate must be positive, got {rate}")
    wanted = None if topics is None else set(topics)
    info = bag_info(path)
    own_node = node is None
    if node is None:
        node = Node("qgl_replay")
    try:
        publishers: dict[str, Any] = {}
        #: Reliable topics with the shallow history of a latched topic: a message published
        #: before its predecessor is acknowledged would overwrite it in the writer's history
        #: and never reach a slow reader, so replay waits for the acknowledgement first.
        shallow: set[str] = set()
        for topic in info.topics:
            if (wanted is None or topic.name in wanted) and topic.name not in publishers and topic.message_count:
                qos = offered_qos(topic.qos)
                publishers[topic.name] = node.create_publisher(
                    message_class(topic.type_name), topic.name, qos)
                if qos.reliability == ReliabilityPolicy.RELIABLE and qos.depth < 10:
                    shallow.add(topic.name)
        deadline = time.monotonic() + wait_for_subscribers_s
        while time.monotonic() < deadline and any(p.get_subscription_count() == 0 for p in publishers.values()):
            time.sleep(0.02)
        if start_delay_s > 0.0:
            time.sleep(start_delay_s)
        count, first_t, last_t = 0, None, 0
        start = last = time.monotonic()
        for message in read_raw(path, publishers.keys()):
            if first_t is None:
                first_t = message.t_ns
                start = time.monotonic()
            due = start + (message.t_ns - first_t) * 1e-9 / rate
            wait = due - time.monotonic()
            if wait > 0.0:
                time.sleep(wait)
            publisher = publishers[message.topic]
            publisher.publish(message.data)
            if message.topic in shallow:
                publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
            last, last_t = time.monotonic(), message.t_ns
            count += 1
        # The last reliable messages may still be in flight: destroying the node now would drop
        # them, so wait (bounded) until every matched subscriber has acknowledged them.
        for publisher in publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
        return PlayResult(count, 0.0 if first_t is None else (last_t - first_t) * 1e-9,
                          0.0 if first_t is None else last - start)
    finally:
        if own_node:
            node.destroy_node()
