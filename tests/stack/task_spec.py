"""What a test that feeds a learner without an executor must say first: the executor's task."""
from __future__ import annotations

from typing import Any


def announce_task(cli: Any, state_dim: int, action_dim: int = 2, observation: str = "tilt",
                  kind: str = "residual", namespace: str = "") -> Any:
    """Publish an executor's latched ``executor/task_spec`` from the test node (keep the
    returned publisher: the message lives as long as it does)."""
    from qg_common.topics import LATCHED, TASK_SPEC, robot_topic
    from qg_interfaces.msg import TaskSpec
    publisher = cli.node.create_publisher(TaskSpec, robot_topic(namespace, TASK_SPEC), LATCHED)
    publisher.publish(TaskSpec(kind=kind, observation=observation, state_dim=state_dim,
                               action_dim=action_dim))
    return publisher
