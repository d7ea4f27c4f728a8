"""Direct transcription of the task into IPOPT problems, built once per (metric, n).

Unknowns are the interior points ``p_1 .. p_{n-1}`` (point-major, ``x[i*dim:(i+1)*dim] =
p_{i+1}``), then one block of slack variables per segment when the metric needs a smooth
reformulation, then (min-max problem only) the epigraph variable ``t``. Start and goal are
the parameters ``p = [s; g]``, so one compiled solver serves every pair (warm started from a
seed curve).

Smooth reformulation (`smooth_square`): IPOPT needs twice continuously differentiable
functions. The objective uses ``F**2`` rather than ``F`` (CasADi simplifies
``sq(sqrt(q))`` to ``q``, so for metrics of the form ``sqrt(q)`` no square root remains);
a metric whose ``F`` is not C^2 may provide the hook ``smooth_square_sx``
(`finsler.hooks`; the car-like metric does: its ``max(r|v_th| - u, 0)`` becomes a
slack with two linear constraints, exact at a minimiser), and the transcription uses it:
the formula lives only in the metric.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from finsler.metrics.base import Metric
from solvers.result import Status

__all__ = [
    "EnergyNLP",
    "MinMaxNLP",
    "SmoothSquare",
    "energy_nlp",
    "ipopt_options",
    "minmax_nlp",
    "smooth_square",
]


@dataclass
class SmoothSquare:
    """``F(x, v)**2`` as a smooth expression of ``(x, v, w)`` with slack variables ``w``.

    ``w`` ``(k, 1)`` slack symbols with bounds ``lbw``/``ubw``; ``w_value`` the exact slack
    values as a (possibly non-smooth) expression of ``(x, v)`` (for initial points);
    ``g`` ``(m, 1)`` constraints with bounds ``lbg``/``ubg``.
    """

    f2: ca.SX
    w: ca.SX
    w_value: ca.SX
    lbw: list[float]
    ubw: list[float]
    g: ca.SX
    lbg: list[float]
    ubg: list[float]


def smooth_square(metric: Metric, x: ca.SX, v: ca.SX, tag: str = "") -> SmoothSquare:
    """Smooth form of ``F(x, v)**2`` for ``metric``: the metric's own
    ``smooth_square_sx(x, v, tag)`` hook (`finsler.hooks`) where it gives one
    (metrics whose ``F`` is not C^2, e.g. the car-like metric's ``max``; the formula stays
    in the metric), else ``F_sx(x, v)**2``."""
    hook = metric.smooth_square_sx(x, v, tag)
    if hook is not None:
        return SmoothSquare(**hook)
    f = metric.F_sx(x, v)
    empty = ca.SX(0, 1)
    return SmoothSquare(f * f, empty, empty, [], [], empty, [], [])


@dataclass
class Constraints:
    """Slack variables (with bounds and initial values) and constraints ``lbg <= g <= ubg``
    collected while a transcription is built (shared by the polyline and spectral NLPs)."""

    slack: list[ca.SX] = field(default_factory=list)
    lbw: list[float] = field(default_factory=list)
    ubw: list[float] = field(default_factory=list)
    g: list[ca.SX] = field(default_factory=list)
    lbg: list[float] = field(default_factory=list)
    ubg: list[float] = field(default_factory=list)
    slack_values: list[ca.SX] = field(default_factory=list)

    def add_square(self, sq: SmoothSquare) -> ca.SX:
        """Record the slacks and constraints of a smooth square; return its ``f2``."""
        if sq.w.numel():
            self.slack.append(sq.w)
            self.lbw += sq.lbw
            self.ubw += sq.ubw
            self.g.append(sq.g)
            self.lbg += sq.lbg
            self.ubg += sq.ubg
            self.slack_values.append(sq.w_value)
        return sq.f2

    def add_domain(self, metric: Metric, x: ca.SX) -> None:
        """Record the domain's nonlinear constraints at point ``x``."""
        for expr, lb, ub in metric.domain.constraints_sx(x):
            self.g.append(expr)
            self.lbg.append(lb)
            self.ubg.append(ub)


def ipopt_options(tol: float = 1e-10, max_iter: int = 1000, **extra: object) -> dict:
    """IPOPT options used by every solver here (mumps, silent)."""
    ipopt = {
        "print_level": 0,
        "sb": "yes",
        "linear_solver": "mumps",
        "tol": tol,
        # IPOPT's defaults accept constraint violations up to 1e-4 and complementarity up
        # to 1e-4 at "convergence": far too loose for an exact slack reformulation.
        "constr_viol_tol": 1e-10,
        "compl_inf_tol": 1e-10,
        "dual_inf_tol": 1e-8,
        "max_iter": max_iter,
        "acceptable_iter": 0,  # never stop early at the acceptable level
    }
    ipopt.update(extra)
    # expand: the mapped MX graph evaluated as one SX graph: the same iterates to rounding
    # and about half the solve time on every metric (the Hessian evaluations are the
    # saving; building costs more, once per (metric, n)). A function CasADi cannot write in
    # SX (a Python callback) stays a call in the expanded graph. Fatrop (CasADi's
    # structure-exploiting interior point) did not converge on the car-like paths, so
    # IPOPT stays the reference solver.
    return {"print_time": False, "expand": True, "ipopt": ipopt, "error_on_fail": False}


@dataclass
class _Path:
    """Symbolic path of the transcription and its constraints (shared by both NLPs)."""

    z: ca.MX  # interior points then slacks
    lbz: np.ndarray
    ubz: np.ndarray
    params: ca.MX
    f2: ca.MX  # (1, n): the smooth squared cost of every segment
    g: ca.MX  # slack constraints of every segment, then domain constraints of every point
    lbg: np.ndarray
    ubg: np.ndarray
    slack_init: ca.Function  # (P (dim, n+1)) -> slack values


def _segment_functions(metric: Metric) -> tuple[ca.Function, ca.Function, ca.Function,
                                                 tuple, tuple, tuple, tuple]:
    """One segment's smooth square and slack constraints ``(x, y, w) -> (f2, g)``, its
    exact slack values ``(x, y) -> w`` and one point's domain constraints ``x -> c``, as
    SX functions (mapped over the segments of every size: the NLP graph is O(1) in ``n``),
    with the bounds of ``w``, ``g`` and ``c``; built once per metric (``metric.derived``)."""
    return metric.derived("transcription.segment", lambda: _build_segment_functions(metric))


def _build_segment_functions(metric: Metric) -> tuple[ca.Function, ca.Function, ca.Function,
                                                       tuple, tuple, tuple, tuple]:
    dim = metric.dim
    x = ca.SX.sym("x", dim)
    y = ca.SX.sym("y", dim)
    c = Constraints()
    f2 = c.add_square(smooth_square(metric, x, y - x))
    w = ca.vertcat(*c.slack) if c.slack else ca.SX(0, 1)
    g = ca.vertcat(*c.g) if c.g else ca.SX(0, 1)
    wv = ca.vertcat(*c.slack_values) if c.slack_values else ca.SX(0, 1)
    seg = ca.Function("seg", [x, y, w], [f2, g])
    wval = ca.Function("wval", [x, y], [wv])
    d = Constraints()
    d.add_domain(metric, x)
    dom = ca.Function("dom", [x], [ca.vertcat(*d.g) if d.g else ca.SX(0, 1)])
    return (seg, wval, dom, (tuple(c.lbw), tuple(c.ubw)), (tuple(c.lbg), tuple(c.ubg)),
            (tuple(d.lbg), tuple(d.ubg)), ())


def nonnegative_rows(bounded: list[tuple[tuple, int, Any]]) -> list:
    """Every finite bound as one row ``row >= 0``, in the order given: ``(bounds, +1, e)``
    for lower bounds ``e[i] >= b[i]``, ``(bounds, -1, e)`` for upper ones; the constraint
    list the interior point and the non-smooth KKT residual both build from
    ``_segment_functions``."""
    rows = []
    for b, sign, e in bounded:
        for i, bi in enumerate(b):
            if np.isfinite(bi):
                rows.append(sign * (e[i] - bi))
    return rows


def domain_rows(metric: Metric, p: ca.SX) -> list:
    """One point's domain as rows ``row >= 0``: the domain's constraints ``dom(p)`` within
    their bounds, then the box sides of every coordinate (lower, upper)."""
    _, _, dom, _, _, (lbgd, ubgd), _ = _segment_functions(metric)
    c = dom(p)
    rows = nonnegative_rows([(lbgd, 1, c), (ubgd, -1, c)])
    lo, hi = metric.domain.bounds()
    for i in range(metric.dim):
        if np.isfinite(lo[i]):
            rows.append(p[i] - float(lo[i]))
        if np.isfinite(hi[i]):
            rows.append(float(hi[i]) - p[i])
    return rows


def _build_path(metric: Metric, n: int) -> _Path:
    """The transcription with ``n`` segments, built from one segment's functions mapped
    over the segments (CasADi ``map``): building costs the same at every size (measured:
    4096 Matsumoto segments 6.4 s as one unrolled SX graph, a few ms mapped)."""
    dim = metric.dim
    seg, wval, dom, (lbw, ubw), (lbgs, ubgs), (lbgd, ubgd), _ = _segment_functions(metric)
    k = seg.nnz_in(2)
    X = ca.MX.sym("X", dim, n - 1)
    W = ca.MX.sym("W", k, n)
    s = ca.MX.sym("s", dim)
    goal = ca.MX.sym("g", dim)
    P = ca.horzcat(s, X, goal)
    f2, gs = seg.map(n)(P[:, :-1], P[:, 1:], W)
    parts = [ca.vec(gs)] if seg.nnz_out(1) else []
    if dom.nnz_out(0):
        parts.append(ca.vec(dom.map(n - 1)(X)))
    g = ca.vertcat(*parts) if parts else ca.MX(0, 1)
    lbg = np.concatenate([np.tile(lbgs, n), np.tile(lbgd, n - 1)]).astype(float)
    ubg = np.concatenate([np.tile(ubgs, n), np.tile(ubgd, n - 1)]).astype(float)
    Pn = ca.MX.sym("P", dim, n + 1)
    sv = ca.vec(wval.map(n)(Pn[:, :-1], Pn[:, 1:])) if k else ca.MX(0, 1)
    slack_init = ca.Function("slack_init", [Pn], [sv])
    z = ca.vertcat(ca.vec(X), ca.vec(W)) if k else ca.vec(X)
    lo, hi = metric.domain.bounds()
    lbz = np.concatenate([np.tile(lo, n - 1), np.tile(np.asarray(lbw, float), n)])
    ubz = np.concatenate([np.tile(hi, n - 1), np.tile(np.asarray(ubw, float), n)])
    return _Path(z, lbz, ubz, ca.vertcat(s, goal), f2, g, lbg, ubg, slack_init)


@dataclass
class _Solved:
    z: np.ndarray
    status: Status
    iterations: int
    objective: float


class _NLPBase:
    n: int
    dim: int
    solver: ca.Function
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    slack_init: ca.Function

    def points_to_z(self, points: np.ndarray) -> np.ndarray:
        """Full path ``(n+1, dim)`` -> decision vector (interior points, exact slacks)."""
        interior = points[1:-1].reshape(-1)
        slack = np.asarray(self.slack_init(points.T)).reshape(-1)
        return np.concatenate([interior, slack])

    def z_to_points(self, z: np.ndarray, s: np.ndarray, g: np.ndarray) -> np.ndarray:
        interior = z[: (self.n - 1) * self.dim].reshape(self.n - 1, self.dim)
        return np.vstack([s[None], interior, g[None]])

    def _call(self, x0: np.ndarray, p: np.ndarray, ubx: np.ndarray | None = None) -> _Solved:
        # Start strictly inside the variable bounds (projection can put seeds on them).
        x0 = np.clip(x0, self.lbx, self.ubx)
        out = self.solver(
            x0=x0,
            p=p,
            lbx=self.lbx,
            ubx=self.ubx if ubx is None else ubx,
            lbg=self.lbg,
            ubg=self.ubg,
        )
        stats = self.solver.stats()
        return _Solved(
            np.asarray(out["x"]).reshape(-1),
            Status.from_ipopt(str(stats.get("return_status", "Unknown"))),
            int(stats.get("iter_count", -1)),
            float(out["f"]),
        )


class EnergyNLP(_NLPBase):
    """``min n * sum_i F(p_i, p_{i+1} - p_i)**2`` over the interior points (eq. 7's energy,
    scaled by ``n`` so that its value is ``~ length**2``), domain constraints, exact
    derivatives. IPOPT sees it divided by the seed's value (a parameter), so that its
    tolerances and barrier parameter are relative."""

    def __init__(self, metric: Metric, n: int, tol: float = 1e-10, max_iter: int = 1000,
                 warm: bool = False) -> None:
        path = _build_path(metric, n)
        self.n, self.dim = n, metric.dim
        scale = ca.MX.sym("scale")  # 1 / (seed's energy): the objective starts at ~1
        obj = scale * n * ca.sum2(path.f2)
        nlp = {"x": path.z, "p": ca.vertcat(path.params, scale), "f": obj, "g": path.g}
        name = f"energy_{_ident(metric.name)}_{n}"
        # mu_init 1e-3 on the normalised objective: IPOPT's default 0.1 lets the disk
        # constraint's barrier term dominate the first iterations and drag paths into worse
        # local minima; 1e-3 reaches lower energies and takes fewer iterations.
        opts = ipopt_options(tol, max_iter, mu_init=1e-3)
        if warm:
            # a start that is already a nearly converged path (the ladder's interpolated
            # optimum of the previous size): a small barrier keeps it in its basin
            # (measured at n = 4096: mu_init 1e-3 drifted to a 0.4% longer local minimum)
            opts = ipopt_options(tol, max_iter, mu_init=1e-7, bound_push=1e-8,
                                 bound_frac=1e-8, mumps_pivtol=1e-8)
            name += "_warm"
        self.nlp, self.options = nlp, opts
        self.solver = ca.nlpsol(name, "ipopt", nlp, opts)
        self._energy = ca.Function("energy", [path.z, path.params], [n * ca.sum2(path.f2)])
        self.lbx, self.ubx = path.lbz, path.ubz
        self.lbg, self.ubg = path.lbg, path.ubg
        self.slack_init = path.slack_init

    def solve(self, seed: np.ndarray) -> tuple[np.ndarray, Status, int, float]:
        """Solve from a seed path ``(n+1, dim)`` (its endpoints are start and goal).

        Returns (points ``(n+1, dim)``, status, iterations, objective)."""
        s, g = seed[0], seed[-1]
        z0 = self.points_to_z(seed)
        p = np.concatenate([s, g])
        e0 = float(self._energy(z0, p))
        scale = 1.0 / e0 if np.isfinite(e0) and e0 > 0 else 1.0
        r = self._call(z0, np.concatenate([p, [scale]]))
        return self.z_to_points(r.z, s, g), r.status, r.iterations, r.objective / scale


class MinMaxNLP(_NLPBase):
    """``min t_1`` subject to ``n**2 F(p_i, p_{i+1} - p_i)**2 * scale <= t_i`` for every
    segment and ``t_i = t_{i+1}`` (the epigraph form of minimising the largest segment
    cost, one epigraph variable per segment so that every constraint is local and the KKT
    matrix stays banded; ``scale`` normalises the starting max to 1), plus a tiny multiple
    of the energy that makes the minimiser unique without moving the max by more than
    ~1e-8 relative.

    Solved from the energy solution in up to three attempts, each limited to
    `wall_budget` seconds (IPOPT's ``max_wall_time``, so a size that cannot be
    solved returns its status in bounded time, never hangs): a warm start (barrier and
    bound push 1e-6 / 1e-8: the start is feasible and nearly optimal), then IPOPT's
    default barrier start, then the default start without the cap on ``t``.
    Measured (Matsumoto, n = 1024): a single ``t`` coupling all constraints and MUMPS's
    default pivot tolerance gave 260 ms per iteration (fill-in) and, at 4096, restoration
    failures after minutes; the chained form with ``mumps_pivtol=1e-8`` and the warm start
    converges in 7-10 iterations.
    """

    REG = 1e-8

    def __init__(self, metric: Metric, n: int, tol: float = 1e-10) -> None:
        path = _build_path(metric, n)
        self.n, self.dim = n, metric.dim
        scale = ca.MX.sym("scale")  # 1 / (starting value of n**2 max C**2): t starts at ~1
        f2 = path.f2.T
        t = ca.MX.sym("t", n)
        obj = t[0] + self.REG * n * scale * ca.sum1(f2)
        g = ca.vertcat(scale * n * n * f2 - t, t[1:] - t[:-1], path.g)
        self.lbg = np.concatenate([np.full(n, -np.inf), np.zeros(n - 1), path.lbg])
        self.ubg = np.concatenate([np.zeros(n), np.zeros(n - 1), path.ubg])
        self.nt = n
        self._nlp = {"x": ca.vertcat(path.z, t), "p": ca.vertcat(path.params, scale),
                     "f": obj, "g": g}
        self._name = f"minmax_{_ident(metric.name)}_{n}"
        self._tol = tol
        self.lbx = np.concatenate([path.lbz, np.zeros(self.nt)])
        self.ubx = np.concatenate([path.ubz, np.full(self.nt, np.inf)])
        self.slack_init = path.slack_init
        self._solvers: dict[str, ca.Function] = {}
        self.solver = self._solver("warm")

    def wall_budget(self) -> float:
        """Seconds allowed per attempt: ``5 + n / 200`` (25 s at n = 4096)."""
        return 5.0 + self.n / 200.0

    def _solver(self, kind: str) -> ca.Function:
        if kind not in self._solvers:
            common = {"mumps_pivtol": 1e-8, "max_wall_time": self.wall_budget()}
            if kind == "warm":
                extra = {"mu_init": 1e-6, "bound_push": 1e-8, "bound_frac": 1e-8}
            else:
                # IPOPT's default barrier start with a moderate bound push: measured at
                # n = 64 to rescue the pairs where the warm start stalls
                extra = {"bound_push": 1e-2, "bound_frac": 1e-2}
            opts = ipopt_options(self._tol, 500, **common, **extra)
            self._solvers[kind] = ca.nlpsol(f"{self._name}_{kind}", "ipopt", self._nlp, opts)
        return self._solvers[kind]

    def solve(
        self, start_points: np.ndarray, start_max_cost: float, cap_factor: float = 1.0 + 1e-6
    ) -> tuple[np.ndarray, Status, int, bool]:
        """Refine ``start_points`` ``(n+1, dim)`` whose largest segment cost is
        ``start_max_cost``; the epigraph variables are capped at ``cap_factor`` times their
        starting value (the cap is removed in the last attempt).

        Returns (points, status, iterations, cap_relaxed)."""
        s, g = start_points[0], start_points[-1]
        scale = 1.0 / max((self.n * start_max_cost) ** 2, 1e-300)
        t0 = cap_factor
        x0 = np.concatenate([self.points_to_z(start_points), np.full(self.nt, t0)])
        p = np.concatenate([s, g, [scale]])
        capped = self.ubx.copy()
        capped[-self.nt:] = t0 * (1.0 + 1e-9)
        its = 0
        r = None
        relaxed = False
        for kind, ubx in (("warm", capped), ("cold", capped), ("cold", None)):
            self.solver = self._solver(kind)
            r = self._call(x0, p, ubx)
            its += max(r.iterations, 0)
            relaxed = ubx is None
            if r.status.converged:
                break
        assert r is not None
        return self.z_to_points(r.z[:-self.nt], s, g), r.status, its, relaxed


def energy_nlp(metric: Metric, n: int, warm: bool = False) -> EnergyNLP:
    """The energy NLP of ``metric`` with ``n`` segments, built once per metric, ``n`` and
    ``warm`` (``metric.derived``; ``warm``: IPOPT options for starts that are nearly
    converged)."""
    return metric.derived(f"transcription.energy.{n}.{bool(warm)}",
                          lambda: EnergyNLP(metric, n, warm=warm))


def minmax_nlp(metric: Metric, n: int) -> MinMaxNLP:
    """The min-max NLP of ``metric`` with ``n`` segments, built once per metric and ``n``
    (``metric.derived``)."""
    return metric.derived(f"transcription.minmax.{n}", lambda: MinMaxNLP(metric, n))


def _ident(name: str) -> str:
    """A CasADi-valid identifier fragment from a metric name."""
    out = "".join(ch if ch.isalnum() else "_" for ch in name)
    while "__" in out:
        out = out.replace("__", "_")
    return out.strip("_") or "metric"
