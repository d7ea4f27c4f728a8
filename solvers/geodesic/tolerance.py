"""Accuracy on request: the size of a discrete geodesic doubled until its continuum length
is known to a relative tolerance (``solve_geodesic(..., tol=...)``).

Each size is warm started from the previous path; the polyline lengths of the sizes
solved so far are extrapolated by `richardson` (order 2 when it is observed), and
the refinement stops when the estimated error is below ``tol`` times the length or at
``max_segments`` (`solve_to_tol`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from finsler.errors import InputError, short
from finsler.infra.limits import check_count
from finsler.metrics.base import Metric
from solvers.geodesic.pair_solver import refine_checked_minmax, solve_pair, solve_pairs
from solvers.geodesic.request import SolveRequest
from solvers.inputs import check_segments
from solvers.result import GeodesicResult, SolverError, Status
from solvers.seeding.plans import SeedPlan, resample

__all__ = ["EXPECTED_ORDER", "TOL_MAX_SEGMENTS", "TOL_MIN", "check_tol", "richardson",
           "solve_to_tol"]

#: Largest size [`solve_geodesic`][solvers.geodesic.solve.solve_geodesic] doubles to for ``tol``.
TOL_MAX_SEGMENTS = 16384
#: Smallest ``tol``: the rounding term of `Metric.segment_length_error`'s estimate
#: (``1e2 * machine eps * length``), below which no error estimate can fall.
TOL_MIN = 1e2 * float(np.finfo(np.float64).eps)
#: Order of the polyline length of a smooth geodesic: chords lose O(h**2) per unit length.
EXPECTED_ORDER = 2.0


def richardson(sizes: Sequence[int], lengths: Sequence[float], quad_errors: Sequence[float],
               expected: float = EXPECTED_ORDER) -> dict[str, Any]:
    """Continuum length from polyline lengths at doubling sizes ``sizes`` ``(k,)``.

    With three or more sizes the observed order ``p = log2(d1 / d2)`` of the last two
    differences is computed; it is "seen" when both differences have the same sign, shrink,
    and ``|p - expected| <= 0.5``. Then ``length = L_k - d2 / (2**expected - 1)`` and the
    error estimate is the size of that correction (the estimated error of ``L_k``, an
    overestimate of the extrapolated value's error) plus the quadrature errors. Otherwise
    ``length = L_k`` with the estimate ``|d2|`` (bounds the error of ``L_k`` for any
    monotone convergence of order >= 1) plus the quadrature errors; with one size the
    estimate is infinite. Returns ``length``, ``error_estimate``, ``order`` (or None),
    ``order_seen``."""
    L = [float(v) for v in lengths]
    q = float(quad_errors[-1]) + (float(quad_errors[-2]) if len(L) > 1 else 0.0)
    if len(L) < 2:
        return {"length": L[-1], "error_estimate": float("inf"), "order": None,
                "order_seen": False}
    d2 = L[-2] - L[-1]
    order = None
    seen = False
    if len(L) >= 3:
        d1 = L[-3] - L[-2]
        if d1 != 0.0 and d2 != 0.0 and np.sign(d1) == np.sign(d2) and abs(d2) < abs(d1):
            order = float(np.log(abs(d1) / abs(d2)) / np.log(sizes[-1] / sizes[-2]))
            seen = abs(order - expected) <= 0.5
    if seen:
        corr = d2 / ((sizes[-1] / sizes[-2]) ** expected - 1.0)
        return {"length": L[-1] - corr, "error_estimate": abs(corr) + q, "order": order,
                "order_seen": True}
    return {"length": L[-1], "error_estimate": abs(d2) + q, "order": order,
            "order_seen": False}


def _tol_estimate(levels: list[dict[str, Any]], nonconvex: bool) -> dict[str, Any]:
    """`richardson` over the sizes solved so far; through non-convex regions of ``F``
    (where discrete minimisers may chatter and the order can change with the size) the
    order must be seen on the last two triples of sizes before it is used."""
    args = ([lv["segments"] for lv in levels], [lv["length"] for lv in levels],
            [lv["quadrature_error"] for lv in levels])
    est = richardson(*args)
    if nonconvex and est["order_seen"]:
        before = richardson(*(a[:-1] for a in args)) if len(levels) >= 4 else None
        if before is None or not before["order_seen"]:
            L = args[1]
            est = {"length": L[-1], "error_estimate": abs(L[-2] - L[-1]) + args[2][-1]
                   + args[2][-2], "order": est["order"], "order_seen": False}
    return est


def check_tol(m: Metric, n: int, tol: Any, max_segments: Any) -> tuple[float, int]:
    """``tol`` (a relative tolerance in ``(0, 1)``) and ``max_segments`` (a size ``>= n``)
    checked, as ``(float, int)``: what `solve_to_tol` takes."""
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.floating)) or not (
            np.isfinite(tol) and 0 < tol < 1):
        raise InputError(f"tol must be a relative tolerance in (0, 1), got "
                         f"{short(repr(tol), 80)}")
    if tol < TOL_MIN:
        raise InputError(f"tol = {tol:g} is below {TOL_MIN:.3g}, which no refinement can "
                         "reach: every length's error estimate carries a rounding term of "
                         "100 float64 epsilons")
    if isinstance(max_segments, bool) or not isinstance(max_segments, (int, np.integer)) \
            or max_segments < n:
        raise InputError(f"max_segments must be an integer >= segments ({n}), got "
                         f"{short(repr(max_segments), 80)}")
    check_count(max_segments, "max_segments", n, 1 << 16)  # named, not "segments"
    return float(tol), check_segments(m, int(max_segments))


def solve_to_tol(req: SolveRequest, s: np.ndarray, g: np.ndarray, t0: float, *,
                 initial: Sequence[np.ndarray] = (), strict: bool = False) -> GeodesicResult:
    """``solve_geodesic(..., tol=tol)`` from checked input (``s`` / ``g`` points in the
    request's domain; the request's ``tol`` / ``max_segments`` by `check_tol`): the pair
    solved at the request's size with its seeds and the ``initial`` paths, then at doubled
    sizes, each warm started from the last, until `_tol_estimate` is within ``tol`` or
    ``max_segments`` is reached; ``t0``: the caller's start time (for ``wall_time``)."""
    m, tol, minmax = req.metric, req.tol, req.minmax
    max_segments = req.max_segments or TOL_MAX_SEGMENTS
    if tol is None:
        raise InputError("solve_to_tol needs a request with tol")
    res = first = solve_pair(req.at(req.segments, minmax=False), s, g, initial)
    iterations = first.iterations
    levels: list[dict[str, Any]] = []
    while True:
        le = m.path_length_error(res.points, rtol=0.05 * float(tol))
        levels.append({"segments": res.segments, "length": float(le.value),
                       "quadrature_error": float(le.error), "status": res.status.label,
                       "nonconvex_points": res.nonconvex_points})
        est = _tol_estimate(levels, res.nonconvex_points > 0)
        done = len(levels) >= 3 and est["error_estimate"] <= tol * abs(est["length"])
        if done or 2 * res.segments > max_segments or not res.converged or res.status in (
                Status.TRIVIAL, Status.SHORT):
            break
        nxt = 2 * res.segments
        warm = [("refined", resample(res.points, np.ones(res.segments), nxt))]
        again = req.at(nxt, plan=SeedPlan.default(m, req.method), global_seeds=False,
                       minmax=False, warm=True)
        res = solve_pairs(again, np.stack([s, g])[None], [warm])[0]
        iterations += res.iterations
    # the seeding happened at the first size; later sizes are warm starts of its winner
    res.seeds_tried, res.seeds_agreeing = first.seeds_tried, first.seeds_agreeing
    res.seed_energies, res.best_seed = first.seed_energies, first.best_seed
    res.seed_families, res.alternative_gap = first.seed_families, first.alternative_gap
    res.levels, res.iterations = first.levels, iterations
    if res.status in (Status.TRIVIAL, Status.SHORT):
        seg = m.segment_length_error(s, g)
        est = {"length": float(seg.value), "error_estimate": float(seg.error),
               "order": None, "order_seen": False}
        done = True
    res.length_estimate = float(est["length"])
    res.error_estimate = float(est["error_estimate"])
    res.order = est["order"]
    res.order_seen = bool(est["order_seen"])
    res.tol = float(tol)
    res.tol_reached = bool(done)
    res.tol_levels = levels
    if minmax:
        res.minmax = refine_checked_minmax(m, res)
    res.wall_time = time.perf_counter() - t0
    if strict and not (res.converged and res.tol_reached
                       and (res.minmax is None or res.minmax.converged)):
        raise SolverError(f"{m.name}: tol {tol:g} not reached (estimate "
                          f"{res.error_estimate:.3e} at {res.segments} segments, status "
                          f"{res.status.label})", res)
    return res
