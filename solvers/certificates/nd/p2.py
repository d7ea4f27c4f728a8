"""Quadratic (P2) potentials for `solvers.certificates.nd.certificate.certify_nd`.

A piecewise-linear potential has one gradient per cell, which must satisfy the dual
condition where F is smallest over the cell: the bound loses about ``h |grad log F| / 2``
(first order in the cell's width ``h``). A P2 potential (continuous, quadratic on each
Delaunay cell; unknowns at the vertices and edge midpoints) has a gradient AFFINE in each
cell, ``g(z) = g_c + G (z - c)``, which can follow F across the cell: the loss is second
order. The pieces:

1. the LP (cvxpy, as the P1 element) maximises ``phi(goal) - phi(start)`` under rows
   ``g_T(z_k) . w <= F(z_k, w)`` at the cell's P2 nodes ``z_k`` and directions ``w`` of a
   grid on the cube's surface (row generation), plus the points and directions the
   verification could not close (cuts);
2. the verification (`verify_p2`) proves ``g_T(z) . w <= R F(z, w)`` for every ``z``
   of every cell of the region and every ``w``: ``H = g_T(z) . w - R F(z, w)`` is bounded
   by ONE affine-arithmetic form over a box of ``(z, w)`` (`finsler.enclosures.affine.affine_forms`;
   the affine gradient and F share the noise symbols of ``z``, so their first-order
   variations cancel), its linear part in ``z`` maximised over the cell's (sub)simplex (its
   vertices), not the whole box (where the quadratic would be extrapolated); branch and
   bound splits the direction boxes and bisects the simplices;
3. the gradient ``(g_c, G)`` of each cell is computed in float64 with an a-posteriori bound
   of its error (`P2Cells.affine_gradients`), added to ``g . w`` in step 2.

F must have affine rules for every operation of its program (``sqrt``, powers, ``sin``,
``cos``, the arithmetic, ``abs``, ``max``/``min`` through ``abs``, signs and truth values:
`finsler.enclosures.affine`); where it has not (``exp``, say) `affine_missing` names the
operation and the caller keeps the P1 element. ``max`` and ``min`` are written through
``abs`` before F is differentiated (`finsler.lowering.max_through_abs`), so the
enclosure of ``grad_w F`` stays bounded across a kink (car-like's).

Nothing here imports `solvers.certificates.nd.certificate`.
"""

from __future__ import annotations

import itertools
import logging
import time
from typing import Any

import casadi as ca
import numpy as np

from finsler.enclosures.affine import affine_forms
from finsler.lowering import LoweredFunction, lower, max_through_abs
from finsler.metrics.base import Metric
from solvers.certificates.domain import domain_constraints, outside_domain
from solvers.certificates.nd.parts import Cells, face_boxes, split_directions

_LOG = logging.getLogger(__name__)
_EPS = float(np.finfo(float).eps)
#: every (sub)simplex is verified blown up by this factor about its centroid, so that the
#: pieces of a bisection cover their parent whatever the rounding of the midpoint
_GROW = 1e-9
#: rounds of the separation (fine directions at the order-4 lattice) before the proof, and
#: the ratio above 1 it cuts
SEP_ROUNDS = 6
SEP_TOL = 5e-4
#: directions added per node and round of row generation (the worst violated ones); with 2,
#: a few nodes whose gradient the objective does not fix kept a row generation going for
#: 40 rounds at a constant LP value
ROWGEN_PER_NODE = 16
#: a cell's simplices are split before its direction boxes when ``BEND_WEIGHT`` x (the
#: Hessian's norm over the gradient's + the tangent map's norm) x their diameter exceeds
#: the boxes' width, and never later than ``0.5 / median cell diameter`` x the diameter
BEND_WEIGHT = 0.1
#: work budget of one verification (items alive at a level x 2**n)
MAX_ELEMENTS = 6_000_000


def lowered_f_joint(metric: Metric) -> LoweredFunction:
    """``u = (z, w) -> F(z, w)`` as one input (what the affine forms need), lowered once."""
    def build() -> LoweredFunction:
        u = ca.SX.sym("u", 2 * metric.dim)
        f = max_through_abs(ca.Function("f", [u], [metric.F_sx(u[: metric.dim],
                                                               u[metric.dim:])]))(u)
        return lower(ca.Function(f"cnd_fj_{metric._ident}", [u], [f]))
    return metric.derived("certify_nd.f_joint", build)


def affine_missing(metric: Metric) -> str | None:
    """Why the P2 element is not possible for the metric (an operation of F without an
    affine rule, or an unbounded domain), or None."""
    fn = lowered_f_joint(metric)
    n = metric.dim
    lo = np.concatenate([np.asarray(metric.domain.bounds()[0], float), -np.ones(n)])
    hi = np.concatenate([np.asarray(metric.domain.bounds()[1], float), np.ones(n)])
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return "the domain's bounding box is not finite"
    mid = 0.5 * (lo + hi)
    try:
        affine_forms(fn, mid[None], mid[None] + 1e-3)
    except NotImplementedError as err:
        return str(err)
    return None


def affine_ready(metric: Metric) -> bool:
    """Whether every operation of the metric's F has an affine rule (P2 is possible)."""
    return affine_missing(metric) is None


def nodes(n: int) -> np.ndarray:
    """Barycentric coordinates ``(K, n+1)`` of the P2 nodes: vertices, edge midpoints."""
    eye = np.eye(n + 1)
    mids = [0.5 * (eye[i] + eye[j]) for i in range(n + 1) for j in range(i + 1, n + 1)]
    return np.concatenate([eye, np.array(mids)])


class P2Cells:
    """The P2 unknowns of `Cells`: one per vertex, then
    one per edge (its midpoint's value); ``dof`` ``(T, K)`` in the order of `nodes`."""

    def __init__(self, cells: Cells) -> None:
        simp = cells.simp
        k = simp.shape[1]
        self.n = k - 1
        self.pairs = np.array([(i, j) for i in range(k) for j in range(i + 1, k)])
        e = np.sort(simp[:, self.pairs], axis=2).reshape(-1, 2)
        uniq, inv = np.unique(e, axis=0, return_inverse=True)
        nv = cells.points.shape[0]
        self.dof = np.concatenate([simp, nv + inv.reshape(simp.shape[0], -1)], axis=1)
        self.n_dofs = int(nv + uniq.shape[0])
        self.cells = cells

    def basis(self, lam: np.ndarray) -> np.ndarray:
        """Values ``(R, K)`` of the cell's basis functions at barycentric ``lam``."""
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        return np.concatenate([lam * (2 * lam - 1), 4 * lam[:, i] * lam[:, j]], axis=1)

    def grad_coef(self, t: np.ndarray, lam: np.ndarray, w: np.ndarray) -> np.ndarray:
        """``grad phi_T(z) . w`` as a linear map ``(R, K)`` of the cell's unknowns (cell
        ``t``, barycentric ``lam`` of ``z``)."""
        gl = np.einsum("rji,rj->ri", self.cells.coef[t], w)  # grad lambda_i . w
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        return np.concatenate([(4 * lam - 1) * gl,
                               4 * (lam[:, i] * gl[:, j] + lam[:, j] * gl[:, i])], axis=1)

    def barycentric(self, t: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Barycentric coordinates ``(R, n+1)`` of points ``z`` in cells ``t``."""
        x0 = self.cells.points[self.cells.simp[t, 0]]
        coef = self.cells.coef[t]  # (R, n, n+1)
        lam = np.einsum("rji,rj->ri", coef[:, :, 1:], z - x0)
        return np.concatenate([1.0 - lam.sum(axis=1, keepdims=True), lam], axis=1)

    def row_nodes(self, t: np.ndarray, blo: np.ndarray, bhi: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """The LP's row points of cells ``t``: the P2 nodes ``(T, K, n)`` moved into the box
        ``[blo, bhi]`` where a cell sticks out of it (the proof covers only the cell's part in
        the box), and their barycentric coordinates ``(T, K, n+1)`` in the cell (rows at the
        unmoved nodes with bounds of F at the moved ones disagreed with the gradient: ratios
        of 7 at rows the LP satisfied)."""
        x = self.cells.points[self.cells.simp[t]]
        k = self.dof.shape[1]
        zk = np.clip(np.einsum("kv,tvn->tkn", nodes(self.n), x), blo, bhi)
        lam = self.barycentric(np.repeat(t, k), zk.reshape(-1, self.n))
        return zk, lam.reshape(t.size, k, self.n + 1)

    def affine_gradients(self, phi: np.ndarray, t: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For cells ``t``: the gradient at the centroid ``g_c`` ``(T, n)``, the constant
        Hessian ``G`` ``(T, n, n)`` and a bound ``(T,)`` of the 2-norm of the error of
        ``g_c + G (z - c)`` anywhere in the cell (a posteriori: the exact potential
        satisfies ``phi(m_ij) - phi(x_i) = g(x_i + e_ij / 4) . e_ij / 2`` on every half
        edge; the residual of the computed ``(g_c, G)`` over the least singular value of
        that system, doubled)."""
        cells, n = self.cells, self.n
        vals = phi[self.dof[t]]  # (T, K)
        gl = cells.coef[t]  # (T, n, n+1): column i is grad lambda_i
        k = n + 1
        lc = 1.0 / k
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        vv, ve = vals[:, :k], vals[:, k:]
        gc = np.einsum("ti,tni->tn", vv * (4 * lc - 1), gl) + np.einsum(
            "tp,tnp->tn", ve * 4 * lc, gl[:, :, i] + gl[:, :, j])
        hess = 4 * np.einsum("ti,tai,tbi->tab", vv, gl, gl) + 4 * np.einsum(
            "tp,tap,tbp->tab", ve, gl[:, :, i], gl[:, :, j])
        hess = hess + 4 * np.einsum("tp,tap,tbp->tab", ve, gl[:, :, j], gl[:, :, i])
        x = cells.points[cells.simp[t]]  # (T, k, n)
        c = x.mean(axis=1)
        # half edges from both ends: (i -> j) and (j -> i)
        a_idx = np.concatenate([i, j])
        b_idx = np.concatenate([j, i])
        mid_val = np.concatenate([ve, ve], axis=1)
        xa, xb = x[:, a_idx], x[:, b_idx]
        e = xb - xa  # (T, E, n)
        zq = xa + 0.25 * e - c[:, None]
        gq = gc[:, None] + np.einsum("tab,teb->tea", hess, zq)
        lhs = np.einsum("tea,tea->te", gq, 0.5 * e)
        rhs = mid_val - vv[:, a_idx]
        res = lhs - rhs
        mag = (np.abs(mid_val) + np.abs(vv[:, a_idx]) + np.einsum(
            "tea,tea->te", np.abs(gc[:, None]) + np.einsum(
                "tab,teb->tea", np.abs(hess), np.abs(zq)), np.abs(e)))
        rnorm = np.linalg.norm(res, axis=1) + 16 * (n + 2) * _EPS * np.linalg.norm(mag, axis=1)
        # the system in the unknowns (g_c, G's upper triangle)
        iu = np.triu_indices(n)
        cols_g = 0.5 * e  # (T, E, n)
        outer = zq[..., :, None] * (0.5 * e)[..., None, :]  # d/dG_ab of zq . G^T ... (sym)
        sym = outer + np.swapaxes(outer, -1, -2)
        diag = iu[0] == iu[1]
        cols_h = np.where(diag, 0.5 * sym[..., iu[0], iu[1]], sym[..., iu[0], iu[1]])
        mat = np.concatenate([cols_g, cols_h], axis=2)  # (T, E, n + n(n+1)/2)
        smin = np.linalg.svd(mat, compute_uv=False)[:, -1]
        diam = np.max(np.linalg.norm(x - c[:, None], axis=2), axis=1)
        with np.errstate(divide="ignore"):
            du = 2.0 * rnorm / smin
        err = du * (1.0 + np.sqrt(2.0) * diam) * (1 + 1e-6)
        return gc, hess, np.where(np.isfinite(err), err, np.inf)


def verify_p2(fj: LoweredFunction, fg: LoweredFunction, x: np.ndarray, gc: np.ndarray,
              hess: np.ndarray, gerr: np.ndarray, blo: np.ndarray, bhi: np.ndarray,
              r_start: float, tol: float, start_faces: int = 4, max_depth: int = 10,
              max_elements: int = MAX_ELEMENTS, cons: Any = None) -> dict[str, Any]:
    """A proven ``R`` with ``g_T(z) . v <= R F(z, v)`` for every cell ``T`` (vertices ``x``
    ``(T, n+1, n)``, gradient ``gc + hess (z - centroid)`` with error ``gerr``), every ``z``
    of the cell inside the box ``[blo, bhi]`` and the domain (``cons`` from
    `solvers.certificates.domain.domain_constraints`; None: the box) and every ``v``.
    ``fj``: ``(z, w) -> F`` as one input; ``fg``: ``(z, w) -> (F, grad_w F)``.

    Items are (cell, simplex inside it, box of directions on the cube's surface). On each,
    one affine form of ``H = g(z) . w - R F(z, w)`` over the box of the simplex times the
    direction box; its linear part in ``z`` is maximised over the simplex's vertices (the
    simplex lies in its box), in ``w`` over the box. ``R`` starts at ``r_start (1 + tol)``
    and rises to ``(1 + tol)`` x the largest ratio ``g(z) . c / F(z, c)`` seen at an item's
    centre; items whose bound is ``<= 0`` are done, the others split: the directions in
    ``2**(n-1)`` every level, the simplex in two (longest edge) every other level, up to
    ``max_depth`` levels or ``max_elements`` items; what is left is bounded by the ratio of
    the upper bound of ``g . w`` to the lower bound of F over the item (first order).
    Returns ``R`` and the cuts (cell, point, direction, ratio) for the next LP."""
    n = gc.shape[1]
    centroid = x.mean(axis=1)
    cell_diam = np.max(np.linalg.norm(x - centroid[:, None], axis=2), axis=1)
    diam_scale = float(np.median(cell_diam))
    w_map = tangent_maps(fg, x, gc, hess)
    # per cell, how fast the bound's ingredients move with z: the gradient relative to its
    # size and the direction boxes (a cell whose potential bends 1000x faster than its
    # neighbours' needs simplices that much smaller)
    bend = (np.linalg.norm(hess, ord=2, axis=(1, 2))
            / np.maximum(np.linalg.norm(gc, axis=1), 1e-300)
            + np.linalg.norm(w_map, ord=2, axis=(1, 2)))
    z_weight = np.maximum(0.5 / diam_scale, BEND_WEIGHT * bend)
    wlo0, whi0 = face_boxes(n, start_faces)
    nb = wlo0.shape[0]
    cell = np.repeat(np.arange(gc.shape[0]), nb)
    simp = np.repeat(x, nb, axis=0)
    wlo, whi = np.tile(wlo0, (gc.shape[0], 1)), np.tile(whi0, (gc.shape[0], 1))
    r_target = r_start * (1.0 + tol)
    cut_above = r_target
    r_fail = -np.inf
    boxes, depth = 0, 0
    cuts: list[tuple[np.ndarray, ...]] = []
    t0 = time.perf_counter()
    while cell.size:
        boxes += cell.size
        sc = simp.mean(axis=1)
        grown = sc[:, None] + (simp - sc[:, None]) * (1.0 + _GROW)
        zlo = np.maximum(grown.min(axis=1), blo)
        zhi = np.minimum(grown.max(axis=1), bhi)
        outside = np.any(zlo > zhi, axis=1)
        zlo, zhi = np.minimum(zlo, zhi), np.maximum(zlo, zhi)
        outside |= outside_domain(cons, zlo, zhi)  # no path goes there
        zp = np.clip(sc, zlo, zhi)
        c = 0.5 * (wlo + whi) + np.einsum("tjk,tk->tj", w_map[cell], zp - centroid[cell])
        gz = gc[cell] + np.einsum("tab,tb->ta", hess[cell], zp - centroid[cell])
        (fp, _g) = fg(zp, c)
        fp = np.asarray(fp, float).reshape(-1)
        with np.errstate(all="ignore"):
            point = np.einsum("ij,ij->i", gz, c) / fp
        point = np.where(np.isfinite(point) & (fp > 0), point, np.inf)
        point[outside] = -np.inf
        cut = point > cut_above
        if np.any(cut):
            cuts.append((cell[cut], zp[cut], c[cut], point[cut]))
        r_target = max(r_target, float(np.max(point, initial=-np.inf)) * (1.0 + tol))
        # simplices inside the box: noise along their own axes first; the axis box where
        # that leaves the item open or the simplex sticks out; the tighter bound of the two
        up_h, up_p = np.full(cell.size, np.inf), np.full(cell.size, np.inf)
        f_low = np.full(cell.size, -np.inf)
        inner = np.flatnonzero(np.all(grown.min(axis=1) >= blo, axis=1)
                               & np.all(grown.max(axis=1) <= bhi, axis=1) & ~outside)
        if inner.size:
            up_h[inner], up_p[inner], f_low[inner] = _bounds_moving(
                fj, fg, cell[inner], grown[inner], zlo[inner], zhi[inner], wlo[inner],
                whi[inner], centroid, gc, hess, gerr, w_map, r_target, oriented=True)
        rest = np.flatnonzero(~(up_h <= 0.0) & ~outside)
        if rest.size:
            ua_h, ua_p, fa_low = _bounds_moving(
                fj, fg, cell[rest], grown[rest], zlo[rest], zhi[rest], wlo[rest], whi[rest],
                centroid, gc, hess, gerr, w_map, r_target)
            up_h[rest] = np.minimum(up_h[rest], ua_h)
            up_p[rest] = np.minimum(up_p[rest], ua_p)
            f_low[rest] = np.maximum(f_low[rest], fa_low)
        open_ = ~(up_h <= 0.0) & ~outside
        final = depth >= max_depth or int(open_.sum()) * 2 ** n > max_elements
        if final and np.any(open_):
            with np.errstate(all="ignore"):
                ratio = np.where(up_p[open_] <= 0, 0.0,
                                 np.where(f_low[open_] > 0,
                                          up_p[open_] / f_low[open_] * (1 + 4 * _EPS),
                                          np.inf))
            r_fail = max(r_fail, float(np.max(ratio)))
            break
        cell, simp, wlo, whi = cell[open_], simp[open_], wlo[open_], whi[open_]
        if not cell.size:
            break
        # split what is wider: the direction box (cube coordinates) or the simplex
        # (relative to the median cell's diameter, x 1/2: with x 2 the proof of a pair near
        # the disk's rim kept splitting simplices under direction boxes of width 1/16 and
        # ran out of items, 8.3 M boxes; with x 1/2 it closed in 1.6 M)
        wwid = np.max(whi - wlo, axis=1)
        zdiam = np.max(np.linalg.norm(simp - simp.mean(axis=1, keepdims=True), axis=2), 1)
        by_w = wwid > zdiam * z_weight[cell]
        iw, iz = np.flatnonzero(by_w), np.flatnonzero(~by_w)
        wlo_a, whi_a, pa = split_directions(wlo[iw], whi[iw], iw)
        simp_b, pb = _bisect(simp[iz])
        pb = iz[pb]
        cell = np.concatenate([cell[pa], cell[pb]])
        simp = np.concatenate([simp[pa], simp_b])
        wlo = np.concatenate([wlo_a, wlo[pb]])
        whi = np.concatenate([whi_a, whi[pb]])
        depth += 1
    if cuts:
        cc = np.concatenate([q[0] for q in cuts])
        cz = np.concatenate([q[1] for q in cuts])
        cw = np.concatenate([q[2] for q in cuts])
        cr = np.concatenate([q[3] for q in cuts])
        order = np.lexsort((-cr, cc))  # per cell, the worst first; 3 per cell
        cc, cz, cw, cr = cc[order], cz[order], cw[order], cr[order]
        first = np.r_[0, np.flatnonzero(np.diff(cc)) + 1]
        rank = np.arange(cc.size) - np.repeat(first, np.diff(np.r_[first, cc.size]))
        keep = rank < 3
        cut_out = (cc[keep], cz[keep], cw[keep], cr[keep])
    else:
        cut_out = (np.zeros(0, np.int64), np.zeros((0, n)), np.zeros((0, n)), np.zeros(0))
    return {"R": max(r_target, r_fail), "r_target": r_target, "boxes": boxes, "depth": depth,
            "open": int(np.unique(cut_out[0]).size), "cuts": cut_out,
            "seconds": time.perf_counter() - t0}


def _bisect(simp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each simplex ``(N, n+1, n)`` cut in two at the midpoint of its longest edge;
    returns the children and their parents' indices."""
    k = simp.shape[1]
    pairs = np.array(list(itertools.combinations(range(k), 2)))
    d = simp[:, pairs[:, 0]] - simp[:, pairs[:, 1]]
    longest = np.argmax(np.einsum("npk,npk->np", d, d), axis=1)
    rows = np.arange(simp.shape[0])
    i, j = pairs[longest, 0], pairs[longest, 1]
    mid = 0.5 * (simp[rows, i] + simp[rows, j])
    a, b = simp.copy(), simp.copy()
    a[rows, i] = mid
    b[rows, j] = mid
    return np.concatenate([a, b]), np.concatenate([rows, rows])


def p2_weights(p2: P2Cells, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unknowns and weights of the P2 potential's value at the point ``p``."""
    from finsler.errors import InputError

    s = int(p2.cells.tri.find_simplex(p[None])[0])
    if s < 0:
        raise InputError("a point lies outside the certification mesh")
    lam = p2.barycentric(np.array([s]), p[None])
    return p2.dof[s], p2.basis(lam)[0]


def _more_rows(rows: tuple[np.ndarray, ...], p2: P2Cells, rel: np.ndarray, t: np.ndarray,
               z: np.ndarray, w: np.ndarray, f: Any) -> tuple[np.ndarray, ...]:
    """The LP's extra rows ``(cell, barycentric, direction, F)`` with rows at points ``z``
    of region cells ``t`` in directions ``w`` appended where ``F`` is finite and positive."""
    f = np.asarray(f, float).reshape(-1)
    ok = np.isfinite(f) & (f > 0)
    ec, elam, ew, eb = rows
    return (np.concatenate([ec, t[ok]]),
            np.concatenate([elam, p2.barycentric(rel[t[ok]], z[ok])]),
            np.concatenate([ew, w[ok]]), np.concatenate([eb, f[ok]]))


def run_p2(m: Metric, f_fn: LoweredFunction, s: np.ndarray, g: np.ndarray, upper: float,
           cap: float, spec: Any, blo: np.ndarray, bhi: np.ndarray, scale: float,
           rng: np.random.Generator, points: np.ndarray, dirs: np.ndarray,
           times: dict[str, float], t_start: float) -> dict[str, Any]:
    """The mesh rounds of `solvers.certificates.nd.certificate.certify_nd` with the P2 element (see
    the module docstring); ``spec`` an ``NDSpec``. Returns the best round's figures, the
    rounds and how it stopped."""
    from solvers.certificates.nd.parts import (
        LPFailure,
        add_points,
        box_distance,
        build_cells,
        edge_midpoints,
        lowered_f_grad,
        reached,
        round_record,
        solve_rows_lp,
    )
    from solvers.status import CertifyStatus

    fj = lowered_f_joint(m)
    cons = domain_constraints(m)
    fg_fn = lowered_f_grad(m)[1]
    n = m.dim
    lat = nodes(n)
    k_nodes = lat.shape[0]
    nd = dirs.shape[0]
    face = np.flatnonzero((np.sum(np.abs(dirs), axis=1) == 1.0)
                          | np.all(np.abs(dirs) == 1.0, axis=1))
    best: dict[str, Any] = {"lower": 0.0, "R": float("nan"), "lp_status": "not_solved",
                            "rows": 0, "cells": 0, "rel": 0, "vertices": 0}
    rounds: list[dict[str, Any]] = []
    stopped_by, status, message = "max_rounds", CertifyStatus.BUDGET_REACHED, ""
    for _ in range(spec.max_rounds):
        t0 = time.perf_counter()
        cells = build_cells(points, blo, bhi, rng, spec.h_path)
        points = cells.points
        dist = box_distance(s, cells.zlo, cells.zhi) + box_distance(g, cells.zlo, cells.zhi)
        rel = np.flatnonzero(cells.inside & ~cells.flat
                             & ~(scale * dist > upper * (1 + 1e-9))
                             & ~outside_domain(cons, cells.zlo, cells.zhi))
        p2 = P2Cells(cells)
        x = cells.points[cells.simp[rel]]
        cen = x.mean(axis=1)
        nr = rel.size
        zk, lam_k = p2.row_nodes(rel, blo, bhi)
        times["mesh"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        (bv,) = f_fn(np.repeat(zk.reshape(-1, n), nd, 0), np.tile(dirs, (nr * k_nodes, 1)))
        b = np.asarray(bv, float).reshape(nr, k_nodes, nd)
        b_lp = np.maximum(np.where(np.isfinite(b), b, 0.0), 1e-9 * float(np.nanmax(b)))
        times["bounds"] += time.perf_counter() - t0
        s_w, g_w = p2_weights(p2, s), p2_weights(p2, g)
        active = np.zeros((nr, k_nodes, nd), bool)
        active[:, :, face] = True
        ec, elam = np.zeros(0, np.int64), np.zeros((0, n + 1))
        ew, eb = np.zeros((0, n)), np.zeros(0)
        result: dict[str, Any] | None = None
        failure = None
        sep_lat = lattice(n, 4)
        sep_rounds = 0
        for _lp in range(spec.lp_rounds):
            rc, rk, rd = np.nonzero(active)
            t_rows = np.concatenate([rc, ec])
            lam_rows = np.concatenate([lam_k[rc, rk], elam])
            w_rows = np.concatenate([dirs[rd], ew])
            b_rows = np.concatenate([b_lp[rc, rk, rd], eb])
            t0 = time.perf_counter()
            coef = p2.grad_coef(rel[t_rows], lam_rows, w_rows)
            try:
                phi, duals, lp_status = solve_rows_lp(coef, p2.dof[rel[t_rows]], p2.n_dofs,
                                                      b_rows, s_w, g_w, 10.0 * cap)
            except LPFailure as err:
                failure = str(err)
                break
            times["lp"] += time.perf_counter() - t0
            gcs, hs, gerr = p2.affine_gradients(phi, rel)
            gk = gcs[:, None] + np.einsum("tab,tkb->tka", hs, zk - cen[:, None])
            ratio = np.einsum("tkn,dn->tkd", gk, dirs) / b_lp
            viol = (ratio > 1.0 + (1e-7 if sep_rounds == 0 else 1e-3)) & ~active
            _LOG.debug("P2 LP %d: %d rows, value %.6g, grid ratio %.6g, %d violations, "
                       "%d separation rounds, %.1f s", _lp, b_rows.size,
                       float(g_w[1] @ phi[g_w[0]] - s_w[1] @ phi[s_w[0]]),
                       float(np.max(ratio)), int(np.count_nonzero(viol)), sep_rounds,
                       time.perf_counter() - t0)
            if np.any(viol):  # row generation: the worst directions of each node
                flat = np.where(viol, ratio, -np.inf).reshape(nr * k_nodes, nd)
                order = np.argsort(-flat, axis=1)[:, :ROWGEN_PER_NODE]
                take = np.isfinite(np.take_along_axis(flat, order, 1))
                node = np.repeat(np.arange(nr * k_nodes), order.shape[1])[take.ravel()]
                active.reshape(nr * k_nodes, nd)[node, order.ravel()[take.ravel()]] = True
                continue
            if sep_rounds < SEP_ROUNDS:  # separation at the order-4 lattice, fine directions
                zs = np.clip(np.einsum("kv,tvn->tkn", sep_lat, x), blo, bhi)
                ps = gcs[:, None] + np.einsum("tab,tkb->tka", hs, zs - cen[:, None])
                wbest, rb = best_directions(fg_fn, zs.reshape(-1, n), ps.reshape(-1, n), faces=4)
                rb = rb.reshape(nr, -1)
                sep_rounds += 1
                in_dom = m.domain.contains(zs.reshape(-1, n)).reshape(nr, -1)
                bad = (rb > 1.0 + SEP_TOL) & in_dom
                _LOG.debug("P2 separation %d: largest ratio %.6g in the domain, %d points "
                           "above 1 + %g", sep_rounds,
                           float(np.max(np.where(in_dom, rb, -np.inf), initial=-np.inf)),
                           int(np.count_nonzero(bad)), SEP_TOL)
                if np.any(bad):
                    order = np.argsort(-np.where(bad, rb, -np.inf), axis=1)[:, :8]
                    take = np.take_along_axis(bad, order, 1)
                    tt = np.repeat(np.arange(nr), order.shape[1])[take.ravel()]
                    kk = order.ravel()[take.ravel()]
                    zz_new = zs[tt, kk]
                    ww_new = wbest.reshape(nr, -1, n)[tt, kk]
                    fb, _ = fg_fn(zz_new, ww_new)
                    ec, elam, ew, eb = _more_rows((ec, elam, ew, eb), p2, rel, tt, zz_new,
                                                  ww_new, fb)
                    continue
            r_lp = max(float(np.max(ratio)), 1e-300)
            if ec.size:
                ge = gcs[ec] + np.einsum("tab,tb->ta", hs[ec],
                                         np.einsum("rv,rvn->rn", elam, x[ec]) - cen[ec])
                r_lp = max(r_lp, float(np.max(np.einsum("ij,ij->i", ge, ew) / eb)))
            t0 = time.perf_counter()
            ver = verify_p2(fj, fg_fn, x, gcs, hs, gerr, blo, bhi, r_lp, spec.verify_tol,
                            max_depth=spec.verify_depth, cons=cons)
            times["verify"] += time.perf_counter() - t0
            _LOG.debug("P2 proof: R %.6g (grid %.6g), %.1f s", ver["R"], r_lp,
                       time.perf_counter() - t0)
            dphi = float(g_w[1] @ phi[g_w[0]] - s_w[1] @ phi[s_w[0]])
            lower = min(dphi / ver["R"] * (1 - 1e-12), upper) if ver["R"] > 0 else 0.0
            result = {"lower": max(lower, 0.0), "R": ver["R"], "lp_status": lp_status,
                      "rows": int(b_rows.size), "cells": cells.n_cells, "rel": int(nr),
                      "vertices": int(cells.points.shape[0]), "dphi": dphi, "ver": ver,
                      "duals": duals, "t_rows": t_rows, "b_rows": b_rows}
            if result["lower"] > best["lower"]:
                best = result
            cc, cz, cw, _ = ver["cuts"]
            if (reached(upper, best["lower"], spec.target_gap) or not cc.size
                    or ver["R"] <= r_lp * (1 + 2 * spec.verify_tol)):
                break
            (fb,) = f_fn(cz, cw)
            ec, elam, ew, eb = _more_rows((ec, elam, ew, eb), p2, rel, cc, cz, cw, fb)
        if failure is not None:
            stopped_by, status, message = "lp_failed", CertifyStatus.LP_FAILED, failure
            break
        if result is None:
            stopped_by = "lp_rounds"
            continue
        rounds.append(round_record(result, upper, t_start))
        if reached(upper, best["lower"], spec.target_gap):
            stopped_by, status = "target_gap", CertifyStatus.CERTIFIED
            break
        diam2 = np.max(np.sum((x - cen[:, None]) ** 2, axis=2), axis=1)
        weight = np.bincount(result["t_rows"], weights=result["duals"] * result["b_rows"],
                             minlength=nr) * diam2
        order = np.argsort(-weight)
        cum = np.cumsum(weight[order])
        kk = (int(np.searchsorted(cum, spec.mark_fraction * cum[-1]) + 1)
              if cum.size and cum[-1] > 0 else max(1, nr // 10))
        new = edge_midpoints(cells, rel[order[:kk]], rng)
        if cells.n_cells + 6 * new.shape[0] > spec.max_cells:
            stopped_by = "max_cells"
            break
        points = add_points(cells.points, new)
    return {"best": best, "rounds": rounds, "stopped_by": stopped_by, "status": status,
            "message": message}


# ----------------------------------------------------------------------------------------
# moving direction boxes: w = u + W_T (z - z_T), W_T the derivative of the tangency
# ----------------------------------------------------------------------------------------
def best_directions(fg: LoweredFunction, zz: np.ndarray, pp: np.ndarray, faces: int = 6,
                    chunk: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """For points ``zz`` ``(m, n)`` and covectors ``pp``: unit directions nearly maximising
    ``p . w / F(z, w)`` (a grid on the cube, then four rounds of 24 random perturbations at
    shrinking scales) and the ratios there (not a proof: rows and targets only)."""
    from solvers.certificates.nd.parts import cube_directions

    n = zz.shape[1]
    dirs = cube_directions(n, faces)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    m = zz.shape[0]
    best = np.empty((m, n))
    for a in range(0, m, chunk):
        sl = slice(a, a + chunk)
        q = zz[sl].shape[0]
        f, _ = fg(np.repeat(zz[sl], dirs.shape[0], 0), np.tile(dirs, (q, 1)))
        r = (pp[sl] @ dirs.T) / np.asarray(f, float).reshape(q, -1)
        best[sl] = dirs[np.argmax(r, axis=1)]
    rng = np.random.default_rng(0)
    ratio = np.zeros(m)
    for scale in (0.15, 0.05, 0.016, 0.005):
        pert = rng.normal(size=(24, n)) * scale
        cand = best[:, None] + np.concatenate([np.zeros((1, n)), pert])[None]
        cand /= np.linalg.norm(cand, axis=2, keepdims=True)
        f, _ = fg(np.repeat(zz, cand.shape[1], 0), cand.reshape(-1, n))
        r = np.einsum("mcn,mn->mc", cand, pp) / np.asarray(f, float).reshape(m, -1)
        k = np.argmax(r, axis=1)
        best = cand[np.arange(m), k]
        ratio = r[np.arange(m), k]
    return best, ratio


def lattice(n: int, order: int) -> np.ndarray:
    """Barycentric coordinates of the order-``order`` lattice of the simplex."""
    pts = [np.array(c, float) / order for c in itertools.product(range(order + 1),
                                                                 repeat=n + 1)
           if sum(c) == order]
    return np.array(pts)


def tangent_maps(fg: LoweredFunction, x: np.ndarray, gc: np.ndarray, hess: np.ndarray
                 ) -> np.ndarray:
    """Per cell an ``(n, n)`` map ``W`` with ``w*(z) ~ w*(c) + W (z - c)``, ``w*(z)`` the
    direction (scaled onto the cube's surface) maximising ``g(z) . w / F(z, w)``; zero where
    the maximisers at the vertices and centre are not on one face. Only steers the
    verification (any ``W`` keeps it sound)."""

    t_n, k, n = x.shape
    cen = x.mean(axis=1)
    pts = np.concatenate([x, cen[:, None]], axis=1)  # (T, k+1, n)
    p = gc[:, None] + np.einsum("tab,tkb->tka", hess, pts - cen[:, None])
    zz, pp = pts.reshape(-1, n), p.reshape(-1, n)
    m = zz.shape[0]
    best, _ = best_directions(fg, zz, pp)
    face = np.argmax(np.abs(best), axis=1) * 2 + (best[np.arange(m), np.argmax(
        np.abs(best), axis=1)] > 0)
    cube = best / np.max(np.abs(best), axis=1, keepdims=True)
    cube = cube.reshape(t_n, k + 1, n)
    same = np.all(face.reshape(t_n, k + 1) == face.reshape(t_n, k + 1)[:, :1], axis=1)
    design = np.concatenate([np.ones((t_n, k + 1, 1)), pts - cen[:, None]], axis=2)
    coef = np.linalg.pinv(design) @ cube  # (T, n+1, n)
    w_map = np.swapaxes(coef[:, 1:], 1, 2)  # (T, n, n): w_j = sum_k W_jk dz_k
    # the moved surface must keep the origin well inside: |W (z - c)|_inf <= 0.25
    reach = np.max(np.abs(np.einsum("tjk,tvk->tvj", w_map, x - cen[:, None])), axis=(1, 2))
    ok = same & np.isfinite(reach) & (reach <= 0.25)
    return np.where(ok[:, None, None], w_map, 0.0)


def oriented_frames(simp: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For simplices ``(N, k, n)``: centres ``m``, matrices ``A`` ``(N, n, n)`` and the
    vertices' coordinates ``eps`` ``(N, k, n)`` with ``vertex = m + A eps`` and
    ``|eps| <= 1``: a box along the principal axes of each simplex's vertices, widened by
    ``1e-9`` (relative) so that it holds the simplex whatever the rounding."""
    c = simp.mean(axis=1)
    xc = simp - c[:, None]
    _, vec = np.linalg.eigh(np.einsum("tvj,tvk->tjk", xc, xc))
    y = np.einsum("tvj,tjk->tvk", xc, vec)
    lo, hi = y.min(axis=1), y.max(axis=1)
    mid = 0.5 * (lo + hi)
    r = 0.5 * (hi - lo)
    r = np.maximum(r, 1e-12 * np.max(r, axis=1, keepdims=True) + 1e-300) * (1 + 1e-9)
    eps = (y - mid[:, None]) / r[:, None]
    return c + np.einsum("tjk,tk->tj", vec, mid), vec * r[:, None, :], eps


def _bounds_moving(fj: LoweredFunction, fg: LoweredFunction, cell: np.ndarray,
                   simp: np.ndarray, zlo: np.ndarray, zhi: np.ndarray, wlo: np.ndarray,
                   whi: np.ndarray, centroid: np.ndarray, gc: np.ndarray, hess: np.ndarray,
                   gerr: np.ndarray, w_map: np.ndarray, r: float, chunk: int = 100_000,
                   oriented: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """As `_bounds` with the direction box moving with z: ``w = u + W (z - c_T)``,
    ``u`` in the box. Mean value in ``u``: ``H(z, c_u) + sum_i max|g_i(z) - r dF/dw_i| r_i``
    with both terms affine forms over (z, u), so the cross terms cancel near the tangency.

    The noise symbols of ``z`` span the box ``[zlo, zhi]``, or with ``oriented`` a box along
    the simplex's principal axes that holds it (`oriented_frames`; sound only for
    simplices inside ``[zlo, zhi]``, which the caller checks). A sliver across the axes
    fills a small part of its axis box: there the products ``g(z) . w`` and ``F(z, w)`` are
    enclosed over much more than the simplex (a proof ran out of items on two such cells,
    whose potential bends fast across them)."""
    from finsler.enclosures.affine import AffineInput

    n = gc.shape[1]
    u_ = _EPS / 2
    out_h, out_p, out_f = (np.empty(cell.size) for _ in range(3))
    for a0 in range(0, cell.size, chunk):
        sl = slice(a0, a0 + chunk)
        t = cell[sl]
        nn = t.size
        sv = simp[sl]
        g, h, ge, wm = gc[t], hess[t], gerr[t], w_map[t]
        cz = centroid[t]
        zl, zh = zlo[sl], zhi[sl]
        if oriented:
            mz, az_, eps_o = oriented_frames(sv)
        else:
            mz = 0.5 * zl + 0.5 * zh
            rz = np.maximum(zh - mz, mz - zl) * (1 + 4 * u_)
            az_ = rz[:, :, None] * np.eye(n)[None]  # z_j = mz_j + sum_k az_[j, k] eps_k
        mu = 0.5 * (wlo[sl] + whi[sl])
        ru = np.maximum(whi[sl] - mu, mu - wlo[sl]) * (1 + 4 * u_)
        with np.errstate(all="ignore"):
            def lin_form(c0: np.ndarray, az: np.ndarray, au: np.ndarray) -> Any:
                a = np.concatenate([az, au], axis=1)
                e = 16 * (n + 2) * u_ * (np.abs(c0) + np.sum(np.abs(a), 1)) + 1e-300
                rad = np.sum(np.abs(a), 1) + e
                return AffineInput.form(c0, a, e, c0 - rad * (1 + 1e-12), c0 + rad * (1 + 1e-12))

            zero = np.zeros((nn, n))
            zf = [lin_form(mz[:, j], az_[:, j], zero) for j in range(n)]
            dz0 = mz - cz
            ha = np.einsum("tib,tbk->tik", h, az_)
            wa = np.einsum("tjb,tbk->tjk", wm, az_)
            gf = [lin_form(g[:, i] + np.einsum("tk,tk->t", h[:, i], dz0), ha[:, i], zero)
                  for i in range(n)]
            wc = mu + np.einsum("tjk,tk->tj", wm, dz0)
            w0 = [lin_form(wc[:, j], wa[:, j], zero) for j in range(n)]
            wf = [lin_form(wc[:, j], wa[:, j], np.eye(n)[j][None] * ru)
                  for j in range(n)]
            # the simplex's vertices in the noise coordinates (the linear part's maximum
            # over the simplex is at one of them)
            if oriented:
                eps_v = eps_o
            else:
                eps_v = np.where(rz[:, None] > 0, (sv - mz[:, None]) / np.where(
                    rz[:, None] > 0, rz[:, None], 1.0), 0.0)

            def upper(form: Any, eps_v: np.ndarray = eps_v) -> np.ndarray:
                az, au = form.a[:, :n], form.a[:, n:]
                lin = np.einsum("tvk,tk->tv", eps_v, az)
                val = form.c + np.max(lin, 1) + np.sum(np.abs(au), 1) + form.e
                if oriented:  # eps_v is computed, not exact: 1e-9 covers its error
                    val = val + 1e-9 * np.sum(np.abs(az), 1)
                return val + 16 * (n + 2) * u_ * (np.abs(form.c) + np.max(np.abs(lin), 1)
                                                  + np.sum(np.abs(au), 1) + form.e)

            wnorm = np.linalg.norm(np.abs(wc) + np.sum(np.abs(wa), axis=2) + ru, axis=1)
            # first term: u at the box's centre
            (f1,) = AffineInput.run(fj, [zf + w0])
            p1 = gf[0] * w0[0]
            for i in range(1, n):
                p1 = p1 + gf[i] * w0[i]
            term1 = upper(p1 - f1 * r) + ge * wnorm
            # second term: the coefficient of (u - c_u)
            outs = AffineInput.run(fg, [zf, wf])
            fw, grads = outs[0], outs[1:]
            term2 = np.zeros(nn)
            for i in range(n):
                kap = gf[i] - grads[i] * r
                mag = np.abs(kap.c) + np.sum(np.abs(kap.a), 1) + kap.e
                mag = np.minimum(mag, np.maximum(np.abs(kap.iv.lo), np.abs(kap.iv.hi)))
                term2 = term2 + (mag + ge) * ru[:, i] * (1 + 4 * u_)
            mv = term1 + term2 * (1 + 8 * n * u_)
            # joint form (far from the tangency)
            pj = gf[0] * wf[0]
            for i in range(1, n):
                pj = pj + gf[i] * wf[i]
            uj = upper(pj - fw * r) + ge * wnorm
            up = upper(pj) + ge * wnorm
            # plain intervals: max g . w - r min F over the simplex x the moved box
            from finsler.enclosures.intervals import Interval, enclose

            gv = g[:, None] + np.einsum("tab,tvb->tva", h, sv - cz[:, None])
            sg = 32 * (n + 2) * u_ * (np.abs(g) + np.einsum(
                "tab,tb->ta", np.abs(h), np.max(np.abs(sv - cz[:, None]), axis=1)))
            glo, ghi = gv.min(axis=1) - ge[:, None] - sg, gv.max(axis=1) + ge[:, None] + sg
            wlo2 = np.array([wf[j].iv.lo for j in range(n)]).T
            whi2 = np.array([wf[j].iv.hi for j in range(n)]).T
            prod = np.maximum(np.maximum(glo * wlo2, glo * whi2),
                              np.maximum(ghi * wlo2, ghi * whi2))
            pmax = np.sum(prod, axis=1) * (1 + 4 * n * u_) + 1e-300
            (fb,), _g = enclose(fg, Interval(zl, zh), Interval(wlo2, whi2))
            plain = (Interval(pmax) - Interval(np.float64(r)) * fb).hi
        uh = np.minimum(np.minimum(mv, uj), plain)
        up = np.minimum(up, pmax)
        out_h[sl] = np.where(np.isnan(uh), np.inf, uh)
        out_p[sl] = np.where(np.isnan(up), np.inf, up)
        flo = np.maximum(fw.iv.lo, fb.lo)
        out_f[sl] = np.where(np.isnan(flo), -np.inf, flo)
    return out_h, out_p, out_f
