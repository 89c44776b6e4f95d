"""Q-Graph bounds against an independent exact solver (policy iteration, sparse solves)."""

from __future__ import annotations

import math
import pathlib
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from qg_learning_node.learner.qgraph import QGraph  # noqa: E402
from reference_solver import exact_edge_values  # noqa: E402

ZERO = np.array([0.0, 0.0])


def state(node: int) -> np.ndarray:
    return np.array([0.25 * node, -1.0 - node])


def action(act: int) -> np.ndarray:
    return np.array([1.0 + act, 0.5])


def reference(transitions, gamma, zero_action: bool) -> dict[tuple, float]:
    """Exact Q of every distinct (s, a), zero-action self-loops spelled out independently."""
    edges: dict[tuple, tuple] = {}
    for s, a, r, s2, term in transitions:
        edges.setdefault((s, a), (r, s2, term))
        if zero_action and not term and s != s2:
            edges.setdefault((s2, 'zero'), (r, s2, False))
    nodes = sorted({k[0] for k in edges} | {v[1] for v in edges.values()})
    ids = {n: i for i, n in enumerate(nodes)}
    keys = list(edges)
    q = exact_edge_values([ids[k[0]] for k in keys], [ids[edges[k][1]] for k in keys],
                          [edges[k][0] for k in keys], [edges[k][2] for k in keys],
                          gamma, len(nodes))
    return dict(zip(keys, q))


def tolerance(q: float) -> float:
    return 1e-9 * (1.0 + abs(q)) if math.isfinite(q) else 0.0


def graph_value(graph: QGraph, key: tuple) -> float:
    s, a = key
    return graph.lower_bound(state(s), ZERO if a == 'zero' else action(a))


def assert_matches(graph: QGraph, expected: dict[tuple, float]) -> None:
    assert len(graph) == len(expected)
    for key, q in expected.items():
        got = graph_value(graph, key)
        if math.isinf(q):
            assert got == q, key
        else:
            assert got == pytest.approx(q, rel=1e-9, abs=1e-9), key


@st.composite
def random_graphs(draw):
    """Random transition sequences: loops, self-loops, revisits, several terminals.

    (s, a) always leads to the same s' (deterministic MDP); terminal nodes have no successors;
    the reward depends on the reached state only (as in our task, needed for zero actions).
    """
    n = draw(st.integers(2, 9))
    terminals = set(draw(st.lists(st.integers(0, n - 1), max_size=3)))
    sources = [i for i in range(n) if i not in terminals] or [0]
    terminals.discard(sources[0])
    rewards = draw(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=n, max_size=n))
    outcome: dict[tuple, int] = {}
    transitions = []
    for _ in range(draw(st.integers(1, 30))):
        s = draw(st.sampled_from(sources))
        a = draw(st.integers(0, 2))
        s2 = outcome.setdefault((s, a), draw(st.integers(0, n - 1)))
        transitions.append((s, a, rewards[s2], s2, s2 in terminals))
    return transitions


def fill(transitions, gamma, zero_action, capacity=None, check_each=False):
    graph = QGraph(gamma, capacity=capacity, zero_action=ZERO if zero_action else None)
    for i, (s, a, r, s2, term) in enumerate(transitions):
        graph.add(state(s), action(a), r, state(s2), term)
        if check_each:
            assert_matches(graph, reference(transitions[:i + 1], gamma, zero_action))
    return graph


@settings(max_examples=150, deadline=None)
@given(random_graphs(), st.sampled_from([0.5, 0.9, 0.99]), st.booleans())
@pytest.mark.slow
def test_bounds_equal_exact_solution_after_every_insertion(transitions, gamma, zero_action):
    fill(transitions, gamma, zero_action, check_each=True)


@settings(max_examples=100, deadline=None)
@given(random_graphs(), st.sampled_from([0.5, 0.9, 0.99]), st.booleans(), st.integers(1, 8))
def test_fifo_bounds_stay_below_full_graph_solution(transitions, gamma, zero_action, capacity):
    graph = fill(transitions, gamma, zero_action, capacity=capacity)
    full = reference(transitions, gamma, zero_action)
    kept = reference(transitions[-capacity:], gamma, zero_action)
    assert graph.num_real == min(capacity, len(transitions))
    for key, q_full in full.items():
        assert graph_value(graph, key) <= q_full + tolerance(q_full), key
    for key, q_kept in kept.items():  # and never weaker than re-solving the kept data
        assert graph_value(graph, key) >= q_kept - tolerance(q_kept), key


def test_long_chain_with_loop_back_is_exact_and_fast():
    """A 2000-step chain whose end loops back to its start, then a terminal exit."""
    gamma, n = 0.99, 2000
    chain = [(i, 0, -1.0, i + 1, False) for i in range(n)]
    loop_back = [(n, 0, -0.5, 0, False)]
    exit_ = [(n // 2, 1, 0.0, n + 1, True)]
    transitions = chain + loop_back + exit_
    graph = fill(transitions, gamma, zero_action=False)
    assert_matches(graph, reference(transitions, gamma, False))


def test_pure_loop_without_terminal_gets_closed_form_value():
    gamma = 0.9
    transitions = [(0, 0, -1.0, 1, False), (1, 0, -2.0, 2, False), (2, 0, -3.0, 0, False)]
    graph = fill(transitions, gamma, zero_action=False)
    loop = (-1.0 - 2.0 * gamma - 3.0 * gamma ** 2) / (1 - gamma ** 3)
    assert graph.lower_bound(state(0), action(0)) == pytest.approx(loop, rel=1e-12)


def test_zero_action_turns_loose_end_into_self_loop_bound():
    graph = QGraph(0.9, zero_action=ZERO)
    graph.add(state(0), action(0), -0.5, state(1), False)
    assert graph.lower_bound(state(1), ZERO) == pytest.approx(-5.0)
    assert graph.lower_bound(state(0), action(0)) == pytest.approx(-0.5 - 0.9 * 5.0)
    assert len(graph) == 2
    bounds = graph.lower_bounds(np.stack([state(0), state(1), state(5)]),
                                np.stack([action(0), ZERO, ZERO]))
    np.testing.assert_allclose(bounds, [-5.0, -5.0, -np.inf])


def test_census_kinds_and_path_lengths():
    graph = QGraph(0.9)
    for s, a, r, s2, term in [(1, 0, 0.0, 0, True), (2, 0, -1.0, 1, False), (3, 0, -1, 2, False),
                              (4, 0, -1.0, 4, False), (5, 0, -1.0, 6, False)]:
        graph.add(state(s), action(a), r, state(s2), term)
    census = graph.census()
    assert census['directly_connected'] == 1
    assert census['connected'] == 2
    assert census['disconnected'] == 1
    assert census['loose_end'] == 1
    assert census['path_length_histogram'] == {1: 1, 2: 1}
    assert graph.transition_kind(state(3), action(0)) == ('connected', 2)


def test_state_dict_round_trip_keeps_bounds_and_growth():
    transitions = [(0, 0, -1.0, 1, False), (1, 0, -1.0, 2, False), (2, 0, 0.0, 3, True)]
    graph = fill(transitions[:2], 0.9, zero_action=True, capacity=5)
    clone = QGraph.from_state_dict(graph.state_dict())
    for g in (graph, clone):
        g.add(state(2), action(0), 0.0, state(3), True)
    assert clone.census() == graph.census()
    assert clone.num_real == graph.num_real == 3 and len(clone) == 5
    assert clone.lower_bound(state(0), action(0)) == graph.lower_bound(state(0), action(0))
    assert clone.lower_bound(state(0), action(0)) == pytest.approx(-1.0 - 0.9)
    clone.add(state(5), action(0), -1.0, state(0), False)  # the original must not see this
    assert len(clone) == 7 and len(graph) == 5


def test_invalid_arguments_raise():
    with pytest.raises(ValueError):
        QGraph(1.0)
    with pytest.raises(ValueError):
        QGraph(0.9, capacity=0)


def test_state_merging_joins_episodes_that_pass_through_the_same_cell() -> None:
    """Episode A reaches the goal through s1; episode B ends (a loose end) 4e-4 away from s1.
    The exact graph knows nothing of B's transition; with a 0.01 grid B reaches s1's cell and
    inherits its path to the goal."""
    gamma = 0.9
    s0, s1, goal = np.array([0.0, 0.0]), np.array([0.5, 0.5]), np.array([1.0, 1.0])
    b_start, b_end = np.array([0.2, -0.2]), np.array([0.5004, 0.4996])
    a, b = np.array([1.0]), np.array([0.3])
    for resolution, expected in ((0.0, -math.inf), (0.01, -1.0 + gamma * 0.0)):
        graph = QGraph(gamma, resolution=resolution)
        graph.add(s0, a, -1.0, s1, False)
        graph.add(s1, a, 0.0, goal, True)
        graph.add(b_start, b, -1.0, b_end, False)
        assert graph.lower_bound(b_start, b) == expected
        np.testing.assert_array_equal(graph.lower_bounds(np.array([b_start]), np.array([b])),
                                      [expected])
    # -0.0 and 0.0 are one cell, and a bad resolution is refused
    graph = QGraph(gamma, resolution=0.1)
    graph.add(np.array([-0.01, 0.0]), a, 0.0, goal, True)
    assert graph.lower_bound(np.array([0.01, 0.0]), a) == 0.0
    with pytest.raises(ValueError, match="resolution"):
        QGraph(gamma, resolution=-1.0)
