"""The ``robot`` process: sim, bridge and estimator nodes composed around one 1 kHz loop."""
from __future__ import annotations

from sim_robot_node.node_runtime import run_nodes
from sim_robot_node.sim_node import SimNode

from robot_bridge_node.bridge_node import BridgeNode
from robot_bridge_node.estimator_node import WrenchEstimatorNode


def main(args: list[str] | None = None) -> int:
    return run_nodes([SimNode, BridgeNode, WrenchEstimatorNode],
                     ["sim.yaml", "bridge.yaml", "wrench_estimator.yaml"], args)


if __name__ == "__main__":
    raise SystemExit(main())
