"""The Franka plugin's pure-Python core (no rclpy): the arm's description, its parameters, the
hardware interface over libfranka, and franky-sim's host with its scene extensions."""
