"""Continuum distances: a Chebyshev pseudospectral transcription with degree doubling.

The curve is one polynomial of degree ``N`` per coordinate, represented by its values at the
Chebyshev-Gauss-Lobatto nodes ``tau_j = -cos(pi j / N)`` of ``[-1, 1]`` (endpoints fixed to
start and goal). Its energy ``int F(gamma, gamma')**2 dtau`` is evaluated by Gauss-Legendre
quadrature at ``M`` points; the values and derivatives there are extra NLP variables tied to
the nodes by linear equality constraints (so the Hessian stays block-sparse), and the domain
constraints are imposed at the quadrature points. The energy minimiser has constant speed;
its length ``L_N = sum_q w_q F(gamma(tau_q), gamma'(tau_q))`` converges to the distance
spectrally (faster than any power of ``1/N``) where the metric is smooth along an analytic
geodesic and no domain constraint is active.

`distance` seeds the lowest degree with the globally seeded task solution
(`solvers.solve_geodesic`), doubles ``N`` (warm start: the previous polynomial is
exactly representable) and stops when ``|L_N - L_{N/2}| <= rtol * L_N``. Under spectral
convergence ``|L_N - L_{N/2}| ~ |L_{N/2} - d| >> |L_N - d|``, so the difference is a
conservative estimate of the error of ``L_N``; a small rounding floor is added.
"""

from __future__ import annotations

import math
import time
from typing import Any

import casadi as ca
import numpy as np

from finsler.domains import describe_value
from finsler.errors import InputError
from finsler.infra.limits import check_number
from finsler.metrics.base import Metric
from solvers.chebyshev import (
    chebyshev_nodes,
    differentiation_matrix,
    interpolation_matrix,
)
from solvers.geodesic.solve import solve_geodesic
from solvers.inputs import as_metric, check_point, domain_scale, is_short_pair
from solvers.result import DistanceResult, DistanceStatus, SolverError, Status
from solvers.transcription import Constraints, _ident, ipopt_options, smooth_square

__all__ = [
    "SpectralNLP",
    "chebyshev_nodes",
    "differentiation_matrix",
    "distance",
    "interpolation_matrix",
    "spectral_nlp",
]

#: Degrees tried by [`distance`][solvers.distance] (doubling), by metric dimension.
DEGREES_LOW_DIM = (8, 16, 32, 64, 128)
DEGREES_HIGH_DIM = (8, 16, 32, 64)
#: Highest polynomial degree of `distance` (its NLP is dense in the nodes: a degree
#: of 256 already has a 65536-entry differentiation matrix per coordinate).
MAX_DEGREE = 256

#: Relative rounding floor added to every error estimate.
ROUNDING_FLOOR = 1e-13
#: Smallest ``rtol`` of `distance`: float64's relative resolution (an ``rtol`` between it
#: and ``ROUNDING_FLOOR`` is answered with TOLERANCE_NOT_REACHED).
RTOL_MIN = float(np.finfo(np.float64).eps)


def _quadrature_points(n: int) -> int:
    return n + n // 2 + 8


class SpectralNLP:
    """Energy NLP of degree-``n`` polynomial curves for ``metric`` (start/goal parameters)."""

    def __init__(self, metric: Metric, n: int, tol: float = 1e-12) -> None:
        self.metric, self.n, self.dim = metric, n, metric.dim
        dim = metric.dim
        mq = _quadrature_points(n)
        tq, wq = np.polynomial.legendre.leggauss(mq)
        self.wq = wq
        self.Lq = interpolation_matrix(n, tq)  # (mq, n+1)
        self.Dq = self.Lq @ differentiation_matrix(n)  # (mq, n+1)
        X = ca.SX.sym("X", n - 1, dim)
        s = ca.SX.sym("s", dim)
        g = ca.SX.sym("g", dim)
        P = ca.SX.sym("P", mq, dim)
        V = ca.SX.sym("V", mq, dim)
        Y = ca.vertcat(s.T, X, g.T)
        link = ca.vertcat(ca.vec(P - ca.mtimes(ca.DM(self.Lq), Y)),
                          ca.vec(V - ca.mtimes(ca.DM(self.Dq), Y)))
        obj = 0
        c = Constraints()
        for q in range(mq):
            obj += wq[q] * c.add_square(smooth_square(metric, P[q, :].T, V[q, :].T, tag=str(q)))
            c.add_domain(metric, P[q, :].T)
        slack, lbw, ubw, gs, lbg, ubg, slack_val = (
            c.slack, c.lbw, c.ubw, c.g, c.lbg, c.ubg, c.slack_values
        )
        z = ca.vertcat(ca.vec(X), ca.vec(P), ca.vec(V), *slack)
        cons = ca.vertcat(link, *gs)
        nlink = link.shape[0]
        self.lbg = np.concatenate([np.zeros(nlink), np.asarray(lbg, float)])
        self.ubg = np.concatenate([np.zeros(nlink), np.asarray(ubg, float)])
        lo, hi = metric.domain.bounds()
        # column-major vec: all rows of coordinate 0, then coordinate 1, ...
        self.lbz = np.concatenate([np.repeat(lo, n - 1), np.repeat(lo, mq),
                                   np.full(mq * dim, -np.inf), np.asarray(lbw, float)])
        self.ubz = np.concatenate([np.repeat(hi, n - 1), np.repeat(hi, mq),
                                   np.full(mq * dim, np.inf), np.asarray(ubw, float)])
        sv = ca.vertcat(*slack_val) if slack_val else ca.SX(0, 1)
        self.slack_init = ca.Function("slack_init", [P, V], [sv])
        nlp = {"x": z, "p": ca.vertcat(s, g), "f": obj, "g": cons}
        self.solver = ca.nlpsol(f"spectral_{_ident(metric.name)}_{n}", "ipopt", nlp,
                                ipopt_options(tol, max_iter=3000))
        self.mq = mq

    def solve(self, nodes: np.ndarray) -> tuple[np.ndarray, Status, int]:
        """Solve from initial node values ``(n+1, dim)`` (first/last row: start/goal).

        Returns (optimal node values ``(n+1, dim)``, status, iterations)."""
        s, g = nodes[0], nodes[-1]
        P, V = self.Lq @ nodes, self.Dq @ nodes
        slack = np.asarray(self.slack_init(P, V)).reshape(-1)
        z0 = np.concatenate([nodes[1:-1].T.reshape(-1), P.T.reshape(-1), V.T.reshape(-1),
                             slack])
        z0 = np.clip(z0, self.lbz, self.ubz)
        out = self.solver(x0=z0, p=np.concatenate([s, g]), lbx=self.lbz, ubx=self.ubz,
                          lbg=self.lbg, ubg=self.ubg)
        stats = self.solver.stats()
        z = np.asarray(out["x"]).reshape(-1)
        interior = z[: (self.n - 1) * self.dim].reshape(self.dim, self.n - 1).T
        res = np.vstack([s[None], interior, g[None]])
        return (res, Status.from_ipopt(str(stats.get("return_status", "Unknown"))),
                int(stats.get("iter_count", -1)))

    def length(self, nodes: np.ndarray) -> tuple[float, np.ndarray]:
        """Length of the polynomial curve by the quadrature, and its quadrature points."""
        P, V = self.Lq @ nodes, self.Dq @ nodes
        f = self.metric.F(P, V)
        return float(self.wq @ f), P


def spectral_nlp(metric: Metric, n: int) -> SpectralNLP:
    """The degree-``n`` pseudospectral NLP of ``metric``, built once per metric and ``n``
    (``metric.derived``)."""
    return metric.derived(f"spectral.nlp.{n}", lambda: SpectralNLP(metric, n))


def _nodes_from_path(points: np.ndarray, n: int) -> np.ndarray:
    """Piecewise-linear interpolation of a discrete path ``(k+1, dim)`` (parameter i/k) at the
    Chebyshev nodes mapped to ``[0, 1]`` -> ``(n+1, dim)``."""
    k = points.shape[0] - 1
    t = 0.5 * (chebyshev_nodes(n) + 1.0)
    grid = np.linspace(0.0, 1.0, k + 1)
    out = np.stack([np.interp(t, grid, points[:, d]) for d in range(points.shape[1])], 1)
    out[0], out[-1] = points[0], points[-1]
    return out


def distance(
    metric: Metric | str,
    start: Any,
    goal: Any,
    rtol: float | None = None,
    *,
    degrees: tuple[int, ...] | None = None,
    strict: bool = False,
) -> DistanceResult:
    """Length of the minimising geodesic from ``start`` to ``goal`` (each ``(dim,)``) to a
    relative tolerance ``rtol`` (default 1e-8 for smooth metrics, 1e-4 otherwise), with an
    error estimate.

    The status is ``CONVERGED`` only if the estimate is below ``rtol * distance``, every
    IPOPT solve converged, the length does not exceed the upper bound of the discrete
    path (``upper_bound``, eq. 58 quadrature) by more than the estimate, and (for metrics
    not convex everywhere) ``F(x, .)`` is convex at every quadrature point of the curve; a
    curve through a non-convex region gets ``NOT_CONVEX`` (its length is that of a smooth
    local minimiser, not the continuum infimum). ``strict=True`` raises
    [`SolverError`][solvers.SolverError] unless converged.
    """
    t0 = time.perf_counter()
    m = as_metric(metric)
    if rtol is None:
        rtol = 1e-8 if m.smooth else 1e-4
    rtol = check_number(rtol, "rtol", 0.0, 1.0, low_open=True, high_open=True)
    if rtol < RTOL_MIN:
        raise InputError(f"rtol = {rtol:g} is below {RTOL_MIN:.3g}, the relative resolution "
                         "of float64: no length can be known that finely")
    if degrees is None:
        degrees = DEGREES_LOW_DIM if m.dim <= 3 else DEGREES_HIGH_DIM
    if not isinstance(degrees, (list, tuple)) or len(degrees) < 2 or len(degrees) > 16 or any(
        isinstance(d, bool) or not isinstance(d, (int, np.integer)) or not 2 <= d <= MAX_DEGREE
        for d in degrees
    ) or list(degrees) != sorted(set(degrees)):
        raise InputError(f"degrees must be 2 to 16 increasing integers in [2, {MAX_DEGREE}], "
                         f"got {describe_value(degrees)}")
    s = check_point(m, start, "start")
    g = check_point(m, goal, "goal")
    if np.array_equal(s, g):
        nodes = np.repeat(s[None], degrees[0] + 1, 0)
        return DistanceResult(0.0, 0.0, float(rtol), DistanceStatus.TRIVIAL, [], [], nodes,
                              math.inf, time.perf_counter() - t0, Status.TRIVIAL)
    if is_short_pair(m, s, g):
        # straight segment: its length differs from d by O(|g - s|**2) relatively; the
        # estimate takes the constant as 10 in units of the domain size (an assumption
        # stated in the docs, not a proof), i.e. <= 1e-13 relative here
        seg = float(m.segment_length(s, g, 8))
        rel = float(np.max(np.abs(g - s))) / domain_scale(m)
        est = seg * (10.0 * rel * rel + ROUNDING_FLOOR)
        nodes = s + 0.5 * (chebyshev_nodes(degrees[0])[:, None] + 1.0) * (g - s)
        return DistanceResult(seg, est, float(rtol), DistanceStatus.CONVERGED, [], [seg],
                              nodes, math.inf, time.perf_counter() - t0, Status.SHORT, seg)
    discrete = solve_geodesic(m, s, g, min(m.task.segments, 64))
    nodes = _nodes_from_path(discrete.points, degrees[0])
    lengths: list[float] = []
    used: list[int] = []
    status = DistanceStatus.TOLERANCE_NOT_REACHED
    ipopt_status = Status.SUCCESS
    estimate = math.inf
    quad_pts = None
    prev_n = None
    for n in degrees:
        if prev_n is not None:
            # exact re-representation of the previous polynomial on the finer nodes
            nodes = interpolation_matrix(prev_n, chebyshev_nodes(n)) @ nodes
        nlp = spectral_nlp(m, n)
        nodes, st, _ = nlp.solve(nodes)
        length, quad_pts = nlp.length(nodes)
        used.append(n)
        lengths.append(length)
        prev_n = n
        if not st.converged:
            ipopt_status = st
            status = DistanceStatus.SOLVER_FAILED
            break
        if len(lengths) >= 2:
            estimate = abs(lengths[-1] - lengths[-2]) + ROUNDING_FLOOR * abs(length)
            if estimate <= rtol * length:
                status = DistanceStatus.CONVERGED
                break
    upper = discrete.length_quadrature
    if status is DistanceStatus.CONVERGED and lengths[-1] > upper + estimate:
        status = DistanceStatus.TOLERANCE_NOT_REACHED
    min_conv = math.inf
    if not m.convex_everywhere and quad_pts is not None:
        min_conv = float(np.min(m.convexity(m.domain.project(quad_pts))))
        if min_conv < 0 and status is not DistanceStatus.SOLVER_FAILED:
            status = DistanceStatus.NOT_CONVEX
    res = DistanceResult(
        distance=lengths[-1],
        error_estimate=estimate,
        rtol=float(rtol),
        status=status,
        degrees=used,
        lengths=lengths,
        nodes=nodes,
        min_convexity=min_conv,
        wall_time=time.perf_counter() - t0,
        ipopt_status=ipopt_status,
        upper_bound=upper,
        discrete=discrete,
    )
    if strict and not res.converged:
        raise SolverError(
            f"{m.name}: distance not converged ({status.label}, estimate {estimate:.3e}, "
            f"rtol {rtol:g})",
            res,
        )
    return res
