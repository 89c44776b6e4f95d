"""Replay memory: FIFO order, sampling, trajectory links, checkpoints."""

from __future__ import annotations

import numpy as np
import pytest
from qg_learning_node.learner.replay import ReplayMemory


def chain(memory: ReplayMemory, n: int, start: int = 0, zero_loops: bool = False) -> None:
    for t in range(start, start + n):
        s, s2 = np.array([t, 0.0]), np.array([t + 1, 0.0])
        memory.add(s, np.array([1.0]), -float(t), s2, t == start + n - 1)
        if zero_loops and t != start + n - 1:
            memory.add(s2, np.zeros(1), -float(t), s2, False, synthetic=True)


def test_fifo_overwrites_oldest_and_samples_stored_rows():
    memory = ReplayMemory(5, 2, 1)
    chain(memory, 8)
    assert len(memory) == 5
    assert sorted(memory.rewards) == [-7.0, -6.0, -5.0, -4.0, -3.0]
    batch = memory.sample(64, np.random.default_rng(0))
    assert batch.states.shape == (64, 2) and batch.actions.shape == (64, 1)
    assert set(batch.rewards) <= {-7.0, -6.0, -5.0, -4.0, -3.0}
    np.testing.assert_array_equal(batch.next_states[:, 0], batch.states[:, 0] + 1)
    assert np.all(np.isneginf(batch.lower_bounds))
    assert memory.reward_range() == (-7.0, -3.0)


def test_unbounded_memory_grows():
    memory = ReplayMemory(None, 2, 1)
    chain(memory, 3000)
    assert len(memory) == 3000
    assert memory.rewards[2999] == -2999.0


def test_trajectory_context_follows_real_steps_and_skips_zero_loops():
    memory = ReplayMemory(None, 2, 1)
    chain(memory, 4, zero_loops=True)  # slots: t0, z, t1, z, t2, z, t3(terminal)
    context = memory.trajectory_context(np.array([2]), horizon=3)  # sample t1
    np.testing.assert_array_equal(context.future_rewards[0], [-2.0, -3.0, 0.0])
    np.testing.assert_array_equal(context.future_valid[0], [True, True, False])
    np.testing.assert_array_equal(context.future_terminals[0], [False, True, False])
    np.testing.assert_array_equal(context.past_valid[0], [True, False, False])
    assert context.past_states[0, 0, 0] == 0.0
    loop = memory.trajectory_context(np.array([1]), horizon=2)  # a zero loop has no neighbours
    assert not loop.future_valid.any() and not loop.past_valid.any()


def test_interleaved_robots_each_continue_their_own_trajectory():
    """Two robots' steps arrive interleaved; each links to its own previous step only."""
    memory = ReplayMemory(None, 2, 1)
    for t in range(3):          # slots: a0, b0, a1, b1, a2, b2
        for robot, offset in (("a", 0.0), ("b", 100.0)):
            memory.add(np.array([t + offset, 0.0]), np.array([1.0]), -(t + offset),
                       np.array([t + 1 + offset, 0.0]), False, stream=robot)
    context = memory.trajectory_context(np.array([0, 1]), horizon=2)   # a0, b0
    np.testing.assert_array_equal(context.future_rewards, [[-1.0, -2.0], [-101.0, -102.0]])
    assert context.future_valid.all()
    restored = ReplayMemory(None, 2, 1)         # the chain ends survive a checkpoint
    restored.load_state_dict(memory.state_dict())
    restored.add(np.array([103.0, 0.0]), np.array([1.0]), -103.0, np.array([104.0, 0.0]), True,
                 stream="b")
    assert restored.prev[6] == 5                # b3 continues b2


def test_links_break_when_neighbour_is_overwritten():
    memory = ReplayMemory(3, 2, 1)
    chain(memory, 5)  # keeps t2, t3, t4
    oldest = int(np.flatnonzero(memory.rewards == -2.0)[0])
    context = memory.trajectory_context(np.array([oldest]), horizon=2)
    assert not context.past_valid.any()
    np.testing.assert_array_equal(context.future_valid[0], [True, True])


def test_state_dict_round_trip():
    memory = ReplayMemory(4, 2, 1)
    chain(memory, 6)
    clone = ReplayMemory(4, 2, 1)
    clone.load_state_dict(memory.state_dict())
    a = memory.sample(10, np.random.default_rng(3))
    b = clone.sample(10, np.random.default_rng(3))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    with pytest.raises(ValueError):
        ReplayMemory(5, 2, 1).load_state_dict(memory.state_dict())
