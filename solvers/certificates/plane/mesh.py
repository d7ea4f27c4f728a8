"""The meshes the 2-D certificate computes its bound on, and a zigzag curve: the plain
geometry, apart from the bound code (`solvers.certificates.plane.bounds`: values of F,
interval enclosures of its second derivatives, the corrections, which also inflate for the
rounding of the circumradii computed here):

* the convex polygon covering the domain (`_outline`) and point-in-polygon tests;
* the first point set, a hexagonal lattice graded around the solver's path
  (`_initial_points`; spacing ``h_path`` near the path growing to ``h_far``);
* `_Mesh`, the Delaunay triangulation with P2 unknowns (vertices and edge
  midpoints): the gradient of the potential at each triangle's vertices as a linear map
  of its six unknowns, the circumradii, point location and refinement by edge midpoints;
* `_zigzag`, a candidate curve for the upper bound where ``F(z, .)`` is not convex.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

from finsler.domains import Box, Disk
from finsler.errors import InputError
from finsler.metrics.base import Metric


class _Grading(Protocol):
    """The spacing settings of `solvers.MeshSpec` used here (read-only, as in the frozen
    dataclass)."""

    @property
    def h_path(self) -> float: ...
    @property
    def corridor(self) -> float: ...
    @property
    def grade(self) -> float: ...
    @property
    def h_far(self) -> float: ...


def _outline(metric: Metric) -> np.ndarray:
    """Vertices ``(M, 2)`` (counter-clockwise) of a convex polygon containing the domain."""
    dom = metric.domain
    if isinstance(dom, Box):
        (x0, y0), (x1, y1) = dom.low, dom.high
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)
    if isinstance(dom, Disk):
        m = 64
        r = dom.radius / math.cos(math.pi / m)  # circumscribed: the disk lies inside
        a = 2 * np.pi * (np.arange(m) + 0.5) / m
        return np.asarray(dom.center, float) + r * np.stack([np.cos(a), np.sin(a)], 1)
    raise InputError(f"certify needs a 2-D box or disk domain, {metric.name} has "
                     f"{dom.describe()}")


def _inside_polygon(pts: np.ndarray, poly: np.ndarray, margin: float) -> np.ndarray:
    """Points at least ``margin`` inside the convex counter-clockwise polygon."""
    ok = np.ones(pts.shape[0], bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        e = b - a
        normal = np.array([e[1], -e[0]]) / np.linalg.norm(e)  # outward for ccw
        ok &= (pts - a) @ normal <= -margin
    return ok


def _distance_to_path(pts: np.ndarray, path: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Euclidean distance of ``pts`` ``(P, 2)`` to the polyline ``path`` ``(n+1, 2)``."""
    a, b = path[:-1], path[1:]
    e = b - a
    ee = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
    out = np.empty(pts.shape[0])
    for s in range(0, pts.shape[0], chunk):
        p = pts[s:s + chunk, None, :]
        t = np.clip(np.einsum("pij,ij->pi", p - a[None], e) / ee, 0.0, 1.0)
        d = p - (a[None] + t[..., None] * e[None])
        out[s:s + chunk] = np.sqrt(np.min(np.einsum("pij,pij->pi", d, d), axis=1))
    return out


def _spacing(dist: np.ndarray, spec: _Grading) -> np.ndarray:
    return np.minimum(spec.h_far, spec.h_path + spec.grade * np.maximum(dist - spec.corridor,
                                                                          0.0))


def _hex_lattice(lo: np.ndarray, hi: np.ndarray, h: float) -> np.ndarray:
    """Hexagonal lattice of spacing ``h`` through the origin, covering ``[lo, hi]``; the
    lattice of spacing ``2h`` is a subset of it (levels nest)."""
    dy = h * math.sqrt(3) / 2
    j = np.arange(math.floor(lo[1] / dy) - 1, math.ceil(hi[1] / dy) + 2)
    i = np.arange(math.floor(lo[0] / h) - 2, math.ceil(hi[0] / h) + 3)
    ii, jj = np.meshgrid(i, j)
    x = h * (ii + 0.5 * jj)
    y = dy * jj
    pts = np.stack([x.ravel(), y.ravel()], 1)
    keep = np.all((pts >= lo - h) & (pts <= hi + h), axis=1)
    return pts[keep]


def _initial_points(poly: np.ndarray, path: np.ndarray, s: np.ndarray, g: np.ndarray,
                    spec: _Grading) -> np.ndarray:
    lo, hi = poly.min(0), poly.max(0)
    levels = max(0, math.ceil(math.log2(spec.h_far / spec.h_path)))
    pieces = []
    for lev in range(levels + 1):
        h = spec.h_path * 2**lev
        pts = _hex_lattice(lo, hi, h)
        pts = pts[_inside_polygon(pts, poly, 0.3 * h)]
        level = np.ceil(np.log2(_spacing(_distance_to_path(pts, path), spec) / spec.h_path
                                - 1e-9))
        level = np.clip(level, 0, levels)
        pieces.append(pts[level == lev] if lev < levels else pts[level >= lev])
    # the boundary: every polygon edge sampled at the local spacing
    bnd = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        length = float(np.linalg.norm(b - a))
        t = np.linspace(0.0, 1.0, max(2, math.ceil(length / (0.5 * spec.h_path)) + 1))
        cand = a + t[:, None] * (b - a)
        h = _spacing(_distance_to_path(cand, path), spec)
        keep, last = [0], 0.0
        for i in range(1, len(t) - 1):
            if (t[i] - last) * length >= h[i]:
                keep.append(i)
                last = t[i]
        bnd.append(cand[keep])
    pts = np.concatenate(pieces + bnd)
    far = (np.linalg.norm(pts - s, axis=1) > 0.4 * spec.h_path) & (
        np.linalg.norm(pts - g, axis=1) > 0.4 * spec.h_path)
    return np.concatenate([s[None], g[None], pts[far]])


class _Mesh:
    """Delaunay triangulation with P2 unknowns: vertices, then one per edge (midpoint).

    ``region``: a mask of the triangles to keep, from their corners ``(T, 3, 2)`` (the
    others are dropped like slivers: no rows, no unknowns on their edges; their vertices
    keep unknowns that no row involves)."""

    def __init__(self, points: np.ndarray,
                 region: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        from scipy.spatial import Delaunay, QhullError

        self.points = points
        try:
            self.delaunay = Delaunay(points)
        except QhullError as err:  # e.g. fewer than 3 distinct points
            raise InputError(f"certify: the mesh of {points.shape[0]} points cannot be "
                             "triangulated (is the spacing larger than the domain?)") from err
        tri = self.delaunay.simplices
        z = points[tri]
        area2 = ((z[:, 1, 0] - z[:, 0, 0]) * (z[:, 2, 1] - z[:, 0, 1])
                 - (z[:, 1, 1] - z[:, 0, 1]) * (z[:, 2, 0] - z[:, 0, 0]))
        keep = np.abs(area2) > 1e-14 * np.max(np.abs(area2))  # drop slivers of zero area
        if region is not None:
            keep &= region(z)
        self.simplex_row = np.cumsum(keep) - 1
        self.simplex_row[~keep] = -1
        tri = tri[keep]
        self.tri = tri
        nv = points.shape[0]
        local = np.array([[0, 1], [1, 2], [2, 0]])
        e = np.sort(tri[:, local].reshape(-1, 2), axis=1)
        edges, inverse = np.unique(e, axis=0, return_inverse=True)
        self.edges = edges
        self.dofs = np.concatenate([tri, nv + inverse.reshape(-1, 3)], axis=1)  # (T, 6)
        self.n_dofs = nv + edges.shape[0]
        z = points[tri]  # (T, 3, 2)
        jac = np.stack([z[:, 1] - z[:, 0], z[:, 2] - z[:, 0]], axis=2)  # columns
        inv = np.linalg.inv(jac)  # rows: grad lambda_1, grad lambda_2
        gl = np.stack([-(inv[:, 0] + inv[:, 1]), inv[:, 0], inv[:, 1]], axis=1)  # (T, 3, 2)
        # gradient of the P2 potential at vertex m: C[T, m] (2, 6) times the local unknowns
        c = np.zeros((tri.shape[0], 3, 2, 6))
        for m in range(3):
            for i in range(3):
                c[:, m, :, i] = (4.0 * (i == m) - 1.0) * gl[:, i]
            for e_idx, (i, j) in enumerate(local):
                c[:, m, :, 3 + e_idx] = 4.0 * ((j == m) * gl[:, i] + (i == m) * gl[:, j])
        self.grad = c
        # circumradius squared
        a = np.linalg.norm(z[:, 1] - z[:, 2], axis=1)
        b = np.linalg.norm(z[:, 2] - z[:, 0], axis=1)
        cc = np.linalg.norm(z[:, 0] - z[:, 1], axis=1)
        area = 0.5 * np.abs(jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0])
        self.r2 = (a * b * cc / (4.0 * area)) ** 2
        self.midpoints = 0.5 * (points[edges[:, 0]] + points[edges[:, 1]])
        self.centroids = z.mean(axis=1)

    @property
    def n_tri(self) -> int:
        return int(self.tri.shape[0])

    def gradients(self, phi: np.ndarray) -> np.ndarray:
        """Gradient of the potential at the vertices of every triangle ``(T, 3, 2)``."""
        return np.einsum("tmid,td->tmi", self.grad, phi[self.dofs])

    def locate(self, pts: np.ndarray) -> np.ndarray:
        """Triangle (row of ``tri``) holding each point, -1 if none."""
        simplex = self.delaunay.find_simplex(pts)
        return np.where(simplex >= 0, self.simplex_row[simplex], -1)

    def refine(self, marked: np.ndarray) -> np.ndarray:
        """Points of a refined mesh: the marked triangles' edge midpoints added."""
        e = np.unique(self.dofs[marked, 3:].ravel()) - self.points.shape[0]
        return np.concatenate([self.points, self.midpoints[e]])



# ----------------------------------------------------------------------------------------
# a candidate curve for the upper bound
# ----------------------------------------------------------------------------------------
def _zigzag(m: Metric, pts: np.ndarray, k: int, teeth: int = 2) -> np.ndarray | None:
    """The polyline ``pts`` ``(n+1, 2)`` with each segment whose direction ``u`` is cheaper
    as a combination ``a v_j + b v_l`` (``a, b >= 0``, two of ``k`` sampled directions;
    ``a F(z, v_j) + b F(z, v_l) < F(z, u)`` at the segment's midpoint ``z``) replaced by
    ``teeth`` zigzags along ``v_j`` and ``v_l``, projected into the domain; None if no
    segment is. Any curve's length bounds the distance from above, so the zigzag is only a
    candidate: its length is measured, not assumed."""
    ang = 2 * np.pi * np.arange(k) / k
    dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
    d = pts[1:] - pts[:-1]
    n = d.shape[0]
    length = np.linalg.norm(d, axis=1)
    mids = 0.5 * (pts[1:] + pts[:-1])
    ok = length > 0
    fv = m.F(np.repeat(mids, k, axis=0), np.tile(dirs, (n, 1)), check=False).reshape(n, k)
    u = d / np.where(ok, length, 1.0)[:, None]
    fu = m.F(mids, u, check=False)
    # every pair (j, l): solve a v_j + b v_l = u, keep a, b >= 0
    cross = dirs[:, 0][:, None] * dirs[:, 1][None] - dirs[:, 1][:, None] * dirs[:, 0][None]
    good = np.abs(cross) > 1e-9
    safe = np.where(good, cross, 1.0)
    out = [pts[:1]]
    changed = False
    for i in range(n):
        if not ok[i]:
            out.append(pts[i + 1:i + 2])
            continue
        # Cramer: a = (u x v_l) / (v_j x v_l), b = (v_j x u) / (v_j x v_l)
        ux = u[i, 0] * dirs[:, 1] - u[i, 1] * dirs[:, 0]  # u x v
        a = ux[None, :] / safe
        b = -ux[:, None] / safe
        cost = np.where(good & (a >= 0) & (b >= 0), a * fv[i][:, None] + b * fv[i][None, :],
                        np.inf)
        j, l_ = np.unravel_index(int(np.argmin(cost)), cost.shape)
        if not cost[j, l_] < fu[i] * (1 - 1e-9):
            out.append(pts[i + 1:i + 2])
            continue
        changed = True
        step_a = length[i] * a[j, l_] * dirs[j] / teeth
        step_b = length[i] * b[j, l_] * dirs[l_] / teeth
        pieces = np.tile(np.stack([step_a, step_b]), (teeth, 1))
        seg = pts[i] + np.cumsum(pieces, axis=0)
        seg[-1] = pts[i + 1]
        out.append(seg)
    if not changed:
        return None
    zig = np.concatenate(out)
    zig = np.asarray(m.domain.project(zig), dtype=np.float64)
    zig[0], zig[-1] = pts[0], pts[-1]
    return zig
