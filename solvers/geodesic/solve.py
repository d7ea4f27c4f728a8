"""Discrete geodesics of the task: the public entry points `solve_geodesic` and
[`midpoint`][solvers.geodesic.solve.midpoint].

``solve_geodesic`` solves the task discretisation (eq. 7's energy ``sum C(p_i, p_{i+1})**2``
over ``n`` segments) from every seed of a [`SeedPlan`][solvers.seeding.plans.SeedPlan] and keeps the
lowest energy among the converged solves (`solvers.geodesic.pair_solver`: seeding, the batched
Newton method or IPOPT, selection, figures). The seeds are solved at the plan's coarse
size and only the best few distinct optima are carried up a ladder of sizes to ``n``
(multiresolution: time about linear in ``n``). ``refine_minmax`` then minimises the
largest segment cost: the exact ceiling of the paper's task. ``tol`` refines the size
until the continuum length is known to that relative accuracy (`solvers.geodesic.tolerance`,
Richardson extrapolation). Many pairs: `solve_batch` (`solvers.geodesic.batches`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from finsler.domains import describe_value
from finsler.errors import InputError
from finsler.metrics.base import Metric
from solvers.geodesic.pair_solver import resolve_method, solve_pair
from solvers.geodesic.request import SolveRequest, seed_plan
from solvers.geodesic.tolerance import TOL_MAX_SEGMENTS, check_tol, solve_to_tol
from solvers.inputs import as_metric, check_initial, check_point, check_segments
from solvers.result import GeodesicResult, MidpointResult, SolverError
from solvers.seeding.plans import SeedPlan

__all__ = ["midpoint", "solve_geodesic"]


def solve_geodesic(
    metric: Metric | str,
    start: Any,
    goal: Any,
    segments: int | None = None,
    *,
    seeds: SeedPlan | None = None,
    initial: Sequence[np.ndarray] = (),
    global_seeds: bool = True,
    minmax: bool = False,
    strict: bool = False,
    tol: float | None = None,
    max_segments: int = TOL_MAX_SEGMENTS,
    method: str = "auto",
    device: Any = None,
) -> GeodesicResult:
    """Globally seeded discrete geodesic from ``start`` to ``goal`` (each ``(dim,)``).

    Minimises ``sum_i C(p_i, p_{i+1})**2`` over the interior points of an ``n``-segment path
    (default ``n = 2**D`` of the metric's task) from every seed of ``seeds`` (default
    `SeedPlan.default`) plus the given ``initial`` paths ``(m+1, dim)`` (e.g. a
    learned path or an exact path of another size; resampled to ``n + 1`` points at equal
    parameter spacing when ``m != n``); with ``global_seeds=False`` only the ``initial``
    paths are solved (a warm start: no seed plan, no graph); returns the lowest energy
    among IPOPT-converged solves, with
    ``seeds_tried`` / ``seeds_agreeing``. With ``minmax=True`` the min-max refinement is
    attached (``result.minmax``). ``strict=True`` raises `SolverError` unless
    converged.

    ``tol`` (relative, e.g. ``1e-7``): accuracy on request. The size is doubled from ``n``
    (each size warm started from the previous path) until the estimated error of the
    continuum length is below ``tol * length`` or ``max_segments`` is reached; the result
    then carries ``length_estimate`` (Richardson extrapolation of the eq. (58) polyline
    lengths when their order 2 is observed, else the finest length), ``error_estimate``
    (absolute), ``order`` (observed) / ``order_seen`` and ``tol_levels``; min-max runs at
    the final size.

    ``method``: ``"auto"`` (default) solves with the batched Newton method of
    `solvers.newton.driver` where it covers the metric (``F`` smooth), IPOPT otherwise;
    ``"newton"`` / ``"ipopt"`` ask for one. IPOPT also finishes what the Newton method
    cannot (an active domain constraint, a stall); ``result.method`` says which produced
    the path and ``result.residual`` its first-order optimality residual. ``device``: a
    torch device for the Newton method (``"cuda"``; default numpy on the CPU).
    """
    t0 = time.perf_counter()
    # the input is checked here, once; what solves below trusts it
    m = as_metric(metric)
    n = check_segments(m, segments)
    how = resolve_method(m, method)
    s = check_point(m, start, "start")
    g = check_point(m, goal, "goal")
    initial = check_initial(initial)
    if not isinstance(global_seeds, (bool, np.bool_)):
        raise InputError(f"global_seeds must be True or False, got {describe_value(global_seeds)}")
    for name, flag in (("minmax", minmax), ("strict", strict)):
        if not isinstance(flag, (bool, np.bool_)):
            raise InputError(f"{name} must be True or False, got {describe_value(flag)}")
    req = SolveRequest(m, n, seed_plan(m, seeds, how), how, bool(global_seeds), bool(minmax),
                       device=device)
    if tol is not None:
        tol_, max_n = check_tol(m, n, tol, max_segments)
        return solve_to_tol(req.at(n, tol=tol_, max_segments=max_n), s, g, t0,
                            initial=initial, strict=strict)
    res = solve_pair(req, s, g, initial)
    res.wall_time = time.perf_counter() - t0
    if strict and not (res.converged and (res.minmax is None or res.minmax.converged)):
        raise SolverError(
            f"{m.name}: solve did not converge (status {res.status.label}"
            + (f", min-max {res.minmax.status.label}" if res.minmax is not None else "")
            + ")",
            res,
        )
    return res


def midpoint(
    metric: Metric | str,
    start: Any,
    goal: Any,
    segments: int | None = None,
    **kwargs: Any,
) -> MidpointResult:
    """Midpoint ``p_{n/2}`` of the discrete geodesic (``n`` even; default ``2**D``); keyword
    arguments go to [`solve_geodesic`][solvers.geodesic.solve.solve_geodesic]."""
    m = as_metric(metric)
    n = m.task.segments if segments is None else segments  # checked by solve_geodesic
    if isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n % 2:
        raise InputError(f"midpoint needs an even number of segments, got {n}")
    res = solve_geodesic(m, start, goal, segments, **kwargs)
    # the middle node of the returned path (with ``tol`` its size may be a doubling of n)
    return MidpointResult(point=res.points[res.segments // 2].copy(), geodesic=res)
