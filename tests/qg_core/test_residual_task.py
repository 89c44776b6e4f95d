"""The residual task's states (the thesis's 4-D wrench state and the tilt state beside it), and
its reward, goal and bore check measured on the tool pose against the cell's fixture."""
from __future__ import annotations

import math

import numpy as np
import pytest
from qg_common.shaft_task import TOOL_DOWN, ShaftTaskGeometry
from qg_common.types import N_START_POSES
from qg_learning_node.executor.residual_task import (
    Observation,
    ResidualTask,
    TaskConfig,
    state_dim,
    tilt_from_push_axis,
)
from qg_learning_node.learner.actor_mlp import ActorMLP
from scipy.spatial.transform import Rotation

DOWN = Rotation.from_rotvec([np.pi, 0.0, 0.0])     # tool z pointing down: the inserted pose
PUSH = np.array([0.0, 0.0, -1.0])


CELL = ShaftTaskGeometry()


def _obs(wrench, rotation=TOOL_DOWN, position=(0.45, 0.0, 0.4)) -> Observation:
    return Observation(wrench=np.asarray(wrench, float), tool_position=np.asarray(position, float),
                       tool_rotation=np.asarray(rotation, float))


def _task(**config) -> ResidualTask:
    return ResidualTask(TaskConfig(**config), CELL)


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
    thesis = _task(observation="thesis")
    tilt = _task(observation="tilt", tilt_range=0.5)
    assert thesis.state_dim == state_dim("thesis") == 4
    assert tilt.state_dim == state_dim("tilt") == 6
    np.testing.assert_allclose(thesis.state(_obs(wrench)), [0.5, -1.0, 0.5, 0.1])
    np.testing.assert_allclose(tilt.state(_obs(wrench, rotation)),
                               [0.5, -1.0, 0.5, 0.1, -0.2, 0.6], atol=1e-12)


@pytest.mark.parametrize("observation, expected", [
    ("tilt_force", [0.5, -1.0, -0.2, 0.6]),      # no torques: they echo the last action
    ("tilt_only", [-0.2, 0.6]),
])
def test_states_without_the_torque_echo(observation, expected) -> None:
    """The smaller tilt states take the same components, with the same scales, as ``tilt``."""
    wrench = [10.0, -40.0, -15.0, 1.5, 0.3, 0.0]
    rotation = (DOWN * Rotation.from_rotvec([0.1, -0.3, 0.0])).as_matrix()
    task = _task(observation=observation, tilt_range=0.5)
    assert task.state_dim == state_dim(observation) == len(expected)
    np.testing.assert_allclose(task.state(_obs(wrench, rotation)), expected, atol=1e-12)


def test_the_depth_state_is_the_tips_measured_depth_below_the_bearing_face() -> None:
    """``tilt_depth``: the tilt as ``tilt_only`` reads it, then the depth the goal is measured
    by, scaled by ``depth_range``: 1 fully inserted, 0.5 halfway, about 0 at the face, negative
    above it (clipped at -1)."""
    task = _task(observation="tilt_depth", tilt_range=0.5, depth_range=0.016)
    assert task.state_dim == state_dim("tilt_depth") == 3
    target = CELL.target_tool_position()
    up = CELL.fixture().rotation[:, 2]
    rotation = (DOWN * Rotation.from_rotvec([0.1, -0.3, 0.0])).as_matrix()
    for raised, depth_state in ((0.0, CELL.full_depth / 0.016), (0.008, 0.5),
                                (CELL.full_depth, 0.0), (CELL.full_depth + 0.004, -0.25),
                                (0.2, -1.0)):
        state = task.state(_obs(np.zeros(6), position=target + raised * up))
        np.testing.assert_allclose(state[2], depth_state, atol=1e-12)
    state = task.state(_obs(np.zeros(6), rotation, target))
    np.testing.assert_allclose(state[:2], _task(observation="tilt_only").state(
        _obs(np.zeros(6), rotation, target)), atol=1e-12)


def test_the_motion_state_is_how_far_the_last_step_moved_the_tip_in() -> None:
    """``tilt_motion``: the tilt, then the change of the measured depth since the observation
    the step began from, scaled by ``motion_range``; 0 without one (an episode's start); a
    step that went up reads negative."""
    task = _task(observation="tilt_motion", motion_range=0.002)
    assert task.state_dim == state_dim("tilt_motion") == 3
    target = CELL.target_tool_position()
    up = CELL.fixture().rotation[:, 2]
    deeper, shallower = (_obs(np.zeros(6), position=target + raised * up)
                         for raised in (0.005, 0.006))
    assert task.state(deeper)[2] == 0.0
    np.testing.assert_allclose(task.state(deeper, shallower)[2], 0.5, atol=1e-9)
    np.testing.assert_allclose(task.state(shallower, deeper)[2], -0.5, atol=1e-9)
    assert task.state(deeper, deeper)[2] == 0.0


def test_an_episode_hands_the_task_the_observation_its_step_began_from() -> None:
    """The executor's episode gives ``tilt_motion`` each step's start: the start's state has no
    motion, a step 1 mm in reads +0.5, the next one that stays reads 0."""
    from qg_learning_node.executor.episode import Episode
    task = _task(observation="tilt_motion", motion_range=0.002)
    target = CELL.target_tool_position()
    up = CELL.fixture().rotation[:, 2]
    at = [_obs(np.zeros(6), position=target + raised * up) for raised in (0.006, 0.005, 0.005)]
    episode = Episode("e", "test", 0, "dense", task, None)
    assert episode.begin(at[0])[2] == 0.0
    first = episode.observe(np.zeros(2), at[1])
    np.testing.assert_allclose(first.next_state[2], 0.5, atol=1e-9)
    assert episode.observe(np.zeros(2), at[2]).next_state[2] == 0.0


@pytest.mark.parametrize("bad", [{"observation": "pose"}, {"tilt_range": 0.0},
                                 {"depth_range": -0.01}, {"motion_range": 0.0},
                                 {"sigma_position": 0.0}])
def test_bad_observation_settings_are_refused(bad) -> None:
    with pytest.raises(ValueError):
        TaskConfig(**bad)


def test_the_goal_reward_and_bore_check_are_measured_on_the_tool_pose() -> None:
    """At the inserted pose: the goal, reward 0 either way. 0.4 mm short of the full depth
    (within the 0.5 mm tolerance) still the goal, 0.6 mm short not. Off the axis by more than
    ``max_lateral_offset``: out of the bore. The dense reward falls with both errors."""
    task = _task()
    target = CELL.target_tool_position()
    assert task.succeeded(_obs(np.zeros(6), position=target))
    assert task.reward(_obs(np.zeros(6), position=target), "sparse") == 0.0
    assert task.reward(_obs(np.zeros(6), position=target), "dense") == pytest.approx(0.0)
    up = CELL.fixture().rotation[:, 2]
    assert task.succeeded(_obs(np.zeros(6), position=target + 0.0004 * up))
    short = _obs(np.zeros(6), position=target + 0.0006 * up)
    assert not task.succeeded(short) and task.reward(short, "sparse") == -1.0
    assert -0.03 < task.reward(short, "dense") < 0.0
    tilted = Rotation.from_rotvec([0.3, 0.0, 0.0]).as_matrix() @ TOOL_DOWN
    assert task.reward(_obs(np.zeros(6), tilted, target), "dense") < -0.15
    beside = target + np.array([0.016, 0.0, 0.0])
    assert task.left_bore(_obs(np.zeros(6), position=beside))
    assert not task.left_bore(_obs(np.zeros(6), position=target + [0.014, 0.0, 0.0]))


def test_a_turned_and_tilted_fixture_moves_the_goal_the_starts_and_the_tilt_reference() -> None:
    """A housing turned 90 deg and tilted 10 deg: its starts are 15 deg from its bore axis with
    the tip on it, reached along that axis; the inserted pose along it is the goal; the tilt
    state reads zero with the shaft on the tilted axis."""
    cell = ShaftTaskGeometry(housing_yaw=math.pi / 2, housing_tilt=math.radians(10.0))
    task = ResidualTask(TaskConfig(observation="tilt_only"), cell)
    axis = cell.bore_axis()
    for k in range(N_START_POSES):
        start = cell.start_pose(k)
        m = cell.measure(start.position, start.rotation)
        assert m.tilt == pytest.approx(math.radians(15.0), abs=1e-9)
        assert m.lateral_offset < 1e-12 and not m.inserted
        rim = -m.insertion_depth - cell.shaft_radius * math.sin(m.tilt)
        assert rim == pytest.approx(cell.start_clearance, abs=1e-12)
        np.testing.assert_allclose(start.approach, cell.approach_distance * axis, atol=1e-15)
        assert start.label == k
    inserted = Rotation.align_vectors([axis], [[0.0, 0.0, 1.0]])[0].as_matrix()
    goal = _obs(np.zeros(6), inserted, cell.target_tool_position())
    assert task.succeeded(goal)
    np.testing.assert_allclose(task.state(goal), [0.0, 0.0], atol=1e-12)


def test_the_truth_rides_along_and_never_decides() -> None:
    """A simulation's truth saying "inserted" does not make an episode's goal: the measured pose
    does."""
    from qg_common.types import GroundTruth
    truth = GroundTruth(wrench=np.zeros(6), insertion_depth=0.016, plunger_travel=0.004,
                        success=True, position_error=0.0, orientation_error=np.zeros(2),
                        lateral_offset=0.0, tilt=0.0)
    above = Observation(np.zeros(6), CELL.target_tool_position() + [0.0, 0.0, 0.01], TOOL_DOWN,
                        truth)
    assert not _task().succeeded(above)


def test_actor_reports_its_input_size() -> None:
    """The executor refuses an actor whose input does not match its observation."""
    layers = [(np.zeros((100, 6), np.float32), np.zeros(100, np.float32)),
              (np.zeros((2, 100), np.float32), np.zeros(2, np.float32))]
    assert ActorMLP(layers).input_dim == 6
