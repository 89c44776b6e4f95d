"""The fast in-process experiment runner: the thesis's experiments on the simulated stack.

It composes the same cores as the ROS nodes (robot loop, EKF, episode logic, learner) in one
process per run, without DDS, so sweeps that would take days through the node graph fit into
hours. ``python -m qg_experiments --profile small`` runs a profile of
``config/experiments.yaml`` and writes ``docs/results.md``.

The runs of a sweep are independent, so they go to a pool of one worker process per core, or
with ``--backend ray`` to Ray (a local Ray, or a cluster with ``--address``) for more cores than
one machine has; a seed gives the same result on either (``tasks``, ``ray_backend``).

This package is the only one that composes the bridge's cores (``robot_bridge_node``) with the
executor's and learner's (``qg_learning_node``); robots and the free peg are loaded by name
(``robot_bridge_node.robots``, ``environments``), so it imports no simulator either. The ch. 7
toy graphs (``toys``) live here too.
"""

import importlib as _importlib
import sys as _sys

if "gymnasium" in _sys.modules:      # gymnasium.make("qg_experiments:QGInsertion-v0")
    _importlib.import_module("qg_experiments.gym_envs")      # registers the environments
