"""The executor's pure core (no rclpy): the task MDPs, the episode state machine, exploration
noise, observations from a step, episode requests and ids.

``executor_node`` drives it from service calls and at-rest events; the experiments
(``qg_experiments``) drive the same classes in a plain loop, so both run one task.
"""
