"""Graphs over the domain whose shortest paths seed the exact solver.

`GraphSeeder`: a dense lattice over the domain for ``dim <= 3`` or a sampled roadmap (k
nearest neighbours) for higher dimensions, edge weights the straight-segment lengths of
eq. (58) (Gauss-Legendre quadrature of ``F``), built once per metric (`graph_seeder`,
cached). A query links start and goal to their nearest nodes and runs Dijkstra
(``scipy.sparse.csgraph``); `GraphSeeder.routes` gives several distinct routes per pair.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from finsler.metrics.base import Metric

__all__ = ["ROUTE_PENALTY", "GraphSeeder", "graph_seeder"]


class GraphSeeder:
    """Shortest paths on a graph over the domain (lattice for ``dim <= 3``, roadmap above).

    ``nodes`` ``(N, dim)``; directed edges ``(rows, cols)`` with weights the eq. (58)
    lengths of the straight segments. Built once; queries are independent of each other.
    """

    def __init__(self, metric: Metric, nodes: np.ndarray, k_link: int, radius: float) -> None:
        self.metric = metric
        self.nodes = nodes
        self.tree = cKDTree(nodes)
        self.k_link = k_link
        self.radius = radius

    @classmethod
    def lattice(cls, metric: Metric, spacing: tuple[float, ...], reach: tuple[int, ...]
                ) -> GraphSeeder:
        """Regular lattice of the given spacing per coordinate over the domain's bounding
        box (nodes inside the domain), edges to every offset within ``reach`` per
        coordinate whose entries have no common divisor (no duplicated collinear edges)."""
        flat, inside, shape = cls._grid(metric, spacing)
        index = -np.ones(flat.shape[0], dtype=np.int64)
        index[inside] = np.arange(int(inside.sum()))
        index = index.reshape(shape)
        offsets = [
            o
            for o in np.ndindex(*(2 * r + 1 for r in reach))
            if any(v != r for v, r in zip(o, reach))
        ]
        offsets = [tuple(v - r for v, r in zip(o, reach)) for o in offsets]
        offsets = [o for o in offsets if math.gcd(*[abs(v) for v in o]) == 1]
        rows, cols = [], []
        ijk = np.stack(np.meshgrid(*[np.arange(m) for m in shape], indexing="ij"), -1)
        ijk = ijk.reshape(-1, metric.dim)[inside]
        for o in offsets:
            nb = ijk + np.asarray(o)
            ok = np.all((nb >= 0) & (nb < np.asarray(shape)), axis=1)
            src = np.flatnonzero(ok)
            dst = index[tuple(nb[ok].T)]
            good = dst >= 0
            rows.append(src[good])
            cols.append(dst[good])
        self = cls(metric, flat[inside], k_link=2 ** metric.dim * 2,
                   radius=float(np.linalg.norm(spacing)) * max(reach))
        self._set_edges(np.concatenate(rows), np.concatenate(cols))
        return self

    @staticmethod
    def _grid(metric: Metric, spacing: tuple[float, ...]
              ) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        """The lattice's points over the domain's bounding box ``(P, dim)``, which lie
        inside the domain ``(P,)``, and the grid's shape."""
        lo, hi = metric.domain.bounds()
        axes = [np.arange(a, b + 1e-12, h) for a, b, h in zip(lo, hi, spacing)]
        axes = [ax + 0.5 * ((b - a) - (ax[-1] - ax[0])) for ax, a, b in zip(axes, lo, hi)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
        flat = grid.reshape(-1, metric.dim)
        return flat, np.asarray(metric.domain.contains(flat), bool), grid.shape[:-1]

    @classmethod
    def lattice_nodes(cls, metric: Metric, spacing: tuple[float, ...]) -> np.ndarray:
        """The nodes of `lattice` (inside the domain), without its edges."""
        flat, inside, _ = cls._grid(metric, spacing)
        return flat[inside]

    @classmethod
    def roadmap(cls, metric: Metric, n_nodes: int, k: int, seed: int = 0) -> GraphSeeder:
        """Roadmap of ``n_nodes`` uniform samples (seeded), each linked both ways to its
        ``k`` nearest neighbours (Euclidean in coordinates)."""
        rng = np.random.default_rng(seed)
        nodes = metric.domain.sample(n_nodes, rng)
        tree = cKDTree(nodes)
        _, nb = tree.query(nodes, k=k + 1)
        rows = np.repeat(np.arange(n_nodes), k)
        cols = nb[:, 1:].reshape(-1)
        r = np.concatenate([rows, cols])
        c = np.concatenate([cols, rows])
        key = _unique(r * n_nodes + c)
        self = cls(metric, nodes, k_link=k, radius=np.inf)
        self._set_edges(key // n_nodes, key % n_nodes)
        return self

    @classmethod
    def aligned(cls, metric: Metric, nodes: np.ndarray, steps: tuple[float, ...],
                directions: int = 200, keep: int = 16, base: GraphSeeder | None = None
                ) -> GraphSeeder:
        """A graph for anisotropic metrics (3-D): from every node, edges along the
        ``keep`` directions of least ``F(node, u)`` among ``directions`` unit vectors
        ``u`` (a Fibonacci sphere), each ``steps`` long, to the node nearest to their end
        (car-like: forward along the node's heading, turning either way; no edge
        sideways or backwards, which cost ``sqrt(1 + c_p)`` times more). Only values of
        ``F`` choose the directions. ``base``: a graph whose nodes and edges are kept too
        (its lattice links for the moves the chosen directions miss)."""
        if metric.dim != 3:
            from finsler.errors import InputError

            raise InputError(f"aligned graphs are 3-D; the metric has dim {metric.dim}")
        i = np.arange(directions) + 0.5
        phi, th = np.arccos(1.0 - 2.0 * i / directions), np.pi * (1.0 + 5.0**0.5) * i
        u = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
        if base is not None:
            nodes = np.vstack([base.nodes, nodes])
        tree = cKDTree(nodes)
        keep = min(keep, directions)
        rows, cols = [], []
        chunk = max(1, 400_000 // directions)
        for a in range(0, nodes.shape[0], chunk):
            x = nodes[a:a + chunk]
            f = metric.F(np.repeat(x, directions, 0), np.tile(u, (len(x), 1)))
            f = np.asarray(f).reshape(len(x), directions)
            best = np.argpartition(f, keep - 1, axis=1)[:, :keep] if keep < directions \
                else np.argsort(f, 1)
            src = np.repeat(np.arange(a, a + len(x)), keep)
            for step in steps:
                end = (x[:, None] + step * u[best]).reshape(-1, 3)
                _, dst = tree.query(end)
                good = metric.domain.contains(end) & (dst != src)
                rows.append(src[good])
                cols.append(dst[good])
        if base is not None:
            rows.append(base.rows)
            cols.append(base.cols)
        n = nodes.shape[0]
        key = _unique(np.concatenate(rows) * n + np.concatenate(cols))
        self = cls(metric, nodes, k_link=base.k_link if base is not None else 16,
                   radius=np.inf)
        self._set_edges(key // n, key % n)
        return self

    def _set_edges(self, rows: np.ndarray, cols: np.ndarray) -> None:
        w = np.empty(rows.size)
        chunk = 200_000
        for a in range(0, rows.size, chunk):
            sl = slice(a, a + chunk)
            w[sl] = self.metric.segment_length(self.nodes[rows[sl]], self.nodes[cols[sl]], 4)
        self.rows, self.cols, self.weights = rows, cols, w

    def path(self, s: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Shortest graph path from ``s`` to ``g``: (points ``(m+1, dim)``, edge costs
        ``(m,)``), or ``None`` if the graph does not connect them."""
        return self.paths(np.asarray(s)[None], np.asarray(g)[None])[0]

    def paths(self, starts: np.ndarray, goals: np.ndarray
              ) -> list[tuple[np.ndarray, np.ndarray] | None]:
        """Shortest graph paths of many pairs ``(K, dim)`` at once (one graph with a start
        and a goal node per pair: a start node has only outgoing links, a goal node only
        incoming ones, so no path crosses another pair's; one Dijkstra call from all the
        start nodes)."""
        return [r[0] if r else None for r in self.routes(starts, goals, 1)]

    def routes(self, starts: np.ndarray, goals: np.ndarray, count: int
               ) -> list[list[tuple[np.ndarray, np.ndarray]]]:
        """Up to ``count`` distinct routes per pair (``(K, dim)`` each), shortest first:
        after each route, the edges touching its inner nodes cost ``ROUTE_PENALTY`` times
        more and Dijkstra runs again (another side of an obstacle or a hill); a route
        through the same nodes as an earlier one is not repeated. Per pair a list of
        (points ``(m+1, dim)``, edge costs ``(m,)``), empty if the graph does not connect
        the pair."""
        s_all = np.asarray(starts, dtype=np.float64).reshape(-1, self.metric.dim)
        g_all = np.asarray(goals, dtype=np.float64).reshape(-1, self.metric.dim)
        K = s_all.shape[0]
        nn = self.nodes.shape[0]
        k = min(self.k_link, nn)
        _, si = self.tree.query(s_all, k=k)
        _, gi = self.tree.query(g_all, k=k)
        si, gi = si.reshape(K, k), gi.reshape(K, k)
        m = self.metric
        ws = m.segment_length(np.repeat(s_all, k, 0), self.nodes[si.reshape(-1)], 4)
        wg = m.segment_length(self.nodes[gi.reshape(-1)], np.repeat(g_all, k, 0), 4)
        wd = np.atleast_1d(m.segment_length(s_all, g_all, 4))
        S = nn + np.arange(K)
        G = nn + K + np.arange(K)
        rows = np.concatenate([self.rows, np.repeat(S, k), gi.reshape(-1), S])
        cols = np.concatenate([self.cols, si.reshape(-1), np.repeat(G, k), G])
        w = np.concatenate([self.weights, ws, wg, wd])
        w = np.maximum(w, 1e-300)  # csgraph drops explicit zeros
        size = nn + 2 * K
        graph = sp.csr_matrix((w, (rows, cols)), shape=(size, size))
        allnodes = np.vstack([self.nodes, s_all, g_all])
        found: list[list[np.ndarray]] = []
        for j in range(K):
            mine: list[np.ndarray] = []
            g_j, used = graph, np.zeros(size, bool)
            for _ in range(count):
                # the direct link bounds the distance: nothing farther needs exploring
                dist, pred = dijkstra(g_j, directed=True, indices=int(S[j]),
                                      return_predecessors=True,
                                      limit=float(w[-K + j]) * 1.000001)
                if not np.isfinite(dist[G[j]]):
                    break
                seq = [int(G[j])]
                while seq[-1] != S[j]:
                    seq.append(int(pred[seq[-1]]))
                seq.reverse()
                inner = np.asarray(seq[1:-1], dtype=np.int64)
                if not mine or not np.all(used[inner]):
                    mine.append(np.asarray(seq))
                if len(mine) >= count or len(seq) <= 2:
                    break
                used[inner] = True
                coo = g_j.tocoo()
                data = np.where(used[coo.row] | used[coo.col],
                                coo.data * ROUTE_PENALTY, coo.data)
                g_j = sp.csr_matrix((data, (coo.row, coo.col)), shape=(size, size))
            found.append(mine)
        # edge costs of every route in one evaluation
        flat = [allnodes[seq] for mine in found for seq in mine]
        out: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(K)]
        if flat:
            a = np.concatenate([p[:-1] for p in flat])
            b = np.concatenate([p[1:] for p in flat])
            costs = np.atleast_1d(m.segment_length(a, b, 4))
            it = iter(np.split(costs, np.cumsum([len(p) - 1 for p in flat])[:-1]))
            pts = iter(flat)
            for j, mine in enumerate(found):
                out[j] = [(next(pts), next(it)) for _ in mine]
        return out


def _unique(keys: np.ndarray) -> np.ndarray:
    """Sorted distinct values of an integer array (``np.unique``; sorting and comparing
    neighbours is several times faster here than numpy 2's hash-based path)."""
    k = np.sort(keys)
    return k[np.concatenate([[True], k[1:] != k[:-1]])] if k.size else k


#: How much more the edges at an earlier route's nodes cost when the next route is sought.
ROUTE_PENALTY = 3.0


def graph_seeder(metric: Metric) -> GraphSeeder:
    """The graph of ``metric``, built once per metric (``metric.derived``; sizes chosen for
    the speed targets)."""
    return metric.derived("seeding.graph", lambda: _build_graph_seeder(metric))


def _build_graph_seeder(metric: Metric) -> GraphSeeder:
    if metric.dim == 2:
        lo, hi = metric.domain.bounds()
        h = float(np.max(hi - lo)) / 48.0
        return GraphSeeder.lattice(metric, (h, h), (3, 3))
    if metric.dim == 3:
        lo, hi = metric.domain.bounds()
        hx = float(np.max(hi[:2] - lo[:2])) / 20.0
        ht = float(hi[2] - lo[2]) / 32.0
        base = GraphSeeder.lattice(metric, (hx, hx, ht), (2, 2, 1))
        # aligned edges from a finer lattice, and the lattice's own: on car-like tuning
        # pairs the route of both reaches basins neither reaches alone (the aligned edges
        # alone lose some). Built once per metric (about 52k nodes, 1.6M edges: seconds)
        fine = GraphSeeder.lattice_nodes(metric, (hx / 2, hx / 2, ht))
        return GraphSeeder.aligned(metric, fine, (0.075 * float(np.max(hi[:2] - lo[:2])),
                                                  0.15 * float(np.max(hi[:2] - lo[:2]))),
                                   base=base)
    return GraphSeeder.roadmap(metric, n_nodes=1500, k=10, seed=0)
