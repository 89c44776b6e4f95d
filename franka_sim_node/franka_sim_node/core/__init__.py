"""franka_sim's pure-Python core (no rclpy): franky-sim's host with its scene extensions, and the
scenes (the shaft task's cell, a demo block)."""
