"""``QGInsertionROS-v0``: the shaft insertion through a running robot process, over ROS 2.

Any Gymnasium agent learns through the real stack this way, as SERL's robot environments do over
their robot servers: the environment takes the executor's place. A reset calls the robot's
``move_to_start`` service, which opens a session (the bridge executes only that session's
setpoints from then on, so a stale sender cannot move the arm) and answers with the settled
start; a step publishes one wrench setpoint of the session on ``wrench_setpoint`` and waits for
the ``ee_at_rest`` event that completes it. States, rewards, caps and the goal come from the
executor's cores (:class:`~.residual_env.ResidualEnv`), so this is the node's task, not a copy.

``namespace`` picks the robot: ``qgl up --robots N`` runs N robot processes in ``/robot0`` ..
``/robot<N-1>``, and N environments, one per namespace, step them side by side (in one process
or in N). The arm (realistic or ideal, its seed) is the robot process's: start it with
``--params-file config/panda_ideal.yaml`` or ``-p panda_scene.imperfections.seed:=N``. The robot
runs in ``lockstep`` by default; a ``realtime`` one works too, its watchdog holding the pose
whenever the agent takes longer than ``safety.watchdog_timeout`` (0.1 s) between steps. ``reset(seed=...)`` seeds gymnasium's generator only: the
robot process's noise streams are its own, so the environment is registered ``nondeterministic``.

The environment owns its rclpy context and spins its executor itself until what it waits for has
arrived (rclpy's ``spin_until_future_complete`` costs 4-21 ms a call here).
"""
from __future__ import annotations

import dataclasses
import itertools
import os
from typing import Any

import numpy as np
from qg_common import topics
from qg_common.conversions import setpoint_msg, start_pose_request
from qg_common.params import config_file, load_ros_params
from qg_common.ros_client import CliNode, call_service
from qg_interfaces.msg import AtRest, WrenchSetpoint
from qg_interfaces.srv import MoveToStart
from qg_learning_node.conversions import observation_from_msg
from qg_learning_node.executor.parameters import load_geometry
from qg_learning_node.executor.residual_task import Observation, TaskConfig

from qg_experiments.gym_envs.insertion import TRAIN_MAX_STEPS
from qg_experiments.gym_envs.residual_env import ResidualEnv

__all__ = ["RosInsertionEnv"]

#: Distinct session names for environments of one process.
_SESSIONS = itertools.count()


class RosInsertionEnv(ResidualEnv):
    """The residual force policy on the robot process in ``namespace``.

    :param namespace: the robot's namespace (``robot0`` under ``qgl up --robots N``; "" = root).
    :param domain_id: the ROS domain; ``None``: ``$ROS_DOMAIN_ID`` (as every process of the stack).
    :param observation: the state; ``None``: ``executor.yaml``'s (as the executor node's).
    :param reward: ``dense`` | ``sparse``; ``None``: ``executor.yaml``'s.
    :param max_steps: step cap of an episode (default: the grid's training cap, 50).
    :param step_timeout: [s] wall time to wait for one step's at-rest event.
    :param reset_timeout: [s] wall time to wait for ``move_to_start`` (its discovery included).
    :param config_dir: the stack's ``config/``; ``None``: the installed files.
    """

    #: Not drawn (yet): its robot is another process's; ``qgl render`` draws its bags.
    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, namespace: str = "", domain_id: int | None = None,
                 observation: str | None = None, reward: str | None = None,
                 max_steps: int = TRAIN_MAX_STEPS, step_timeout: float = 10.0,
                 reset_timeout: float = 30.0, config_dir: str | None = None) -> None:
        task = TaskConfig.from_dict(load_ros_params(config_file("executor.yaml",
                                                                config_dir))["task"])
        if observation is not None:
            task = dataclasses.replace(task, observation=observation)
        geometry = load_geometry(load_ros_params(config_file("shaft_task.yaml", config_dir)),
                                 "shaft_task.yaml")
        super().__init__(task, geometry, reward, max_steps)
        if not step_timeout > 0 or not reset_timeout > 0:
            raise ValueError("step_timeout and reset_timeout must be > 0 s")
        self.namespace = namespace.strip("/")
        self.step_timeout, self.reset_timeout = float(step_timeout), float(reset_timeout)
        domain = domain_id if domain_id is not None else int(os.environ.get("ROS_DOMAIN_ID", 0))
        self._reset_service = topics.robot_topic(self.namespace, topics.MOVE_TO_START)
        self._cli = CliNode("gym_env", domain_id=domain).__enter__()
        node = self._cli.node
        self._events: dict[int, AtRest] = {}
        self._at_rest = node.create_subscription(
            AtRest, topics.robot_topic(self.namespace, topics.EE_AT_REST), self._on_at_rest,
            topics.COMMAND_QOS)
        self._setpoints = node.create_publisher(
            WrenchSetpoint, topics.robot_topic(self.namespace, topics.WRENCH_SETPOINT),
            topics.COMMAND_QOS)
        self._env_id = f"{node.get_name()}_{next(_SESSIONS)}"
        self.session = ""
        self._seq = 0
        self._observation: Observation | None = None

    def _on_at_rest(self, msg: AtRest) -> None:
        self._events[int(msg.seq)] = msg

    def _wait(self, condition: Any, timeout: float, what: str) -> None:
        """Spin until ``condition()``; :raises TimeoutError: naming ``what`` after ``timeout``."""
        if not self._cli.spin_until(condition, timeout):
            raise TimeoutError(f"{what} within {timeout:.0f} s (is the robot process "
                               f"{'/' + self.namespace if self.namespace else ''} up?)")

    def _reset_robot(self, pose: int) -> Observation:
        self.session = f"{self._env_id}_ep{self.episodes}"
        response = call_service(self._cli, MoveToStart, self._reset_service,
                                start_pose_request(self.residual.start_pose(pose),
                                                   session=self.session), self.reset_timeout)
        if not response.success:
            raise RuntimeError(f"{self._reset_service} refused the reset: {response.message}")
        # Nothing may be lost from here on: both ends of the step topics must be matched.
        self._wait(lambda: self._setpoints.get_subscription_count() > 0,
                   self.reset_timeout, f"nobody subscribed {self._setpoints.topic_name}")
        self._wait(lambda: self._at_rest.get_publisher_count() > 0,
                   self.reset_timeout, f"nobody published {self._at_rest.topic_name}")
        self._seq, self._events = 0, {}
        self._observation = observation_from_msg(response.observation)
        return self._observation

    def _execute(self, action: np.ndarray) -> Observation:
        assert self._observation is not None
        self._seq += 1
        seq = self._seq
        command = self.residual.command(action, self._observation)
        self._setpoints.publish(setpoint_msg(seq, command,
                                             self._cli.node.get_clock().now().to_msg(),
                                             self.session))
        self._wait(lambda: seq in self._events, self.step_timeout,
                   f"no {self._at_rest.topic_name} event for setpoint {seq}")
        self._observation = observation_from_msg(self._events.pop(seq))
        return self._observation

    def _info(self, observation: Observation) -> dict[str, Any]:
        return {**super()._info(observation), "session": self.session}

    def close(self) -> None:
        """Leave the robot safe (the base push only, from where it is) and the ROS graph."""
        if self._cli is None:
            return
        if self._observation is not None and self.session:
            self._seq += 1
            self._setpoints.publish(setpoint_msg(self._seq, self.residual.hold(),
                                                 self._cli.node.get_clock().now().to_msg(),
                                                 self.session))
            self._cli.spin_for(0.05)
        self._cli.__exit__(None, None, None)
        self._cli = None
