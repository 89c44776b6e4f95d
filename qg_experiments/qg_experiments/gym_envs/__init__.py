"""The stack's tasks as Gymnasium environments, found by ``import gymnasium``.

Why: a user of Stable-Baselines3, CleanRL or RL Zoo can train on the shaft insertion (and any
Gymnasium agent on the real ROS stack) without learning our runner, and our own algorithms can be
checked against maintained implementations on exactly the same task. The environments wrap the
cores the runner and the ROS nodes use (``InsertionRobot``, ``NextagePeg``, ``ResidualTask``,
``Episode``); none of them has its own copy of the task logic.

How gymnasium finds them: ``gymnasium.make("qg_experiments:QGInsertion-v0")`` (gymnasium's
``module:id`` form imports ``qg_experiments``, which registers them once gymnasium is loaded), or
``import qg_experiments.gym_envs`` and then the bare ids. ``setup.py`` also names
:func:`register_envs` under the ``gymnasium.envs`` entry point, the plugin hook that gymnasium
0.26-0.29 called on ``import gymnasium``; gymnasium 1.x (pinned: 1.4.0) no longer reads it.
Registering only names the classes: it loads neither pybullet, torch nor rclpy.

=========================  ==============================================================
``QGInsertion-v0``         the Panda shaft into the bearing, in process (:mod:`.insertion`)
``QGPeg-v0``               the free peg into the clearance-fit hole, experiment 5's (:mod:`.peg`)
``QGNextagePeg-v0``        the Nextage peg into the clearance-fit hole, in process (:mod:`.peg`)
``QGInsertionROS-v0``      the Panda shaft through a running robot process (:mod:`.ros_insertion`)
``QGSparseMountainCar-v0`` Gymnasium's continuous mountain car, reward -1 per step and 0 at the
                           goal: a standard task with the thesis's sparse reward
                           (:mod:`.sparse_mountain_car`)
=========================  ==============================================================
"""
from __future__ import annotations

__all__ = ["ENV_IDS", "IN_PROCESS_ENV_IDS", "ROS_ENV_IDS", "register_envs"]

#: Environments that need nothing but this Python environment.
IN_PROCESS_ENV_IDS = {
    "QGInsertion-v0": "qg_experiments.gym_envs.insertion:InsertionEnv",
    "QGPeg-v0": "qg_experiments.gym_envs.peg:FreePegEnv",
    "QGNextagePeg-v0": "qg_experiments.gym_envs.peg:NextagePegEnv",
    "QGSparseMountainCar-v0": "qg_experiments.gym_envs.sparse_mountain_car:SparseMountainCar",
}
#: Environments that drive a robot process over ROS 2 (``qgl up`` or ``robot_bridge_node robot``).
ROS_ENV_IDS = {
    "QGInsertionROS-v0": "qg_experiments.gym_envs.ros_insertion:RosInsertionEnv",
}
ENV_IDS = {**IN_PROCESS_ENV_IDS, **ROS_ENV_IDS}


def register_envs() -> None:
    """Register every environment of :data:`ENV_IDS` with gymnasium (idempotent).

    The step caps are the environments' own (``max_steps``, kept apart from termination); no
    ``TimeLimit`` is added, so ``gymnasium.make(..., max_episode_steps=n)`` stays the user's.
    """
    from gymnasium.envs.registration import register, registry
    for env_id, entry_point in ENV_IDS.items():
        if env_id not in registry:
            # A robot process's noise streams are its own: a seed cannot replay its episodes.
            register(id=env_id, entry_point=entry_point, nondeterministic=env_id in ROS_ENV_IDS)


register_envs()
