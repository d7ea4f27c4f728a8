"""Global seeding: initial curves for IPOPT and graph searches whose shortest paths seed it.

* :func:`seed_curves`: straight line, curves bulging to either side (several amplitudes),
  seeded random smooth perturbations; all projected into the domain.
* :class:`GraphSeeder`: a dense lattice over the domain for ``dim <= 3`` or a sampled
  roadmap (k nearest neighbours) for higher dimensions, edge weights the straight-segment
  lengths of eq. (58) (Gauss-Legendre quadrature of ``F``), built once per metric
  (:func:`graph_seeder`, cached). A query links start and goal to their nearest nodes and
  runs Dijkstra (``scipy.sparse.csgraph``); the path is resampled to ``n + 1`` points at
  equal cost spacing.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from finsler.metric import Metric

__all__ = ["GraphSeeder", "SeedPlan", "graph_seeder", "resample", "seed_curves"]


@dataclass(frozen=True)
class SeedPlan:
    """Which initial curves to try (a strategy object, see STYLE.md).

    ``bulges``: amplitudes (fractions of ``|g - s|``) of the sine bulges, each tried on
    both sides (in 2-D; in higher dimensions along seeded random directions orthogonal to
    ``g - s``); ``random``: number of seeded random smooth perturbations; ``graph``: use the
    lattice / roadmap shortest path; ``seed``: seed of the random perturbations.
    ``coarse``: if set (and below the requested ``n``), every seed is first solved with
    ``coarse`` segments and only the ``refine_top`` lowest energies are refined at ``n``
    (warm started from the coarse solutions); selection stays by the fine energy.
    """

    bulges: tuple[float, ...] = (0.3,)
    random: int = 0
    graph: bool = True
    seed: int = 0
    coarse: int | None = None
    refine_top: int = 3

    def __post_init__(self) -> None:
        from finsler.errors import InputError

        if any(not (np.isfinite(a) and a > 0) for a in self.bulges):
            raise InputError(f"bulge amplitudes must be positive, got {self.bulges!r}")
        if not isinstance(self.random, int) or self.random < 0:
            raise InputError(f"random must be a non-negative integer, got {self.random!r}")
        if self.coarse is not None and (not isinstance(self.coarse, int) or self.coarse < 2):
            raise InputError(f"coarse must be None or an integer >= 2, got {self.coarse!r}")
        if not isinstance(self.refine_top, int) or self.refine_top < 1:
            raise InputError(f"refine_top must be a positive integer, got {self.refine_top!r}")

    @staticmethod
    def default(metric: Metric) -> SeedPlan:
        """Defaults measured to meet the speed targets (see benchmarks/solver_speed.py)."""
        if metric.name == "matsumoto":
            # measured on 200 pairs (n=64): never above Adam-from-straight-line; against 20
            # starts, higher energy on 11 pairs by at most 0.46% (near-equal local minima of
            # the non-convex metric), lower on 3
            return SeedPlan(bulges=(0.25, 0.6), random=2, graph=True)
        if metric.name == "carlike":
            # measured on 40 pairs: (0.3,) alone missed a lower energy on 10 of them, by up
            # to 157%; these 14 starts were within 0.5% of 19 starts on all 40
            return SeedPlan(bulges=(0.15, 0.3, 0.5, 0.7), random=4, graph=True)
        if metric.name == "panda-pole":
            return SeedPlan(bulges=(0.3,), random=2, graph=True)
        return SeedPlan(bulges=(0.3,), random=0, graph=metric.dim <= 3)


def resample(path: np.ndarray, weights: np.ndarray, n: int) -> np.ndarray:
    """Resample a polyline ``(m+1, dim)`` with per-edge costs ``(m,)`` at ``n + 1`` points of
    equal cumulative cost (linear interpolation within edges) -> ``(n+1, dim)``."""
    cum = np.concatenate([[0.0], np.cumsum(np.maximum(weights, 0.0))])
    if cum[-1] <= 0:
        cum = np.linspace(0.0, 1.0, len(path))
    target = np.linspace(0.0, cum[-1], n + 1)
    out = np.empty((n + 1, path.shape[1]))
    for d in range(path.shape[1]):
        out[:, d] = np.interp(target, cum, path[:, d])
    out[0], out[-1] = path[0], path[-1]
    return out


def seed_curves(
    metric: Metric, s: np.ndarray, g: np.ndarray, n: int, plan: SeedPlan
) -> list[tuple[str, np.ndarray]]:
    """Initial curves ``(n+1, dim)`` from ``s`` to ``g`` named by how they were made."""
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    line = s + t * (g - s)
    out = [("straight", line)]
    d = g - s
    dist = float(np.linalg.norm(d))
    if dist == 0.0:
        return out
    rng = np.random.default_rng(plan.seed)
    dirs: list[np.ndarray] = []
    if metric.dim >= 2:
        # first: perpendicular in the first two coordinates (the plane for 2-D/3-D metrics)
        perp = np.zeros(metric.dim)
        planar = d[:2]
        if np.linalg.norm(planar) > 1e-12:
            perp[:2] = np.array([-planar[1], planar[0]]) / np.linalg.norm(planar)
        else:
            perp[0] = 1.0
        dirs.append(perp)
    bump = np.sin(np.pi * t)
    scale = dist if metric.dim <= 3 else max(dist, 1.0)
    for a in plan.bulges:
        for k, base in enumerate(dirs or [np.zeros(metric.dim)]):
            for sign in (1.0, -1.0):
                if metric.dim > 3:
                    e = rng.normal(size=metric.dim)
                    e -= (e @ d) / (d @ d) * d
                    e /= np.linalg.norm(e)
                else:
                    e = base
                curve = line + sign * a * scale * bump * e
                out.append((f"bulge{'+' if sign > 0 else '-'}{a:g}#{k}", curve))
    for k in range(plan.random):
        modes = np.arange(1, 4)
        coef = rng.normal(size=(len(modes), metric.dim)) * 0.15 * scale / modes[:, None]
        pert = np.sin(np.pi * t * modes[None, :]) @ coef
        out.append((f"random{k}", line + pert))
    return [(name, _project(metric, c, s, g)) for name, c in out]


def _project(metric: Metric, curve: np.ndarray, s: np.ndarray, g: np.ndarray) -> np.ndarray:
    c = np.asarray(metric.domain.project(curve), dtype=np.float64)
    c[0], c[-1] = s, g
    return c


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
        lo, hi = metric.domain.bounds()
        axes = [np.arange(a, b + 1e-12, h) for a, b, h in zip(lo, hi, spacing)]
        axes = [ax + 0.5 * ((b - a) - (ax[-1] - ax[0])) for ax, a, b in zip(axes, lo, hi)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
        shape = grid.shape[:-1]
        flat = grid.reshape(-1, metric.dim)
        inside = metric.domain.contains(flat)
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
        key = np.unique(r * n_nodes + c)
        self = cls(metric, nodes, k_link=k, radius=np.inf)
        self._set_edges(key // n_nodes, key % n_nodes)
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
        nn = self.nodes.shape[0]
        k = min(self.k_link, nn)
        _, si = self.tree.query(s, k=k)
        _, gi = self.tree.query(g, k=k)
        si, gi = np.atleast_1d(si), np.atleast_1d(gi)
        m = self.metric
        ws = m.segment_length(np.repeat(s[None], k, 0), self.nodes[si], 4)
        wg = m.segment_length(self.nodes[gi], np.repeat(g[None], k, 0), 4)
        wd = float(m.segment_length(s, g, 4))
        S, G = nn, nn + 1
        rows = np.concatenate([self.rows, np.full(k, S), gi, [S]])
        cols = np.concatenate([self.cols, si, np.full(k, G), [G]])
        w = np.concatenate([self.weights, ws, wg, [wd]])
        w = np.maximum(w, 1e-300)  # csgraph drops explicit zeros
        graph = sp.csr_matrix((w, (rows, cols)), shape=(nn + 2, nn + 2))
        dist, pred = dijkstra(graph, directed=True, indices=S, return_predecessors=True)
        if not np.isfinite(dist[G]):
            return None
        seq = [G]
        while seq[-1] != S:
            seq.append(int(pred[seq[-1]]))
        seq.reverse()
        allnodes = np.vstack([self.nodes, s[None], g[None]])
        pts = allnodes[seq]
        costs = m.segment_length(pts[:-1], pts[1:], 4)
        return pts, np.atleast_1d(costs)


@functools.lru_cache(maxsize=8)
def graph_seeder(metric: Metric) -> GraphSeeder:
    """The graph of ``metric``, built once per metric (sizes chosen for the speed targets)."""
    if metric.dim == 2:
        lo, hi = metric.domain.bounds()
        h = float(np.max(hi - lo)) / 48.0
        return GraphSeeder.lattice(metric, (h, h), (3, 3))
    if metric.dim == 3:
        lo, hi = metric.domain.bounds()
        hx = float(np.max(hi[:2] - lo[:2])) / 20.0
        ht = float(hi[2] - lo[2]) / 32.0
        return GraphSeeder.lattice(metric, (hx, hx, ht), (2, 2, 1))
    return GraphSeeder.roadmap(metric, n_nodes=1500, k=10, seed=0)
