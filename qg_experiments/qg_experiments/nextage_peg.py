"""The Nextage peg through the stack's cores in one process (the fast runner's Nextage).

``robot:=sim_nextage`` in the ROS stack runs the simulated Nextage plugin under the bridge's
position loop (task-space IK at 1 kHz, the wrist sensor, the rest detector that ends a step),
and the executor's ``PegTask`` turns at-rest observations into states and rewards and actions
into pose references. Here the same cores are called directly, read from the same config files
(``peg_task.yaml``, ``nextage.yaml``, ``bridge.yaml``, ``executor_nextage.yaml``), behind the
interface of the free
peg environment, so experiment 5 (``peg.run_peg``) runs either robot unchanged.

A start index draws the same tip position as the free peg's ``reset(seed)`` (both sample the
free workspace with ``numpy.random.default_rng(seed)``): the two robots start where the other
would.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from qg_common.params import config_file, load_ros_params, merge_params
from qg_common.peg_task import PegCell
from qg_common.types import StepResult
from qg_learning_node.executor.observation import observation_from_step
from qg_learning_node.executor.peg_task import PEG_ACTION_DIM, PEG_STATE_DIM, PegTask, PegTaskConfig
from qg_learning_node.executor.residual_task import Observation
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.position_loop import PositionLoop, build_position_loop

__all__ = ["NextagePeg"]


class NextagePeg:
    """The simulated Nextage, its position loop and the executor's peg task, in process.

    :param config_dir: the stack's ``config/`` (``None``: the installed files).
    :param episode_steps: step cap of an episode (``truncated`` after it; not terminal).
    :param reward: ``dense`` | ``sparse`` (``PegTask.reward``).
    """

    state_dim = PEG_STATE_DIM
    action_dim = PEG_ACTION_DIM

    def __init__(self, config_dir: str | None = None, episode_steps: int = 200,
                 reward: str = "dense") -> None:
        def params(name: str) -> dict[str, Any]:
            return load_ros_params(config_file(name, config_dir))
        robot_params = merge_params(params("peg_task.yaml"), params("nextage.yaml"))
        self.robot_params = robot_params          # the sim_nextage plugin's
        bridge = params("bridge.yaml")
        self.loop: PositionLoop = build_position_loop(
            load_robot("sim_nextage", robot_params),
            {**bridge, "position_control": robot_params["position_control"]})
        self.loop.begin()
        self.task = PegTask(PegTaskConfig.from_dict(params("executor_nextage.yaml")["peg"]),
                            PegCell.from_dict(robot_params["peg_task"]))
        self.episode_steps = episode_steps
        self.reward_kind = reward
        self.steps = 0
        self.sim_time = 0.0
        self.step_timeouts = 0
        self._observation: Observation | None = None

    @property
    def truncated(self) -> bool:
        """True once the episode has run ``episode_steps`` steps."""
        return self.steps >= self.episode_steps

    def reset(self, seed: int) -> np.ndarray:
        """The tip at the ``seed``-th free start, the arm settled there; the initial state."""
        self.loop.reset(self.task.start_pose(seed))
        self._observation = self._observe(self.loop.result(self.loop.time))
        self.steps = 0
        return self.task.state(self._observation)

    def tip(self) -> np.ndarray:
        """The peg tip in the workspace frame [m], as the executor computes it.

        :raises ValueError: before ``reset``.
        """
        if self._observation is None:
            raise ValueError("call reset() before tip()")
        return self.task.tip(self._observation)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool]:
        """Move the tip by ``action`` until the arm is at rest: next state, reward, terminal.

        :raises ValueError: before ``reset``, or for a non-finite action.
        """
        if self._observation is None:
            raise ValueError("call reset() before step()")
        result = self.loop.execute(self.task.command(action, self._observation))
        self.sim_time += result.duration
        self.step_timeouts += int(result.timed_out)
        self.steps += 1
        self._observation = self._observe(result)
        return (self.task.state(self._observation),
                self.task.reward(self._observation, self.reward_kind),
                self.task.succeeded(self._observation))

    @property
    def observation(self) -> Observation | None:
        """What the last reset or step observed (ground truth for evaluation included)."""
        return self._observation

    def close(self) -> None:
        """Release the plugin's simulation (its pybullet client)."""
        close = getattr(self.loop.simulation, "close", None)
        if close is not None:
            close()

    def _observe(self, result: StepResult) -> Observation:
        """What the executor would get in the ``AtRest`` message: the result and the tool pose
        from forward kinematics of the measured joints."""
        tool = self.loop.controller.tool
        return observation_from_step(result, tool.position, tool.rotation)
