"""The pieces of `solvers.certificates.nd.certificate.certify_nd`: the sampled directions,
the graded point cloud and its Delaunay cells, the rigorous lower bounds of F over a cell,
the cell-by-cell verification of a potential, and the LP.

Directions are points ``w`` of the surface of the cube ``[-1, 1]**n`` (every nonzero
vector is a positive multiple of one; both sides of ``g . v <= F(z, v)`` are 1-homogeneous
in ``v``). Enclosures are `finsler.enclosures.intervals.enclose` of the metric's own ``F`` and of
its gradient in ``v`` (lowered CasADi, outward rounding): where ``F`` is not smooth (the
car-like metric's ``max`` and ``abs``) the interval programs of the derivative take the
hull of both branches where the branch is uncertain on the box, which contains Clarke's
generalised gradient, so the mean-value form below stays valid.

Nothing here imports `solvers.certificates.nd.certificate`.
"""

from __future__ import annotations

import itertools
import time
from typing import Any

import casadi as ca
import numpy as np

from finsler.enclosures.intervals import Interval, enclose
from finsler.errors import InputError, short
from finsler.lowering import LoweredFunction, lower, max_through_abs
from finsler.metrics.base import Metric

#: cvxpy solver of the LPs (as the 2-D certificate).
LP_SOLVER = "CLARABEL"
_EPS = float(np.finfo(float).eps)


class LPFailure(RuntimeError):
    """The LP solver failed (turned into `solvers.CertifyStatus.LP_FAILED`)."""


# ----------------------------------------------------------------------------------------
# directions, points, cells
# ----------------------------------------------------------------------------------------
def cube_directions(n: int, q: int) -> np.ndarray:
    """The points of the grid ``linspace(-1, 1, q + 1)**n`` on the cube's surface
    ``(M, n)``."""
    t = np.linspace(-1.0, 1.0, q + 1)
    grid = np.stack(np.meshgrid(*([t] * n), indexing="ij"), -1).reshape(-1, n)
    return grid[np.max(np.abs(grid), axis=1) == 1.0]


def face_boxes(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The cube's surface cut into ``2 n k**(n-1)`` boxes ``(lo, hi)`` ``(P, n)`` (one
    coordinate fixed at +-1)."""
    edges = np.linspace(-1.0, 1.0, k + 1)
    lo, hi = [], []
    for axis in range(n):
        for sign in (-1.0, 1.0):
            for idx in itertools.product(range(k), repeat=n - 1):
                a = np.empty(n)
                b = np.empty(n)
                a[axis] = b[axis] = sign
                others = [i for i in range(n) if i != axis]
                for o, i in zip(others, idx, strict=True):
                    a[o], b[o] = edges[i], edges[i + 1]
                lo.append(a)
                hi.append(b)
    return np.array(lo), np.array(hi)


def distance_to_path(pts: np.ndarray, path: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """Euclidean distance of ``pts`` ``(P, n)`` to the polyline ``path`` ``(m+1, n)``."""
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


def point_cloud(lo: np.ndarray, hi: np.ndarray, path: np.ndarray, h_path: float,
                corridor: float, h_far: float, rng: np.random.Generator) -> np.ndarray:
    """Points whose Delaunay cells cover the box ``[lo, hi]`` (the domain's bounding box):
    the corners of the box widened by ``h_far / 2`` (exact), lattices of spacing ``h_far``,
    ``h_far / 2``, ... down to ``h_path``, each kept within a band around the path
    (``corridor`` for the finest, doubling outward), jittered by up to 0.15 of their
    spacing (no degenerate cells: generic positions)."""
    n = lo.size
    pad = 0.5 * h_far
    a, b = lo - pad, hi + pad
    corners = np.array(list(itertools.product(*zip(a, b, strict=True))), float)
    pts = [corners]
    h = h_far
    levels = []
    while True:
        levels.append(h)
        if h <= h_path * (1 + 1e-9):
            break
        h = max(h / 2.0, h_path)
    for i, h in enumerate(levels):
        counts = np.maximum(np.ceil((b - a) / h).astype(int), 1)
        axes = [np.linspace(a[j], b[j], counts[j] + 1) for j in range(n)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, n)
        if i > 0:
            band = corridor * 2.0 ** (len(levels) - 1 - i)
            grid = grid[distance_to_path(grid, path) <= band + h]
        grid = grid + rng.uniform(-0.15, 0.15, grid.shape) * h
        pts.append(grid)
    out = np.concatenate(pts)
    keep = np.all((out >= a) & (out <= b), axis=1)
    return out[keep]


class Cells:
    """Delaunay simplices of a point set with the gradient of the piecewise-linear
    potential on each as a linear map of its ``n + 1`` vertex values (``coef`` ``(T, n,
    n+1)``), and each cell's box ``[zlo, zhi]`` clipped to the domain's bounding box."""

    def __init__(self, points: np.ndarray, blo: np.ndarray, bhi: np.ndarray) -> None:
        from scipy.spatial import Delaunay

        self.tri = Delaunay(points)
        self.points = self.tri.points
        self.simp = self.tri.simplices.astype(np.int64)
        x = self.points[self.simp]  # (T, n+1, n)
        e = x[:, 1:] - x[:, :1]
        det = np.linalg.det(e)
        vol_scale = np.prod(np.max(np.abs(e), axis=1), axis=1)
        self.flat = np.abs(det) <= 1e-10 * vol_scale
        e_safe = np.where(self.flat[:, None, None], np.eye(e.shape[1]), e)
        ginv = np.linalg.inv(e_safe)  # g = ginv @ (phi_1..n - phi_0)
        self.e = e_safe
        self.coef = np.concatenate([-ginv.sum(axis=2, keepdims=True), ginv], axis=2)
        self.zlo = np.maximum(x.min(axis=1), blo)
        self.zhi = np.minimum(x.max(axis=1), bhi)
        self.inside = np.all(self.zlo <= self.zhi, axis=1)  # meets the bounding box
        self.centroid = x.mean(axis=1)

    @property
    def n_cells(self) -> int:
        return int(self.simp.shape[0])

    def weights(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vertex indices and barycentric weights of the point ``p`` ``(n,)``."""
        s = int(self.tri.find_simplex(p[None])[0])
        if s < 0:
            raise InputError("a point lies outside the certification mesh")
        t = self.tri.transform[s]
        bary = t[:-1] @ (p - t[-1])
        return self.simp[s], np.append(bary, 1.0 - bary.sum())

    def gradients(self, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gradients ``(T, n)`` of the potential and a bound ``(T,)`` of their error in
        the 2-norm (a posteriori: the residual of ``E g = dphi`` times ``|E^-1|``)."""
        vals = phi[self.simp]
        dphi = vals[:, 1:] - vals[:, :1]
        g = np.einsum("tij,tj->ti", self.coef[:, :, 1:], dphi)
        r = np.einsum("tij,tj->ti", self.e, g) - dphi
        n = g.shape[1]
        rnorm = (np.linalg.norm(r, axis=1) + 4 * n * _EPS * (
            np.linalg.norm(self.e, axis=(1, 2)) * np.linalg.norm(g, axis=1)
            + np.linalg.norm(dphi, axis=1)) + 4 * _EPS * np.abs(vals).max(axis=1))
        inv_norm = np.linalg.norm(self.coef[:, :, 1:], axis=(1, 2))
        return g, 2.0 * inv_norm * rnorm * (1 + 1e-6)


def reached(upper: float, lower: float, target: float) -> bool:
    """The target gap is reached (never with an infinite upper bound)."""
    return bool(np.isfinite(upper) and upper - lower <= target * upper)


def box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Euclidean distance of the point ``p`` to each box, rounded down."""
    d = np.linalg.norm(p - np.clip(p, lo, hi), axis=1)
    return d * (1 - 1e-12)


def round_record(result: dict[str, Any], upper: float, t_start: float) -> dict[str, Any]:
    """What a mesh round reports (``NDResult.rounds``), from the round's best LP result."""
    return {"cells": result["cells"], "relevant_cells": result["rel"],
            "vertices": result["vertices"], "rows": result["rows"],
            "lp_value": result["dphi"], "verified_ratio": result["R"],
            "verify_boxes": result["ver"]["boxes"], "verify_open": result["ver"]["open"],
            "lower": result["lower"], "gap": (upper - result["lower"]) / upper,
            "seconds": time.perf_counter() - t_start}


def build_cells(points: np.ndarray, blo: np.ndarray, bhi: np.ndarray,
                rng: np.random.Generator, h: float) -> Cells:
    """`Cells` of ``points`` whose last two (start and goal) stay put; flat cells
    inside the box (degenerate positions) are removed by moving the others by up to
    ``1e-6 h`` (up to three tries)."""
    cells = Cells(points, blo, bhi)
    for _try in range(3):
        if not np.any(cells.flat & cells.inside):
            break
        fixed = np.zeros(points.shape[0], bool)
        fixed[-2:] = True
        points = points + np.where(fixed[:, None], 0.0,
                                   rng.uniform(-1e-6, 1e-6, points.shape) * h)
        cells = Cells(points, blo, bhi)
    return cells


def add_points(points: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``points`` with ``new`` inserted before the last two (start and goal), which
    `build_cells` keeps in place."""
    return np.concatenate([points[:-2], new, points[-2:]])


# ----------------------------------------------------------------------------------------
# enclosures
# ----------------------------------------------------------------------------------------
def lowered_f_grad(metric: Metric) -> tuple[LoweredFunction, LoweredFunction]:
    """``(x, v) -> F`` and ``(x, v) -> (F, grad_v F)`` lowered once per metric, with
    ``max``/``min`` written through ``abs`` (`finsler.lowering.max_through_abs`: the
    enclosure of the gradient across a kink stays bounded)."""
    def build() -> tuple[LoweredFunction, LoweredFunction]:
        x = ca.SX.sym("x", metric.dim)
        v = ca.SX.sym("v", metric.dim)
        f = max_through_abs(ca.Function("f", [x, v], [metric.F_sx(x, v)]))(x, v)
        gv = ca.gradient(f, v)
        tag = metric._ident
        return (lower(ca.Function(f"cnd_f_{tag}", [x, v], [f])),
                lower(ca.Function(f"cnd_fg_{tag}", [x, v], [f, ca.densify(gv)])))
    return metric.derived("certify_nd.f_grad", build)


def f_lower(fn: LoweredFunction, zlo: np.ndarray, zhi: np.ndarray, wlo: np.ndarray,
            whi: np.ndarray, chunk: int = 400_000) -> np.ndarray:
    """Proven lower bounds ``(N,)`` of ``F`` over the boxes ``Z x W`` (rows broadcast)."""
    n = max(zlo.shape[0], wlo.shape[0])
    zlo, zhi = np.broadcast_to(zlo, (n, zlo.shape[1])), np.broadcast_to(zhi, (n, zlo.shape[1]))
    wlo, whi = np.broadcast_to(wlo, (n, wlo.shape[1])), np.broadcast_to(whi, (n, wlo.shape[1]))
    out = np.empty(n)
    for a in range(0, n, chunk):
        sl = slice(a, a + chunk)
        with np.errstate(all="ignore"):
            f = enclose(fn, Interval(zlo[sl], zhi[sl]), Interval(wlo[sl], whi[sl]))[0]
        out[sl] = f[0].lo
    return np.where(np.isnan(out), -np.inf, out)


def scale_lower_bound(fn: LoweredFunction, blo: np.ndarray, bhi: np.ndarray,
                      split: int = 6, faces: int = 6) -> float:
    """A proven ``m > 0`` (or 0) with ``F(z, v) >= m |v|`` for every ``z`` in the box
    ``[blo, bhi]`` and every ``v``: the smallest lower bound of F over ``split**n`` sub-boxes
    x the cube's surface in ``2 n faces**(n-1)`` pieces, divided by ``sqrt(n)``
    (``|v|_inf >= |v| / sqrt(n)``)."""
    n = blo.size
    edges = [np.linspace(blo[i], bhi[i], split + 1) for i in range(n)]
    idx = np.array(list(itertools.product(range(split), repeat=n)))
    zlo = np.stack([edges[i][idx[:, i]] for i in range(n)], 1)
    zhi = np.stack([edges[i][idx[:, i] + 1] for i in range(n)], 1)
    wlo, whi = face_boxes(n, faces)
    zl, wl = np.repeat(zlo, wlo.shape[0], 0), np.tile(wlo, (zlo.shape[0], 1))
    zh, wh = np.repeat(zhi, wlo.shape[0], 0), np.tile(whi, (zlo.shape[0], 1))
    m = float(np.min(f_lower(fn, zl, zh, wl, wh)))
    return max(m, 0.0) / np.sqrt(n) * (1 - 1e-12)


# ----------------------------------------------------------------------------------------
# verification of a potential, cell by cell
# ----------------------------------------------------------------------------------------
def verify(fg: LoweredFunction, zlo: np.ndarray, zhi: np.ndarray, g: np.ndarray,
           gerr: np.ndarray, r_start: float, tol: float, start_faces: int = 4,
           max_depth: int = 9, max_elements: int = 3_000_000) -> dict[str, Any]:
    """A proven ``R`` with ``g_T . v <= R F(z, v)`` for every cell ``T`` (rows of ``zlo``,
    ``zhi``, ``g`` ``(T, n)``; ``gerr`` bounds the error of ``g`` in the 2-norm), every
    ``z`` in its box and every ``v``. ``r_start``: the LP's largest ratio on its rows.

    Branch and bound over the cube's surface: on a box ``B`` (centre ``c``) of directions,
    ``h(z, w) = g . w - R F(z, w)`` is at most ``h(Z, c) + (g - R grad_v F(Z, B)) . (B - c)``
    (mean-value form: second order where ``g`` touches the dual ball, so boxes near the
    tangency are decided after a few splits). ``R`` starts at ``r_start (1 + tol)`` and
    rises to ``(1 + tol)`` x the largest ratio seen at a box's centre; boxes where the bound
    is ``<= 0`` are done; the others are split in four (each free coordinate in two),
    up to ``max_depth`` levels or ``max_elements`` boxes; what is left is bounded by the
    ratio ``max_B (g . w) / min_{Z x B} F`` (first order). Returns ``R`` (the larger of
    the target and those ratios), the centres whose ratio exceeded ``r_start (1 + tol)``
    (``cuts``: cell, direction, ratio; rows for the next LP) and counts."""
    n = g.shape[1]
    wlo0, whi0 = face_boxes(n, start_faces)
    cell = np.repeat(np.arange(g.shape[0]), wlo0.shape[0])
    wlo, whi = np.tile(wlo0, (g.shape[0], 1)), np.tile(whi0, (g.shape[0], 1))
    r_fail = -np.inf
    boxes = 0
    cuts_cell: list[np.ndarray] = []
    cuts_dir: list[np.ndarray] = []
    cuts_ratio: list[np.ndarray] = []
    r_target = r_start * (1.0 + tol)
    cut_above = r_start * (1.0 + tol)
    depth = 0
    t0 = time.perf_counter()
    zl, zh = zlo[cell], zhi[cell]
    while cell.size:
        boxes += cell.size
        c = 0.5 * (wlo + whi)
        point = _point_ratio(fg, zl, zh, g[cell], c)
        cut = point > cut_above
        if np.any(cut):
            cuts_cell.append(cell[cut])
            cuts_dir.append(c[cut])
            cuts_ratio.append(point[cut])
        # the target rises to what the centres show (a box proven for a smaller R stays
        # proven for a larger one: F >= 0)
        r_target = max(r_target, float(np.max(point)) * (1.0 + tol))
        h = _upper_h(fg, zl, zh, g[cell], gerr[cell], wlo, whi, c,
                     Interval(np.float64(r_target)))
        open_ = ~(h <= 0.0)
        final = depth >= max_depth or int(open_.sum()) * 2 ** n > max_elements
        if final and np.any(open_):
            ratio, _ = _ratio_bound(fg, zl[open_], zh[open_], g[cell[open_]],
                                    gerr[cell[open_]], wlo[open_], whi[open_], c[open_])
            r_fail = max(r_fail, float(np.max(ratio)))
            break
        cell, wlo, whi, zl, zh = (cell[open_], wlo[open_], whi[open_], zl[open_],
                                  zh[open_])
        if not cell.size:
            break
        # directions in 2**(n-1); every other level the cell's box too, in two along its
        # widest side (the gradient of F over a large box is too wide to decide)
        k = cell.size
        wlo, whi, idx = split_directions(wlo, whi, np.arange(k))
        cell, zl, zh = cell[idx], zl[idx], zh[idx]
        if depth % 2 == 1:
            zl, zh, idx = _split_z(zl, zh)
            cell, wlo, whi = cell[idx], wlo[idx], whi[idx]
        depth += 1
    if cuts_cell:
        cc, cd, cr = np.concatenate(cuts_cell), np.concatenate(cuts_dir), np.concatenate(
            cuts_ratio)
        order = np.lexsort((-cr, cc))  # per cell, the worst first; 3 per cell
        cc, cd, cr = cc[order], cd[order], cr[order]
        first = np.r_[0, np.flatnonzero(np.diff(cc)) + 1]
        rank = np.arange(cc.size) - np.repeat(first, np.diff(np.r_[first, cc.size]))
        keep = rank < 3
        cuts_cell, cuts_dir, cuts_ratio = [cc[keep]], [cd[keep]], [cr[keep]]
    else:
        cuts_cell, cuts_dir, cuts_ratio = [np.zeros(0, np.int64)], [np.zeros((0, n))], [
            np.zeros(0)]
    return {"R": max(r_target, r_fail), "r_target": r_target, "boxes": boxes,
            "depth": depth, "open": int(np.unique(cuts_cell[0]).size),
            "cuts": (cuts_cell[0], cuts_dir[0], cuts_ratio[0]),
            "seconds": time.perf_counter() - t0}


def _dot_upper(g: np.ndarray, gerr: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Upper bound of ``g_exact . w`` for points ``w``."""
    s = np.einsum("ij,ij->i", g, w)
    err = g.shape[1] * 2 * _EPS * np.einsum("ij,ij->i", np.abs(g), np.abs(w))
    return s + err + gerr * np.linalg.norm(w, axis=1) * (1 + 1e-12) + 1e-300


def _upper_h(fg: LoweredFunction, zl: np.ndarray, zh: np.ndarray, g: np.ndarray,
             gerr: np.ndarray, wlo: np.ndarray, whi: np.ndarray, c: np.ndarray,
             rr: Interval, chunk: int = 300_000) -> np.ndarray:
    """Upper bounds of ``g . w - R F(z, w)`` over the boxes."""
    out = np.empty(g.shape[0])
    for a in range(0, g.shape[0], chunk):
        sl = slice(a, a + chunk)
        with np.errstate(all="ignore"):
            (fc,), _ = enclose(fg, Interval(zl[sl], zh[sl]), Interval(c[sl], c[sl]))
            (fb,), grad = enclose(fg, Interval(zl[sl], zh[sl]), Interval(wlo[sl], whi[sl]))
            h = Interval(_dot_upper(g[sl], gerr[sl], c[sl])) - rr * fc
            for i in range(g.shape[1]):
                gi = Interval(g[sl, i] - gerr[sl], g[sl, i] + gerr[sl])
                off = Interval(wlo[sl, i]) - Interval(c[sl, i])
                off = Interval(off.lo, (Interval(whi[sl, i]) - Interval(c[sl, i])).hi)
                h = h + (gi - rr * grad[i]) * off
            # the plain bound max_B g . w - R min F (better far from the tangency)
            corner = np.where(g[sl] > 0, whi[sl], wlo[sl])
            plain = Interval(_dot_upper(g[sl], gerr[sl], corner)) - rr * fb
        out[sl] = np.minimum(h.hi, plain.hi)
    return np.where(np.isnan(out), np.inf, out)


def _point_ratio(fg: LoweredFunction, zl: np.ndarray, zh: np.ndarray, g: np.ndarray,
                 c: np.ndarray) -> np.ndarray:
    """``g . c / Flo(Z, c)``: what a row at direction ``c`` sees (not a proof)."""
    f = f_lower(fg, zl, zh, c, c)
    with np.errstate(all="ignore"):
        out = np.einsum("ij,ij->i", g, c) / f
    return np.where(np.isfinite(out) & (f > 0), out, np.inf)


def _ratio_bound(fg: LoweredFunction, zl: np.ndarray, zh: np.ndarray, g: np.ndarray,
                 gerr: np.ndarray, wlo: np.ndarray, whi: np.ndarray, c: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Upper bounds of ``g . w / F(z, w)`` over ``Z x B`` and the ratio at ``(Z, c)``
    (``g . c`` over the lower bound of ``F(Z, c)``: what a row at ``c`` would see)."""
    with np.errstate(all="ignore"):
        (fc,), _ = enclose(fg, Interval(zl, zh), Interval(c, c))
        (fb,), grad = enclose(fg, Interval(zl, zh), Interval(wlo, whi))
        d = fc
        for i in range(g.shape[1]):
            d = d + grad[i] * Interval(wlo[:, i] - c[:, i], whi[:, i] - c[:, i]) * 1.0
        den = np.maximum(d.lo - 4 * _EPS * np.abs(d.lo), fb.lo)
    corner = np.where(g > 0, whi, wlo)
    num = _dot_upper(g, gerr, corner)
    with np.errstate(all="ignore"):
        ratio = np.where(num <= 0, 0.0, np.where(den > 0, num / den * (1 + 4 * _EPS), np.inf))
        point = np.einsum("ij,ij->i", g, c) / fc.lo
    return ratio, np.where(np.isfinite(point), point, np.inf)


def split_directions(wlo: np.ndarray, whi: np.ndarray, parent: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each direction box cut in two along every free coordinate (``2**(n-1)``
    children); returns them and their parents' indices."""
    lo, hi = wlo, whi
    for i in range(wlo.shape[1]):
        f = hi[:, i] > lo[:, i]
        mid = 0.5 * (lo[f, i] + hi[f, i])
        hi_a = hi.copy()
        hi_a[f, i] = mid
        lo_b, hi_b = lo[f].copy(), hi[f]
        lo_b[:, i] = mid
        lo, hi = np.concatenate([lo, lo_b]), np.concatenate([hi_a, hi_b])
        parent = np.concatenate([parent, parent[f]])
    return lo, hi, parent


def _split_z(zl: np.ndarray, zh: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each box cut in two along its widest side; returns them and their parents."""
    k = zl.shape[0]
    ax = np.argmax(zh - zl, axis=1)
    rows = np.arange(k)
    mid = 0.5 * (zl[rows, ax] + zh[rows, ax])
    hi_a, lo_b = zh.copy(), zl.copy()
    hi_a[rows, ax] = mid
    lo_b[rows, ax] = mid
    return (np.concatenate([zl, lo_b]), np.concatenate([hi_a, zh]),
            np.concatenate([rows, rows]))


# ----------------------------------------------------------------------------------------
# the LP
# ----------------------------------------------------------------------------------------
def solve_lp(cells: Cells, rel: np.ndarray, rows_cell: np.ndarray, rows_dir: np.ndarray,
             rows_b: np.ndarray, s_w: tuple[np.ndarray, np.ndarray],
             g_w: tuple[np.ndarray, np.ndarray], bound: float) -> tuple[np.ndarray, np.ndarray,
                                                                        str]:
    """Maximise ``phi(goal) - phi(start)`` (barycentric ``s_w``, ``g_w``) under the rows
    ``grad phi_T . w <= b`` (cell ``rows_cell`` (indices into ``rel``), direction
    ``rows_dir`` ``(R, n)``, bound ``rows_b``) with ``phi(start) = 0`` and
    ``|phi| <= bound``. Returns ``phi``, the rows' duals and cvxpy's status."""
    t = rel[rows_cell]
    coef = np.einsum("ri,rij->rj", rows_dir, cells.coef[t])  # (R, n+1)
    return solve_rows_lp(coef, cells.simp[t], cells.points.shape[0], rows_b, s_w, g_w, bound)


def solve_rows_lp(coef: np.ndarray, cols: np.ndarray, n_vars: int, rows_b: np.ndarray,
                  s_w: tuple[np.ndarray, np.ndarray], g_w: tuple[np.ndarray, np.ndarray],
                  bound: float) -> tuple[np.ndarray, np.ndarray, str]:
    """Maximise ``x(goal) - x(start)`` (``(indices, weights)`` ``s_w``, ``g_w``) over
    ``n_vars`` unknowns under the rows ``sum_k coef[r, k] x[cols[r, k]] <= rows_b[r]``,
    ``x(start) = 0`` and ``|x| <= bound``. Returns ``x``, the rows' duals and cvxpy's
    status; raises `LPFailure`."""
    import warnings

    import cvxpy as cp
    import scipy.sparse as sp

    nr = rows_b.size
    a = sp.csr_matrix((coef.ravel(), (np.repeat(np.arange(nr), coef.shape[1]), cols.ravel())),
                      shape=(nr, n_vars))
    x = cp.Variable(n_vars)
    obj = g_w[1] @ x[g_w[0]] - s_w[1] @ x[s_w[0]]
    cons = [a @ x <= rows_b, s_w[1] @ x[s_w[0]] == 0, x <= bound, x >= -bound]
    prob = cp.Problem(cp.Maximize(obj), cons)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prob.solve(solver=LP_SOLVER)
    except cp.error.SolverError as err:
        raise LPFailure(f"the LP solver failed: {short(str(err))}") from err
    if x.value is None:
        raise LPFailure(f"the LP ended with status {prob.status}")
    duals = np.maximum(np.asarray(cons[0].dual_value, float), 0.0)
    return np.asarray(x.value, float), duals, str(prob.status)


def edge_midpoints(cells: Cells, marked: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Midpoints of the marked cells' edges (each once), jittered by 2 % of the edge."""
    simp = cells.simp[marked]
    k = simp.shape[1]
    pairs = np.array([(i, j) for i in range(k) for j in range(i + 1, k)])
    e = np.sort(np.stack([simp[:, pairs[:, 0]], simp[:, pairs[:, 1]]], -1).reshape(-1, 2), 1)
    e = np.unique(e, axis=0)
    a, b = cells.points[e[:, 0]], cells.points[e[:, 1]]
    length = np.linalg.norm(b - a, axis=1, keepdims=True)
    return 0.5 * (a + b) + rng.uniform(-0.02, 0.02, a.shape) * length
