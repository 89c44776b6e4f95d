"""The QG-DDPG learner's pure core (no rclpy): Q-Graph, replay memory, DDPG networks, the
learner core and its settings, the training log and the rebuild from recorded bags.

``learner_node`` wraps it in ROS; it imports in a plain Python session, so the algorithm is
usable without a ROS graph.
"""
