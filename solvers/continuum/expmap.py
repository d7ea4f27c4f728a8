"""Exponential and logarithm maps of a Finsler metric: the geodesic initial-value problem
and its inverse.

The geodesic equation ``g(x, x') x'' = b(x, x')`` (the spray) is derived symbolically
from the metric's one SX expression ``F(x, v)`` and its fundamental tensor, once per
metric, on the metric side (`finsler.geometry.Spray` / `finsler.geometry.spray`). The
equation is meaningful only where ``g(x, x')`` is positive definite (``F`` strongly convex, i.e.
Finsler): `exp_map` refuses a start where ``F(x, .)`` is not strongly convex and stops with
status ``NOT_CONVEX`` when the curve reaches such a region.

`exp_map` integrates the first-order system ``(x, v)' = (v, -2 G(x, v))`` with
scipy's DOP853 (8th-order Runge-Kutta) at tight tolerances, stopping at the boundary of
the domain (status ``LEFT_DOMAIN``). `log_map` starts from the solved shortest path
(`solvers.distance`: the initial tangent of its polynomial curve, whose parameter is
proportional to arc length, already has ``F(x, v) ~ d(x, y)``) and polishes ``v`` by
Newton shooting on ``exp(x, v) = y`` with the Jacobian ``d exp / dv`` from the variational
equation, integrated alongside.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from finsler.domains import as_real, is_torch
from finsler.errors import InputError, short
from finsler.geometry import Spray, spray
from finsler.infra.limits import check_count, check_memory, check_number
from finsler.metrics.base import Metric
from finsler.status import Result, json_ready
from solvers.chebyshev import differentiation_matrix
from solvers.continuum.spectral import distance
from solvers.inputs import as_metric, check_point, is_short_pair
from solvers.result import DistanceStatus, SolverError
from solvers.status import ExpStatus, LogStatus

__all__ = ["ExpResult", "ExpStatus", "LogResult", "LogStatus", "exp_map", "log_map"]

#: Default relative and absolute tolerances of the DOP853 integration.
RTOL = 1e-13
ATOL = 1e-13

#: ``g(x, x')`` counts as positive definite while its smallest eigenvalue is above this
#: fraction of its largest.
PD_RATIO = 1e-9

#: Default tolerance of `log_map` on ``|exp(x, v) - y|`` (max norm, coordinates).
LOG_TOL = 1e-11
#: Smallest ``tol`` of `log_map`: a few float64 spacings of coordinates of order 1.
LOG_TOL_MIN = 1e-15
#: Smallest ``rtol`` of the integration: scipy's DOP853 raises smaller ones to it.
RTOL_MIN = 100 * float(np.finfo(np.float64).eps)
#: Most Newton iterations of `log_map` (it converges in a handful where it converges).
MAX_LOG_ITER = 1000

#: Relative gap between ``F(x, log(x, y))`` and the solver's distance above which the
#: shooting is taken to have found another (longer) geodesic.
OTHER_GEODESIC_RTOL = 1e-6


@dataclass
class ExpResult(Result):
    """The geodesic ``gamma`` with ``gamma(0) = start``, ``gamma'(0) = velocity``, at ``t``.

    ``point`` ``(dim,)`` is ``gamma(t_end)`` and ``point_velocity`` ``(dim,)`` its tangent;
    ``t_end == t`` unless the status says the curve stopped early. ``speed`` is
    ``F(start, velocity)``; ``speed_drift`` the largest relative change of
    ``F(gamma, gamma')`` over the integrator's steps (0 in exact arithmetic: a check of the
    integration). ``times`` ``(T,)`` / ``curve`` ``(T, dim)`` sample the curve when it was
    requested (``return_curve``), else they are empty. ``jacobian`` ``(dim, dim)`` is
    ``d gamma(t_end) / d velocity`` when computed (by
    [`log_map`][solvers.continuum.expmap.log_map]).
    """

    metric: str
    start: np.ndarray
    velocity: np.ndarray
    t: float
    point: np.ndarray
    point_velocity: np.ndarray
    t_end: float
    status: ExpStatus
    speed: float
    speed_drift: float
    steps: int
    evaluations: int
    wall_time: float
    message: str = ""
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    curve: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    jacobian: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``geodesics exp --json``; non-finite numbers as ``None``)."""
        out: dict[str, Any] = {
            "metric": self.metric,
            "start": self.start.tolist(),
            "velocity": self.velocity.tolist(),
            "t": self.t,
            "point": self.point.tolist(),
            "point_velocity": self.point_velocity.tolist(),
            "t_end": self.t_end,
            "status": self.status.label,
            "speed": self.speed,
            "length": self.speed * self.t_end,
            "speed_drift": self.speed_drift,
            "steps": self.steps,
            "wall_time": self.wall_time,
        }
        if self.message:
            out["message"] = self.message
        if self.curve.size:
            out["times"] = self.times.tolist()
            out["curve"] = self.curve.tolist()
        return json_ready(out)


@dataclass
class LogResult(Result):
    """Initial velocity ``velocity`` ``(dim,)`` of the shortest geodesic from ``start`` to
    ``goal`` parametrised on ``[0, 1]``: ``exp(start, velocity) = goal`` and
    ``F(start, velocity) = d(start, goal)``.

    ``length`` is ``F(start, velocity)``; ``distance`` the solver's length of the shortest
    path (`solvers.distance`) that seeded the shooting, ``distance_error_estimate`` its
    error estimate; ``residual`` the max-norm of ``exp(start, velocity) - goal``;
    ``iterations`` Newton steps, ``integrations`` geodesic integrations (each with its
    variational equation). ``exp`` is the final integration.
    """

    metric: str
    start: np.ndarray
    goal: np.ndarray
    velocity: np.ndarray
    length: float
    distance: float
    distance_error_estimate: float
    residual: float
    status: LogStatus
    iterations: int
    integrations: int
    wall_time: float
    initial_velocity: np.ndarray
    exp: ExpResult | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``geodesics log --json``; non-finite numbers as ``None``)."""
        return json_ready({
            "metric": self.metric,
            "start": self.start.tolist(),
            "goal": self.goal.tolist(),
            "velocity": self.velocity.tolist(),
            "length": self.length,
            "distance": self.distance,
            "distance_error_estimate": self.distance_error_estimate,
            "residual": self.residual,
            "status": self.status.label,
            "iterations": self.iterations,
            "integrations": self.integrations,
            "wall_time": self.wall_time,
        })


# ----------------------------------------------------------------------------------------
# exp
# ----------------------------------------------------------------------------------------
def _vector(m: Metric, v: Any, name: str) -> np.ndarray:
    arr = as_real(v, name, f"a real numeric vector of shape ({m.dim},)")
    if is_torch(arr):
        arr = arr.detach().cpu().numpy().astype(np.float64)
    if arr.shape != (m.dim,):
        raise InputError(f"{name} must have shape ({m.dim},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    return arr


def _check_speed(m: Metric, x: np.ndarray, v: np.ndarray, names: tuple[str, str]) -> None:
    """Refuse a velocity whose speed ``F(x, v)`` (or ``F(x, v)**2``, which the geodesic
    equation differentiates) overflows or underflows float64."""
    with np.errstate(all="ignore"):
        speed = float(m.F(x, v, check=False))
        unit = float(m.F(x, v / np.max(np.abs(v)), check=False)) if np.any(v) else 0.0
    if not (math.isfinite(unit) and unit >= 0):  # F itself fails here, whatever the scale
        raise InputError(f"{m.name}: F({names[0]}, {names[1]}) = {speed:.6g} at {names[0]} = "
                         f"{short(str(x.tolist()), 60)}, {names[1]} = "
                         f"{short(str(v.tolist()), 60)}: F must be finite and > 0 there")
    if np.any(v) and speed * speed < np.finfo(np.float64).tiny:
        raise InputError(f"{names[1]} = {short(str(v.tolist()), 60)} is too small: the speed "
                         f"F({names[0]}, {names[1]})**2 underflows float64; scale it up (the "
                         "curve of c v at time t / c is the same)")
    if not (math.isfinite(speed) and math.isfinite(speed * speed)):
        raise InputError(f"{names[1]} = {short(str(v.tolist()), 60)} is too large: the speed "
                         f"F({names[0]}, {names[1]}) overflows float64; scale it down (the "
                         "curve of c v at time t / c is the same)")


def _check_convex_at(m: Metric, sp: Spray, x: np.ndarray, v: np.ndarray | None,
                     name: str) -> None:
    """Refuse (InputError) a point where ``F(x, .)`` is not strongly convex."""
    if not m.convex_everywhere:
        lam = float(m.convexity(x[None])[0])
        if not lam > 0:
            raise InputError(
                f"{m.name}: F(x, .) is not strongly convex at {name} = "
                f"{short(str(x.tolist()), 60)} (smallest "
                f"eigenvalue of the fundamental tensor {lam:.3g} <= 0; {m.convexity_note}): "
                "the geodesic equation does not describe shortest curves there, so exp/log "
                "are refused")
    if v is not None and np.any(v != 0) and not sp.pd_ratio(x, v) > PD_RATIO:
        raise InputError(f"{m.name}: the fundamental tensor g({name}, v) is not positive "
                         f"definite at {name} = {short(str(x.tolist()), 60)}, v = "
                         f"{short(str(v.tolist()), 60)}")


def _integrate(m: Metric, sp: Spray, x: np.ndarray, v: np.ndarray, t: float, *,
               variational: bool, samples: int, rtol: float, atol: float) -> ExpResult:
    """Integrate the geodesic equation (and, with ``variational``, ``d(x, v)/dv0``)."""
    t0 = time.perf_counter()
    d = m.dim
    nev = [0]

    def rhs(_s: float, y: np.ndarray) -> np.ndarray:
        nev[0] += 1
        xs, vs = y[:d], y[d:2 * d]
        acc, g = sp.acceleration(xs, vs)
        if not variational:
            return np.concatenate([vs, acc])
        dg, db = sp.parts_jac(xs, vs)
        dg = np.asarray(dg).reshape(d, d, 2 * d, order="F")  # dg[i, j, k] = d g_ij / d z_k
        # d acc / dz = g^{-1} (db/dz - (dg/dz) acc)
        dacc = np.linalg.solve(g, np.asarray(db) - np.einsum("ijk,j->ik", dg, acc))
        phi = y[2 * d:].reshape(2 * d, d)  # d z / d v0
        dphi = np.vstack([phi[d:], dacc @ phi])
        return np.concatenate([vs, acc, dphi.reshape(-1)])

    def leave(_s: float, y: np.ndarray) -> float:
        return float(np.min(np.asarray(sp.margin(y[:d])))) if sp.n_margin else 1.0

    def lose_convexity(_s: float, y: np.ndarray) -> float:
        return sp.pd_ratio(y[:d], y[d:2 * d]) - PD_RATIO

    leave.terminal = True  # type: ignore[attr-defined]
    leave.direction = -1  # type: ignore[attr-defined]
    lose_convexity.terminal = True  # type: ignore[attr-defined]
    lose_convexity.direction = -1  # type: ignore[attr-defined]
    y0 = np.concatenate([x, v])
    if variational:
        y0 = np.concatenate([y0, np.vstack([np.zeros((d, d)), np.eye(d)]).reshape(-1)])
    speed = float(m.F(x, v, check=False))
    with np.errstate(all="ignore"):
        try:
            sol = solve_ivp(rhs, (0.0, t), y0, method="DOP853", rtol=rtol, atol=atol,
                            events=[leave, lose_convexity],
                            dense_output=samples > 0 or not m.convex_everywhere)
            ok, message = sol.status >= 0, ("" if sol.status >= 0 else str(sol.message))
        except np.linalg.LinAlgError as err:
            sol, ok, message = None, False, f"singular fundamental tensor: {err}"
    if sol is None or not ok or not np.all(np.isfinite(sol.y)):
        status = ExpStatus.INTEGRATION_FAILED
        message = message or "non-finite values in the integration"
        ys = sol.y if sol is not None else y0[:, None]
        good = np.flatnonzero(np.all(np.isfinite(ys), axis=0))
        t_steps = sol.t if sol is not None else np.zeros(1)
        last = int(good[-1]) if good.size else 0
        y_end, t_end = (ys[:, last] if good.size else y0), float(t_steps[last])
    else:
        y_end, t_end = sol.y[:, -1], float(sol.t[-1])
        status = ExpStatus.SUCCESS
        if sol.status == 1:
            if sol.t_events[0].size:
                status = ExpStatus.LEFT_DOMAIN
                message = f"the curve reaches the boundary of {m.domain.describe()}"
            else:
                status = ExpStatus.NOT_CONVEX
                message = "the fundamental tensor g(x, x') stops being positive definite"
    times = np.zeros(0)
    curve = np.zeros((0, d))
    steps = 1 if sol is None else len(sol.t)
    pts = y0[None, :2 * d] if sol is None else sol.y[:2 * d].T
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    drift = 0.0
    if speed > 0 and len(pts):
        fs = m.F(pts[:, :d], pts[:, d:], check=False)
        drift = float(np.max(np.abs(fs - speed)) / speed)
    if status in (ExpStatus.SUCCESS, ExpStatus.LEFT_DOMAIN) and not m.convex_everywhere \
            and len(pts):
        # g(x, x') positive definite is what the equation needs; for a metric that is not
        # convex everywhere also refuse points where F(x, .) fails convexity in some
        # direction (the curve is then not locally shortest among all curves)
        # checked at the steps and at 4 points inside each step (dense output)
        ts = np.concatenate([sol.t[:-1, None] + np.linspace(0.0, 1.0, 5, endpoint=False)[None]
                             * np.diff(sol.t)[:, None], sol.t[-1:, None]], axis=None)
        inside = m.domain.project(sol.sol(ts)[:d].T)
        lam = m.convexity(inside)
        bad = np.flatnonzero(lam <= 0)
        if bad.size:
            k = int(bad[0])
            status = ExpStatus.NOT_CONVEX
            y_end, t_end = sol.sol(ts[k]), float(ts[k])
            if k > 0:  # bisect the dense output for the first non-convex point
                lo_t, hi_t = float(ts[k - 1]), t_end
                for _ in range(60):
                    mid = 0.5 * (lo_t + hi_t)
                    xm = m.domain.project(sol.sol(mid)[:d][None])
                    if m.convexity(xm)[0] <= 0:
                        hi_t = mid
                    else:
                        lo_t = mid
                    if hi_t - lo_t <= 1e-12 * max(1.0, hi_t):
                        break
                y_end, t_end = sol.sol(hi_t), hi_t
            message = (f"F(x, .) is not strongly convex at x = {y_end[:d].tolist()} reached "
                       f"at t = {t_end:.6g} ({m.convexity_note})")
    if samples > 0 and sol is not None and sol.sol is not None:
        times = np.linspace(0.0, t_end, samples)
        curve = sol.sol(times)[:d].T.copy()
    jac = y_end[2 * d:].reshape(2 * d, d)[:d] if variational else None
    return ExpResult(
        metric=m.name, start=x, velocity=v, t=float(t), point=y_end[:d].copy(),
        point_velocity=y_end[d:2 * d].copy(), t_end=t_end, status=status, speed=speed,
        speed_drift=drift, steps=steps, evaluations=nev[0],
        wall_time=time.perf_counter() - t0, message=message, times=times, curve=curve,
        jacobian=None if jac is None else jac.copy(),
    )


def exp_map(
    metric: Metric | str,
    x: Any,
    v: Any,
    t: float = 1.0,
    return_curve: bool | int = False,
    *,
    rtol: float = RTOL,
    atol: float = ATOL,
    strict: bool = False,
    names: tuple[str, str] = ("x", "v"),
) -> ExpResult:
    """Exponential map: the point ``gamma(t)`` of the geodesic with ``gamma(0) = x`` ``(dim,)``
    and ``gamma'(0) = v`` ``(dim,)``, for ``t >= 0``.

    The geodesic has constant speed ``F(x, v)``, so its length up to ``t`` is
    ``t * F(x, v)``; for asymmetric metrics ``exp(x, -v)`` is not the reverse curve. The
    curve stops early at the domain's boundary (``LEFT_DOMAIN``) or where ``g(x, x')`` stops
    being positive definite or (for metrics not convex everywhere) ``F(x, .)`` stops being
    strongly convex (``NOT_CONVEX``). ``return_curve``: ``True`` for 129 samples of the curve
    on ``[0, t_end]`` (``result.times``, ``result.curve`` ``(T, dim)``) or an integer number
    of samples (>= 2). ``rtol``/``atol``: DOP853 tolerances. Raises `InputError` for
    bad input, a non-smooth metric or a start where ``F(x, .)`` is not strongly convex;
    ``strict=True`` raises `SolverError` unless the status is ``SUCCESS``.
    ``names``: how error messages call ``x`` and ``v`` (a command line passes its options).
    """
    m = as_metric(metric)
    sp = spray(m)
    xs = check_point(m, x, names[0])
    vs = _vector(m, v, names[1])
    if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not (
            math.isfinite(t) and t >= 0):
        raise InputError(f"t must be a finite number >= 0, got {t!r}")
    samples = _samples(return_curve)
    if samples:  # the dense output is evaluated at every sample: (2 dim, samples) floats
        check_memory((samples, 2 * m.dim), f"return_curve = {samples} samples of the curve",
                     copies=3)
    _check_tolerances(rtol, atol)
    _check_speed(m, xs, vs, names)
    _check_convex_at(m, sp, xs, vs, names[0])
    if t == 0 or not np.any(vs != 0):
        n = samples if samples else 0
        return ExpResult(
            metric=m.name, start=xs, velocity=vs, t=float(t), point=xs.copy(),
            point_velocity=vs.copy(), t_end=float(t), status=ExpStatus.SUCCESS,
            speed=float(m.F(xs, vs, check=False)), speed_drift=0.0, steps=0, evaluations=0,
            wall_time=0.0, times=np.linspace(0.0, float(t), n) if n else np.zeros(0),
            curve=np.repeat(xs[None], n, 0) if n else np.zeros((0, m.dim)))
    res = _integrate(m, sp, xs, vs, float(t), variational=False, samples=samples, rtol=rtol,
                     atol=atol)
    if strict and not res.converged:
        raise SolverError(f"{m.name}: exp_map stopped at t = {res.t_end:.6g} < {t:g} "
                          f"({res.status.label}: {res.message})", res)
    return res


def _samples(return_curve: bool | int) -> int:
    if return_curve is True:
        return 129
    if return_curve is False or return_curve is None:
        return 0
    if not isinstance(return_curve, (int, np.integer)) or return_curve < 2:
        raise InputError(f"return_curve must be a bool or an integer >= 2, got "
                         f"{return_curve!r}")
    return int(return_curve)


def _check_tolerances(rtol: float, atol: float) -> None:
    for name, val in (("rtol", rtol), ("atol", atol)):
        check_number(val, name, 0.0, 1.0, low_open=True, high_open=True)
    if rtol < RTOL_MIN:  # scipy would raise it silently (with a warning) to this floor
        raise InputError(f"rtol = {rtol:g} is below {RTOL_MIN:.3g}, the smallest relative "
                         "tolerance DOP853 works to in float64")


# ----------------------------------------------------------------------------------------
# log
# ----------------------------------------------------------------------------------------
def log_map(
    metric: Metric | str,
    x: Any,
    y: Any,
    *,
    tol: float = LOG_TOL,
    max_iter: int = 30,
    rtol: float = RTOL,
    atol: float = ATOL,
    strict: bool = False,
    names: tuple[str, str] = ("x", "y"),
) -> LogResult:
    """Logarithm map: the initial velocity ``v`` ``(dim,)`` with ``exp(x, v) = y`` and
    ``F(x, v) = d(x, y)`` (the shortest geodesic from ``x`` to ``y``, each ``(dim,)``, on
    ``[0, 1]``).

    The guess is the initial tangent of `solvers.distance`'s curve (globally seeded,
    so the shortest of the geodesics joining the points); Newton's method on
    ``exp(x, v) - y`` with ``d exp / dv`` from the variational equation and a halving line
    search polishes it until ``|exp(x, v) - y|_max <= tol``. Raises `InputError` for
    bad input, a non-smooth metric, or where ``F(x, .)`` is not strongly convex at ``x``,
    ``y`` or along the shortest path (e.g. Matsumoto outside ``|p| ~ 0.289``);
    ``strict=True`` raises `SolverError` unless converged. ``names``: how error
    messages call ``x`` and ``y`` (a command line passes its options).
    """
    t0 = time.perf_counter()
    m = as_metric(metric)
    sp = spray(m)
    xs = check_point(m, x, names[0])
    ys = check_point(m, y, names[1])
    check_number(tol, "tol", 0.0, 1.0, low_open=True, high_open=True)
    if tol < LOG_TOL_MIN:
        raise InputError(f"tol = {tol:g} is below {LOG_TOL_MIN:g}: |exp(x, v) - y| is a "
                         "difference of float64 coordinates, which resolve no finer")
    check_count(max_iter, "max_iter", 1, MAX_LOG_ITER)
    _check_tolerances(rtol, atol)
    _check_convex_at(m, sp, xs, None, names[0])
    _check_convex_at(m, sp, ys, None, names[1])
    if np.array_equal(xs, ys):
        z = np.zeros(m.dim)
        return LogResult(m.name, xs, ys, z, 0.0, 0.0, 0.0, 0.0, LogStatus.TRIVIAL, 0, 0,
                         time.perf_counter() - t0, z.copy())
    if is_short_pair(m, xs, ys):
        v0 = ys - xs
        dist = float(m.segment_length(xs, ys, 8, check=False))
        est = dist * 1e-13
    else:
        dres = distance(m, xs, ys)
        if dres.min_convexity <= 0 or dres.status is DistanceStatus.NOT_CONVEX:
            raise InputError(
                f"{m.name}: the shortest path from {xs.tolist()} to {ys.tolist()} crosses a "
                f"region where F(x, .) is not strongly convex (smallest eigenvalue of the "
                f"fundamental tensor {dres.min_convexity:.3g}; {m.convexity_note}): there "
                "the shortest path is not a solution of the geodesic equation, so the log "
                "map is refused")
        n = dres.nodes.shape[0] - 1
        v0 = 2.0 * (differentiation_matrix(n)[0] @ dres.nodes)  # d/dt, t = (tau + 1) / 2
        dist, est = float(dres.distance), float(dres.error_estimate)
    _check_convex_at(m, sp, xs, v0, "x")
    v = v0.copy()
    integrations = 0

    def shoot(vel: np.ndarray, variational: bool = True) -> tuple[ExpResult, float]:
        nonlocal integrations
        integrations += 1
        r = _integrate(m, sp, xs, vel, 1.0, variational=variational, samples=0, rtol=rtol,
                       atol=atol)
        res = float(np.max(np.abs(r.point - ys))) if r.converged else math.inf
        return r, res

    # the solver's curve is usually within tol already: check it without the (4x dearer)
    # variational equation, and only then shoot with it
    cur, resid = shoot(v, variational=False)
    if resid > tol:
        cur, resid = shoot(v)
    iterations = 0
    while resid > tol and iterations < max_iter:
        if cur.jacobian is None or not cur.converged:
            break
        iterations += 1
        try:
            step = np.linalg.solve(cur.jacobian, ys - cur.point)
        except np.linalg.LinAlgError:
            break  # conjugate point: the Jacobian of exp is singular
        lam = 1.0
        while lam > 1e-4:
            trial, tres = shoot(v + lam * step)
            if tres < resid:
                v, cur, resid = v + lam * step, trial, tres
                break
            lam *= 0.5
        else:
            break  # no decrease: at the integrator's noise floor or stuck
    length = float(m.F(xs, v, check=False))
    if resid <= tol:
        gap = abs(length - dist) / dist if dist > 0 else 0.0
        status = (LogStatus.SUCCESS if gap <= max(OTHER_GEODESIC_RTOL, 10 * est / dist)
                  else LogStatus.OTHER_GEODESIC)
    else:
        status = LogStatus.NOT_CONVERGED
    out = LogResult(m.name, xs, ys, v, length, dist, est, resid, status, iterations,
                    integrations, time.perf_counter() - t0, v0, cur)
    if strict and not out.converged:
        raise SolverError(f"{m.name}: log_map {status.label} (residual {resid:.3e}, tol "
                          f"{tol:g}, F(x, v) = {length:.12g} vs distance {dist:.12g})", out)
    return out
