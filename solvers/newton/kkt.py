"""The optimality residual of a path for a metric whose ``F`` is not smooth: the KKT
residual of the reformulated (slack) problem that the metric's ``smooth_square_sx`` hook
defines (`finsler.hooks`; e.g. the car-like metric's ``max`` of its turning rate).

The reformulated problem (the one IPOPT solves, `solvers.transcription`): minimise
``sum_i f2(p_i, p_{i+1}, w_i)`` over the interior points and one slack block ``w_i`` per
segment, subject to the hook's slack constraints and bounds on ``w``, and the domain's
constraints on every point. For a smooth metric the gradient of the energy is the
measure (`solvers.newton.energy.energy_residual`); for a non-smooth one the energy's
gradient is not an optimality measure (at a kink it is one arbitrary element of the
subdifferential: 0.2 to 4 measured at car-like optima that IPOPT solved to 1e-13 where
the path reverses without turning), so `optimality_residual` gives
`kkt_residual` there. Both are computed from the points alone, independently of
how they were found.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from finsler.metrics.base import Metric
from solvers.newton.energy import energy_residual

__all__ = ["kkt_residual", "optimality_residual", "uses_kkt"]

_TINY = 1e-300

#: Constraints within this fraction of the segment's size (slack constraints) or of the
#: domain's size (domain constraints) of being active take part in the multiplier fit
#: (their complementarity ``lambda c`` is part of the residual); farther ones have
#: multiplier 0. IPOPT's car-like optima lie up to ~4e-8 of the size off a kink (its
#: bounds are relaxed by ~1e-8): a strict activity test (1e-10, 1e-6) missed such kinks
#: and left the residual at the energy gradient's 1e-2 to 4.
NEAR_RTOL = 1e-3

#: Weight of the slacks' stationarity rows in the multiplier fit: they hold (nearly)
#: exactly, so that where ``F`` is differentiable the multipliers are the slacks' own and
#: the residual is the energy's gradient (not a compromise between the two).
SLACK_WEIGHT = 1e4


@dataclass
class _Functions:
    wval: Any  # (x, y) -> the exact slacks
    kkt: Any  # (x, y) -> f2, f2_z, f2_w, slack constraints, their z- and w-Jacobians
    dom: Any  # (p) -> domain constraint values (>= 0 inside), their gradients
    n_slack: int
    n_slack_cons: int
    n_dom_cons: int


def uses_kkt(metric: Metric) -> bool:
    """True if the residual of ``metric``'s paths is `kkt_residual`: ``F`` declared
    not smooth and the metric provides the ``smooth_square_sx`` hook."""
    return (not metric.smooth) and metric.provides("smooth_square_sx")


def _functions(metric: Metric) -> _Functions:
    return metric.derived("nonsmooth.kkt", lambda: _build(metric))


def _build(metric: Metric) -> _Functions:
    from finsler.lowering import lower
    from solvers.transcription import _segment_functions, domain_rows, nonnegative_rows

    seg, wval, _, (lbw, ubw), (lbgs, ubgs), _, _ = _segment_functions(metric)
    d, k = metric.dim, int(seg.nnz_in(2))
    x, y = ca.SX.sym("x", d), ca.SX.sym("y", d)
    w = ca.SX.sym("w", k)
    z = ca.vertcat(x, y)
    f2, g = seg(x, y, w)
    # every constraint as ``c >= 0``: bounds of the slacks, then the slack constraints
    cons = nonnegative_rows([(lbw, 1, w), (ubw, -1, w), (lbgs, 1, g), (ubgs, -1, g)])
    cv = ca.vertcat(*cons) if cons else ca.SX(0, 1)
    part = ca.Function("ns_part", [x, y, w],
                       [f2, ca.gradient(f2, z), ca.gradient(f2, w), cv, ca.jacobian(cv, z),
                        ca.jacobian(cv, w)])
    outs = part(x, y, wval(x, y))  # partial derivatives with w held, at the exact slacks
    dens = ca.densify
    kkt = ca.Function("ns_kkt", [x, y], [dens(ca.vec(o)) for o in outs])
    p = ca.SX.sym("p", d)
    dc = domain_rows(metric, p)
    dv = ca.vertcat(*dc) if dc else ca.SX(0, 1)
    domf = ca.Function("ns_dom", [p], [dens(dv), dens(ca.vec(ca.jacobian(dv, p)))])
    return _Functions(lower(ca.Function("ns_wval", [x, y], [dens(wval(x, y))])), lower(kkt),
                      lower(domf), k, len(cons), len(dc))


def kkt_residual(metric: Metric, points: np.ndarray, scale: float) -> np.ndarray:
    """KKT residual of paths ``(B, n+1, d)`` for the reformulated (slack) problem of a
    metric with ``smooth_square_sx`` (`uses_kkt`), at the exact slacks -> ``(B,)``.

    Each segment's slacks take their exact values (the hook's ``w_value``: then ``F**2``
    is exact and every slack constraint holds). Every constraint is written ``c >= 0``
    (slack bounds and constraints of each segment, the domain's constraints and bounds of
    each interior point); those with ``c`` at most ``NEAR_RTOL`` of the segment's size
    (slack constraints: the largest coordinate of ``p_{i+1} - p_i`` plus the slacks) or
    of ``scale`` (domain constraints) get multipliers ``lambda >= 0``, the others 0. The
    multipliers minimise the 2-norm of the Lagrangian's gradient
    ``grad f - sum_j lambda_j grad c_j`` in the interior points and the slacks together
    with the complementarity ``lambda_j c_j / scale``, the slack rows weighted by
    ``SLACK_WEIGHT`` (a bounded least-squares problem per
    path, `scipy.optimize.lsq_linear`; at a kink of ``F`` two slack constraints are
    active and the split between them is free: the Clarke subdifferential).

    Returns the largest of: that gradient's largest entry in the points times ``scale``
    over the energy (stationarity, as `solvers.newton.energy.energy_residual` for a smooth
    ``F``), its largest entry in the slacks times ``scale`` over the energy, the largest
    ``lambda_j c_j`` over the energy (complementarity), and the largest violation of a
    domain constraint over ``scale`` (feasibility; the slack constraints hold exactly).
    0 exactly at a KKT point."""
    pts = np.asarray(points, dtype=np.float64)
    B, n1, d = pts.shape
    if n1 < 3:
        return np.zeros(B)
    f = _functions(metric)
    x, y = pts[:, :-1].reshape(-1, d), pts[:, 1:].reshape(-1, d)
    f2, fz, fw, cv, cz, cw = f.kkt(x, y)
    k, m = f.n_slack, f.n_slack_cons
    n = n1 - 1
    cz = cz.reshape(B, n, 2 * d, m)  # (path, segment, z, constraint): Jacobian transposed
    cw = cw.reshape(B, n, k, m)
    fz, fw, cv = fz.reshape(B, n, 2 * d), fw.reshape(B, n, k), cv.reshape(B, n, m)
    wv = np.asarray(f.wval(x, y)[0]).reshape(B, n, k) if k else np.zeros((B, n, 0))
    size = np.max(np.abs(pts[:, 1:] - pts[:, :-1]), axis=2) + np.sum(np.abs(wv), 2)
    act = cv <= NEAR_RTOL * size[..., None]
    md = f.n_dom_cons
    if md:
        dv, dj = f.dom(pts[:, 1:-1].reshape(-1, d))
        dv, dj = dv.reshape(B, n - 1, md), dj.reshape(B, n - 1, d, md)
        dact = dv <= NEAR_RTOL * scale
    energy = f2.reshape(B, n).sum(1)
    out = np.zeros(B)
    for b in range(B):
        rows_, cols_, vals_ = [], [], []
        ss, jj = np.nonzero(act[b])  # slack constraints: columns (segment, constraint)
        nc = ss.size
        col = np.arange(nc)
        for which, q in ((0, ss - 1), (1, ss)):  # x of segment s is interior point s - 1
            ok = (q >= 0) & (q < n - 1)
            for i in range(d):
                rows_.append(q[ok] * d + i)
                cols_.append(col[ok])
                vals_.append(-cz[b, ss[ok], which * d + i, jj[ok]])
        for i in range(k):  # slack stationarity, weighted: held (nearly) exactly
            rows_.append((n - 1) * d + ss * k + i)
            cols_.append(col)
            vals_.append(-SLACK_WEIGHT * cw[b, ss, i, jj])
        qq = jd = np.zeros(0, dtype=np.int64)
        if md:  # domain constraints: columns (point, constraint)
            qq, jd = np.nonzero(dact[b])
            for i in range(d):
                rows_.append(qq * d + i)
                cols_.append(nc + np.arange(qq.size))
                vals_.append(-dj[b, qq, i, jd])
        ncol = nc + qq.size
        # complementarity rows: lambda_j c_j / scale (so that they count as the
        # stationarity rows do): a nearly active constraint takes a multiplier only as
        # far as it pays for it
        base = (n - 1) * d + n * k
        cvals = np.concatenate([cv[b][ss, jj], dv[b][qq, jd] if md else np.zeros(0)])
        rows_.append(base + np.arange(ncol))
        cols_.append(np.arange(ncol))
        vals_.append(np.maximum(cvals, 0.0) / scale)
        g = fz[b, :-1, d:] + fz[b, 1:, :d]
        rhs = -np.concatenate([g.ravel(), SLACK_WEIGHT * fw[b].ravel(), np.zeros(ncol)])
        lam = np.zeros(ncol)
        r = -rhs
        if ncol:
            from scipy.optimize import lsq_linear
            from scipy.sparse import coo_matrix

            A = coo_matrix((np.concatenate(vals_), (np.concatenate(rows_),
                                                     np.concatenate(cols_))),
                           shape=(rhs.size, ncol)).tocsr()
            lam = lsq_linear(A.toarray(), rhs, bounds=(0.0, np.inf), method="bvls").x
            r = A @ lam - rhs
        e = max(float(energy[b]), _TINY)
        stat = np.max(np.abs(r[:(n - 1) * d]), initial=0.0) * scale / e
        slack = np.max(np.abs(r[(n - 1) * d:base]), initial=0.0) / SLACK_WEIGHT * scale / e
        comp = np.max(np.abs(lam * cvals), initial=0.0) / e
        viol = float(np.max(np.maximum(-dv[b], 0.0), initial=0.0)) if md else 0.0
        out[b] = max(stat, slack, comp, viol / scale)
    return out


def optimality_residual(metric: Metric, points: np.ndarray, scale: float) -> np.ndarray:
    """The residual reported with paths ``(B, n+1, d)``: `kkt_residual` for a metric
    that `uses_kkt`, else the energy's projected gradient
    (`solvers.newton.energy.energy_residual`) -> ``(B,)``."""
    if uses_kkt(metric):
        return kkt_residual(metric, points, scale)
    return energy_residual(metric, points, scale)
