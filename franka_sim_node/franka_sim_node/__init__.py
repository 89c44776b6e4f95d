"""The rehearsal's robot: franky-sim's MuJoCo FR3 serving libfranka's protocol on loopback, with
the shaft task's cell built from ``sim_robot_node``'s MuJoCo description (``franka_sim``). It is a
simulator beside ``sim_robot_node``, so the real-arm plugin (``franka_robot_node``) stays free of
any simulator; like the simulated robots, nothing imports it."""
