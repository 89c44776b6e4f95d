"""The residual task's states: the thesis's 4-D wrench state and the tilt state beside it."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from qg_learning_node.executor.residual_task import (Observation, ResidualTask, TaskConfig,
                                                     state_dim, tilt_from_push_axis)
from qg_learning_node.learner.actor_mlp import ActorMLP

DOWN = Rotation.from_rotvec([np.pi, 0.0, 0.0])     # tool z pointing down: the inserted pose
PUSH = np.array([0.0, 0.0, -1.0])


def _obs(wrench, rotation=None) -> Observation:
    return Observation(wrench=np.asarray(wrench, float), success=False, position_error=0.0,
                       orientation_error=0.0, lateral_offset=0.0, tool_rotation=rotation)


@pytest.mark.parametrize("rotvec", [[0.26, 0.0, 0.0], [0.0, -0.26, 0.0], [0.1, 0.2, 0.0],
                                    [np.pi / 2, 0.0, 0.0], [0.0, 3.0, 0.0]])
def test_tilt_is_the_rotation_back_to_the_push_axis(rotvec) -> None:
    """Tilting the tool by ``rotvec`` (tool frame) reads as ``-rotvec``: the way back."""
    rotation = (DOWN * Rotation.from_rotvec(rotvec)).as_matrix()
    tilt = tilt_from_push_axis(rotation, PUSH)
    np.testing.assert_allclose(tilt, -np.asarray(rotvec)[:2], atol=1e-12)
    # applying the reading to the tilted tool brings its z axis onto the push axis
    back = rotation @ Rotation.from_rotvec([*tilt, 0.0]).as_matrix()
    np.testing.assert_allclose(back[:, 2], PUSH, atol=1e-12)


def test_tilt_ignores_rotation_about_the_shaft_and_is_zero_when_aligned() -> None:
    spun = (DOWN * Rotation.from_rotvec([0.0, 0.0, 1.2])).as_matrix()
    np.testing.assert_array_equal(tilt_from_push_axis(spun, PUSH), [0.0, 0.0])
    tilted = (DOWN * Rotation.from_rotvec([0.0, 0.0, 1.2]) * Rotation.from_rotvec([0.2, 0, 0]))
    assert np.linalg.norm(tilt_from_push_axis(tilted.as_matrix(), PUSH)) == pytest.approx(0.2)


def test_thesis_and_tilt_states() -> None:
    wrench = [10.0, -40.0, -15.0, 1.5, 0.3, 0.0]
    rotation = (DOWN * Rotation.from_rotvec([0.1, -0.3, 0.0])).as_matrix()
    thesis = ResidualTask(TaskConfig(observation="thesis"))
    tilt = ResidualTask(TaskConfig(observation="tilt", tilt_range=0.5))
    assert thesis.state_dim == state_dim("thesis") == 4
    assert tilt.state_dim == state_dim("tilt") == 6
    np.testing.assert_allclose(thesis.state(_obs(wrench)), [0.5, -1.0, 0.5, 0.1])
    np.testing.assert_allclose(tilt.state(_obs(wrench, rotation)),
                               [0.5, -1.0, 0.5, 0.1, -0.2, 0.6], atol=1e-12)
    with pytest.raises(ValueError, match="tool orientation"):
        tilt.state(_obs(wrench))


@pytest.mark.parametrize("observation, expected", [
    ("tilt_force", [0.5, -1.0, -0.2, 0.6]),      # no torques: they echo the last action
    ("tilt_only", [-0.2, 0.6]),
])
def test_states_without_the_torque_echo(observation, expected) -> None:
    """The smaller tilt states take the same components, with the same scales, as ``tilt``."""
    wrench = [10.0, -40.0, -15.0, 1.5, 0.3, 0.0]
    rotation = (DOWN * Rotation.from_rotvec([0.1, -0.3, 0.0])).as_matrix()
    task = ResidualTask(TaskConfig(observation=observation, tilt_range=0.5))
    assert task.state_dim == state_dim(observation) == len(expected)
    np.testing.assert_allclose(task.state(_obs(wrench, rotation)), expected, atol=1e-12)
    with pytest.raises(ValueError, match="tool orientation"):
        task.state(_obs(wrench))


@pytest.mark.parametrize("bad", [{"observation": "pose"}, {"push_axis": (0.0, 0.0, 0.0)},
                                 {"push_axis": (0.0, 1.0)}, {"tilt_range": 0.0}])
def test_bad_observation_settings_are_refused(bad) -> None:
    with pytest.raises(ValueError):
        TaskConfig(**bad)


def test_push_axis_is_normalised() -> None:
    assert TaskConfig(push_axis=(0.0, 0.0, -2.0)).push_axis == (0.0, 0.0, -1.0)


def test_actor_reports_its_input_size() -> None:
    """The executor refuses an actor whose input does not match its observation."""
    layers = [(np.zeros((100, 6), np.float32), np.zeros(100, np.float32)),
              (np.zeros((2, 100), np.float32), np.zeros(2, np.float32))]
    assert ActorMLP(layers).input_dim == 6
