"""The package split stays enforced: cores never import rclpy; executables are installed."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CORE_FILES = [
    *ROOT.glob("sim_robot_node/sim_robot_node/core/**/*.py"),
    *ROOT.glob("robot_bridge_node/robot_bridge_node/core/**/*.py"),
    *ROOT.glob("qg_learning_node/qg_learning_node/core/**/*.py"),
    *(ROOT / "qg_learning_node/qg_learning_node" / f for f in
      ("qgraph.py", "ddpg.py", "replay.py", "learner_core.py")),
]


def test_cores_do_not_import_rclpy():
    offenders = [str(p.relative_to(ROOT)) for p in CORE_FILES
                 if p.exists() and re.search(r"^\s*(import|from)\s+rclpy", p.read_text(), re.M)]
    assert len([p for p in CORE_FILES if p.exists()]) >= 5
    assert offenders == []


def test_executables_are_where_ros2_run_looks():
    install = ROOT / "ros_ws" / "install"
    for pkg, exe in [("sim_robot_node", "sim"), ("robot_bridge_node", "bridge"),
                     ("robot_bridge_node", "wrench_estimator"), ("robot_bridge_node", "robot"),
                     ("qg_learning_node", "executor"), ("qg_learning_node", "learner")]:
        assert (install / pkg / "lib" / pkg / exe).is_file(), f"{pkg}/{exe}"
        marker = install / pkg / "share" / "ament_index" / "resource_index" / "packages" / pkg
        assert marker.is_file(), marker
