"""Stall recovery: the detector on recorded stalled test episodes, the recovery's counting and
seeding, and its parameters refused with a message (executor/stall_recovery.py).

Both fixtures are real. ``tests/fixtures/stalled_test_episodes_seed0.npz`` (the ``tilt_only``
state): the stall probe's
learning on seed 0 (``benchmarks/stall_recovery_probe.py 0 --cap 60 --fixture``), then each of
the 8 test poses with the deterministic actor on a fresh robot of seed 0, capped at 60 steps.
None inserted. Poses 1, 3, 5, 6 end at a fixed point, poses 0 and 2 in a two-step cycle, pose 7
is still settling into a fixed point through a damped cycle, and pose 4 cycles while drifting
about 0.01 a cycle (still moving). It also holds the actor (its tensors).

``tests/fixtures/stalled_tilt_motion_seed0.npz`` (the ``tilt_motion`` state, the default):
``benchmarks/stall_recovery_probe.py 0 --lr 1e-4 --iterations 10 --cap 60 --fixture ...``, a
learning rate at which the actor stays near the zero residual, which jams. The poses that did
not insert end jammed, the motion jittering around 0 and the actor's action with it, so the
repeat test misses them and the motion test finds them. Pose 5 inserts after 10 steps without
axial motion in which the actor turned the shaft upright (the tilt fell from 0.52 to 0.08).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from qg_common.params import ConfigError, load_ros_params
from qg_learning_node.executor.noise import NoiseConfig
from qg_learning_node.executor.parameters import load_stall_recovery
from qg_learning_node.executor.stall_recovery import (
    StallRecovery,
    StallRecoveryConfig,
    first_stall,
    stalled,
)

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
FIXTURE = FIXTURES / "stalled_test_episodes_seed0.npz"
MOTION_FIXTURE = FIXTURES / "stalled_tilt_motion_seed0.npz"
CONFIG = Path(__file__).resolve().parents[2] / "config" / "executor.yaml"
FIXED_POINTS, CYCLES = (1, 3, 5, 6), (0, 2)


def _episode(pose: int) -> tuple[np.ndarray, np.ndarray]:
    data = np.load(FIXTURE)
    return data[f"states_{pose}"].astype(np.float64), data[f"actions_{pose}"].astype(np.float64)


def test_the_recorded_stalls_are_detected_and_a_moving_episode_is_not() -> None:
    config = StallRecoveryConfig()
    found = {pose: first_stall(*_episode(pose), config) for pose in range(8)}
    # Every fixed point and two-step cycle is found, before the cap of 60 and not before the
    # window has filled; the drifting pose 4 is not (it still moves 0.01 a cycle).
    assert all(config.window - 1 <= found[p] < 40 for p in FIXED_POINTS + CYCLES), found
    assert found[4] is None
    # The fixed points' tail: a change of at most 1.7e-4 (state) and 3.8e-4 (action) per step.
    for pose in FIXED_POINTS:
        states, actions = _episode(pose)
        assert np.abs(np.diff(states[-10:], axis=0)).max() < 2e-4
        assert np.abs(np.diff(actions[-10:], axis=0)).max() < 4e-4
    # A cycle is no fixed point: with period 1 only, the cycles go unnoticed.
    one_step = dataclasses.replace(config, max_period=1)
    assert all(first_stall(*_episode(p), one_step) is None for p in CYCLES)
    assert all(first_stall(*_episode(p), one_step) == found[p] for p in FIXED_POINTS)
    # Tighter than the measured stalls' changes, nothing is a stall.
    strict = dataclasses.replace(config, state_tolerance=1e-5, action_tolerance=1e-5)
    assert all(first_stall(*_episode(p), strict) is None for p in range(8))


def test_a_jam_is_found_by_its_motion_where_the_state_measures_it() -> None:
    data = np.load(MOTION_FIXTURE)
    progress = tuple(int(i) for i in data["progress_dims"])
    assert str(data["observation"]) == "tilt_motion" and progress == (2,)
    config = StallRecoveryConfig()
    poses = [p for p in range(8) if f"states_{p}" in data]
    inserted = {p: len(data[f"states_{p}"]) < int(data["test_max_steps"]) for p in poses}
    stalled_poses = [p for p in poses if not inserted[p]]
    assert len(stalled_poses) >= 4, inserted
    for pose in poses:
        states = data[f"states_{pose}"].astype(np.float64)
        actions = data[f"actions_{pose}"].astype(np.float64)
        found = first_stall(states, actions, config, progress)
        if inserted[pose]:
            # Never a stall, though pose 5 did not move along the bore for 10 steps: its tilt
            # was being turned upright, which is progress.
            assert found is None, (pose, found)
            continue
        # Found within the cap, after a whole window...
        assert found is not None and config.window - 1 <= found < 50, (pose, found)
        # ... where the repeat test finds nothing: the motion and the action jitter more than
        # its tolerances allow (one step's motion up to 0.03, the action's change > 3e-3).
        assert first_stall(states, actions, config) is None
        tail = states[-config.window:]
        assert np.abs(np.diff(tail[:, 2])).max() > config.state_tolerance
        assert np.abs(tail[:, 2]).max() <= config.progress_tolerance
    still = data["states_5"][:11].astype(np.float64)
    assert np.abs(still[2:, 2]).max() <= config.progress_tolerance      # no axial motion...
    assert np.ptp(still[2:, :2], axis=0).max() > 0.3                   # ... but turning
    # A tolerance below the measured jitter finds none of them.
    tight = dataclasses.replace(config, progress_tolerance=1e-3)
    assert all(first_stall(data[f"states_{p}"], data[f"actions_{p}"], tight, progress) is None
               for p in stalled_poses)


def test_a_step_that_moves_is_progress() -> None:
    config = StallRecoveryConfig(window=5)
    jammed = np.column_stack([np.full(5, 0.2), np.full(5, -0.1),
                              [0.01, -0.02, 0.03, -0.01, 0.0]])
    jittering = np.tile([0.2, -0.4], (5, 1)) + np.arange(5)[:, None] * 0.01  # the action too
    assert stalled(jammed, jittering, config, progress=(2,))
    assert not stalled(jammed, jittering, config)          # the repeat test misses the jam
    sliding = jammed.copy()
    sliding[3, 2] = 0.06                   # one step of 0.12 mm within the window: progress
    assert not stalled(sliding, jittering, config, progress=(2,))
    upright = jammed.copy()
    upright[:, 0] -= np.arange(5) * 0.02   # the tilt turned by 0.08 over the window: progress
    assert not stalled(upright, jittering, config, progress=(2,))
    assert stalled(upright[4:].repeat(5, 0), jittering, config, progress=(2,))


def test_a_moving_state_or_action_is_no_stall() -> None:
    config = StallRecoveryConfig(window=5)
    still = np.tile([0.04, -0.05], (5, 1))
    action = np.tile([0.2, -0.4], (5, 1))
    assert stalled(still, action, config)
    assert not stalled(still[:4], action[:4], config)           # the window is not full
    creeping = still + np.arange(5)[:, None] * 2e-3               # 2e-3 a step: progress
    assert not stalled(creeping, action, config)
    turning = action + np.arange(5)[:, None] * [0.0, 4e-3]
    assert not stalled(still, turning, config)
    with pytest.raises(ValueError, match="5 states but 4 actions"):
        stalled(still, action[:4], config)


def test_recovery_perturbs_its_steps_counts_once_and_needs_a_new_window() -> None:
    config = StallRecoveryConfig(enabled=True, window=4, steps=3)
    state, action = np.array([0.04, -0.05]), np.array([0.2, -0.4])
    watch = StallRecovery(config, 2, seed=7, noise=NoiseConfig(sigma=0.3))
    sent = [watch.act(state, action) for _ in range(18)]
    perturbed = [not np.array_equal(a, action) for a in sent]
    # Steps 0-2 fill the window, 3 detects: 3, 4, 5 perturbed; 6-9 refill, 9 detects again and
    # the second recovery is twice as long (growth 2): 9-14; 15-17 refill.
    assert perturbed == [False] * 3 + [True] * 3 + [False] * 3 + [True] * 6 + [False] * 3
    assert watch.recoveries == 2 and watch.started_at == [3, 9]
    assert [watch.recovery_steps(k) for k in (1, 2, 3)] == [3, 6, 12]
    flat = StallRecovery(dataclasses.replace(config, growth=1.0), 2, seed=7)
    assert [flat.recovery_steps(k) for k in (1, 2, 3)] == [3, 3, 3]
    assert all(np.all(np.abs(a) <= 1.0) for a in sent)
    again = StallRecovery(config, 2, seed=7, noise=NoiseConfig(sigma=0.3))
    assert all(np.array_equal(a, b) for a, b in zip(sent, [again.act(state, action)
                                                           for _ in range(18)]))
    other = StallRecovery(config, 2, seed=8, noise=NoiseConfig(sigma=0.3))
    assert not np.array_equal(sent[3], [other.act(state, action) for _ in range(4)][3])
    capped = StallRecovery(dataclasses.replace(config, max_recoveries=1), 2, seed=7)
    [capped.act(state, action) for _ in range(30)]
    assert capped.recoveries == 1


def test_the_dither_moves_each_dimension_by_its_amplitude() -> None:
    config = StallRecoveryConfig(enabled=True, window=3, steps=4, perturbation="dither",
                                 dither=0.25)
    watch = StallRecovery(config, 2, seed=3)
    action = np.array([0.1, -0.2])
    sent = np.array([watch.act(np.zeros(2), action) for _ in range(6)])
    np.testing.assert_array_equal(sent[:2], [action, action])
    np.testing.assert_allclose(np.abs(sent[2:] - action), 0.25)
    assert watch.recoveries == 1


def test_the_shipped_setting_is_off_and_valid() -> None:
    config = load_stall_recovery(load_ros_params(CONFIG), "executor.yaml")
    assert config == StallRecoveryConfig()          # the file and the code agree
    assert config.enabled is False                  # the thesis protocol


@pytest.mark.parametrize("values, message", [
    ({"window": 2, "max_period": 2}, "must be longer than max_period"),
    ({"window": 0}, "window must be an integer >= 1"),
    ({"steps": 0}, "steps must be an integer >= 1"),
    ({"steps": 2.5}, "steps must be an integer"),
    ({"state_tolerance": -1e-3}, "state_tolerance must be finite and >= 0"),
    ({"action_tolerance": float("nan")}, "action_tolerance must be finite"),
    ({"progress_tolerance": -0.05}, "progress_tolerance must be finite and >= 0"),
    ({"growth": 0.5}, "growth must be a finite factor >= 1"),
    ({"perturbation": "shake"}, "perturbation must be one of"),
    ({"dither": 0.0}, r"dither must be in \(0, 2\]"),
    ({"max_recoveries": -1}, "max_recoveries must be an integer >= 0"),
    ({"enabled": "yes"}, "enabled must be true or false"),
])
def test_bad_values_are_refused_with_a_message(values: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        StallRecoveryConfig(**values)


def test_the_file_loader_refuses_unknown_keys_and_values_out_of_range() -> None:
    with pytest.raises(ConfigError, match=r"stall_recovery\.windw"):
        load_stall_recovery({"stall_recovery": {"windw": 10}}, "executor.yaml")
    with pytest.raises(ConfigError, match=r"'stall_recovery\.window' = 1 is out of range"):
        load_stall_recovery({"stall_recovery": {"window": 1}}, "executor.yaml")
    with pytest.raises(ValueError, match="unknown parameters"):
        StallRecoveryConfig.from_dict({"enable": True})
