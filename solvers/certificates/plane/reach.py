"""The region a short path can reach, for `solvers.certificates.plane.certificate.certify_plane`.

The dual bound needs ``dphi(v) <= F(z, v)`` only where a curve from ``x`` to ``y`` no
longer than the upper bound ``U`` can go. With a PROVEN speed floor ``F(z, v) >= m |v|``
on the whole domain, ``d(x, z) >= m |z - x|``, so a point ``z`` with
``m (|z - x| + |y - z|) > U`` lies on no such curve. A potential that satisfies the rows on
every triangle that meets the ellipse ``|z - x| + |y - z| <= U / m`` proves
``min(phi(y) - phi(x), U) <= d(x, y)``: if a curve were shorter than that, it would be no
longer than ``U`` and so would stay in those triangles, where ``phi`` grows along it by at
most its length. The triangles outside need no rows and no enclosures.

The floor ``m`` is the smallest lower end of interval enclosures (`finsler.enclosures.intervals`,
outward rounding) of ``F(z, u)`` over a grid of boxes covering the domain's outline times
boxes of arcs of unit directions ``u`` (any unit ``u`` lies in one), built once per metric
(`finsler.Metric.derived`). Where an enclosure is not finite or not positive the
floor is 0 and nothing is pruned.
"""

from __future__ import annotations

import math

import numpy as np

from finsler.enclosures.intervals import Interval, enclose
from finsler.metrics.base import Metric

__all__ = ["reachable_triangles", "speed_floor"]

#: Boxes per side of the grid over the outline, and arcs of unit directions.
FLOOR_CELLS = 32
FLOOR_ARCS = 64
#: Bisections (x, y and the arc in half) of the boxes whose enclosure ends below
#: ``FLOOR_TARGET`` times the smallest value at the boxes' centres.
FLOOR_DEPTH = 4
FLOOR_TARGET = 0.95
#: Relative margin on ``U / m`` (the float64 rounding of the distances compared to it).
MARGIN = 1e-9


def speed_floor(metric: Metric, poly: np.ndarray) -> float:
    """Proven ``m >= 0`` with ``F(z, u) >= m`` for every ``z`` of the convex polygon
    ``poly`` ``(M, 2)`` (counter-clockwise) and every unit vector ``u``."""
    key = "certify.speed_floor." + np.ascontiguousarray(poly, float).tobytes().hex()
    return metric.derived(key, lambda: _speed_floor(metric, poly))


def _speed_floor(metric: Metric, poly: np.ndarray, cells: int = FLOOR_CELLS,
                 arcs: int = FLOOR_ARCS, depth: int = FLOOR_DEPTH) -> float:
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    edges = [np.linspace(lo[i], hi[i], cells + 1) for i in range(2)]
    edges[0][-1], edges[1][-1] = hi[0], hi[1]
    ix, iy = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    blo = np.stack([edges[0][ix.ravel()], edges[1][iy.ravel()]], 1)
    bhi = np.stack([edges[0][ix.ravel() + 1], edges[1][iy.ravel() + 1]], 1)
    meets = _boxes_meet_polygon(blo, bhi, poly)
    blo, bhi = blo[meets], bhi[meets]
    n_box = blo.shape[0]
    # arcs [a0, a1] of angles (multiples of 2 pi / arcs: the axes are arc ends)
    a0 = np.tile(2 * np.pi * np.arange(arcs) / arcs, n_box)
    a1 = np.tile(2 * np.pi * (np.arange(arcs) + 1) / arcs, n_box)
    blo, bhi = np.repeat(blo, arcs, axis=0), np.repeat(bhi, arcs, axis=0)
    # the target: a little below the smallest value at the boxes' centres
    centre = 0.5 * (a0 + a1)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        (f_c,) = metric.lowered_F(0.5 * (blo + bhi), np.stack([np.cos(centre),
                                                               np.sin(centre)], 1))
    f_c = np.asarray(f_c, float).reshape(-1)
    if f_c.size == 0 or not np.all(np.isfinite(f_c)) or f_c.min() <= 0:
        return 0.0
    target = FLOOR_TARGET * float(f_c.min())
    floor = np.inf
    for level in range(depth + 1):
        low = _enclose_low(metric, blo, bhi, a0, a1)
        low = np.where(np.isfinite(low), low, -np.inf)
        loose = low < target
        floor = min(floor, float(low[~loose].min(initial=np.inf)))
        if not np.any(loose):
            break
        if level == depth:
            floor = min(floor, float(low[loose].min()))
            break
        # split the loose boxes in half along x, y and the arc: 8 children each
        blo, bhi, a0, a1 = blo[loose], bhi[loose], a0[loose], a1[loose]
        mid, am = 0.5 * (blo + bhi), 0.5 * (a0 + a1)
        kids = []
        for xs in ((blo[:, 0], mid[:, 0]), (mid[:, 0], bhi[:, 0])):
            for ys in ((blo[:, 1], mid[:, 1]), (mid[:, 1], bhi[:, 1])):
                for arc in ((a0, am), (am, a1)):
                    kids.append((np.stack([xs[0], ys[0]], 1), np.stack([xs[1], ys[1]], 1),
                                 arc[0], arc[1]))
        blo, bhi, a0, a1 = (np.concatenate([k[i] for k in kids]) for i in range(4))
    return max(floor, 0.0) if math.isfinite(floor) else 0.0


def _enclose_low(metric: Metric, blo: np.ndarray, bhi: np.ndarray, a0: np.ndarray,
                 a1: np.ndarray) -> np.ndarray:
    """Lower ends of enclosures of ``F(z, u)`` over the boxes ``[blo, bhi]`` of points
    times the arcs ``[a0, a1]`` of angles (no axis inside an arc: the box of an arc is
    the box of its two ends, widened for the rounding of cos and sin)."""
    ends = [np.stack([np.cos(a), np.sin(a)], 1) for a in (a0, a1)]
    alo = np.minimum(ends[0], ends[1]) - 4e-16
    ahi = np.maximum(ends[0], ends[1]) + 4e-16
    (f,) = enclose(metric.lowered_F, Interval(blo, bhi), Interval(alo, ahi))
    return np.asarray(f[0].lo, float).reshape(-1) * np.ones(blo.shape[0])


def _boxes_meet_polygon(lo: np.ndarray, hi: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Whether the boxes ``[lo, hi]`` ``(N, 2)`` meet the convex counter-clockwise polygon
    (separating axes: the polygon's edge normals; the boxes lie in its bounding box)."""
    corners = np.stack([lo, np.stack([hi[:, 0], lo[:, 1]], 1), hi,
                        np.stack([lo[:, 0], hi[:, 1]], 1)], axis=1)  # (N, 4, 2)
    meets = np.ones(lo.shape[0], bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        normal = np.array([b[1] - a[1], a[0] - b[0]])  # outward for ccw
        meets &= ~np.all((corners - a) @ normal > 0, axis=1)
    return meets


def _distance_to_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Euclidean distance of the point ``p`` ``(2,)`` to the closed triangles ``tri``
    ``(T, 3, 2)`` (0 inside)."""
    best = np.full(tri.shape[0], np.inf)
    for i in range(3):
        a, b = tri[:, i], tri[:, (i + 1) % 3]
        e = b - a
        ee = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
        t = np.clip(np.einsum("ij,ij->i", p - a, e) / ee, 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (a + t[:, None] * e), axis=1))
    # inside: the point is on the same side of the three edges
    cross = [(tri[:, (i + 1) % 3, 0] - tri[:, i, 0]) * (p[1] - tri[:, i, 1])
             - (tri[:, (i + 1) % 3, 1] - tri[:, i, 1]) * (p[0] - tri[:, i, 0])
             for i in range(3)]
    inside = (np.all(np.stack(cross) >= 0, axis=0) | np.all(np.stack(cross) <= 0, axis=0))
    return np.where(inside, 0.0, best)


def reachable_triangles(corners: np.ndarray, start: np.ndarray, goal: np.ndarray,
                        reach: float) -> np.ndarray:
    """Mask ``(T,)`` of the triangles ``corners`` ``(T, 3, 2)`` that may hold a point
    ``z`` with ``|z - start| + |goal - z| <= reach`` (kept unless the distances to the two
    triangles' closest points already add up to more; ``reach`` infinite keeps all)."""
    if not math.isfinite(reach):
        return np.ones(corners.shape[0], bool)
    near = _distance_to_triangles(start, corners) + _distance_to_triangles(goal, corners)
    return near <= reach * (1.0 + MARGIN)
