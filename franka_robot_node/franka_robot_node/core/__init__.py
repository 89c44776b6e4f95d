"""The Franka plugin's pure-Python core (no rclpy): the arm's description, its parameters and
the hardware interface over libfranka."""
