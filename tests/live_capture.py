"""What the live graph carries, captured by a test node, to hold a recorded bag against.

Subscriptions use the QoS the stack's own subscribers use (`qg_common.topics`): transient-local
for `/episode_status`, reliable for the RL-rate topics, best effort (deep, so a slow test process
loses nothing) for the 1 kHz ones. Messages are kept serialized, as a bag stores them.
"""
from __future__ import annotations

from collections.abc import Iterable

from qg_recording.episode_recorder import TOPICS

SENSOR_TOPICS = ("/joint_states", "/wrench_estimate", "/ee_pose", "/ee_twist")
RL_TOPICS = ("/episode_status", "/transitions", "/wrench_setpoint", "/ee_at_rest")


def live_qos(topic: str):
    """The reliability and durability the stack's subscribers of ``topic`` ask for, with a
    history deep enough that a test process that spins late drops nothing."""
    from qg_common import topics
    from rclpy.qos import QoSProfile
    profile = {"/episode_status": topics.LATCHED, "/transitions": topics.RELIABLE_DEEP}.get(
        topic, topics.SENSOR_QOS if topic in SENSOR_TOPICS else QoSProfile(depth=topics.COMMAND_QOS))
    return QoSProfile(depth=5000, reliability=profile.reliability, durability=profile.durability)


class LiveCapture:
    """Serialized messages received per topic, in arrival order."""

    def __init__(self, cli, topics: Iterable[str] = SENSOR_TOPICS + RL_TOPICS) -> None:
        from qg_recording.player import message_class
        self.received: dict[str, list[bytes]] = {}
        for topic in topics:
            self.received[topic] = []
            cli.node.create_subscription(message_class(TOPICS[topic].type_name), topic,
                                         self.received[topic].append, live_qos(topic), raw=True)

    def decoded(self, topic: str) -> list:
        from qg_recording.player import message_class
        from rclpy.serialization import deserialize_message
        cls = message_class(TOPICS[topic].type_name)
        return [deserialize_message(data, cls) for data in self.received[topic]]


def stamp_ns(msg) -> int:
    stamp = msg.header.stamp if hasattr(msg, "header") else msg.stamp
    return stamp.sec * 10**9 + stamp.nanosec


def offered_qos(cli, topic: str) -> list[tuple[str, str, str]]:
    """(reliability, durability, type hash) of every publisher of ``topic`` the graph reports."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    return [(ReliabilityPolicy(i.qos_profile.reliability).name.lower(),
             DurabilityPolicy(i.qos_profile.durability).name.lower(), str(i.topic_type_hash))
            for i in cli.node.get_publishers_info_by_topic(topic)]
