"""Q-Graph: exact Q-values of the replay data as lower bounds for QG-DDPG (SPEC §3-4).

Every stored transition ``(s, a, r, s')`` is an edge between exactly identified states (the bytes of
the float64 values, no discretisation). Dropping loose ends leaves a finite deterministic MDP whose
exact Q-values are valid lower bounds of the optimal Q-function of the real task, whatever the
network believes. QG-DDPG clips its TD targets from below with them.

Why the bounds are kept incrementally rather than re-solved: the learner adds one transition per
RL step and samples bounds every training iteration, so a full solve per cycle would cost
O(transitions) every 20 steps. Instead each node keeps its best known value ``V`` and the edge that
achieves it (a policy pointer); an edge's bound is ``r`` (terminal) or ``r + gamma * V[s']``.

How exactness is reached with loops, without a fixed-point iteration that converges only
geometrically (``gamma**m`` per traversal of an m-loop):

* values only ever increase (adding data can only add options), and every value is the return of
  some path in the data, so it is always a valid lower bound;
* a new edge propagates improvements backwards along predecessor edges with a worklist
  (Bellman-Ford style, thesis Algorithm 3);
* a self-loop ``s -> s`` is evaluated in closed form, ``r / (1 - gamma)``;
* a node improved twice in one propagation wave may have closed a loop of policy pointers; the
  loop is then evaluated in closed form, ``r_L / (1 - gamma**m)`` (SPEC §3), which is policy
  iteration's exact evaluation step;
* a new edge into a node without a value cannot improve anything by propagation (its target has
  no value), but it may close a loop in a region of dead ends; a depth-first search from its target
  finds such a loop, which is then evaluated in closed form.

At the end of every ``add`` no edge can raise its source's value by more than a relative 1e-12,
every node that reaches a terminal or a loop has a finite value, and every value is achievable, so
the values are the exact solution of the loose-end-free subgraph.

With a capacity, the oldest real transition is removed first (FIFO). Values already propagated stay:
they were achievable in the data seen so far, so they remain valid lower bounds.

Zero action (SPEC §4): after a non-terminal transition with ``s != s'`` the self-loop
``(s', a_zero, r, s')`` is added without executing it; rewards here depend only on the reached
state, so its reward is the ``r`` of the step that reached ``s'``. It lives as long as the real
transitions that reached ``s'`` (a reference count), so capacity counts real transitions only.

Determinism assumption: an edge is identified by ``(s, a)``. A repeated ``(s, a)`` only raises the
multiplicity of the stored edge; its first ``(r, s')`` is kept.

State merging (``resolution > 0``, beyond the thesis): continuous states of a real task never
repeat bit for bit, so the exact graph is a set of chains joined only by the zero-action loops,
and its bounds are mostly ``r / (1 - gamma)`` of those loops. Rounding every state to a grid of
``resolution`` (in scaled state units) before identifying it joins the chains of different
episodes that pass through the same cell, so a path to the goal found once bounds every
transition that reaches that cell. The price: the graph's MDP is then an aggregation of the real
one, and its values are lower bounds only up to the value spread inside a cell.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

__all__ = ['QGraph', 'TRANSITION_KINDS']

NEG_INF = float('-inf')
_REL_TOL = 1e-12
TRANSITION_KINDS = ('directly_connected', 'connected', 'disconnected', 'loose_end')


def _as_bytes(x: np.ndarray) -> bytes:
    return np.ascontiguousarray(x, dtype=np.float64).tobytes()


def _copy(value):
    """Copy of a graph attribute down to its immutable items (lists of lists for adjacency)."""
    if isinstance(value, (list, deque)):
        return [list(x) if isinstance(x, list) else x for x in value]
    if isinstance(value, dict):
        return dict(value)
    if isinstance(value, np.ndarray):
        return value.copy()
    return value


class QGraph:
    """Incremental data graph with exact Q-values of its loose-end-free subgraph.

    :param gamma: discount factor in [0, 1).
    :param capacity: maximum number of real (executed) transitions; ``None`` = unbounded.
    :param zero_action: action that leaves the state unchanged; enables the self-loops.
    :param resolution: grid cell size for identifying states (0: exact, the thesis's graph).
    """

    def __init__(self, gamma: float, capacity: int | None = None,
                 zero_action: np.ndarray | None = None, resolution: float = 0.0) -> None:
        if not 0.0 <= gamma < 1.0:
            raise ValueError(f'gamma must lie in [0, 1), got {gamma}')
        if capacity is not None and capacity < 1:
            raise ValueError(f'capacity must be >= 1 or None, got {capacity}')
        if not resolution >= 0.0:
            raise ValueError(f'resolution must be >= 0, got {resolution}')
        self.gamma = float(gamma)
        self.capacity = capacity
        self.resolution = float(resolution)
        self.zero_action = (None if zero_action is None
                            else np.asarray(zero_action, dtype=np.float64).ravel().copy())
        self._zero_bytes = None if self.zero_action is None else _as_bytes(self.zero_action)
        # nodes (ids are list indices, reused after removal)
        self._node_of: dict[bytes, int] = {}
        self._node_key: list[bytes | None] = []
        self._value: list[float] = []
        self._choice: list[int] = []  # edge achieving value, -1 if none
        self._out: list[list[int]] = []
        self._in: list[list[tuple[int, float, int]]] = []  # (source, reward, edge) of the
        # non-terminal edges ending here: the propagation loop reads them without edge look-ups
        self._degree: list[int] = []  # edge ends touching the node
        self._stamp: list[int] = []  # propagation wave that last improved the node
        self._free_nodes: list[int] = []
        # edges
        self._edge_of: dict[bytes, int] = {}  # s_bytes + a_bytes -> edge id
        self._e_key: list[bytes | None] = []
        self._e_src: list[int] = []
        self._e_dst: list[int] = []
        self._e_r: list[float] = []
        self._e_term: list[bool] = []
        self._e_count: list[int] = []
        self._e_zero: list[bool] = []
        self._free_edges: list[int] = []
        self._fifo: deque[tuple[int, int]] = deque()  # (real edge, its zero loop or -1)
        self._wave = 0
        self._num_real = 0

    # ------------------------------------------------------------------ public API
    def add(self, s: np.ndarray, a: np.ndarray, r: float, s_next: np.ndarray,
            terminal: bool) -> None:
        """Store a transition, add its zero-action self-loop and update all bounds."""
        sb, nb = self._state_key(s), self._state_key(s_next)
        r = float(r)
        terminal = bool(terminal)
        edge = self._insert(sb, _as_bytes(a), r, nb, terminal, zero=False)
        loop = -1
        if self._zero_bytes is not None and not terminal and sb != nb:
            loop = self._insert(nb, self._zero_bytes, r, nb, False, zero=True)
        self._num_real += 1
        if self.capacity is not None:
            self._fifo.append((edge, loop))
            while self._num_real > self.capacity:
                self._num_real -= 1
                old, old_loop = self._fifo.popleft()
                self._release(old)
                if old_loop >= 0:
                    self._release(old_loop)

    def lower_bound(self, s: np.ndarray, a: np.ndarray) -> float:
        """Graph Q-value of ``(s, a)``; ``-inf`` if unknown or a loose end."""
        edge = self._edge_of.get(self._state_key(s) + _as_bytes(a))
        return NEG_INF if edge is None else self._edge_bound(edge)

    def lower_bounds(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Row-wise :meth:`lower_bound` of a batch (one dict lookup per row)."""
        states = np.ascontiguousarray(self._snap(states), dtype=np.float64)
        actions = np.ascontiguousarray(actions, dtype=np.float64)
        get, bound = self._edge_of.get, self._edge_bound
        out = np.full(len(states), NEG_INF)
        for i, (s, a) in enumerate(zip(states, actions)):
            edge = get(s.tobytes() + a.tobytes())
            if edge is not None:
                out[i] = bound(edge)
        return out

    def __len__(self) -> int:
        """Number of distinct stored transitions, zero-action self-loops included."""
        return len(self._edge_of)

    @property
    def num_real(self) -> int:
        """Real (executed) transitions stored, counted with repetition."""
        return self._num_real

    def transition_kind(self, s: np.ndarray, a: np.ndarray) -> tuple[str, int | None]:
        """Kind of the stored transition ``(s, a)`` (SPEC §3) and, unless it is disconnected or a
        loose end, the number of transitions from its ``s'`` to the nearest terminal."""
        edge = self._edge_of.get(self._state_key(s) + _as_bytes(a))
        if edge is None:
            raise KeyError('transition not stored')
        edges, kind, hops = self._classify()
        i = int(np.flatnonzero(edges == edge)[0])
        return TRANSITION_KINDS[kind[i]], (int(hops[i]) if kind[i] < 2 else None)

    def census(self) -> dict:
        """Counts of stored transitions per kind and the histogram of shortest path lengths
        (transitions from ``s'`` to a terminal) of the connected ones."""
        edges, kind, hops = self._classify()
        counts: dict = {name: int(np.sum(kind == i)) for i, name in enumerate(TRANSITION_KINDS)}
        lengths, freq = np.unique(hops[kind == 1], return_counts=True)
        counts['total'] = len(edges)
        counts['zero_action_loops'] = int(np.asarray(self._e_zero, dtype=bool)[edges].sum())
        counts['path_length_histogram'] = {int(k): int(c) for k, c in zip(lengths, freq)}
        return counts

    def state_dict(self) -> dict:
        """Picklable snapshot of the whole graph (for learner checkpoints); shares no containers
        with the live graph."""
        return {k: _copy(v) for k, v in vars(self).items()}

    @classmethod
    def from_state_dict(cls, state: dict) -> QGraph:
        graph = cls.__new__(cls)
        graph.resolution = 0.0            # checkpoints from before state merging
        graph.__dict__.update(state)
        graph._fifo = deque(state['_fifo'])
        return graph

    # ------------------------------------------------------------------ storage
    def _snap(self, states: np.ndarray) -> np.ndarray:
        """States rounded to the merging grid (``+ 0.0`` turns -0.0 into 0.0: same bytes)."""
        states = np.asarray(states, dtype=np.float64)
        if self.resolution == 0.0:
            return states
        return np.round(states / self.resolution) * self.resolution + 0.0

    def _state_key(self, s: np.ndarray) -> bytes:
        return _as_bytes(self._snap(s))

    def _node(self, key: bytes) -> int:
        node = self._node_of.get(key)
        if node is not None:
            return node
        if self._free_nodes:
            node = self._free_nodes.pop()
            self._node_key[node] = key
            self._value[node] = NEG_INF
            self._choice[node] = -1
            self._out[node] = []
            self._in[node] = []
            self._degree[node] = 0
            self._stamp[node] = 0
        else:
            node = len(self._node_key)
            self._node_key.append(key)
            self._value.append(NEG_INF)
            self._choice.append(-1)
            self._out.append([])
            self._in.append([])
            self._degree.append(0)
            self._stamp.append(0)
        self._node_of[key] = node
        return node

    def _insert(self, sb: bytes, ab: bytes, r: float, nb: bytes, terminal: bool,
                zero: bool) -> int:
        key = sb + ab
        edge = self._edge_of.get(key)
        if edge is not None:
            self._e_count[edge] += 1
            return edge
        u, v = self._node(sb), self._node(nb)
        if self._free_edges:
            edge = self._free_edges.pop()
            self._e_key[edge], self._e_src[edge], self._e_dst[edge] = key, u, v
            self._e_r[edge], self._e_term[edge] = r, terminal
            self._e_count[edge], self._e_zero[edge] = 1, zero
        else:
            edge = len(self._e_key)
            self._e_key.append(key)
            self._e_src.append(u)
            self._e_dst.append(v)
            self._e_r.append(r)
            self._e_term.append(terminal)
            self._e_count.append(1)
            self._e_zero.append(zero)
        self._edge_of[key] = edge
        self._out[u].append(edge)
        if not terminal:
            self._in[v].append((u, r, edge))
        self._degree[u] += 1
        self._degree[v] += 1
        self._update_for_new_edge(edge, u, v, r, terminal)
        return edge

    def _release(self, edge: int) -> None:
        self._e_count[edge] -= 1
        if self._e_count[edge] > 0:
            return
        u, v = self._e_src[edge], self._e_dst[edge]
        del self._edge_of[self._e_key[edge]]
        self._e_key[edge] = None
        self._out[u].remove(edge)
        if not self._e_term[edge]:
            self._in[v].remove((u, self._e_r[edge], edge))
        if self._choice[u] == edge:
            self._choice[u] = -1  # the value stays: still a valid lower bound
        self._free_edges.append(edge)
        for node in (u, v):
            self._degree[node] -= 1
            if self._degree[node] == 0:
                del self._node_of[self._node_key[node]]
                self._node_key[node] = None
                self._free_nodes.append(node)

    # ------------------------------------------------------------------ bounds
    def _edge_bound(self, edge: int) -> float:
        if self._e_term[edge]:
            return self._e_r[edge]
        return self._e_r[edge] + self.gamma * self._value[self._e_dst[edge]]

    def _update_for_new_edge(self, edge: int, u: int, v: int, r: float, terminal: bool) -> None:
        if terminal:
            candidate = r
        elif u == v:
            candidate = r / (1.0 - self.gamma)
        elif self._value[v] == NEG_INF:
            path = self._path(v, u)
            if path is not None:
                self._propagate(self._set_loop([edge] + path))
            return
        else:
            candidate = r + self.gamma * self._value[v]
        current = self._value[u]
        if current == NEG_INF or candidate > current + _REL_TOL * (1.0 + abs(current)):
            self._value[u] = candidate
            self._choice[u] = edge
            self._propagate([u])

    def _path(self, start: int, goal: int) -> list[int] | None:
        """Edges of some path start -> goal (depth-first), or None. Only called from nodes without
        a value, whose whole forward region has no value either, so the search stays in it."""
        parent_edge = {start: -1}
        stack = [start]
        while stack:
            node = stack.pop()
            for edge in self._out[node]:
                nxt = self._e_dst[edge]
                if nxt in parent_edge:
                    continue
                parent_edge[nxt] = edge
                if nxt == goal:
                    path = []
                    while nxt != start:
                        edge = parent_edge[nxt]
                        path.append(edge)
                        nxt = self._e_src[edge]
                    return path[::-1]
                stack.append(nxt)
        return None

    def _set_loop(self, edges: list[int]) -> list[int]:
        """Give the nodes of a loop of edges their exact value of staying in it forever."""
        g, m = self.gamma, len(edges)
        rewards = [self._e_r[e] for e in edges]
        loop_return = sum(r * g ** j for j, r in enumerate(rewards))
        value = loop_return / (1.0 - g ** m)
        nodes = []
        for j in range(m - 1, -1, -1):  # V(c_j) = r_j + g * V(c_{j+1}), V(c_m) = V(c_0)
            value = rewards[j] + g * value
            node = self._e_src[edges[j]]
            if value > self._value[node]:
                self._value[node] = value
                self._choice[node] = edges[j]
            nodes.append(node)
        return nodes

    def _policy_loop(self, start: int, wave: int) -> list[int] | None:
        """Edges of the loop of policy pointers through ``start`` within this wave, if any."""
        edges = []
        seen = {start}
        node = start
        while True:
            edge = self._choice[node]
            if edge < 0 or self._e_term[edge]:
                return None
            edges.append(edge)
            node = self._e_dst[edge]
            if node == start:
                return edges
            if node in seen or self._stamp[node] != wave:
                return None
            seen.add(node)

    def _propagate(self, start: list[int]) -> None:
        """Worklist back-propagation of value improvements (thesis Algorithm 3, PROPAGATELB)."""
        self._wave += 1
        wave = self._wave
        g = self.gamma
        value, choice, stamp = self._value, self._choice, self._stamp
        in_edges = self._in
        for node in start:
            stamp[node] = wave
        queue = deque(start)
        while queue:
            node = queue.popleft()
            v_node = value[node]
            for pred, reward, edge in in_edges[node]:
                candidate = reward / (1.0 - g) if pred == node else reward + g * v_node
                current = value[pred]
                if current != NEG_INF and candidate <= current + _REL_TOL * (1.0 + abs(current)):
                    continue
                value[pred] = candidate
                choice[pred] = edge
                if stamp[pred] == wave:
                    loop = self._policy_loop(pred, wave)
                    if loop is not None:
                        queue.extend(self._set_loop(loop))
                stamp[pred] = wave
                queue.append(pred)

    # ------------------------------------------------------------------ census
    def _classify(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Stored edge ids, their kind (index into TRANSITION_KINDS) and the number of transitions
        from their ``s'`` to the nearest terminal (-1 if none). Graph searches run in scipy."""
        edges = np.fromiter(self._edge_of.values(), dtype=np.int64, count=len(self._edge_of))
        src, dst = np.asarray(self._e_src)[edges], np.asarray(self._e_dst)[edges]
        term = np.asarray(self._e_term, dtype=bool)[edges]
        n = len(self._node_key)  # node id n is an extra source node for the searches
        step, cont = ~term, np.flatnonzero(~term)

        def reverse_graph(extra_targets: np.ndarray) -> sp.csr_matrix:
            rows = np.concatenate([dst[step], np.full(len(extra_targets), n)])
            cols = np.concatenate([src[step], extra_targets])
            return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1))

        # shortest number of transitions from each node to a terminal
        dist = csgraph.shortest_path(reverse_graph(src[term]), unweighted=True, indices=n)
        # nodes with an infinite path: those that reach a loop (a strongly connected component
        # with more than one node, or a self-loop)
        forward = sp.csr_matrix((np.ones(len(cont)), (src[cont], dst[cont])), shape=(n, n))
        _, label = csgraph.connected_components(forward, connection='strong')
        size = np.bincount(label, minlength=n)
        on_loop = size[label] > 1
        on_loop[src[cont][src[cont] == dst[cont]]] = True
        reach = np.zeros(n + 1, dtype=bool)
        reach[csgraph.breadth_first_order(reverse_graph(np.flatnonzero(on_loop)), n,
                                          return_predecessors=False)] = True
        d_next = dist[dst]
        kind = np.where(term, 0, np.where(np.isfinite(d_next), 1, np.where(reach[dst], 2, 3)))
        hops = np.where(term, 0, np.where(np.isfinite(d_next), d_next, -1)).astype(np.int64)
        return edges, kind, hops
