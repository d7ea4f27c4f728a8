"""Quadratic (P2) potentials for :func:`solvers.certify_nd.certify_nd` (issue 46, 3-D bar).

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
2. the verification (:func:`verify_p2`) proves ``g_T(z) . w <= R F(z, w)`` for every ``z``
   of every cell of the region and every ``w``: ``H = g_T(z) . w - R F(z, w)`` is bounded
   by ONE affine-arithmetic form over a box of ``(z, w)`` (:func:`finsler.affine.affine_forms`;
   the affine gradient and F share the noise symbols of ``z``, so their first-order
   variations cancel), its linear part in ``z`` maximised over the cell's (sub)simplex (its
   vertices), not the whole box (where the quadratic would be extrapolated); branch and
   bound splits the direction boxes and bisects the simplices;
3. the gradient ``(g_c, G)`` of each cell is computed in float64 with an a-posteriori bound
   of its error (:meth:`P2Cells.affine_gradients`), added to ``g . w`` in step 2.

F must have affine rules for every operation of its program (smooth metrics: ``sqrt``,
powers, ``sin``, ``cos``, the arithmetic); where it has not (``max``, ``abs``: car-like)
:func:`affine_ready` says so and the caller keeps the P1 element.

Nothing here imports :mod:`solvers.certify_nd`.
"""

from __future__ import annotations

import itertools
import time
from typing import Any

import casadi as ca
import numpy as np

from finsler.affine import affine_forms
from finsler.lowering import LoweredFunction, lower
from finsler.metric import Metric
from solvers.certify_nd_parts import Cells, face_boxes

_EPS = float(np.finfo(float).eps)
#: every (sub)simplex is verified blown up by this factor about its centroid, so that the
#: pieces of a bisection cover their parent whatever the rounding of the midpoint
_GROW = 1e-9
_DEBUG = bool(__import__("os").environ.get("CERTIFY_P2_DEBUG"))


def lowered_f_joint(metric: Metric) -> LoweredFunction:
    """``u = (z, w) -> F(z, w)`` as one input (what the affine forms need), lowered once."""
    def build() -> LoweredFunction:
        u = ca.SX.sym("u", 2 * metric.dim)
        f = metric.F_sx(u[: metric.dim], u[metric.dim:])
        return lower(ca.Function(f"cnd_fj_{metric._ident}", [u], [f]))
    return metric.derived("certify_nd.f_joint", build)


def affine_ready(metric: Metric) -> bool:
    """Whether every operation of the metric's F has an affine rule (P2 is possible)."""
    fn = lowered_f_joint(metric)
    n = metric.dim
    lo = np.concatenate([np.asarray(metric.domain.bounds()[0], float), -np.ones(n)])
    hi = np.concatenate([np.asarray(metric.domain.bounds()[1], float), np.ones(n)])
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return False
    mid = 0.5 * (lo + hi)
    try:
        affine_forms(fn, mid[None], mid[None] + 1e-3)
    except NotImplementedError:
        return False
    return True


def nodes(n: int) -> np.ndarray:
    """Barycentric coordinates ``(K, n+1)`` of the P2 nodes: vertices, edge midpoints."""
    eye = np.eye(n + 1)
    mids = [0.5 * (eye[i] + eye[j]) for i in range(n + 1) for j in range(i + 1, n + 1)]
    return np.concatenate([eye, np.array(mids)])


class P2Cells:
    """The P2 unknowns of :class:`~solvers.certify_nd_parts.Cells`: one per vertex, then
    one per edge (its midpoint's value); ``dof`` ``(T, K)`` in the order of :func:`nodes`."""

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
              max_elements: int = int(__import__("os").environ.get("P2_MAXEL", "2000000"))) -> dict[str, Any]:
    """A proven ``R`` with ``g_T(z) . v <= R F(z, v)`` for every cell ``T`` (vertices ``x``
    ``(T, n+1, n)``, gradient ``gc + hess (z - centroid)`` with error ``gerr``), every ``z``
    of the cell inside the box ``[blo, bhi]`` and every ``v``. ``fj``: ``(z, w) -> F`` as
    one input; ``fg``: ``(z, w) -> (F, grad_w F)``.

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
        c = 0.5 * (wlo + whi)
        zp = np.clip(sc, zlo, zhi)
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
        up_h, up_p, f_low = _bounds(fj, fg, cell, grown, zlo, zhi, wlo, whi, centroid, gc, hess,
                                    gerr, r_target)
        open_ = ~(up_h <= 0.0) & ~outside
        final = depth >= max_depth or int(open_.sum()) * 2 ** n > max_elements
        if final and np.any(open_):
            with np.errstate(all="ignore"):
                ratio = np.where(up_p[open_] <= 0, 0.0,
                                 np.where(f_low[open_] > 0,
                                          up_p[open_] / f_low[open_] * (1 + 4 * _EPS),
                                          np.inf))
            r_fail = max(r_fail, float(np.max(ratio)))
            if _DEBUG:
                o = np.flatnonzero(open_)
                worst = o[np.argsort(-ratio)[:8]]
                for q in worst:
                    print("   open", cell[q], zlo[q].round(3), zhi[q].round(3), wlo[q].round(3),
                          whi[q].round(3), "ratio", ratio[np.searchsorted(o, q)].round(4),
                          "up_h", up_h[q], flush=True)
                print("   open items", o.size, "cells", np.unique(cell[o]).size, flush=True)
            break
        cell, simp, wlo, whi = cell[open_], simp[open_], wlo[open_], whi[open_]
        if not cell.size:
            break
        # split what is wider: the direction box (cube coordinates) or the simplex
        # (relative to its cell's diameter, x 2)
        wwid = np.max(whi - wlo, axis=1)
        zdiam = np.max(np.linalg.norm(simp - simp.mean(axis=1, keepdims=True), axis=2), 1)
        by_w = wwid > 2.0 * zdiam / cell_diam[cell]
        iw, iz = np.flatnonzero(by_w), np.flatnonzero(~by_w)
        wlo_a, whi_a, pa = _split_dirs(wlo[iw], whi[iw], iw)
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


def _bounds(fj: LoweredFunction, fg: LoweredFunction, cell: np.ndarray, simp: np.ndarray,
            zlo: np.ndarray, zhi: np.ndarray, wlo: np.ndarray, whi: np.ndarray,
            centroid: np.ndarray, gc: np.ndarray, hess: np.ndarray, gerr: np.ndarray,
            r: float, chunk: int = 200_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Upper bounds of ``H = g(z) . w - r F(z, w)`` and of ``g(z) . w``, and a lower bound
    of ``F``, over (simplex ``simp``) x (direction box ``B``, centre ``c``) for each item.

    ``H(z, w) <= H(z, c) + (g(z) - r grad_w F(z, B)) . (w - c)`` (mean value in ``w``);
    ``H(z, c)`` by one affine form in ``z`` (the affine gradient and ``F(., c)`` share the
    noise symbols: second order in the simplex's width), its linear part maximised over the
    simplex's vertices; the second term by intervals (second order near the tangency, where
    ``g`` touches ``r grad_w F``). The smaller of that and ``max g . w - r min F``."""
    from finsler.intervals import Interval, enclose

    n = gc.shape[1]
    out_h, out_p, out_f = (np.empty(cell.size) for _ in range(3))
    for a0 in range(0, cell.size, chunk):
        sl = slice(a0, a0 + chunk)
        t = cell[sl]
        sv = simp[sl]
        g, h, ge = gc[t], hess[t], gerr[t]
        c = 0.5 * (wlo[sl] + whi[sl])
        with np.errstate(all="ignore"):
            mid, rad, [(cf, af, ef, _)] = affine_forms(
                fj, np.concatenate([zlo[sl], c], 1), np.concatenate([zhi[sl], c], 1))
            mz, rz = mid[:, :n], rad[:, :n]
            dz = mz - centroid[t]
            q = g + np.einsum("tab,tb->ta", h, dz)  # g at the box's centre
            cp = np.einsum("ta,ta->t", q, c)
            apz = rz * np.einsum("tab,ta->tb", h, c)
            mag = np.einsum("ta,ta->t", np.abs(g) + np.einsum(
                "tab,tb->ta", np.abs(h), np.abs(dz)), np.abs(c)) + np.sum(np.abs(apz), 1)
            ch = cp - r * cf
            az = apz - r * af[:, :n]
            eh = (r * ef * (1 + 4 * _EPS) + 32 * (n + 2) * _EPS * (mag + r * np.abs(cf))
                  + ge * np.linalg.norm(c, axis=1) * (1 + 1e-12) + 1e-300)
            eps_v = np.where(rz[:, None] > 0, (sv - mz[:, None]) / np.where(
                rz[:, None] > 0, rz[:, None], 1.0), 0.0)
            lin = np.einsum("tvk,tk->tv", eps_v, az)
            h_c = (ch + np.max(lin, axis=1) + eh
                   + 16 * (n + 2) * _EPS * (np.abs(ch) + np.max(np.abs(lin), axis=1) + eh))
            # the range of the affine gradient over the simplex (its vertices) +- gerr
            gv = g[:, None] + np.einsum("tab,tvb->tva", h, sv - centroid[t][:, None])
            slack_g = 32 * (n + 2) * _EPS * (np.abs(g) + np.einsum(
                "tab,tb->ta", np.abs(h), np.max(np.abs(sv - centroid[t][:, None]), axis=1)))
            glo = gv.min(axis=1) - ge[:, None] - slack_g
            ghi = gv.max(axis=1) + ge[:, None] + slack_g
            (fb,), grad = enclose(fg, Interval(zlo[sl], zhi[sl]), Interval(wlo[sl], whi[sl]))
            rr = Interval(np.float64(r))
            mv = Interval(h_c)
            for i in range(n):
                off = Interval(wlo[sl, i]) - Interval(c[:, i])
                off = Interval(off.lo, (Interval(whi[sl, i]) - Interval(c[:, i])).hi)
                mv = mv + (Interval(glo[:, i], ghi[:, i]) - rr * grad[i]) * off
            # max over (simplex, box) of g . w: per coordinate, the largest product
            prod = np.maximum(np.maximum(glo * wlo[sl], glo * whi[sl]),
                              np.maximum(ghi * wlo[sl], ghi * whi[sl]))
            pmax = np.sum(prod, axis=1) * (1 + 4 * n * _EPS) + 1e-300
            plain = Interval(pmax) - rr * fb
        uh = np.minimum(mv.hi, plain.hi)
        out_h[sl] = np.where(np.isnan(uh), np.inf, uh)
        out_p[sl] = np.where(np.isnan(pmax), np.inf, pmax)
        out_f[sl] = np.where(np.isnan(fb.lo), -np.inf, fb.lo)
    return out_h, out_p, out_f


def _split_dirs(wlo: np.ndarray, whi: np.ndarray, parent: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each direction box cut in two along every free coordinate."""
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


def run_p2(m: Metric, f_fn: LoweredFunction, s: np.ndarray, g: np.ndarray, upper: float,
           cap: float, spec: Any, blo: np.ndarray, bhi: np.ndarray, scale: float,
           rng: np.random.Generator, points: np.ndarray, dirs: np.ndarray,
           times: dict[str, float], t_start: float) -> dict[str, Any]:
    """The mesh rounds of :func:`solvers.certify_nd.certify_nd` with the P2 element (see
    the module docstring); ``spec`` an ``NDSpec``. Returns the best round's figures, the
    rounds and how it stopped."""
    from solvers.certify_nd_parts import (
        LPFailure,
        box_distance,
        build_cells,
        edge_midpoints,
        reached,
        solve_rows_lp,
    )
    from solvers.status import CertifyStatus

    from solvers.certify_nd_parts import lowered_f_grad

    fj = lowered_f_joint(m)
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
                             & ~(scale * dist > upper * (1 + 1e-9)))
        p2 = P2Cells(cells)
        x = cells.points[cells.simp[rel]]
        cen = x.mean(axis=1)
        zk = np.clip(np.einsum("kv,tvn->tkn", lat, x), blo, bhi)  # (nr, K, n)
        nr = rel.size
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
        for _lp in range(spec.lp_rounds):
            rc, rk, rd = np.nonzero(active)
            t_rows = np.concatenate([rc, ec])
            lam_rows = np.concatenate([lat[rk], elam])
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
            if _DEBUG:
                print(f"  lp {_lp}: rows {b_rows.size} value "
                      f"{float(g_w[1] @ phi[g_w[0]] - s_w[1] @ phi[s_w[0]]):.6f} "
                      f"{time.perf_counter() - t0:.1f} s", flush=True)
            gcs, hs, gerr = p2.affine_gradients(phi, rel)
            gk = gcs[:, None] + np.einsum("tab,tkb->tka", hs, zk - cen[:, None])
            ratio = np.einsum("tkn,dn->tkd", gk, dirs) / b_lp
            viol = (ratio > 1.0 + 1e-7) & ~active
            if np.any(viol):  # row generation: the 2 worst directions of each node
                flat = np.where(viol, ratio, -np.inf).reshape(nr * k_nodes, nd)
                order = np.argsort(-flat, axis=1)[:, :2]
                take = np.isfinite(np.take_along_axis(flat, order, 1))
                node = np.repeat(np.arange(nr * k_nodes), 2)[take.ravel()]
                active.reshape(nr * k_nodes, nd)[node, order.ravel()[take.ravel()]] = True
                continue
            r_lp = max(float(np.max(ratio)), 1e-300)
            if ec.size:
                ge = gcs[ec] + np.einsum("tab,tb->ta", hs[ec],
                                         np.einsum("rv,rvn->rn", elam, x[ec]) - cen[ec])
                r_lp = max(r_lp, float(np.max(np.einsum("ij,ij->i", ge, ew) / eb)))
            t0 = time.perf_counter()
            ver = verify_p2(fj, fg_fn, x, gcs, hs, gerr, blo, bhi, r_lp, spec.verify_tol,
                            max_depth=spec.verify_depth)
            times["verify"] += time.perf_counter() - t0
            if _DEBUG:
                print(f"  verify: r_lp {r_lp:.5f} R {ver['R']:.5f} target {ver['r_target']:.5f}"
                      f" boxes {ver['boxes']} depth {ver['depth']} cuts {ver['cuts'][0].size} "
                      f"{ver['seconds']:.1f} s", flush=True)
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
            fb = np.asarray(fb, float).reshape(-1)
            ok = np.isfinite(fb) & (fb > 0)
            ec = np.concatenate([ec, cc[ok]])
            elam = np.concatenate([elam, p2.barycentric(rel[cc[ok]], cz[ok])])
            ew = np.concatenate([ew, cw[ok]])
            eb = np.concatenate([eb, fb[ok]])
        if failure is not None:
            stopped_by, status, message = "lp_failed", CertifyStatus.LP_FAILED, failure
            break
        if result is None:
            stopped_by = "lp_rounds"
            continue
        rounds.append({"cells": result["cells"], "relevant_cells": result["rel"],
                       "vertices": result["vertices"], "rows": result["rows"],
                       "lp_value": result["dphi"], "verified_ratio": result["R"],
                       "verify_boxes": result["ver"]["boxes"],
                       "verify_open": result["ver"]["open"], "lower": result["lower"],
                       "gap": (upper - result["lower"]) / upper,
                       "seconds": time.perf_counter() - t_start})
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
        points = np.concatenate([cells.points, new])
    return {"best": best, "rounds": rounds, "stopped_by": stopped_by, "status": status,
            "message": message}
