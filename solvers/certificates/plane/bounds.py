"""The bounds behind the rows of the 2-D certificate: values of F at the mesh points,
interval enclosures of F's second derivatives over each triangle, the second-order
corrections, and the rows ``b = F - corr`` themselves.

The rule each bound follows is stated in the docstring of
`solvers.certificates.plane.certificate`: ``Hz`` >= the largest eigenvalue of
``Hess_z F(., v_k)`` on a triangle, ``Ht`` >= ``d2/dt2 F(z, w(t))`` along the chord from
``v_k`` to ``v_{k+1}``, both interval enclosures (outward rounding) over the triangle's
bounding box, split into sub-boxes where they are loose.

Groups of directions. With many sampled directions (the fine preset's 512), one enclosure
per triangle and direction is most of a certificate's bound time, yet only about one row
in ten is ever tight or nearly so. `_PointData` therefore first bounds each triangle
over GROUPS of consecutive directions (arcs of at most `GROUP_ARC`; the enclosure
takes ``v`` over the box of the group's directions and the chord points and vectors over
the boxes of its chords, `_chord_boxes`), a proven bound for every direction of the
group, and `_PointData.tighten` bounds single directions on demand, keeping the
smaller of the two proven bounds. `_RowBounds` holds a mesh's rows and tightens in
place the rows the LP uses and those a potential nearly fills
(`solvers.certificates.plane.lp._solve_lp` calls it), so the LP sees the same bounds as
direction-by-direction enclosures wherever they matter. A row left at its group's bound
is only harder to satisfy: every bound the certificate reports stays proven.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from finsler.enclosures.intervals import Interval, enclose, isqrt
from finsler.errors import InputError
from finsler.lowering import LoweredFunction, lower
from finsler.metrics.base import Metric
from solvers.certificates.plane.mesh import _Mesh

__all__: list[str] = []

#: Sub-box splitting (2 x 2 per level) of triangles whose enclosures are infinite or loose.
SPLIT_DEPTH = 2
#: A triangle's box is split where its correction exceeds this fraction of F and its
#: enclosures exceed this multiple of their values at the box's centre.
SPLIT_FRACTION = 0.25
SPLIT_OVERESTIMATE = 1.5
#: Directions are bounded first in groups spanning at most this arc (2 pi / 128: the
#: default preset's 128 directions one by one, the fine preset's 512 by fours). On tuning
#: pairs fours saved 40-60 % of the fine mesh's bound time with the same
#: final gaps; at 128 directions (arcs of 11 degrees) groups of four cost more than they
#: saved (most rows then need tightening).
GROUP_ARC = 2 * math.pi / 128


def direction_group(k: int) -> int:
    """The largest divisor ``g`` of ``k`` whose arc ``2 pi g / k`` is at most
    `GROUP_ARC` (1, one direction at a time, where directions are sparser)."""
    return max([1] + [g for g in range(2, k + 1) if k % g == 0
                      and g * 2 * math.pi / k <= GROUP_ARC * (1 + 1e-12)])


# ----------------------------------------------------------------------------------------
# derivatives of F (CasADi, lowered once per metric and kept in the metric's own cache)
# ----------------------------------------------------------------------------------------
def _second_derivatives(metric: Metric) -> tuple[LoweredFunction, ...]:
    """Lowered functions whose interval enclosures bound the corrections:

    * ``(x, v) -> (h, dh)``: ``h`` the entries ``(H11, H12, H22)`` of ``Hess_x F(x, v)``,
      ``dh`` their gradients in ``x`` (``dh[2 j + i] = d h_j / d x_i``);
    * ``(x, v, d) -> (q, dq)``: ``q = d' Hess_v F(x, v) d`` (the second derivative of F
      along a chord of direction ``d``) and its gradient in ``(x, v)``;
    * ``(x, v) -> h`` and ``(x, v, d) -> q`` alone (the centres of the mean-value forms).

    Built once per metric, in `finsler.Metric.derived` (the metric's one cache of
    derived geometry). The values of F themselves are the metric's
    `lowered_F`.
    """
    return metric.derived("certify.second_derivatives",
                          lambda: _lower_second_derivatives(metric))


def _lower_second_derivatives(metric: Metric) -> tuple[LoweredFunction, ...]:
    """Build `_second_derivatives` (CasADi Hessians of the metric's own ``F``)."""
    x = ca.SX.sym("x", 2)
    v = ca.SX.sym("v", 2)
    d = ca.SX.sym("d", 2)
    f = metric.F_sx(x, v)
    hx, _ = ca.hessian(f, x)
    h = ca.vertcat(hx[0, 0], hx[0, 1], hx[1, 1])
    dh = ca.vertcat(*[ca.gradient(h[j], x) for j in range(3)])
    hv, _ = ca.hessian(f, v)
    q = ca.mtimes([d.T, hv, d])
    dq = ca.gradient(q, ca.vertcat(x, v))
    tag = metric._ident
    return (lower(ca.Function(f"certify_hz_{tag}", [x, v], [ca.densify(h), ca.densify(dh)])),
            lower(ca.Function(f"certify_ht_{tag}", [x, v, d], [ca.densify(q), ca.densify(dq)])),
            lower(ca.Function(f"certify_h_{tag}", [x, v], [ca.densify(h)])),
            lower(ca.Function(f"certify_q_{tag}", [x, v, d], [ca.densify(q)])))


def _eval_values(metric: Metric, x: np.ndarray, v: np.ndarray,
                 chunk: int = 200_000) -> np.ndarray:
    fun = metric.lowered_F
    fs = []
    for a in range(0, x.shape[0], chunk):
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            (f,) = fun(x[a:a + chunk], v[a:a + chunk])
        fs.append(np.asarray(f, float).reshape(-1))
    out = np.concatenate(fs)
    if not np.all(np.isfinite(out)):
        raise InputError(f"{metric.name}: F is not finite on the mesh (the polygon covering "
                         "the domain reaches a singularity of F?)")
    # a lower bound of the exact value: numpy's float64 F is within a few ulp of it
    return out - np.abs(out) * (16 * np.finfo(float).eps)


def _lam_max_upper(h: list[Interval]) -> np.ndarray:
    """Upper bound of the largest eigenvalue of every symmetric 2x2 matrix whose entries
    ``(H11, H12, H22)`` lie in the intervals ``h`` (increasing in H11, H22 and |H12|)."""
    a, b, c = Interval(h[0].hi), Interval(h[1].magnitude()), Interval(h[2].hi)
    lam = 0.5 * (a + c) + isqrt(0.25 * (a - c).square() + b.square())
    return lam.hi


def _centered(at_centre: Interval, slopes: list[Interval], offsets: list[Interval]) -> Interval:
    """Mean-value form ``f(c) + sum_i df/dx_i(X) (X_i - c_i)``."""
    out = at_centre
    for s, o in zip(slopes, offsets, strict=True):
        out = out + s * o
    return out


def _bounds_on_boxes(metric: Metric, lo: np.ndarray, hi: np.ndarray, v: np.ndarray,
                     w: np.ndarray, with_centre: bool = False) -> tuple[np.ndarray, ...]:
    """Enclosure upper bounds, for boxes ``[lo, hi]`` ``(M, 2)`` of points, each with a
    sampled direction ``v`` ``(M, 2)`` and the next one ``w``: ``Hz`` ``(M,)`` >=
    ``lambda_max(Hess_z F(z, v))`` and ``Ht`` ``(M,)`` >= ``d' Hess_v F(z, u) d`` for all
    ``z`` in the box and ``u`` on the chord from ``v`` to ``w`` (``d = w - v``), both >= 0
    (``inf`` where an enclosure is not finite). Each is the tighter of the natural interval
    extension and the mean-value form (interval arithmetic with outward rounding,
    `finsler.enclosures.intervals`). ``with_centre``: also the same two quantities at the box's
    centre (what the bounds would be without any variation over the box)."""
    return _bounds_on_dir_boxes(metric, lo, hi, _chord_boxes(v[None], w[None]), with_centre)


def _chord_boxes(v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Boxes ``(M, 6, 2)`` (lo, hi of the direction ``v``, of the chord points ``u`` and of
    the chord vectors ``d = w - v``) covering the chords from ``v[j]`` to ``w[j]``
    ``(G, M, 2)`` of a group of ``G`` consecutive directions (``d`` rounded outward)."""
    d = [Interval(w[..., i]) - Interval(v[..., i]) for i in range(2)]
    d_lo = np.stack([x.lo for x in d], -1).min(axis=0)
    d_hi = np.stack([x.hi for x in d], -1).max(axis=0)
    u_lo = np.minimum(v.min(axis=0), w.min(axis=0))
    u_hi = np.maximum(v.max(axis=0), w.max(axis=0))
    return np.stack([v.min(axis=0), v.max(axis=0), u_lo, u_hi, d_lo, d_hi], axis=1)


def _bounds_on_dir_boxes(metric: Metric, lo: np.ndarray, hi: np.ndarray, db: np.ndarray,
                         with_centre: bool = False) -> tuple[np.ndarray, ...]:
    """`_bounds_on_boxes` over boxes of directions too: ``Hz`` for every ``v`` of
    ``db[:, 0:2]``, ``Ht`` for every chord point ``u`` in ``db[:, 2:4]`` and chord vector
    ``d`` in ``db[:, 4:6]`` (`_chord_boxes`)."""
    fz, ft, fz_centre, ft_centre = _second_derivatives(metric)
    xbox = Interval(lo, hi)
    centre = 0.5 * (lo + hi)
    dx = [Interval(lo[:, i], hi[:, i]) - Interval(centre[:, i]) for i in range(2)]
    # Hz: Hess_z F at the sampled direction (an exact float64 vector, or a box of them)
    vl, vh = db[:, 0], db[:, 1]
    vbox = Interval(vl) if np.array_equal(vl, vh) else Interval(vl, vh)
    h_box, dh_box = enclose(fz, xbox, vbox)
    (h_c,) = enclose(fz_centre, Interval(centre), vbox)
    h = [h_box[j].intersect(_centered(h_c[j], dh_box[2 * j:2 * j + 2], dx)) for j in range(3)]
    hz = np.maximum(_lam_max_upper(h), 0.0)
    # Ht: the chords
    wl, wh = db[:, 2], db[:, 3]
    wc = 0.5 * (wl + wh)
    d = [Interval(db[:, 4, i], db[:, 5, i]) for i in range(2)]
    dw = [Interval(wl[:, i], wh[:, i]) - Interval(wc[:, i]) for i in range(2)]
    q_box, dq_box = enclose(ft, xbox, Interval(wl, wh), d)
    (q_c,) = enclose(ft_centre, Interval(centre), Interval(wc), d)
    q = q_box[0].intersect(_centered(q_c[0], dq_box, dx + dw))
    ht = np.maximum(q.hi, 0.0)
    bad = ~(np.isfinite(hz) & np.isfinite(ht))
    hz[bad] = np.inf
    ht[bad] = np.inf
    if with_centre:
        return hz, ht, np.maximum(_lam_max_upper(h_c), 0.0), np.maximum(q_c[0].hi, 0.0)
    return hz, ht


def _box_meets_triangle(lo: np.ndarray, hi: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Whether the boxes ``[lo, hi]`` ``(M, 2)`` meet the triangles ``tri`` ``(M, 3, 2)``
    (separating axes: the box's two axes and the triangle's three edge normals; touching
    counts as meeting)."""
    meets = np.all(tri.max(axis=1) >= lo, axis=1) & np.all(tri.min(axis=1) <= hi, axis=1)
    corners = np.stack([lo, np.stack([hi[:, 0], lo[:, 1]], 1), hi,
                        np.stack([lo[:, 0], hi[:, 1]], 1)], axis=1)  # (M, 4, 2)
    for a in range(3):
        p, q, r = tri[:, a], tri[:, (a + 1) % 3], tri[:, (a + 2) % 3]
        normal = np.stack([q[:, 1] - p[:, 1], p[:, 0] - q[:, 0]], 1)
        side = np.einsum("mi,mi->m", r - p, normal)  # the third vertex's side
        proj = np.einsum("mci,mi->mc", corners - p[:, None], normal)
        beyond = np.where(side[:, None] > 0, proj < 0, proj > 0)  # opposite to the vertex
        meets &= ~np.all(beyond, axis=1)
    return meets


def _index_new(keys: list[bytes], index: dict[bytes, int]) -> list[int]:
    """Give the keys not yet in ``index`` the next row numbers; their positions in
    ``keys`` (in order, each key once)."""
    new = []
    for i, key in enumerate(keys):
        if key not in index:
            index[key] = len(index)
            new.append(i)
    return new


class _PointData:
    """Per-point values ``F(p, v_k)`` ``(K,)`` (lowered by a few ulp), computed once per
    point and reused across refinement rounds, and per-triangle second-order bounds
    (`_bounds_on_boxes` on the triangle's bounding box; where a direction's
    correction is above ``SPLIT_FRACTION`` of F and its enclosure above
    ``SPLIT_OVERESTIMATE`` times its centre value (or infinite), on the 2 x 2 sub-boxes
    that meet the triangle, down to ``SPLIT_DEPTH`` levels), cached by the triangle's
    vertices. ``group``: the bounds are first taken over groups of that many consecutive
    directions (`_chord_boxes`; ``tight`` marks the elements since bounded one
    direction at a time by `tighten`). A group's chord boxes must stay clear of the
    origin (arcs well below 90 degrees): `direction_group` keeps them at most 2.8
    degrees."""

    def __init__(self, metric: Metric, k: int, group: int = 1) -> None:
        self.metric = metric
        ang = 2 * np.pi * np.arange(k) / k
        self.dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
        if group < 1 or k % group:
            raise InputError(f"direction group {group} must divide the {k} directions")
        self.group = group
        # boxes of the groups' directions and chords (one bound per triangle and group)
        idx = np.arange(k).reshape(-1, group).T  # (G, K / G)
        self.dbox = _chord_boxes(self.dirs[idx], self.dirs[(idx + 1) % k])
        self.dbox1 = _chord_boxes(self.dirs[None], np.roll(self.dirs, -1, axis=0)[None])
        self.corners = np.zeros((0, 3, 2))
        self.r2 = np.zeros(0)
        self.tight = np.zeros((0, k), bool)
        self.index: dict[bytes, int] = {}
        self.F = np.zeros((0, k))
        self.tri_index: dict[bytes, int] = {}
        self.Hz = np.zeros((0, k))
        self.Ht = np.zeros((0, k))
        self.seconds = 0.0

    def rows(self, pts: np.ndarray) -> np.ndarray:
        """Row indices of ``pts`` ``(P, 2)``, computing the values of new points."""
        keys = [p.tobytes() for p in np.ascontiguousarray(pts)]
        new = _index_new(keys, self.index)
        if new:
            t0 = time.perf_counter()
            p = pts[new]
            k = self.dirs.shape[0]
            f = _eval_values(self.metric, np.repeat(p, k, axis=0),
                             np.tile(self.dirs, (len(new), 1)))
            self.F = np.concatenate([self.F, f.reshape(len(new), k)])
            self.seconds += time.perf_counter() - t0
        return np.fromiter((self.index[key] for key in keys), dtype=np.int64, count=len(keys))

    def triangle_bounds(self, corners: np.ndarray, fmin: np.ndarray, r2: np.ndarray,
                        chunk: int = 32768) -> tuple[np.ndarray, np.ndarray]:
        """``Hz``, ``Ht`` ``(T, K)`` of the triangles with vertices ``corners`` ``(T, 3, 2)``,
        circumradii squared ``r2`` ``(T,)`` and smallest vertex values ``fmin`` ``(T, K)``
        of F."""
        rows = self.triangle_rows(corners, fmin, r2, chunk)
        return self.Hz[rows], self.Ht[rows]

    def triangle_rows(self, corners: np.ndarray, fmin: np.ndarray, r2: np.ndarray,
                      chunk: int = 32768) -> np.ndarray:
        """Row indices of the triangles in ``Hz``, ``Ht``, computing new ones."""
        srt = np.sort(np.ascontiguousarray(corners).view(np.complex128)[..., 0], axis=1)
        keys = [row.tobytes() for row in srt]
        new = _index_new(keys, self.tri_index)
        if new:
            t0 = time.perf_counter()
            k = self.dirs.shape[0]
            n, grp = len(new), self.group
            ng = k // grp
            tri = np.repeat(corners[new], ng, axis=0)  # (n K/G, 3, 2): (triangle, group)
            kidx = np.tile(np.arange(ng), n)
            fm = fmin[new].reshape(n, ng, grp).min(axis=2).reshape(-1)
            rr = np.repeat(r2[new], ng)
            hz = np.empty(n * ng)
            ht = np.empty(n * ng)
            for a in range(0, n * ng, chunk):
                sl = slice(a, a + chunk)
                hz[sl], ht[sl] = self._split_bounds(tri[sl].min(axis=1), tri[sl].max(axis=1),
                                                    tri[sl], kidx[sl], fm[sl], rr[sl], 0)
            hz = np.repeat(hz.reshape(n, ng), grp, axis=1)
            ht = np.repeat(ht.reshape(n, ng), grp, axis=1)
            self.Hz = np.concatenate([self.Hz, hz.reshape(n, k)])
            self.Ht = np.concatenate([self.Ht, ht.reshape(n, k)])
            self.tight = np.concatenate([self.tight, np.full((n, k), grp == 1)])
            self.corners = np.concatenate([self.corners, corners[new]])
            self.r2 = np.concatenate([self.r2, r2[new]])
            self.seconds += time.perf_counter() - t0
        return np.fromiter((self.tri_index[key] for key in keys), dtype=np.int64,
                           count=len(keys))

    def tighten(self, rows: np.ndarray, kk: np.ndarray, fmin: np.ndarray,
                chunk: int = 32768) -> np.ndarray:
        """Bound the elements (triangle row ``rows``, direction ``kk``) ``(M,)`` direction by
        direction where they hold their group's bound (smallest vertex values ``fmin``
        ``(M,)``), keeping the smaller of the two (both are proven) -> mask of the
        elements changed."""
        todo = ~self.tight[rows, kk]
        if not np.any(todo):
            return todo
        t0 = time.perf_counter()
        key = np.unique(rows[todo] * self.dirs.shape[0] + kk[todo], return_index=True)[1]
        idx = np.flatnonzero(todo)[key]
        r, k_, fm = rows[idx], kk[idx], fmin[idx]
        tri = self.corners[r]
        hz = np.empty(idx.size)
        ht = np.empty(idx.size)
        for a in range(0, idx.size, chunk):
            sl = slice(a, a + chunk)
            hz[sl], ht[sl] = self._split_bounds(tri[sl].min(axis=1), tri[sl].max(axis=1),
                                                tri[sl], k_[sl], fm[sl], self.r2[r[sl]], 0,
                                                self.dbox1)
        self.Hz[r, k_] = np.minimum(self.Hz[r, k_], hz)
        self.Ht[r, k_] = np.minimum(self.Ht[r, k_], ht)
        self.tight[r, k_] = True
        self.seconds += time.perf_counter() - t0
        return todo

    def _split_bounds(self, lo: np.ndarray, hi: np.ndarray, tri: np.ndarray, kidx: np.ndarray,
                      fmin: np.ndarray, r2: np.ndarray, depth: int,
                      dbox: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of elements ``(M,)``: box ``[lo, hi]`` within triangle ``tri``, direction
        ``kidx``; a loose element is bounded by the max over its sub-boxes meeting the
        triangle."""
        dbox = self.dbox if dbox is None else dbox
        hz, ht, hz_c, ht_c = _bounds_on_dir_boxes(self.metric, lo, hi, dbox[kidx],
                                                  with_centre=True)
        if depth >= SPLIT_DEPTH:
            return hz, ht
        with np.errstate(invalid="ignore"):
            # split where the correction matters AND the enclosure overestimates (where F
            # truly curves that much, smaller boxes cannot help: the mesh is refined instead)
            large = ~(0.5 * hz * r2 + ht / 8.0 <= SPLIT_FRACTION * fmin)
            over = ~((hz <= SPLIT_OVERESTIMATE * hz_c + 1e-12 * fmin)
                     & (ht <= SPLIT_OVERESTIMATE * ht_c + 1e-12 * fmin))
            loose = large & over
        if not np.any(loose):
            return hz, ht
        idx = np.flatnonzero(loose)
        lo_l, hi_l = lo[idx], hi[idx]
        mid = 0.5 * (lo_l + hi_l)
        sub_lo, sub_hi, parent = [], [], []
        for ax, bx in ((lo_l[:, 0], mid[:, 0]), (mid[:, 0], hi_l[:, 0])):
            for ay, by in ((lo_l[:, 1], mid[:, 1]), (mid[:, 1], hi_l[:, 1])):
                sl, sh = np.stack([ax, ay], 1), np.stack([bx, by], 1)
                keep = _box_meets_triangle(sl, sh, tri[idx])
                sub_lo.append(sl[keep])
                sub_hi.append(sh[keep])
                parent.append(idx[keep])
        par = np.concatenate(parent)
        shz, sht = self._split_bounds(np.concatenate(sub_lo), np.concatenate(sub_hi),
                                      tri[par], kidx[par], fmin[par], r2[par], depth + 1,
                                      dbox)
        hz[idx] = -np.inf
        ht[idx] = -np.inf
        np.maximum.at(hz, par, shz)
        np.maximum.at(ht, par, sht)
        return hz, ht


# ----------------------------------------------------------------------------------------
# the rows of the LP
# ----------------------------------------------------------------------------------------
def _row_bounds(mesh: _Mesh, data: _PointData) -> tuple[np.ndarray, np.ndarray]:
    """Right-hand sides ``b`` ``(T, 3, K)`` and the corrections ``c`` ``(T, K)`` (infinite
    where the enclosures are)."""
    rb = _RowBounds(mesh, data)
    return rb.b, rb.corr


class _RowBounds:
    """The rows of a mesh: ``b`` ``(T, 3, K)`` and ``corr`` ``(T, K)`` from the data's
    bounds (by groups of directions), tightened in place by `tighten`."""

    def __init__(self, mesh: _Mesh, data: _PointData) -> None:
        vert_rows = data.rows(mesh.points)
        self.f = data.F[vert_rows[mesh.tri]]  # (T, 3, K)
        self.r2 = mesh.r2
        self.data = data
        self.trows = data.triangle_rows(mesh.points[mesh.tri], self.f.min(axis=1), mesh.r2)
        with np.errstate(invalid="ignore"):
            self.corr = _corrections(data.Hz[self.trows], data.Ht[self.trows], mesh.r2)
        self.b = self.f - self.corr[:, None, :]

    def tighten(self, tri: np.ndarray, kk: np.ndarray) -> None:
        """Direction-by-direction bounds for the rows (triangle ``tri``, direction ``kk``)
        (and the chord before each, whose ``Ht`` the row's correction also takes); ``b``
        and ``corr`` of the triangles touched are updated in place."""
        k = self.b.shape[2]
        t = np.concatenate([tri, tri])
        kk = np.concatenate([kk, (kk - 1) % k])
        changed = self.data.tighten(self.trows[t], kk, self.f[t, :, kk].min(axis=1))
        if not np.any(changed):
            return
        ts = np.unique(t[changed])
        with np.errstate(invalid="ignore"):
            self.corr[ts] = _corrections(self.data.Hz[self.trows[ts]],
                                         self.data.Ht[self.trows[ts]], self.r2[ts])
        self.b[ts] = self.f[ts] - self.corr[ts][:, None, :]


def _corrections(hz: np.ndarray, ht: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """``Hz R**2 / 2 + max(Ht_{k-1}, Ht_k) / 8`` ``(T, K)``, inflated for the float64
    rounding of this line and of ``R**2``."""
    corr = 0.5 * hz * r2[:, None] + np.maximum(ht, np.roll(ht, 1, axis=1)) / 8.0
    return corr * (1.0 + 1e-12)
