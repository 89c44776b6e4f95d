"""The fast in-process experiment runner: the thesis's experiments on the simulated stack.

It composes the same cores as the ROS nodes (robot loop, EKF, episode logic, learner) in one
process per run, without DDS, so sweeps that would take days through the node graph fit into
hours. ``python -m qg_learning_node.experiments --profile small`` runs a profile of
``config/experiments.yaml`` and writes ``docs/results.md``.

The runs of a sweep are independent, so they go to a pool of one worker process per core, or
with ``--backend ray`` to Ray (a local Ray, or a cluster with ``--address``) for more cores than
one machine has; a seed gives the same result on either (``tasks``, ``ray_backend``).
"""
