"""``QGInsertionROS-v0`` against real robot processes: gymnasium's checker, whole episodes, and
two namespaced robots stepped side by side by two environments."""
from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from qg_experiments.gym_envs import ROS_ENV_IDS

pytestmark = pytest.mark.ros

NAMESPACES = ("robot0", "robot1")


def test_the_ros_environment_runs_episodes_on_robot_processes_side_by_side(stack) -> None:
    stack.start(*[(ns, "robot_bridge_node", "robot", ("--ros-args", "-r", f"__ns:=/{ns}"))
                  for ns in NAMESPACES])
    assert "QGInsertionROS-v0" in ROS_ENV_IDS       # (importing gym_envs registered it)
    envs = [gymnasium.make("QGInsertionROS-v0", namespace=ns, domain_id=stack.domain_id,
                           max_steps=3).unwrapped for ns in NAMESPACES]
    try:
        check_env(envs[0], skip_render_check=True)
        starts = [env.reset(options={"pose": pose}) for env, pose in zip(envs, (1, 5))]
        for (obs, info), env in zip(starts, envs):
            assert env.observation_space.contains(obs) and info["pose"] == env.episode.initial_pose
        assert not np.array_equal(starts[0][0], starts[1][0])       # two robots, two poses
        assert starts[0][1]["session"] != starts[1][1]["session"]
        ended = [False, False]
        steps = 0
        while not all(ended):                     # one step on each robot in turn
            for i, env in enumerate(envs):
                if ended[i]:
                    continue
                obs, reward, terminated, truncated, info = env.step(np.array([0.6, -0.6]))
                assert env.observation_space.contains(obs) and -1.0 <= reward <= 0.0
                assert isinstance(info["is_success"], bool) and info["position_error"] > 0
                ended[i] = terminated or truncated
                steps += 1
        assert 2 <= steps <= 6
        for env in envs:
            assert env.episode.end_reason in ("goal", "step_cap", "left_bore")
    finally:
        for env in envs:
            env.close()
    assert stack.launcher.poll() == [], stack.logs()
