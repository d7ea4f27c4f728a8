"""Batched primal-dual interior point for the slack reformulation of a non-smooth energy.

A metric whose ``F`` is not smooth (declares ``smooth = False``) and provides the
``smooth_square_sx`` hook (`finsler.hooks`; the car-like metric's ``max`` of its
turning rate) has a smooth reformulated problem, the one IPOPT solves
(`solvers.transcription`): minimise ``sum_i f2(p_i, p_{i+1}, w_i)`` over the interior
points and one slack block ``w_i`` per segment, subject to the hook's slack constraints
and the domain's constraints on every interior point. `interior_energy` solves it
for a batch of paths at once, every path its own problem (the same role as
`solvers.newton.energy.newton_energy` for a smooth ``F``).

Every constraint is written ``c >= 0`` and kept strictly positive (a feasible interior
point). An iteration is one Newton step of the primal-dual barrier equations
``grad f - J^T lambda = 0``, ``lambda_j c_j = mu``: with ``Sigma = lambda / c`` the primal
step solves ``(H_L + J^T Sigma J) dz = -(grad f - J^T mu / c)`` (``H_L`` the Hessian of
the Lagrangian), the right side being the barrier function's gradient. The constraints
are block diagonal (a segment's slack constraints touch its two points and its slacks,
a point's domain constraints only that point), so the slacks are eliminated segment by
segment (a Schur complement of the segment's positive definite slack block) and the
system in the points stays block tridiagonal: it is solved by
`block_tridiagonal_solve` (pivot blocks that are not
definite shifted, a descent direction of the barrier function). The step length: the
fraction-to-boundary rule (``tau = max(0.99, 1 - mu)``) on the linearised constraints and
on the multipliers, then Armijo backtracking on the barrier function with every
constraint positive. The barrier parameter falls as IPOPT's monotone rule: when a row's
barrier problem is solved to ``kappa_eps * mu``, ``mu <- max(mu_min, min(0.2 mu, mu**1.5))``.
The objective is scaled per row by its initial energy (as this package's IPOPT solves
scale it to 1).

A row converges when ``mu`` is at its floor and its KKT error (stationarity of the
Lagrangian in the points and slacks times the domain size, and the complementarity
``lambda_j c_j``, in the scaled objective) is at most ``tol``. Rows that cannot step
(no acceptable step even after shifting the Hessian) report ``STALLED``, rows at the
iteration cap ``MAX_ITERATIONS``: the caller finishes those by IPOPT.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from finsler.errors import InputError
from finsler.metrics.base import Metric
from solvers.newton.backends import _NUMPY_OPS
from solvers.newton.block_tridiagonal import block_tridiagonal_solve, block_tridiagonal_solve_dense
from solvers.newton.energy import NewtonBatch
from solvers.status import NewtonStatus

__all__ = ["InteriorOptions", "covers_interior", "interior_energy"]


#: Up to this many blocks in a group's systems (its running rows times interior points;
#: a group is one pair's rows, see `interior_energy`) the block-tridiagonal solve
#: runs on dense stacks (`block_tridiagonal_solve_dense`, fewer and larger array
#: operations), above it on fields (the smooth Newton method's solve): the same
#: elimination, equal only to rounding, so the choice is the group's own (a row's path
#: never depends on rows of other groups: chosen by the whole batch's count, one car-like
#: pair converged to a path of length 10.02 alone and 16.15 beside one other pair).
#: Measured with 3 x 3 blocks, one thread: 127 blocks, 1 / 8 / 16 / 32 systems 1.1 / 2.2 /
#: 4.0 / 6.2 ms dense against 2.5 / 3.4 / 4.2 / 5.7 ms on fields (255 blocks: 8 systems 4.4
#: against 5.3 ms, 16 5.9 against 5.0 ms): the last iterations of a group run a few rows.
DENSE_BLOCKS_MAX = 1500


def covers_interior(metric: Metric) -> bool:
    """True if `interior_energy` solves ``metric``: ``F`` declared not smooth and the
    metric provides the ``smooth_square_sx`` hook (its slack reformulation)."""
    return (not metric.smooth) and metric.provides("smooth_square_sx")


@dataclass(frozen=True)
class InteriorOptions:
    """Settings of `interior_energy`. ``tol``: KKT error at convergence (scaled
    objective); ``mu_min``: the barrier parameter's floor; ``mu0``: its first value times
    ``0.1 / (number of constraints per path)``; ``max_iter``: iterations per row;
    ``line_steps``: step lengths tried (halving); ``kappa_eps``: a barrier problem counts as
    solved at ``kappa_eps * mu``."""

    tol: float = 1e-9
    mu_min: float = 1e-12
    mu0: float = 1.0
    max_iter: int = 300
    line_steps: int = 8
    kappa_eps: float = 10.0
    armijo: float = 1e-4
    delta0: float = 1e-4
    delta_max: float = 1e10
    short_step: float = 0.1

    def __post_init__(self) -> None:
        for name in ("tol", "mu_min", "mu0", "kappa_eps", "armijo", "delta0", "delta_max",
                     "short_step"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    np.isfinite(v) and v > 0):
                raise InputError(f"{name} must be positive and finite, got {v!r}")
        for name in ("max_iter", "line_steps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")


@dataclass
class _Fns:
    seg: Any  # (x, y, w, lam) -> f2, grad f2 (z, w), c, c's Jacobian^T, Hessian of f2 - lam c
    seg_val: Any  # (x, y, w) -> f2, c
    wval: Any  # (x, y) -> exact slacks
    dom: Any | None  # (p, lam) -> c, Jacobian^T, Hessian of -lam c
    dom_val: Any | None  # p -> c
    k: int  # slacks per segment
    m: int  # slack constraints per segment
    md: int  # domain constraints per point


def _functions(metric: Metric) -> _Fns:
    return metric.derived("interior.functions", lambda: _build(metric))


def _build(metric: Metric) -> _Fns:
    from finsler.lowering import lower
    from solvers.transcription import _segment_functions, domain_rows, nonnegative_rows

    seg, wval, _, (lbw, ubw), (lbgs, ubgs), _, _ = _segment_functions(metric)
    d, k = metric.dim, int(seg.nnz_in(2))
    x, y, w = ca.SX.sym("x", d), ca.SX.sym("y", d), ca.SX.sym("w", k)
    zw = ca.vertcat(x, y, w)
    f2, g = seg(x, y, w)
    cons = nonnegative_rows([(lbw, 1, w), (ubw, -1, w), (lbgs, 1, g), (ubgs, -1, g)])
    cv = ca.vertcat(*cons)
    m = len(cons)
    lam = ca.SX.sym("lam", m)
    lag = f2 - ca.dot(lam, cv)
    dens = ca.densify
    segf = ca.Function("ip_seg", [x, y, w, lam],
                       [dens(f2), dens(ca.gradient(f2, zw)), dens(cv),
                        dens(ca.vec(ca.jacobian(cv, zw))), dens(ca.vec(ca.hessian(lag, zw)[0]))])
    segv = ca.Function("ip_seg_val", [x, y, w], [dens(f2), dens(cv)])
    p = ca.SX.sym("p", d)
    dc = domain_rows(metric, p)
    md = len(dc)
    domf = domv = None
    if md:
        dv = ca.vertcat(*dc)
        lamd = ca.SX.sym("lamd", md)
        domf = lower(ca.Function("ip_dom", [p, lamd],
                                 [dens(dv), dens(ca.vec(ca.jacobian(dv, p))),
                                  dens(ca.vec(ca.hessian(-ca.dot(lamd, dv), p)[0]))]))
        domv = lower(ca.Function("ip_dom_val", [p], [dens(dv)]))
    return _Fns(lower(segf), lower(segv), lower(ca.Function("ip_wval", [x, y],
                                                            [dens(wval(x, y))])),
                domf, domv, k, m, md)


def _mv(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Stacks of small matrices times vectors: ``a[..., i, j] v[..., j]``, summed over
    ``j`` in order, a product and a sum per ``j`` (bitwise the broadcast product and sum
    over the short axis, ~2-6x faster; a matrix product rounds differently, and the
    interior point's long runs amplify that into other local optima)."""
    out = a[..., 0] * v[..., None, 0]
    for j in range(1, a.shape[-1]):
        out += a[..., j] * v[..., None, j]
    return out


def _mtv(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Transposed: ``a[..., j, i] v[..., j]`` (as `_mv`)."""
    out = a[..., 0, :] * v[..., 0, None]
    for j in range(1, a.shape[-2]):
        out += a[..., j, :] * v[..., j, None]
    return out


class _State:
    """The running batch (numpy): points ``P`` ``(B, n+1, d)``, slacks ``W`` ``(B, n, k)``,
    multipliers ``L`` ``(B, n, m)`` (segments) and ``Ld`` ``(B, n-1, md)`` (points),
    barrier parameter ``mu`` and objective scale ``fs`` ``(B,)``."""

    def __init__(self, metric: Metric, paths: np.ndarray, opt: InteriorOptions,
                 scale: float, groups: np.ndarray | None = None) -> None:
        self.f = _functions(metric)
        self.opt, self.scale, self.d = opt, float(scale), metric.dim
        self.evaluations = 0
        self.value_evaluations = 0
        P = np.array(paths, dtype=np.float64)
        B, n1, d = P.shape
        self.n = n1 - 1
        f = self.f
        # strictly inside the domain: projected, then pulled towards the bounds' centre
        lo, hi = metric.domain.bounds()
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        mid = np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (lo + hi), 0.0)
        inner = np.asarray(metric.domain.project(P[:, 1:-1].reshape(-1, d)), dtype=np.float64)
        inner = mid + (1.0 - 1e-6) * (inner - mid)
        P[:, 1:-1] = inner.reshape(B, self.n - 1, d)
        self.P = P
        x, y = P[:, :-1].reshape(-1, d), P[:, 1:].reshape(-1, d)
        W = np.asarray(f.wval(x, y)[0]).reshape(B, self.n, f.k)
        seglen = np.max(np.abs(P[:, 1:] - P[:, :-1]), axis=2)  # (B, n)
        self.W = W + 1e-2 * np.maximum(seglen, 1e-6 * self.scale)[..., None]
        e0, _ = self._values(self.P, self.W)
        self.fs = 1.0 / np.maximum(e0, 1e-300)
        ncons = self.n * f.m + (self.n - 1) * f.md
        self.mu = np.full(B, opt.mu0 * 0.1 / ncons)
        c, cd = self._cons(self.P, self.W)
        self.L = self.mu[:, None, None] / c
        self.Ld = self.mu[:, None, None] / cd if f.md else np.zeros((B, self.n - 1, 0))
        self.status = np.zeros(B, dtype=np.int64)
        self.groups = (np.zeros(B, dtype=np.int64) if groups is None
                       else np.unique(groups, return_inverse=True)[1].reshape(B))
        self.iterations = np.zeros(B, dtype=np.int64)
        self.delta = np.zeros(B)
        self.error = np.full(B, np.inf)
        ok = np.all(c > 0, axis=(1, 2)) & np.isfinite(e0)
        if f.md:
            ok &= np.all(cd > 0, axis=(1, 2))
        self.status[~ok] = NewtonStatus.NOT_FINITE

    # -- evaluations ----------------------------------------------------------------------
    def _values(self, P: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sum of ``f2`` ``(K,)`` and the smallest constraint value per path."""
        d, f = self.d, self.f
        K = P.shape[0]
        self.value_evaluations += K * self.n
        f2, _ = f.seg_val(P[:, :-1].reshape(-1, d), P[:, 1:].reshape(-1, d),
                          W.reshape(-1, f.k))
        return f2.reshape(K, self.n).sum(1), None

    def _cons(self, P: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, f = self.d, self.f
        K = P.shape[0]
        _, c = f.seg_val(P[:, :-1].reshape(-1, d), P[:, 1:].reshape(-1, d), W.reshape(-1, f.k))
        cd = (f.dom_val(P[:, 1:-1].reshape(-1, d))[0].reshape(K, self.n - 1, f.md)
              if f.md else np.zeros((K, self.n - 1, 0)))
        return c.reshape(K, self.n, f.m), cd

    def _barrier(self, P: np.ndarray, W: np.ndarray, fs: np.ndarray, mu: np.ndarray
                 ) -> np.ndarray:
        """Barrier function ``fs sum f2 - mu sum log c`` ``(K,)`` (``inf`` where a constraint
        is not positive)."""
        d, f = self.d, self.f
        K = P.shape[0]
        self.value_evaluations += K * self.n
        f2, c = f.seg_val(P[:, :-1].reshape(-1, d), P[:, 1:].reshape(-1, d),
                          W.reshape(-1, f.k))
        c = c.reshape(K, -1)
        if f.md:
            cd = f.dom_val(P[:, 1:-1].reshape(-1, d))[0].reshape(K, -1)
            c = np.concatenate([c, cd], 1)
        with np.errstate(all="ignore"):
            lg = np.where(c > 0, np.log(np.maximum(c, 1e-300)), -np.inf).sum(1)
            return fs * f2.reshape(K, self.n).sum(1) - mu * lg

    # -- one iteration of the rows ``idx`` ------------------------------------------------
    def step(self, idx: np.ndarray) -> None:
        f, d, opt = self.f, self.d, self.opt
        n, k, m, md = self.n, f.k, f.m, f.md
        A = idx.size
        P, W, L, Ld = self.P[idx], self.W[idx], self.L[idx], self.Ld[idx]
        fs, mu = self.fs[idx], self.mu[idx]
        nz = 2 * d + k
        x, y = P[:, :-1].reshape(-1, d), P[:, 1:].reshape(-1, d)
        self.evaluations += A * n
        f2, gf, c, JT, HL = f.seg(x, y, W.reshape(-1, k), (L / fs[:, None, None]).reshape(-1, m))
        gf = gf.reshape(A, n, nz) * fs[:, None, None]
        c = c.reshape(A, n, m)
        JT = JT.reshape(A, n, nz, m)
        HL = HL.reshape(A, n, nz, nz) * fs[:, None, None, None]
        if md:
            cd, JdT, Hd = f.dom(P[:, 1:-1].reshape(-1, d), Ld.reshape(-1, md))
            cd = cd.reshape(A, n - 1, md)
            JdT = JdT.reshape(A, n - 1, d, md)
            Hd = Hd.reshape(A, n - 1, d, d)
        # KKT error at the current point (scaled objective): stationarity, complementarity
        lag = gf - _mv(JT, L)
        gp = np.zeros((A, n - 1, d))
        gp += lag[:, :-1, d:2 * d]
        gp += lag[:, 1:, :d]
        if md:
            gp -= _mv(JdT, Ld)
        stat = np.maximum(np.abs(gp).max(axis=(1, 2)) * self.scale,
                          np.abs(lag[..., 2 * d:]).max(axis=(1, 2), initial=0.0) * self.scale)
        comp = np.abs(L * c).max(axis=(1, 2))
        if md:
            comp = np.maximum(comp, np.abs(Ld * cd).max(axis=(1, 2)))
        err0 = np.maximum(stat, comp)
        self.error[idx] = err0
        done = (mu <= opt.mu_min * (1 + 1e-12)) & (err0 <= opt.tol)
        # barrier updates while the barrier problem is solved (IPOPT's monotone rule)
        for _ in range(8):
            comp_mu = np.abs(L * c - mu[:, None, None]).max(axis=(1, 2))
            if md:
                comp_mu = np.maximum(comp_mu, np.abs(Ld * cd - mu[:, None, None]).max(
                    axis=(1, 2)))
            errm = np.maximum(stat, comp_mu)
            lower = (errm <= opt.kappa_eps * mu) & (mu > opt.mu_min * (1 + 1e-12))
            if not lower.any():
                break
            mu = np.where(lower, np.maximum(opt.mu_min, np.minimum(0.2 * mu, mu ** 1.5)), mu)
        self.mu[idx] = mu
        # the primal-dual system
        sig = L / c
        H = HL + (JT * sig[..., None, :]) @ np.swapaxes(JT, -1, -2)
        g = gf - _mv(JT, mu[:, None, None] / c)
        zi, wi = slice(0, 2 * d), slice(2 * d, nz)
        if k:
            Cinv = np.linalg.inv(H[..., wi, wi])
            Bm = H[..., zi, wi]
            BC = Bm @ Cinv
            Hz = H[..., zi, zi] - BC @ np.swapaxes(Bm, -1, -2)
            gz = g[..., zi] - _mv(BC, g[..., wi])
        else:
            Hz, gz = H, g
        D = Hz[:, :-1, d:, d:] + Hz[:, 1:, :d, :d]
        rhs = -(gz[:, :-1, d:] + gz[:, 1:, :d])
        if md:
            sd = Ld / cd
            D = D + Hd + (JdT * sd[..., None, :]) @ np.swapaxes(JdT, -1, -2)
            rhs = rhs - (-_mv(JdT, mu[:, None, None] / cd))
        off = np.zeros((A, n - 1, d, d))
        off[:, :-1] = Hz[:, 1:-1, :d, d:]
        dscale = np.abs(np.trace(D, axis1=2, axis2=3)).mean(1) / d
        dscale = np.where(np.isfinite(dscale) & (dscale > 0), dscale, 1.0)
        shift = (self.delta[idx] * dscale)[:, None]
        # per group (never by the whole batch: the two solves agree only to rounding)
        grp = self.groups[idx]
        few = np.bincount(grp)[grp] * (n - 1) <= DENSE_BLOCKS_MAX
        dp, okf = np.zeros((A, n - 1, d)), np.zeros(A, bool)
        if few.any():  # a few rows: fewer, larger array operations
            r = np.flatnonzero(few)
            with np.errstate(all="ignore"):
                dp[r], okf[r] = block_tridiagonal_solve_dense(
                    D[r] + shift[r, ..., None, None] * np.eye(d), off[r], rhs[r], dscale[r],
                    local=True)
        if not few.all():
            r = np.flatnonzero(~few)
            diagf = [[np.ascontiguousarray(D[r, :, i, j]) + (shift[r] if i == j else 0.0)
                      for j in range(d)] for i in range(d)]
            offf = [[np.ascontiguousarray(off[r, :, i, j]) for j in range(d)] for i in range(d)]
            rhsf = [np.ascontiguousarray(rhs[r, :, i]) for i in range(d)]
            with np.errstate(all="ignore"):
                sol, okr = block_tridiagonal_solve(_NUMPY_OPS, diagf, offf, rhsf,
                                                   dscale[r, None], local=True,
                                                   method="cyclic")
            dp[r], okf[r] = np.stack(sol, -1), np.asarray(okr, bool)  # (A, n-1, d)
        factored = np.asarray(okf, bool) & np.all(np.isfinite(dp), axis=(1, 2))
        dp = np.where(factored[:, None, None], dp, 0.0)
        dfull = np.zeros((A, n + 1, d))
        dfull[:, 1:-1] = dp
        dz = np.concatenate([dfull[:, :-1], dfull[:, 1:]], 2)  # (A, n, 2d)
        if k:
            dw = -_mv(Cinv,
                            g[..., wi] + _mtv(Bm, dz))
            dzw = np.concatenate([dz, dw], 2)
        else:
            dw = np.zeros((A, n, 0))
            dzw = dz
        Jd = _mtv(JT, dzw)  # (A, n, m): linearised change of c
        dL = mu[:, None, None] / c - L - sig * Jd
        tau = np.maximum(0.99, 1.0 - mu)
        with np.errstate(all="ignore"):
            r = np.where(Jd < 0, -tau[:, None, None] * c / Jd, np.inf).min(axis=(1, 2))
            rl = np.where(dL < 0, -tau[:, None, None] * L / dL, np.inf).min(axis=(1, 2))
        if md:
            Jdd = _mtv(JdT, dp)
            dLd = mu[:, None, None] / cd - Ld - sd * Jdd
            with np.errstate(all="ignore"):
                r = np.minimum(r, np.where(Jdd < 0, -tau[:, None, None] * cd / Jdd,
                                           np.inf).min(axis=(1, 2)))
                rl = np.minimum(rl, np.where(dLd < 0, -tau[:, None, None] * Ld / dLd,
                                             np.inf).min(axis=(1, 2)))
        amax = np.minimum(1.0, r)
        adual = np.minimum(1.0, rl)
        # Armijo backtracking on the barrier function, all step lengths at once
        phi0 = fs * f2.reshape(A, n).sum(1) - mu * (
            np.log(c).reshape(A, -1).sum(1) + (np.log(cd).reshape(A, -1).sum(1) if md else 0))
        slope = np.einsum("asi,asi->a", g[..., zi], dz) + (
            np.einsum("asi,asi->a", g[..., wi], dw) if k else 0.0)
        if md:
            slope = slope - np.einsum("apj,apj->a", np.einsum(
                "apij,apj->api", JdT, mu[:, None, None] / cd), dp)
        # (the point gradient of the barrier terms of the domain constraints)
        live = np.flatnonzero(factored & (slope < 0) & np.isfinite(slope))
        moved = np.zeros(A, bool)
        alpha = np.zeros(A)
        # the longest step first; the rows it fails for try the next two, then the rest
        # at once (the same accepted step as trying them one by one, in fewer calls; most
        # rows that fail the full step take a half or a quarter step)
        halvings = 2.0 ** -np.arange(1, opt.line_steps)
        for steps in (np.ones(1), halvings[:2], halvings[2:]):
            if not live.size or not steps.size:
                break
            al = amax[live][None, :] * steps[:, None]  # (S, Lv)
            S = steps.size
            Pt = P[live][None] + al[..., None, None] * dfull[live][None]
            Wt = W[live][None] + al[..., None, None] * dw[live][None]
            ph = self._barrier(Pt.reshape(S * live.size, n + 1, d),
                               Wt.reshape(S * live.size, n, k), np.tile(fs[live], S),
                               np.tile(mu[live], S)).reshape(S, live.size)
            good = np.isfinite(ph) & (
                ph <= phi0[live][None] + opt.armijo * al * slope[live][None])
            has = good.any(0)
            first = np.argmax(good, 0)
            rows = live[has]
            moved[rows] = True
            alpha[rows] = al[first[has], np.flatnonzero(has)]
            live = live[~has]
        # updates
        a = alpha[:, None, None]
        P = P + a * dfull
        W = W + a * dw
        ad = np.where(moved, adual, 0.0)[:, None, None]
        L = L + ad * dL
        if md:
            Ld = Ld + ad * dLd
        # safeguard: multipliers within [mu / (kappa c), kappa mu / c] at the new point
        cn, cdn = self._cons(P, W)
        kap = 1e10
        L = np.clip(L, mu[:, None, None] / (kap * cn), kap * mu[:, None, None] / cn)
        if md:
            Ld = np.clip(Ld, mu[:, None, None] / (kap * cdn), kap * mu[:, None, None] / cdn)
        self.P[idx], self.W[idx], self.L[idx] = P, W, L
        if md:
            self.Ld[idx] = Ld
        self.iterations[idx] += 1
        # a step cut short (by the boundary or the line search) means a direction too long
        # for its model: the shift grows (Levenberg-Marquardt); a full step lowers it
        stuck = (~moved | (alpha < opt.short_step)) & ~done
        self.delta[idx] = np.where(stuck, np.maximum(self.delta[idx] * 4.0, opt.delta0),
                                   self.delta[idx] / 3.0)
        self.delta[idx] = np.where(self.delta[idx] < 1e-12, 0.0, self.delta[idx])
        st = self.status
        st[idx[done]] = NewtonStatus.CONVERGED
        st[idx[~done & (self.delta[idx] > opt.delta_max)]] = NewtonStatus.STALLED
        over = ~done & (self.iterations[idx] >= opt.max_iter) & (st[idx] == NewtonStatus.RUNNING)
        st[idx[over]] = NewtonStatus.MAX_ITERATIONS


def interior_energy(metric: Metric, paths: Any, options: InteriorOptions | None = None, *,
                    scale: float = 1.0, groups: Any = None) -> NewtonBatch:
    """Minimise the discrete energy of every path of ``paths`` ``(B, n+1, d)`` (ends fixed)
    for a metric that `covers_interior`, through its slack reformulation, all rows at
    once (numpy); ``scale``: the domain's size. Interior points are first moved strictly
    inside the domain (by ``1e-6`` of their distance from the bounds' centre). Returns a
    `NewtonBatch`: ``energy`` the energy ``sum C**2`` of the points
    (exact slacks), ``residual`` the final KKT error (see the module docstring).
    ``groups`` ``(B,)`` (e.g. each row's pair): a row's result depends only on the rows of
    its group (the block solve is chosen per group, `DENSE_BLOCKS_MAX`); default one
    group."""
    if not covers_interior(metric):
        raise InputError(f"{metric.name}: the interior-point method needs a metric that is "
                         "not smooth and provides smooth_square_sx")
    opt = options or InteriorOptions()
    shape = np.shape(paths)
    if len(shape) != 3 or shape[2] != metric.dim or shape[1] < 3:
        raise InputError(f"paths must have shape (B, n+1, {metric.dim}) with n >= 2, got "
                         f"{shape}")
    if groups is not None:
        groups = np.asarray(groups)
        if groups.shape != (shape[0],) or not np.issubdtype(groups.dtype, np.integer):
            raise InputError(f"groups must be integers of shape ({shape[0]},), got "
                             f"{groups.dtype} {groups.shape}")
    st = _State(metric, np.asarray(paths, dtype=np.float64), opt, scale, groups)
    while True:
        idx = np.flatnonzero(st.status == NewtonStatus.RUNNING)
        if idx.size == 0:
            break
        st.step(idx)
    f = st.f
    d = metric.dim
    B = st.P.shape[0]
    x, y = st.P[:, :-1].reshape(-1, d), st.P[:, 1:].reshape(-1, d)
    wex = np.asarray(f.wval(x, y)[0])
    f2, _ = f.seg_val(x, y, wex)
    energy = f2.reshape(B, st.n).sum(1)
    energy = np.where(st.status == NewtonStatus.NOT_FINITE, np.inf, energy)
    return NewtonBatch(st.P, energy, st.error.copy(), st.iterations.copy(), st.status.copy(),
                       st.evaluations, st.value_evaluations)
