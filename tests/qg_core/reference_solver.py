"""Independent exact solver for a data graph: policy iteration with sparse linear solves.

Kept apart from the incremental Q-Graph on purpose: the tests and the benchmark compare the two.
It solves the loose-end-free subgraph as a deterministic finite MDP from scratch.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def exact_edge_values(src: np.ndarray, dst: np.ndarray, reward: np.ndarray,
                      terminal: np.ndarray, gamma: float, num_nodes: int) -> np.ndarray:
    """Exact Q-value of every edge (``-inf`` for edges into nodes without terminal or loop ahead).

    Edges are arrays indexed by edge; node ids run from 0 to ``num_nodes - 1``.
    """
    src, dst = np.asarray(src, dtype=np.int64), np.asarray(dst, dtype=np.int64)
    reward, terminal = np.asarray(reward, dtype=np.float64), np.asarray(terminal, dtype=bool)
    live = _live_nodes(src, dst, terminal, num_nodes)
    usable = terminal | live[dst]
    edges = np.flatnonzero(usable & live[src])
    # initial policy: the first usable edge of every live node
    policy = np.full(num_nodes, -1, dtype=np.int64)
    policy[src[edges[::-1]]] = edges[::-1]
    nodes = np.flatnonzero(live)
    value = np.full(num_nodes, -np.inf)
    for _ in range(10 * max(1, len(nodes)) + 10):
        value[nodes] = _evaluate(policy, nodes, src, dst, reward, terminal, gamma)
        q = _edge_q(edges, dst, reward, terminal, gamma, value)
        best = np.full(num_nodes, -np.inf)
        np.maximum.at(best, src[edges], q)
        improve = best[nodes] > value[nodes] + 1e-12 * (1.0 + np.abs(value[nodes]))
        if not improve.any():
            break
        order = np.argsort(q, kind='stable')  # later assignments win: the best edge per node
        greedy = np.full(num_nodes, -1, dtype=np.int64)
        greedy[src[edges[order]]] = edges[order]
        better = nodes[improve]
        policy[better] = greedy[better]
    else:
        raise RuntimeError('policy iteration did not converge')
    out = np.full(len(src), -np.inf)
    out[usable] = _edge_q(np.flatnonzero(usable), dst, reward, terminal, gamma, value)
    return out


def _edge_q(edges, dst, reward, terminal, gamma, value):
    return np.where(terminal[edges], reward[edges],
                    reward[edges] + gamma * np.where(terminal[edges], 0.0, value[dst[edges]]))


def _evaluate(policy, nodes, src, dst, reward, terminal, gamma):
    """Solve V = r_pi + gamma * P_pi V on the live nodes."""
    index = np.full(len(policy), -1, dtype=np.int64)
    index[nodes] = np.arange(len(nodes))
    e = policy[nodes]
    rows = np.arange(len(nodes))
    cont = ~terminal[e]
    matrix = sp.identity(len(nodes), format='csr') - sp.csr_matrix(
        (np.full(cont.sum(), gamma), (rows[cont], index[dst[e[cont]]])),
        shape=(len(nodes), len(nodes)))
    return spla.spsolve(matrix.tocsc(), reward[e])


def _live_nodes(src, dst, terminal, num_nodes):
    """Nodes from which a terminal edge or an infinite path exists."""
    live = np.ones(num_nodes, dtype=bool)
    has_edge = np.zeros(num_nodes, dtype=bool)
    has_edge[src] = True
    live &= has_edge
    while True:
        ok = terminal | live[dst]
        count = np.bincount(src[ok], minlength=num_nodes) if ok.any() else np.zeros(num_nodes)
        new_live = live & (count > 0)
        if (new_live == live).all():
            return live
        live = new_live
