"""The loop's log lines reach the bridge's logger at their own severity, whatever came before
(rclpy refuses a call site whose severity changes: one line once crashed the robot process's
reader thread, and with it the robot process, on franky-sim's first watchdog hold)."""
from __future__ import annotations

import pytest


def test_lines_of_every_severity_in_any_order_are_logged() -> None:
    import rclpy
    from rclpy.node import Node
    from robot_bridge_node.bridge_node import log_at

    rclpy.init(domain_id=230)          # no test's processes use it; nothing is published
    try:
        node = Node("log_at_test")
        for level in ("warning", "error", "info", "warning", "info", "error", "fatal"):
            log_at(node, level, f"a {level} line")
        node.destroy_node()
    finally:
        rclpy.shutdown()


def test_a_line_repeated_within_a_second_is_logged_once(monkeypatch: pytest.MonkeyPatch) -> None:
    import rclpy
    from rclpy.node import Node
    from robot_bridge_node import bridge_node

    rclpy.init(domain_id=230)
    try:
        node = Node("log_at_repeat_test")
        said: list[str] = []
        logger = node.get_logger()
        monkeypatch.setattr(node, "get_logger", lambda: logger)
        monkeypatch.setattr(logger, "error", said.append)
        for _ in range(3):
            bridge_node.log_at(node, "error", "the same complaint")
        bridge_node.log_at(node, "error", "another complaint")
        assert said == ["the same complaint", "another complaint"]
        node.destroy_node()
    finally:
        rclpy.shutdown()
