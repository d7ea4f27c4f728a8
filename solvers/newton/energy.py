"""Batched Newton solves of the discrete energy: many (pair, seed) problems at once.

The discrete energy of a path ``p_0 .. p_n`` (ends fixed) is ``E = sum_i phi(p_i, p_{i+1})``
with ``phi(x, y) = C(x, y)**2 = F(x, y - x)**2`` (eq. 7). It is a sum over segments, so its
gradient in the interior points gathers the end-point gradients of neighbouring segments
and its Hessian is block tridiagonal: the diagonal block of point ``j`` is ``phi_yy`` of
segment ``j - 1`` plus ``phi_xx`` of segment ``j``, the block coupling points ``j`` and
``j + 1`` is ``phi_xy`` of segment ``j``. ``phi`` with its gradient and Hessian in ``(x, y)``
is ONE CasADi function derived symbolically from the metric's ``F_sx``
(`finsler.Metric.segment_derivatives`), evaluated for every segment of every problem
at once through the lowering: no second formula.

`newton_energy` minimises ``E`` for a batch of paths ``(B, n+1, dim)``, each problem
with its own step, damping and convergence test (`NewtonState`); the Hessian is
factorised by block Thomas elimination or block cyclic reduction
(`block_tridiagonal_solve`), vectorised over problems and
blocks. Arrays are kept "structure of arrays": a field of ``d x d`` blocks is a ``d x d``
list of arrays ``(B, M)``, so every block operation is a few elementwise array operations
(no tiny matrix products).

The same code runs on numpy (float64, CPU) and on torch tensors on any device
(``device="cuda"``); every array operation it needs goes through a small backend
(`backend_for`). This module holds the energy terms, the
iteration and its line search (the backends in `solvers.newton.backends`, the block
solves in `solvers.newton.block_tridiagonal`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from finsler.errors import InputError
from finsler.metrics.base import Metric
from solvers.newton.backends import _NUMPY_OPS, backend_for
from solvers.newton.block_tridiagonal import Mat, Vec, all_rows, block_tridiagonal_solve, sum_
from solvers.status import NewtonStatus

__all__ = [
    "EnergyTerms",
    "NewtonBatch",
    "NewtonOptions",
    "NewtonState",
    "energy_residual",
    "energy_terms",
    "newton_energy",
]


@dataclass(frozen=True)
class NewtonOptions:
    """Settings of `newton_energy`.

    ``gtol``: convergence when ``residual = |grad E|_inf * scale / E <= gtol`` (``scale``:
    the domain's size; a dimensionless first-order residual, the same measure as IPOPT's
    dual infeasibility on the energy scaled to 1 that this package's IPOPT solves use).
    ``max_iter``: iterations per problem. ``delta0`` / ``delta_max``: first and largest
    shift of the Hessian (relative to its mean diagonal; see `NewtonState`).
    ``armijo``: sufficient decrease of the line search; ``line_steps``: step lengths
    ``2**-k``, ``k < line_steps``, tried at once. ``boundary_hits``: consecutive
    iterations whose full step left the domain without progress before a problem stops
    as ``BOUNDARY``. ``chunk``: segments per evaluation of the derivatives (cache-sized
    blocks are about twice as fast on numpy).
    """

    gtol: float = 1e-10
    max_iter: int = 200
    delta0: float = 1e-4
    delta_max: float = 1e10
    armijo: float = 1e-4
    line_steps: int = 4
    boundary_hits: int = 4
    chunk: int = 16384

    def __post_init__(self) -> None:
        for name in ("gtol", "delta0", "delta_max", "armijo"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    np.isfinite(v) and v > 0):
                raise InputError(f"{name} must be positive and finite, got {v!r}")
        for name in ("max_iter", "boundary_hits", "chunk", "line_steps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")


# ----------------------------------------------------------------------------------------
# the energy, its gradient and block-tridiagonal Hessian for a batch of paths
# ----------------------------------------------------------------------------------------
@dataclass
class EnergyTerms:
    """Energy ``(B,)`` (``sum C**2``), gradient field (``d`` arrays ``(B, n-1)``) in the
    interior points, Hessian fields: ``diag`` and ``off`` (``d x d`` arrays ``(B, n-1)``,
    ``off[.][.][:, j]`` coupling interior points ``j`` and ``j + 1``, the last column 0).
    Without the Hessian, ``diag`` and ``off`` are ``None``."""

    energy: Any
    grad: Vec
    diag: Mat | None
    off: Mat | None

    def take(self, ops: Any, rows: Any) -> EnergyTerms:
        k = ops.index(rows)
        return EnergyTerms(self.energy[k], [g[k] for g in self.grad],
                           None if self.diag is None else [[x[k] for x in r] for r in self.diag],
                           None if self.off is None else [[x[k] for x in r] for r in self.off])

    def put(self, ops: Any, rows: Any, src: EnergyTerms) -> None:
        k = ops.index(rows)
        self.energy[k] = src.energy
        for a, b in zip(self.grad, src.grad):
            a[k] = b
        for mine, theirs in ((self.diag, src.diag), (self.off, src.off)):
            done: list[Any] = []  # symmetric fields share entries: write each once
            for ra, rb in zip(mine, theirs):
                for a, b in zip(ra, rb):
                    if not any(a is d for d in done):
                        done.append(a)
                        a[k] = b


def _rows(ops: Any, shape: tuple[int, int], c: Any) -> Any:
    if isinstance(c, (int, float)):
        return ops.full(shape, float(c))
    return c


def energy_terms(metric: Metric, ops: Any, points: Vec, chunk: int = 16384,
                 hessian: bool = True) -> EnergyTerms:
    """`EnergyTerms` of paths given as a field ``points`` (``d`` arrays
    ``(B, n+1)``) on the backend ``ops``."""
    fn = metric.segment_derivatives
    d = len(points)
    b, n1 = points[0].shape
    n = n1 - 1
    step = b if ops.name == "torch" else max(1, chunk // n)
    parts = []
    for a in range(0, b, step):
        rows = slice(a, min(b, a + step))
        x = [ops.contiguous(p[rows, :-1]) for p in points]
        y = [ops.contiguous(p[rows, 1:]) for p in points]
        parts.append(fn.run(ops.lowering, [x, y]))
    sizes = [min(step, b - a) for a in range(0, b, step)]

    def gather(o: int, e: int) -> Any:
        vals = [_rows(ops, (size, n), p[o][e]) for size, p in zip(sizes, parts, strict=True)]
        return vals[0] if len(vals) == 1 else ops.cat(vals, 0)

    phi = gather(0, 0)
    energy = phi.sum(1)
    g = [gather(1, i) for i in range(2 * d)]
    grad = [g[d + i][:, :-1] + g[i][:, 1:] for i in range(d)]
    if not hessian:
        return EnergyTerms(energy, grad, None, None)
    upper = {}
    e = 0
    for i in range(2 * d):
        for j in range(i, 2 * d):
            upper[i, j] = gather(2, e)
            e += 1

    def h(i: int, j: int) -> Any:
        return upper[min(i, j), max(i, j)]

    diag: Mat = [[None] * d for _ in range(d)]
    for i in range(d):
        for k in range(i, d):
            diag[i][k] = h(d + i, d + k)[:, :-1] + h(i, k)[:, 1:]
            diag[k][i] = diag[i][k]
    z = ops.zeros((b, 1))
    off = [[ops.cat([h(i, d + k)[:, 1:-1], z], 1) for k in range(d)] for i in range(d)]
    return EnergyTerms(energy, grad, diag, off)


def _to_field(ops: Any, paths: Any) -> Vec:
    """``(B, n+1, d)`` -> a field of ``d`` contiguous arrays ``(B, n+1)`` on ``ops``."""
    arr = ops.asarray(paths)
    return [ops.contiguous(arr[..., i]) for i in range(arr.shape[-1])]


def _from_field(ops: Any, field: Vec) -> np.ndarray:
    return np.stack([ops.to_numpy(f) for f in field], -1)


def energy_residual(metric: Metric, points: np.ndarray, scale: float) -> np.ndarray:
    """First-order optimality residual of paths ``(B, n+1, d)`` (numpy): the largest entry
    of the projected gradient of ``E = sum C**2`` in the interior points, times the
    domain size ``scale``, over ``E`` -> ``(B,)``. Projected: at a point on the domain's
    boundary the part of the gradient whose descent direction leaves the domain is
    dropped (``(p - project(p - t grad)) / t``, the step ``t`` moving the point of the
    largest entry by ``1e-3 * scale``); 0 exactly at a first-order (KKT) point."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[1] < 3:
        return np.zeros(pts.shape[0])
    with np.errstate(all="ignore"):
        terms = energy_terms(metric, _NUMPY_OPS, _to_field(_NUMPY_OPS, pts), hessian=False)
    g = np.stack(terms.grad, -1)
    inner = pts[:, 1:-1]
    gmax = np.max(np.abs(g), axis=(1, 2))
    # the step moves the point of the largest gradient entry by 1e-3 of the domain: a
    # point closer than that to the boundary, pushed outwards, counts as on it (IPOPT's
    # solutions lie within ~1e-8 inside their active bounds)
    t = (1e-3 * scale / np.maximum(gmax, 1e-300))[:, None, None]
    moved = np.asarray(metric.domain.project((inner - t * g).reshape(-1, pts.shape[2])),
                       dtype=np.float64).reshape(inner.shape)
    pg = (inner - moved) / t
    with np.errstate(all="ignore"):
        return np.max(np.abs(pg), axis=(1, 2)) * scale / np.maximum(terms.energy, 1e-300)


# ----------------------------------------------------------------------------------------
# the solver
# ----------------------------------------------------------------------------------------
@dataclass
class NewtonBatch:
    """Result of `newton_energy` (numpy): ``points`` ``(B, n+1, d)``, ``energy``
    ``(B,)`` (``sum C**2``), ``residual`` ``(B,)`` (see `NewtonOptions`),
    ``iterations`` ``(B,)``, ``status`` ``(B,)`` of `NewtonStatus` values;
    ``evaluations``: segments evaluated with their derivatives, ``value_evaluations``:
    segments evaluated for their cost only (line searches)."""

    points: np.ndarray
    energy: np.ndarray
    residual: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    evaluations: int = 0
    value_evaluations: int = 0


class NewtonState:
    """A running batch of `newton_energy` problems, stepped one iteration at a time
    by `step` (callers may stop problems between steps with `drop`).

    An iteration of a problem: a Newton direction of its Hessian made positive definite,
    then a line search on the Armijo condition. With ``local`` (the default) only the
    pivot blocks that are not definite are shifted (block-wise modified Cholesky, see
    `block_tridiagonal_solve`); otherwise, as IPOPT's inertia correction, the whole
    Hessian by the smallest tried multiple ``delta`` of its mean diagonal (0 if possible,
    else the last shift / 3, raised x8 until it factorises). A problem whose last step
    was a full one tries the full step first, with the derivatives at the trial point
    (accepted: nothing more to evaluate); otherwise the energies of the steps ``2**-k``
    (``k < line_steps``) are evaluated at once (values of ``F`` only) and the longest
    acceptable one is taken. A trial point outside the domain is not acceptable; without
    an acceptable step the shift grows.
    """

    def __init__(self, metric: Metric, paths: Any, options: NewtonOptions, ops: Any,
                 scale: float, local: bool = True) -> None:
        self.m, self.ops, self.opt, self.scale = metric, ops, options, float(scale)
        self.local = bool(local)
        self.domain = metric.domain
        # a box domain is handled by projected Newton (Bertsekas): coordinates at a bound
        # that the gradient pushes out are held there, the others take the Newton step
        # of the reduced system, and trial points are projected (clamped) onto the box
        self.box = bool(self.domain.is_box)
        lo, hi = self.domain.bounds()
        self.lo, self.hi = [float(v) for v in lo], [float(v) for v in hi]
        self.bound_eps = 1e-9 * float(scale)
        self.points = _to_field(ops, paths)
        b = self.points[0].shape[0]
        self.status = np.zeros(b, dtype=np.int64)
        self.iterations = np.zeros(b, dtype=np.int64)
        self.delta = np.zeros(b)
        self.full = np.ones(b, dtype=bool)
        self.hits = np.zeros(b, dtype=np.int64)
        self.evaluations = 0
        self.value_evaluations = 0
        self.energy = np.full(b, np.inf)
        self.residual = np.full(b, np.inf)
        self.active = np.arange(b)
        self.terms = self._terms(self.points)  # of the active problems, in their order
        finite = self._finite(self.terms)
        self._update(self.active, self.terms, self.points)
        self.status[~finite] = NewtonStatus.NOT_FINITE
        self._retire()

    # -- helpers --------------------------------------------------------------------------
    def _terms(self, p: Vec) -> EnergyTerms:
        self.evaluations += int(p[0].shape[0] * (p[0].shape[1] - 1))
        with np.errstate(all="ignore"):
            return energy_terms(self.m, self.ops, p, self.opt.chunk)

    def _energies(self, p: Vec) -> np.ndarray:
        """``sum C**2`` of a path field (values of F only) -> numpy ``(K,)``."""
        x = [self.ops.contiguous(c[:, :-1]) for c in p]
        v = [self.ops.contiguous(c[:, 1:]) - xi for c, xi in zip(p, x)]
        self.value_evaluations += int(x[0].shape[0] * x[0].shape[1])
        with np.errstate(all="ignore"):
            (c,) = self.m.lowered_F.run(self.ops.lowering, [x, v])
        c = _rows(self.ops, tuple(x[0].shape), c[0])
        return self.ops.to_numpy((c * c).sum(1)).astype(np.float64)

    def _finite(self, t: EnergyTerms) -> np.ndarray:
        ops = self.ops
        ok = ops.isfinite(t.energy)
        for a in (*t.grad, *(x for r in t.diag for x in r), *(x for r in t.off for x in r)):
            ok = ok & all_rows(ops, ops.isfinite(a))
        return ops.to_numpy(ok).astype(bool)

    def _held(self, pts: Vec, grad: Vec) -> list[Any] | None:
        """Box domains: per coordinate, ``(K, n-1)`` masks of the interior coordinates at
        a bound (within ``bound_eps``) that the gradient pushes outwards; else ``None``."""
        if not self.box:
            return None
        out = []
        for i, (p, g) in enumerate(zip(pts, grad, strict=True)):
            x = p[:, 1:-1]
            out.append(((x <= self.lo[i] + self.bound_eps) & (g > 0))
                       | ((x >= self.hi[i] - self.bound_eps) & (g < 0)))
        return out

    def _update(self, idx: np.ndarray, t: EnergyTerms, pts: Vec | None = None) -> None:
        """Energies and residuals (the largest entry of the projected gradient, relative)
        of the problems ``idx`` from their terms (``pts``: their points, for box
        domains)."""
        ops = self.ops
        held = self._held(pts, t.grad) if pts is not None else None
        grads = t.grad if held is None else [ops.where(h, 0.0, g)
                                             for g, h in zip(t.grad, held, strict=True)]
        g = None
        for a in grads:
            m = ops.abs(a).max(1)
            m = m.values if hasattr(m, "values") else m
            g = m if g is None else ops.maximum(g, m)
        e = ops.to_numpy(t.energy)
        with np.errstate(all="ignore"):
            self.residual[idx] = ops.to_numpy(g) * self.scale / np.maximum(e, 1e-300)
        self.energy[idx] = e

    def _inside(self, p: Vec) -> np.ndarray:
        """Paths of a field whose points all lie in the domain (to ``1e-12`` of its size:
        points projected onto its boundary count as inside) -> numpy ``(K,)``."""
        ops = self.ops
        if self.box:  # trial points are projected onto the box
            return np.ones(p[0].shape[0], dtype=bool)
        tol = 1e-12 * self.scale
        if ops.name == "numpy":
            flat = np.stack(p, -1).reshape(-1, len(p))
            ok = self.domain.contains(flat, tol=tol)
            return np.asarray(ok, dtype=bool).reshape(p[0].shape[0], -1).all(1)
        flat = ops.torch.stack(p, -1).reshape(-1, len(p))
        gap = (self.domain.project(flat) - flat).abs().amax(-1)
        return ops.to_numpy((gap <= tol).reshape(p[0].shape[0], -1).all(1)).astype(bool)

    def _retire(self) -> None:
        """Mark converged problems; keep only the running ones active."""
        idx = self.active
        run = self.status[idx] == NewtonStatus.RUNNING
        conv = run & (self.residual[idx] <= self.opt.gtol)
        self.status[idx[conv]] = NewtonStatus.CONVERGED
        keep = np.flatnonzero(self.status[idx] == NewtonStatus.RUNNING)
        if keep.size != idx.size:
            self.terms = self.terms.take(self.ops, keep)
            self.active = idx[keep]

    def drop(self, which: Any) -> None:
        """Stop the (running) problems ``which`` (indices into the batch) as ``DROPPED``."""
        which = np.asarray(which, dtype=np.int64)
        run = which[self.status[which] == NewtonStatus.RUNNING]
        self.status[run] = NewtonStatus.DROPPED
        self._retire()

    @property
    def running(self) -> bool:
        return self.active.size > 0

    def paths(self, which: Any = None) -> np.ndarray:
        """Current points ``(K, n+1, d)`` (numpy) of the problems ``which`` (default all)."""
        pts = _from_field(self.ops, self.points)
        return pts if which is None else pts[np.asarray(which)]

    # -- one iteration ------------------------------------------------------------------
    def _direction(self) -> tuple[Vec, np.ndarray]:
        """Newton directions of the active problems from their (modified) Hessians ->
        (direction field, factorised ``(A,)``)."""
        ops, idx, t, opt = self.ops, self.active, self.terms, self.opt
        d = len(t.grad)
        dsum = sum_(ops.abs(t.diag[i][i]) for i in range(d)).mean(1) / d
        dscale = ops.to_numpy(dsum)
        dscale = np.where(np.isfinite(dscale) & (dscale > 0), dscale, 1.0)
        neg = [-g for g in t.grad]
        diag_f, off_f = t.diag, t.off
        held = self._held([p[ops.index(idx)] for p in self.points], t.grad)
        if held is not None:  # the reduced system: held coordinates decoupled, step 0
            one = ops.asarray(dscale)[:, None]
            neg = [ops.where(h, 0.0, g) for g, h in zip(neg, held, strict=True)]
            diag_f = [[ops.where(held[i], one, t.diag[i][i]) if i == k else
                       ops.where(held[i] | held[k], 0.0, t.diag[i][k]) for k in range(d)]
                      for i in range(d)]
            nxt = [ops.cat([h[:, 1:], h[:, :1] & False], 1) for h in held]
            off_f = [[ops.where(held[i] | nxt[k], 0.0, t.off[i][k]) for k in range(d)]
                     for i in range(d)]
        if self.local:
            # block-wise modification where needed, plus the problem's shift (raised when
            # no step is acceptable)
            sc = ops.asarray(dscale)[:, None]
            shift = ops.asarray(self.delta[idx] * dscale)[:, None]
            dg = [[diag_f[i][k] + shift if i == k else diag_f[i][k] for k in range(d)]
                  for i in range(d)]
            with np.errstate(all="ignore"):
                sol, ok = block_tridiagonal_solve(ops, dg, off_f, neg, sc, local=True)
            fin = ops.to_numpy(ok).astype(bool)
            for s in sol:
                fin &= ops.to_numpy(all_rows(ops, ops.isfinite(s))).astype(bool)
            return sol, fin
        last = self.delta[idx]
        delta = np.where(last > 0, last / 3.0, 0.0)
        direction = [ops.zeros(tuple(g.shape)) for g in t.grad]
        todo = np.arange(idx.size)
        factored = np.zeros(idx.size, bool)
        with np.errstate(all="ignore"):
            for _ in range(40):
                sub = ops.index(todo)
                sc = ops.asarray(dscale[todo])[:, None]
                shift = ops.asarray(delta[todo] * dscale[todo])[:, None]
                dg = [[diag_f[i][k][sub] + shift if i == k else diag_f[i][k][sub]
                       for k in range(d)] for i in range(d)]
                sol, ok = block_tridiagonal_solve(
                    ops, dg, [[x[sub] for x in r] for r in off_f], [g[sub] for g in neg], sc)
                ok = ops.to_numpy(ok).astype(bool)
                for s in sol:
                    ok &= ops.to_numpy(all_rows(ops, ops.isfinite(s))).astype(bool)
                good = todo[ok]
                if good.size:
                    kk, src = ops.index(good), ops.index(np.flatnonzero(ok))
                    for dst, s in zip(direction, sol):
                        dst[kk] = s[src]
                factored[good] = True
                todo = todo[~ok]
                if todo.size == 0:
                    break
                delta[todo] = np.where(delta[todo] == 0, opt.delta0, delta[todo] * 8.0)
                todo = todo[delta[todo] <= opt.delta_max]
                if todo.size == 0:
                    break
        self.delta[idx] = np.where(factored, delta, self.delta[idx])
        return direction, factored

    def step(self) -> None:
        """One iteration of every running problem."""
        ops, idx, opt = self.ops, self.active, self.opt
        if idx.size == 0:
            return
        t = self.terms
        k = ops.index(idx)
        direction, factored = self._direction()
        slope = ops.to_numpy(sum_((g * s).sum(1) for g, s in zip(t.grad, direction)))
        e0 = self.energy[idx].copy()
        base = [p[k] for p in self.points]
        moved = np.zeros(idx.size, bool)
        alpha = np.zeros(idx.size)
        left = np.zeros(idx.size, bool)

        def trial(rows: np.ndarray, a: float) -> Vec:
            kr = ops.index(rows)
            out = []
            for i, (p, s) in enumerate(zip(base, direction)):
                q = p[kr]  # indexed by an index array: a copy on either backend
                q[:, 1:-1] = q[:, 1:-1] + a * s[kr]
                if self.box:  # projected onto the box (held coordinates do not move)
                    q[:, 1:-1] = ops.clip(q[:, 1:-1], self.lo[i], self.hi[i])
                out.append(q)
            return out

        def decrease(rows: np.ndarray, pts: Vec, a: Any) -> np.ndarray:
            """The Armijo model's decrease: ``a * slope``, or along the projection arc (box
            domains) the gradient times the actual displacement."""
            if not self.box:
                return a * slope[rows]
            kr = ops.index(rows)
            dot = sum_(((q[:, 1:-1] - p[kr][:, 1:-1]) * g[kr]).sum(1)
                       for q, p, g in zip(pts, base, t.grad, strict=True))
            return ops.to_numpy(dot)

        def accept(rows: np.ndarray, pts: Vec, new: EnergyTerms, a: Any) -> None:
            kk = ops.index(idx[rows])
            for dst, src in zip(self.points, pts):
                dst[kk] = src
            t.put(ops, rows, new)
            self._update(idx[rows], new, pts)
            moved[rows] = True
            alpha[rows] = a

        # 1. full steps, with the derivatives at the trial points
        try_full = np.flatnonzero(factored & self.full[idx])
        if try_full.size:
            pts = trial(try_full, 1.0)
            inside = self._inside(pts)
            left[try_full[~inside]] = True
            sel = np.flatnonzero(inside)
            if sel.size:
                ks = ops.index(sel)
                pin = [p[ks] for p in pts]
                new = self._terms(pin)
                fin = self._finite(new)
                e1 = ops.to_numpy(new.energy)
                ev = try_full[sel]
                dec = decrease(ev, pin, 1.0)
                ok = fin & (slope[ev] < 0) & (e1 <= e0[ev] + opt.armijo * dec)
                ok |= fin & (np.abs(e1 - e0[ev]) <= 1e-15 * np.abs(e0[ev]))  # round-off tie
                if ok.any():
                    good = np.flatnonzero(ok)
                    kg = ops.index(good)
                    accept(ev[good], [p[kg] for p in pin], new.take(ops, good), 1.0)
        # 2. a line search on values of F for the others
        ls = np.flatnonzero(factored & ~moved & (slope < 0))
        if ls.size:
            steps = [2.0 ** -j for j in range(opt.line_steps)]
            trials = [trial(ls, a) for a in steps]
            allp = [ops.cat([tr[i] for tr in trials], 0) for i in range(len(base))]
            inside = self._inside(allp)
            e = np.full(inside.size, np.inf)
            ins = np.flatnonzero(inside)
            if ins.size:
                ki = ops.index(ins)
                e[ins] = self._energies([p[ki] for p in allp])
            e = e.reshape(len(steps), ls.size)
            dec = np.stack([decrease(ls, tr, a) for tr, a in zip(trials, steps, strict=True)])
            good = np.isfinite(e) & (e <= e0[ls][None] + opt.armijo * dec)
            left[ls[~inside.reshape(len(steps), ls.size)[0]]] = True
            has = good.any(0)
            if has.any():
                which = np.flatnonzero(has)
                first = np.argmax(good, 0)[which]
                flat = ops.index(first * ls.size + which)
                pts = [p[flat] for p in allp]
                accept(ls[which], pts, self._terms(pts), np.asarray(steps)[first])
        self.iterations[idx] += 1
        self.full[idx] = np.where(moved, alpha == 1.0, False)
        stuck = factored & ~moved
        self.delta[idx] = np.where(stuck, np.maximum(self.delta[idx] * 8.0, opt.delta0),
                                   np.where(moved & self.local, self.delta[idx] / 3.0,
                                            self.delta[idx]))
        self.delta[idx] = np.where(self.delta[idx] < 1e-12, 0.0, self.delta[idx])
        self.hits[idx] = np.where(moved, 0, np.where(left, self.hits[idx] + 1, self.hits[idx]))
        st = self.status
        st[idx[~factored | (self.delta[idx] > opt.delta_max)]] = NewtonStatus.STALLED
        st[idx[self.hits[idx] >= opt.boundary_hits]] = NewtonStatus.BOUNDARY
        over = (self.iterations[idx] >= opt.max_iter) & (st[idx] == NewtonStatus.RUNNING)
        st[idx[over & (self.residual[idx] > opt.gtol)]] = NewtonStatus.MAX_ITERATIONS
        self._retire()

    def result(self) -> NewtonBatch:
        return NewtonBatch(self.paths(), self.energy.copy(), self.residual.copy(),
                           self.iterations.copy(), self.status.copy(), self.evaluations,
                           self.value_evaluations)


def newton_energy(metric: Metric, paths: Any, options: NewtonOptions | None = None, *,
                  device: Any = None, scale: float = 1.0, local: bool = True) -> NewtonBatch:
    """Minimise the discrete energy of every path of ``paths`` ``(B, n+1, d)`` (ends fixed,
    points in the domain) by Newton steps, all problems at once; ``device``: ``None`` for
    numpy, or a torch device; ``scale``: the domain's size (for the residual). Returns a
    `NewtonBatch` (numpy)."""
    opt = options or NewtonOptions()
    ops = backend_for(device)
    shape = tuple(paths.shape) if hasattr(paths, "shape") else np.shape(paths)
    if len(shape) != 3 or shape[2] != metric.dim or shape[1] < 3:
        raise InputError(f"paths must have shape (B, n+1, {metric.dim}) with n >= 2, got "
                         f"{shape}")
    state = NewtonState(metric, paths, opt, ops, scale, local)
    while state.running:
        state.step()
    return state.result()
