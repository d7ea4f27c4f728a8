"""A shortest-path field over a lattice whose edges the metric chooses: routes for global seeding.

A lattice of equal spacing in every coordinate covers the domain's bounding box (nodes
inside the domain). Its moves are every integer offset within ``reach`` cells per
coordinate (entries without a common divisor) that is at least ``prune`` cheaper than
every split of it into two shorter moves of the set: a strongly anisotropic metric
(car-like: sideways motion 10x dearer than forward) keeps long moves along its cheap
directions and short ones across them, so graph lengths stay close to the true ones
without millions of redundant edges. Edge weights are the eq. (58) lengths of the
straight segments (Gauss-Legendre quadrature of ``F``). Only values of ``F`` choose the
moves.

Where ``F`` does not depend on some coordinates (a translation-invariant metric; car-like
depends on the heading alone), the costs of all moves are computed once per lattice value
of the coordinates it depends on: exact, and thousands of times fewer evaluations. Where
``F`` depends on every coordinate, the moves are chosen at a seeded sample of nodes (their
union is kept) and every edge is weighed where it lies.

A query searches the graph forward from a start and backward to a goal (Dijkstra,
``scipy.sparse.csgraph``): the sum of the two distances at a node is the length of the
shortest route through it. The shortest route, then routes through nodes far from the
routes already taken (a via-node search: another side of the disk, another winding of the
heading), are the seeds. A forward field is kept per distinct start, so goals that share a
start share its search.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from finsler.errors import InputError
from finsler.metrics.base import Metric

__all__ = ["FieldSpec", "LatticeField", "lattice_field"]


@dataclass(frozen=True)
class FieldSpec:
    """The lattice of a `LatticeField`: ``resolution`` cells along the longest side
    of the domain's bounding box (the same spacing in every coordinate), moves within
    ``reach`` cells per coordinate, kept when at least ``prune`` (relative) cheaper than
    every split into two, start and goal linked to their ``link`` nearest nodes."""

    resolution: int = 64
    reach: int = 6
    prune: float = 0.03
    link: int = 8

    def __post_init__(self) -> None:
        for name, lo in (("resolution", 2), ("reach", 1), ("link", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise InputError(f"FieldSpec.{name} must be an integer >= {lo}, got {v!r}")
        if self.resolution > 1024:
            raise InputError(f"FieldSpec.resolution must be at most 1024, got "
                             f"{self.resolution}")
        if not (isinstance(self.prune, (int, float)) and not isinstance(self.prune, bool)
                and 0.0 <= self.prune < 1.0):
            raise InputError(f"FieldSpec.prune must be in [0, 1), got {self.prune!r}")


def _depends(metric: Metric) -> np.ndarray:
    """Which coordinates of ``x`` the symbolic ``F(x, v)`` depends on ``(dim,)`` bool."""
    x = ca.SX.sym("x", metric.dim)
    v = ca.SX.sym("v", metric.dim)
    f = metric.F_sx(x, v)
    return np.array([bool(ca.depends_on(f, x[i])) for i in range(metric.dim)])


def _offsets(dim: int, reach: int) -> np.ndarray:
    """Integer moves ``(M, dim)`` within ``reach`` per coordinate, not zero, entries without
    a common divisor (a multiple of a move is that move repeated)."""
    grid = np.stack(np.meshgrid(*[np.arange(-reach, reach + 1)] * dim, indexing="ij"), -1)
    o = grid.reshape(-1, dim)
    o = o[np.any(o != 0, axis=1)]
    g = np.gcd.reduce(np.abs(o), axis=1)
    return o[g == 1]


def _splits(offsets: np.ndarray, reach: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every split of a move into two moves of the set: indices ``(o, a, b)`` with
    ``offsets[o] = offsets[a] + offsets[b]``, sorted by ``o``."""
    dim = offsets.shape[1]
    base = 4 * reach + 1
    key = ((offsets + 2 * reach) * base ** np.arange(dim)).sum(1)
    lookup = -np.ones(base**dim, dtype=np.int64)
    lookup[key] = np.arange(len(offsets))
    oi, ai, bi = [], [], []
    for a in range(len(offsets)):
        rest = offsets - offsets[a]
        ok = np.all(np.abs(rest) <= reach, axis=1)
        idx = np.flatnonzero(ok)
        kb = ((rest[idx] + 2 * reach) * base ** np.arange(dim)).sum(1)
        b = lookup[kb]
        good = b >= 0
        oi.append(idx[good])
        ai.append(np.full(int(good.sum()), a))
        bi.append(b[good])
    o, a, b = np.concatenate(oi), np.concatenate(ai), np.concatenate(bi)
    order = np.argsort(o, kind="stable")
    return o[order], a[order], b[order]


class LatticeField:
    """The lattice graph of ``metric`` (`FieldSpec`) and its shortest-path searches.

    ``nodes`` ``(N, dim)``; ``graph`` the forward edges (CSR, ``N + 1`` rows: the last row is
    a start's links, rewritten per query) and ``back`` the reversed edges with a goal's
    links in its last row.
    """

    def __init__(self, metric: Metric, spec: FieldSpec) -> None:
        self.metric = metric
        self.spec = spec
        lo, hi = (np.asarray(b, dtype=np.float64) for b in metric.domain.bounds())
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise InputError(f"{metric.name}: a lattice field needs a bounded domain")
        self.h = float(np.max(hi - lo)) / spec.resolution
        counts = np.maximum(np.floor((hi - lo) / self.h + 1e-9).astype(int), 1)
        axes = [a + 0.5 * ((b - a) - c * self.h) + self.h * np.arange(c + 1)
                for a, b, c in zip(lo, hi, counts)]
        self.shape = tuple(len(ax) for ax in axes)
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, metric.dim)
        inside = np.asarray(metric.domain.contains(grid), bool)
        self.index = -np.ones(grid.shape[0], dtype=np.int64)
        self.index[inside] = np.arange(int(inside.sum()))
        self.nodes = grid[inside]
        ijk = np.stack(np.unravel_index(np.flatnonzero(inside), self.shape), -1)
        self.tree = cKDTree(self.nodes / self.h)
        self._build(ijk)
        self._fields: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    # -- construction ---------------------------------------------------------------------
    def _build(self, ijk: np.ndarray) -> None:
        m, spec = self.metric, self.spec
        offsets = _offsets(m.dim, spec.reach)
        o_i, a_i, b_i = _splits(offsets, spec.reach)
        starts = np.flatnonzero(np.r_[True, o_i[1:] != o_i[:-1]])
        dep = _depends(m)
        shape = np.asarray(self.shape)
        if dep.any():
            cls_shape = shape[dep]
            n_cls = int(np.prod(cls_shape))
        else:
            cls_shape, n_cls = np.zeros(0, int), 1
        rows, cols, weights = [], [], []
        if n_cls <= 1024:
            # one representative point per class: F is the same at every node of a class
            cls_ijk = np.stack(np.unravel_index(np.arange(n_cls), tuple(cls_shape)), -1) \
                if dep.any() else np.zeros((1, 0), int)
            rep = np.zeros((n_cls, m.dim))
            rep[:, dep] = self._coords(cls_ijk, dep)
            rep[:, ~dep] = self.nodes[0, ~dep]
            cost = self._move_costs(rep, offsets)  # (n_cls, M)
            keep = self._prune(cost, cls_ijk, offsets[:, dep], cls_shape, o_i, a_i, b_i,
                               starts)
            node_cls = np.ravel_multi_index(tuple(ijk[:, dep].T), tuple(cls_shape)) \
                if dep.any() else np.zeros(len(ijk), int)
            for j, o in enumerate(offsets):
                src = np.flatnonzero(keep[node_cls, j])
                dst = self._neighbour(ijk[src] + o)
                good = dst >= 0
                rows.append(src[good])
                cols.append(dst[good])
                weights.append(cost[node_cls[src[good]], j])
        else:
            # F depends on every coordinate: the moves useful at a seeded sample of nodes
            rng = np.random.default_rng(0)
            pick = rng.choice(len(ijk), size=min(64, len(ijk)), replace=False)
            cost = self._move_costs(self.nodes[pick], offsets)
            keep = self._prune(cost, None, None, None, o_i, a_i, b_i, starts).any(0)
            for j in np.flatnonzero(keep):
                dst = self._neighbour(ijk + offsets[j])
                src = np.flatnonzero(dst >= 0)
                rows.append(src)
                cols.append(dst[src])
            r, c = np.concatenate(rows), np.concatenate(cols)
            weights = [self._lengths(self.nodes[r], self.nodes[c])]
            rows, cols = [r], [c]
        r, c = np.concatenate(rows), np.concatenate(cols)
        w = np.maximum(np.concatenate(weights), 1e-300)  # csgraph drops explicit zeros
        self.edges = (r, c, w)
        n = len(self.nodes)
        self.moves = int(np.sum(keep)) if keep.ndim == 1 else int(keep.any(0).sum())
        self.graph = self._with_spare_row(r, c, w, n)
        self.back = self._with_spare_row(c, r, w, n)

    def _coords(self, cls_ijk: np.ndarray, dep: np.ndarray) -> np.ndarray:
        lo, hi = (np.asarray(b, dtype=np.float64) for b in self.metric.domain.bounds())
        counts = np.asarray(self.shape) - 1
        first = lo + 0.5 * ((hi - lo) - counts * self.h)
        return first[dep] + self.h * cls_ijk

    def _move_costs(self, points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """Eq. (58) length of every move from every point ``(P, M)`` (the moves' ends are
        not required to lie in the domain: the formula of ``F`` is evaluated there)."""
        P, M = len(points), len(offsets)
        a = np.repeat(points, M, 0)
        b = a + np.tile(offsets * self.h, (P, 1))
        return self._lengths(a, b).reshape(P, M)

    def _lengths(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        out = np.empty(len(a))
        for s in range(0, len(a), 250_000):
            out[s:s + 250_000] = self.metric.segment_length(a[s:s + 250_000],
                                                            b[s:s + 250_000], 4, check=False)
        return out

    def _prune(self, cost: np.ndarray, cls_ijk: np.ndarray | None,
               dmoves: np.ndarray | None, cls_shape: np.ndarray | None, o_i: np.ndarray,
               a_i: np.ndarray, b_i: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """Per class (row of ``cost``) which moves are at least ``prune`` cheaper than
        every split: the first part from the class's point, the second from the class
        the first part ends in (``cls_ijk`` and the moves' steps ``dmoves`` in the
        dependent coordinates; ``None``: the second part from the same point)."""
        n_cls, M = cost.shape
        keep = np.ones((n_cls, M), bool)
        for k in range(n_cls):
            first = cost[k, a_i]
            if cls_ijk is None:
                second = cost[k, b_i]
            else:
                nxt = cls_ijk[k] + dmoves[a_i]
                ok = np.all((nxt >= 0) & (nxt < cls_shape), axis=1)
                second = np.full(len(a_i), np.inf)
                if ok.any():
                    ci = np.ravel_multi_index(tuple(nxt[ok].T), tuple(cls_shape)) \
                        if len(cls_shape) else np.zeros(int(ok.sum()), int)
                    second[ok] = cost[ci, b_i[ok]]
            best = np.minimum.reduceat(first + second, starts)
            split_moves = o_i[starts]
            keep[k, split_moves] = cost[k, split_moves] * (1.0 + self.spec.prune) < best
        return keep

    def _neighbour(self, ijk: np.ndarray) -> np.ndarray:
        """Node index of lattice indices ``(P, dim)`` (``-1``: off the grid or outside)."""
        shape = np.asarray(self.shape)
        ok = np.all((ijk >= 0) & (ijk < shape), axis=1)
        out = -np.ones(len(ijk), dtype=np.int64)
        out[ok] = self.index[np.ravel_multi_index(tuple(ijk[ok].T), self.shape)]
        return out

    def _with_spare_row(self, r: np.ndarray, c: np.ndarray, w: np.ndarray, n: int
                        ) -> sp.csr_matrix:
        """CSR of ``n + 1`` nodes whose last row holds ``link`` entries a query rewrites."""
        k = self.spec.link
        g = sp.csr_matrix((w, (r, c)), shape=(n + 1, n + 1))
        g.sort_indices()
        data = np.concatenate([g.data, np.ones(k)])
        indices = np.concatenate([g.indices, np.arange(k)]).astype(g.indices.dtype)
        indptr = g.indptr.copy()
        indptr[-1] = indptr[-2] + k
        return sp.csr_matrix((data, indices, indptr), shape=(n + 1, n + 1))

    # -- queries --------------------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        """(nodes, edges)."""
        return len(self.nodes), len(self.edges[0])

    def _search(self, graph: sp.csr_matrix, point: np.ndarray, forward: bool
                ) -> tuple[np.ndarray, np.ndarray]:
        """Distances and predecessors ``(N + 1,)`` of a search from ``point`` (forward:
        from it; else to it, on the reversed graph), its links to the ``link`` nearest
        nodes weighed by eq. (58)."""
        k = self.spec.link
        _, near = self.tree.query(point / self.h, k=k)
        near = np.atleast_1d(near)
        p = np.repeat(point[None], k, 0)
        w = self._lengths(p, self.nodes[near]) if forward \
            else self._lengths(self.nodes[near], p)
        order = np.argsort(near)
        graph.indices[-k:] = near[order]
        graph.data[-k:] = np.maximum(w[order], 1e-300)
        n = len(self.nodes)
        return dijkstra(graph, directed=True, indices=n, return_predecessors=True)

    def forward(self, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The forward field of ``start``: graph distances from it to every node and the
        search's predecessors (kept per distinct start: goals sharing a start share it)."""
        key = np.asarray(start, dtype=np.float64).tobytes()
        got = self._fields.get(key)
        if got is None:
            got = self._search(self.graph, np.asarray(start, dtype=np.float64), True)
            if len(self._fields) >= 64:
                self._fields.pop(next(iter(self._fields)))
            self._fields[key] = got
        return got

    def distances(self, start: np.ndarray) -> np.ndarray:
        """Graph distances ``(N,)`` from ``start`` to every node (an upper bound of the
        distance up to the lattice's resolution)."""
        return self.forward(start)[0][:-1]

    def routes(self, start: np.ndarray, goal: np.ndarray, count: int, separation: float,
               ratio: float = np.inf) -> list[np.ndarray]:
        """Up to ``count`` routes from ``start`` to ``goal``, points ``(m+1, dim)``: the
        shortest, then each the shortest through a node at least ``separation`` cells from
        every route before it (in lattice units: another basin), if its graph length is at
        most ``ratio`` times the shortest's. Empty when the lattice does not connect the
        pair."""
        s = np.asarray(start, dtype=np.float64)
        g = np.asarray(goal, dtype=np.float64)
        ds, ps = self.forward(s)
        dg, pg = self._search(self.back, g, False)
        n = len(self.nodes)
        total = ds[:n] + dg[:n]
        if not np.isfinite(total).any():
            return []
        out: list[np.ndarray] = []
        far = total <= ratio * np.min(total)
        if not far.any():
            far[int(np.argmin(total))] = True
        for _ in range(count):
            cand = np.where(far, total, np.inf)
            v = int(np.argmin(cand))
            if not np.isfinite(cand[v]):
                break
            seq_f = [v]
            while ps[seq_f[-1]] >= 0 and seq_f[-1] != n:
                seq_f.append(int(ps[seq_f[-1]]))
            seq_b = [v]
            while pg[seq_b[-1]] >= 0 and seq_b[-1] != n:
                seq_b.append(int(pg[seq_b[-1]]))
            inner = np.asarray([i for i in seq_f[::-1] if i != n] + [i for i in seq_b[1:]
                                                                     if i != n])
            pts = np.vstack([s[None], self.nodes[inner], g[None]])
            out.append(pts)
            left = np.flatnonzero(far)
            d, _ = cKDTree(self.nodes[inner] / self.h).query(self.nodes[left] / self.h,
                                                             distance_upper_bound=separation)
            far[left[np.isfinite(d)]] = False
        return out


def lattice_field(metric: Metric, spec: FieldSpec | None = None) -> LatticeField:
    """The lattice field of ``metric`` for ``spec`` (default `FieldSpec`), built
    once per metric and spec (``metric.derived``)."""
    spec = spec or FieldSpec()
    if not isinstance(spec, FieldSpec):
        raise InputError(f"spec must be a FieldSpec, got {type(spec).__name__}")
    if metric.dim not in (2, 3):
        raise InputError(f"{metric.name}: lattice fields are for 2-D and 3-D metrics, the "
                         f"metric has dim {metric.dim}")
    key = f"field.lattice:{spec.resolution}:{spec.reach}:{spec.prune}:{spec.link}"
    return metric.derived(key, lambda: LatticeField(metric, spec))

