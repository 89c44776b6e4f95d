"""Q-Graph benchmark: incremental insertion speed, memory, bound look-up, and an exact re-solve.

Data: 100 episodes of up to 1000 steps of a random walk on a 120 x 120 lattice of 4-D float states
(continuous actions, the next state rounded to the lattice), so states are revisited, loops form
and (s, a) pairs are almost all distinct, as with continuous residual actions. A small goal region
is terminal; the reward depends only on the reached state. Zero-action self-loops are on.
The exact solution (policy iteration with scipy sparse solves, tests/qg_core/reference_solver.py)
is computed on the same data in the same run and every bound is compared with it.
Last line: one JSON object.
"""

from __future__ import annotations

import json
import pathlib
import sys
import time
import tracemalloc

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'tests' / 'qg_core'))
sys.path.insert(0, str(ROOT / 'qg_learning_node'))
from qg_learning_node.learner.qgraph import QGraph  # noqa: E402
from reference_solver import exact_edge_values  # noqa: E402

GAMMA = 0.99
GRID = 120
EPISODES = 100
STEPS = 1000
ZERO = np.zeros(2)
GOAL = np.array([GRID // 2, GRID // 2 + 12])


def embed(cell: np.ndarray) -> np.ndarray:
    """Lattice cell -> 4-D float state (as scaled wrench features would be)."""
    x, y = (cell / (GRID - 1)) * 2.0 - 1.0
    return np.array([x, y, 0.5 * x * y, x - y])


def make_episodes(rng: np.random.Generator) -> list[tuple]:
    transitions = []
    starts = [np.array([GRID // 2 + 3 * k - 12, GRID // 2]) for k in range(8)]
    for episode in range(EPISODES):
        cell = starts[episode % 8].copy()
        for _ in range(STEPS):
            a = rng.uniform(-1.5, 1.5, size=2)
            if rng.random() < 0.05:
                a = ZERO.copy()  # executed zero action: a real self-loop
            nxt = np.clip(np.rint(cell + a), 0, GRID - 1).astype(int)
            done = bool(np.abs(nxt - GOAL).sum() <= 3)
            reward = 0.0 if done else -1.0 + 0.5 * np.exp(-np.abs(nxt - GOAL).sum() / 10.0)
            transitions.append((embed(cell), a, reward, embed(nxt), done))
            cell = nxt
            if done:
                break
    return transitions


def build(transitions: list[tuple]) -> QGraph:
    graph = QGraph(GAMMA, zero_action=ZERO)
    for s, a, r, s2, done in transitions:
        graph.add(s, a, r, s2, done)
    return graph


def exact_solution(transitions: list[tuple]) -> tuple[list[tuple], np.ndarray]:
    """Distinct (s, a) edges with zero-action loops spelled out, and their exact Q-values."""
    edges: dict[bytes, tuple] = {}
    node_id: dict[bytes, int] = {}
    zb = ZERO.tobytes()
    for s, a, r, s2, done in transitions:
        sb, nb = s.tobytes(), s2.tobytes()
        edges.setdefault(sb + a.tobytes(), (sb, s, a, r, nb, done))
        if not done and sb != nb:
            edges.setdefault(nb + zb, (nb, s2, ZERO, r, nb, False))
    rows = list(edges.values())
    for sb, _, _, _, nb, _ in rows:
        node_id.setdefault(sb, len(node_id))
        node_id.setdefault(nb, len(node_id))
    q = exact_edge_values([node_id[e[0]] for e in rows], [node_id[e[4]] for e in rows],
                          [e[3] for e in rows], [e[5] for e in rows], GAMMA, len(node_id))
    return rows, q


def main() -> None:
    rng = np.random.default_rng(0)
    transitions = make_episodes(rng)
    n = len(transitions)
    print(f'data: {n} real transitions from {EPISODES} episodes, '
          f'{sum(t[4] for t in transitions)} reached the goal')

    t0 = time.perf_counter()
    graph = build(transitions)
    t_insert = time.perf_counter() - t0
    rate = n / t_insert
    census = graph.census()
    print(f'insert with propagation: {t_insert:.2f} s, {rate:,.0f} transitions/s '
          f'({len(graph)} distinct edges incl. {census["zero_action_loops"]} zero-action loops)')
    print('census:', {k: v for k, v in census.items() if k != 'path_length_histogram'})

    tracemalloc.start()
    graph_m = build(transitions)
    mem, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    bytes_per_edge = mem / len(graph_m)
    print(f'memory: {mem / 1e6:.1f} MB, {bytes_per_edge:.0f} bytes per stored transition')
    del graph_m

    t0 = time.perf_counter()
    rows, q_exact = exact_solution(transitions)
    t_exact = time.perf_counter() - t0
    states = np.stack([e[1] for e in rows])
    actions = np.stack([e[2] for e in rows])
    q_graph = graph.lower_bounds(states, actions)
    finite = np.isfinite(q_exact)
    same_inf = np.array_equal(np.isfinite(q_graph), finite)
    error = np.abs(q_graph[finite] - q_exact[finite]) / (1 + np.abs(q_exact[finite]))
    max_err = float(error.max())
    agree = bool(same_inf and max_err < 1e-9)
    print(f'exact sparse solve (policy iteration, scipy): {t_exact:.2f} s; '
          f'bounds agree: {agree} (max rel. error {max_err:.1e}, {finite.sum()} finite)')

    idx = rng.integers(0, len(rows), size=64)
    s64, a64 = states[idx], actions[idx]
    reps = 2000
    t0 = time.perf_counter()
    for _ in range(reps):
        graph.lower_bounds(s64, a64)
    t_lookup = (time.perf_counter() - t0) / reps
    print(f'minibatch bound look-up (64): {t_lookup * 1e6:.0f} us')

    print(json.dumps({
        'transitions': n, 'distinct_edges': len(graph), 'insert_seconds': round(t_insert, 3),
        'transitions_per_second': round(rate), 'goal_transitions_per_second': 50000,
        'bytes_per_transition': round(bytes_per_edge), 'exact_solve_seconds': round(t_exact, 3),
        'bounds_agree': agree, 'max_rel_error': max_err,
        'lookup_64_microseconds': round(t_lookup * 1e6, 1),
    }))


if __name__ == '__main__':
    main()
