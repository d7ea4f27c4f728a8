"""Discrete geodesics of the task: global seeding, energy solve, min-max refinement, batches.

``solve_geodesic`` solves the task discretisation (eq. 7's energy ``sum C(p_i, p_{i+1})**2``
over ``n`` segments) from every seed of a :class:`~solvers.seeding.SeedPlan` and keeps the
lowest energy among the converged solves (selection by energy, not by length: a car-like
local minimum can hide a cheap turn in one long segment, which the energy penalises).
The seeds are solved at the plan's coarse size and only the best few distinct optima
are carried up a ladder of sizes to ``n`` (multiresolution: time about linear in ``n``).
``refine_minmax`` then minimises the largest segment cost: the exact ceiling of the
paper's task. ``tol`` refines the size until the continuum length is known to that
relative accuracy (Richardson extrapolation, :func:`richardson`).
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from finsler.errors import InputError
from finsler.files import OutputError, atomic_write_bytes
from finsler.metric import Metric
from finsler.pool import ProcessPool
from finsler.spec import MetricSpec
from solvers.batched import BatchOptions, BatchSolution, covers, residuals, solve_pairs_batched
from solvers.inputs import (
    SHORT_PAIR,
    as_metric,
    check_pairs,
    check_point,
    check_segments,
    domain_scale,
)
from solvers.newton import backend_for
from solvers.result import (
    GeodesicResult,
    MidpointResult,
    MinMaxResult,
    SolverError,
    Status,
)
from solvers.seeding import SeedPlan, graph_seeder, perturbed_curves, resample, seed_curves
from solvers.transcription import energy_nlp, minmax_nlp

__all__ = [
    "check_initial_paths",
    "check_pairs",
    "check_segments",
    "midpoint",
    "refine_minmax",
    "solve_batch",
    "solve_geodesic",
]

#: Largest size :func:`solve_geodesic` doubles to for ``tol``.
TOL_MAX_SEGMENTS = 16384
#: Order of the polyline length of a smooth geodesic: chords lose O(h**2) per unit length.
EXPECTED_ORDER = 2.0


#: Relative energy difference under which two seeds count as agreeing with the best.
AGREE_RTOL = 1e-6

#: Old private names kept for callers inside the package.
_metric = as_metric
_point = check_point


def check_initial_paths(metric: Metric, pairs: np.ndarray, n: int, paths: Any
                        ) -> np.ndarray | None:
    """Validate caller-given initial paths ``(K, m+1, dim)`` for ``pairs`` ``(K, 2, dim)``
    (one per pair, finite, in the domain, ending at the pair's start and goal) and resample
    them to ``(K, n+1, dim)``; ``None`` passes through."""
    if paths is None:
        return None
    try:
        arr = np.array(paths, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputError(f"initial_paths must be a numeric array, got "
                         f"{type(paths).__name__}") from err
    K = pairs.shape[0]
    if arr.ndim != 3 or arr.shape[0] != K or arr.shape[2] != metric.dim or arr.shape[1] < 2:
        raise InputError(f"initial_paths must have shape ({K}, m+1, {metric.dim}) (one path "
                         f"of m >= 1 segments per pair), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(arr), axis=(1, 2)))[0])
        raise InputError(f"initial_paths[{bad}] has non-finite values")
    return np.stack([_initial_path(metric, arr[k], pairs[k, 0], pairs[k, 1], n,
                                   f"initial_paths[{k}]") for k in range(K)])


def _finish(metric: Metric, points: np.ndarray) -> dict[str, Any]:
    return _finish_many(metric, points[None])[0]


def _finish_many(metric: Metric, paths: np.ndarray, residual: np.ndarray | None = None
                 ) -> list[dict[str, Any]]:
    """The reported figures of paths ``(K, n+1, dim)``, all evaluated at once: segment
    costs, energy, length, the polyline's length by adaptive quadrature with its error,
    largest segment cost, points where ``F`` is not convex (metrics not convex
    everywhere), first-order residual (``residual``: known ones, NaN where unknown)."""
    k, n1, dim = paths.shape
    costs = metric.path_costs(paths, check=False)
    # adaptive quadrature with its error, in parts whose worst case fits the memory limit
    step = max(1, QUAD_SEGMENTS // (n1 - 1))
    parts = [metric.path_length_error(paths[a:a + step], check=False)
             for a in range(0, k, step)]
    quad_value = np.concatenate([np.atleast_1d(q.value) for q in parts])
    quad_error = np.concatenate([np.atleast_1d(q.error) for q in parts])
    nonconvex = np.zeros(k, dtype=np.int64)
    if not metric.convex_everywhere:
        nonconvex = np.sum(metric.convexity(paths.reshape(-1, dim)).reshape(k, n1) < 0.0, 1)
    res = np.full(k, np.nan) if residual is None else np.asarray(residual, dtype=float)
    unknown = np.flatnonzero(~np.isfinite(res))
    if unknown.size:
        res[unknown] = residuals(metric, paths[unknown])
    columns = zip(np.sum(costs**2, 1).tolist(), np.sum(costs, 1).tolist(),
                  quad_value.tolist(), quad_error.tolist(), np.max(costs, 1).tolist(),
                  np.asarray(nonconvex).tolist(), res.tolist(), strict=True)
    return [{"segment_costs": costs[i], "energy": e, "length": length,
             "length_quadrature": qv, "length_quadrature_error": qe, "max_segment_cost": mx,
             "nonconvex_points": nc, "residual": r}
            for i, (e, length, qv, qe, mx, nc, r) in enumerate(columns)]


def _onto_domain(m: Metric, pts: np.ndarray) -> np.ndarray:
    """Project IPOPT's points into the domain: IPOPT relaxes constraints by ~1e-8
    (``bound_relax_factor``); the projection moves points by at most that much, and every
    reported figure is computed from the projected points."""
    out = np.asarray(m.domain.project(pts), dtype=np.float64)
    out[0], out[-1] = pts[0], pts[-1]
    return out


#: Endpoints of a given initial path may differ from start/goal by this much (relative to
#: the domain size; float32 paths of a learned policy), then they are replaced exactly.
INITIAL_END_RTOL = 1e-5


def _initial_path(m: Metric, path: Any, s: np.ndarray, g: np.ndarray, n: int,
                  name: str) -> np.ndarray:
    """Validate a caller-given initial path ``(k+1, dim)`` (finite, in the domain, ends at
    ``s`` and ``g``) and resample it to ``(n+1, dim)`` at equal parameter spacing (the
    given points are kept when ``k`` divides ``n``)."""
    try:
        arr = np.array(path, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise InputError(f"{name} must be a numeric array, got {type(path).__name__}") from err
    if arr.ndim != 2 or arr.shape[1] != m.dim or arr.shape[0] < 2:
        raise InputError(f"{name} must have shape (k+1, {m.dim}) with k >= 1 (here "
                         f"{n + 1} points are solved), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} has non-finite values")
    tol = INITIAL_END_RTOL * domain_scale(m)
    m.domain.check(arr, name, tol=tol)
    for end, want, which in ((arr[0], s, "start"), (arr[-1], g, "goal")):
        if np.max(np.abs(end - want)) > tol:
            raise InputError(f"{name} does not end at the pair's {which}: {end.tolist()} vs "
                             f"{want.tolist()}")
    if arr.shape[0] != n + 1:
        arr = resample(arr, np.ones(arr.shape[0] - 1), n)
    arr = np.asarray(m.domain.project(arr), dtype=np.float64)
    arr[0], arr[-1] = s, g
    return arr


@dataclasses.dataclass
class _Solve:
    """One IPOPT energy solve: the candidate's name, points ``(n+1, dim)``, status,
    iterations, energy (float64, from the projected points), whether the points lie in the
    domain."""

    name: str
    points: np.ndarray
    status: Status
    iterations: int
    energy: float
    feasible: bool
    method: str = "ipopt"

    @property
    def ok(self) -> bool:
        return self.status.converged and self.feasible and bool(np.isfinite(self.energy))

    @property
    def rank(self) -> float:
        return self.energy if self.ok else np.inf


def _solve_one(m: Metric, nlp: Any, name: str, seed: np.ndarray) -> _Solve:
    pts, status, its, _ = nlp.solve(seed)
    pts = _onto_domain(m, pts)
    feasible = bool(np.all(m.domain.contains(pts, tol=1e-9)))
    energy = float(np.sum(m.path_costs(pts[None])[0] ** 2))
    return _Solve(name, pts, status, its, energy, feasible)


def _solve_warm(m: Metric, name: str, seed: np.ndarray, fallback: bool = True) -> _Solve:
    """Solve from a nearly converged path with the warm IPOPT options; if that does not
    converge and ``fallback``, again with the default ones (iterations of both counted)."""
    n = seed.shape[0] - 1
    r = _solve_one(m, energy_nlp(m, n, warm=True), name, seed)
    if r.ok or not fallback:
        return r
    r2 = _solve_one(m, energy_nlp(m, n), name, seed)
    r2.iterations += max(r.iterations, 0)
    return r2


def _distinct(m: Metric, ranked: list[_Solve], keep: int, drop_rtol: float) -> list[_Solve]:
    """The ``keep`` lowest-energy converged solves of ``ranked``, one per optimum (paths
    within 1e-4 of the domain size of a kept one are the same optimum), none more than
    ``drop_rtol`` above the lowest energy (a clearly losing start stops here)."""
    ranked = sorted((r for r in ranked if r.ok), key=lambda r: r.energy)
    out: list[_Solve] = []
    tol = 1e-4 * domain_scale(m)
    for r in ranked:
        if len(out) >= keep or (out and r.energy > out[0].energy * (1.0 + drop_rtol)):
            break
        if any(np.max(np.abs(r.points - o.points)) <= tol for o in out):
            continue
        out.append(r)
    return out


def _ladder(m: Metric, s: np.ndarray, g: np.ndarray, n: int, plan: SeedPlan,
            given: list[tuple[str, np.ndarray]]
            ) -> tuple[list[_Solve], list[dict[str, Any]], int, int, int]:
    """Multiresolution energy stage: every seed of ``plan`` solved at the plan's coarse
    size, ``plan.restarts`` perturbed copies of the best coarse optimum added, then only
    the ``plan.refine_top`` best distinct optima carried up the ladder ``plan.ladder(n)``
    (each level warm started from the previous one by interpolation, losing candidates
    dropped at every level); caller-given paths join at the final size.

    Returns (solves at the final size, per-level summaries, seeds tried, starts (seeds and
    restarts) agreeing with the best coarse energy, total IPOPT iterations)."""
    sizes = plan.ladder(n)
    n0 = sizes[0]
    t0 = time.perf_counter()
    seeds = seed_curves(m, s, g, n0, plan)
    if plan.graph:
        gp = graph_seeder(m).path(s, g)
        if gp is not None:
            seeds.append(("graph", resample(gp[0], gp[1], n0)))
    n_seeds = len(seeds)  # the plan's seeds; caller-given paths are not counted here
    if len(sizes) == 1:
        seeds += given
    nlp = energy_nlp(m, n0)
    solved = [_solve_one(m, nlp, name, seed) for name, seed in seeds]
    if plan.restarts:
        best = min(solved, key=lambda r: r.rank)
        if best.ok:
            for k, curve in enumerate(perturbed_curves(m, best.points, plan.restarts,
                                                       plan.restart_scale, plan.seed)):
                solved.append(_solve_one(m, nlp, f"{best.name}~{k}", curve))
    total_iter = sum(max(r.iterations, 0) for r in solved)
    e0 = min((r.rank for r in solved), default=np.inf)
    agree = sum(1 for r in solved
                if r.ok and abs(r.energy - e0) <= AGREE_RTOL * max(e0, 1e-300))
    levels = [{"segments": n0, "solved": len(solved), "iterations": total_iter,
               "wall_time": time.perf_counter() - t0}]
    for k, size in enumerate(sizes[1:], start=1):
        t1 = time.perf_counter()
        keep = _distinct(m, solved, plan.refine_top, plan.drop_rtol)
        if not keep:  # nothing converged: carry the best attempts so a status comes back
            keep = sorted(solved, key=lambda r: (r.rank, r.energy))[: plan.refine_top]
        prev = sizes[k - 1]
        solved = []
        for r in keep:  # in order of energy
            name = r.name if "@" in r.name else f"{r.name}@{prev}"
            # a runner-up whose warm solve fails stops there (measured at 4096: the cold
            # re-solve of one took 450 iterations, 15 s) once a candidate has converged
            fallback = not any(x.ok for x in solved)
            solved.append(_solve_warm(m, name, resample(r.points, np.ones(prev), size),
                                      fallback))
        if k == len(sizes) - 1:
            nlp = energy_nlp(m, size)
            solved += [_solve_one(m, nlp, name, path) for name, path in given]
        its = sum(max(r.iterations, 0) for r in solved)
        total_iter += its
        levels.append({"segments": size, "solved": len(solved), "iterations": its,
                       "wall_time": time.perf_counter() - t1})
    if plan.polish:
        t1 = time.perf_counter()
        nlp = energy_nlp(m, n)
        best = min(solved, key=lambda r: r.rank)
        tries = []
        if best.ok:
            for k in range(plan.polish):
                curve = perturbed_curves(m, best.points, 1, plan.polish_scale,
                                         plan.seed + 1000 + k)[0]
                r = _solve_one(m, nlp, f"{best.name.split('~')[0]}~p{k}", curve)
                tries.append(r)
                if r.rank < best.energy * (1.0 - 1e-12):
                    best = r
        solved += tries
        its = sum(max(r.iterations, 0) for r in tries)
        total_iter += its
        levels.append({"segments": n, "solved": len(tries), "iterations": its,
                       "wall_time": time.perf_counter() - t1, "polish": True})
    return solved, levels, n_seeds, agree, total_iter


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
    :meth:`SeedPlan.default`) plus the given ``initial`` paths ``(m+1, dim)`` (e.g. a
    learned path or an exact path of another size; resampled to ``n + 1`` points at equal
    parameter spacing when ``m != n``); with ``global_seeds=False`` only the ``initial``
    paths are solved (a warm start: no seed plan, no graph); returns the lowest energy
    among IPOPT-converged solves, with
    ``seeds_tried`` / ``seeds_agreeing``. With ``minmax=True`` the min-max refinement is
    attached (``result.minmax``). ``strict=True`` raises :class:`SolverError` unless
    converged.

    ``tol`` (relative, e.g. ``1e-7``): accuracy on request. The size is doubled from ``n``
    (each size warm started from the previous path) until the estimated error of the
    continuum length is below ``tol * length`` or ``max_segments`` is reached; the result
    then carries ``length_estimate`` (Richardson extrapolation of the eq. (58) polyline
    lengths when their order 2 is observed, else the finest length), ``error_estimate``
    (absolute), ``order`` (observed) / ``order_seen`` and ``tol_levels``; min-max runs at
    the final size.

    ``method``: ``"auto"`` (default) solves with the batched Newton method of
    :mod:`solvers.batched` where it covers the metric (``F`` smooth), IPOPT otherwise;
    ``"newton"`` / ``"ipopt"`` ask for one. IPOPT also finishes what the Newton method
    cannot (an active domain constraint, a stall); ``result.method`` says which produced
    the path and ``result.residual`` its first-order optimality residual. ``device``: a
    torch device for the Newton method (``"cuda"``; default numpy on the CPU).
    """
    t0 = time.perf_counter()
    m = _metric(metric)
    n = check_segments(m, segments)
    how = resolve_method(m, method)
    if tol is not None:
        return _solve_to_tol(m, start, goal, n, tol, max_segments, t0, seeds=seeds,
                             initial=initial, global_seeds=global_seeds, minmax=minmax,
                             strict=strict, method=how, device=device)
    s = _point(m, start, "start")
    g = _point(m, goal, "goal")
    plan = seeds if seeds is not None else SeedPlan.default(m, how)
    if not isinstance(plan, SeedPlan):
        raise InputError(f"seeds must be a SeedPlan, got {type(plan).__name__}")
    given = [(f"initial{k}", _initial_path(m, init, s, g, n, f"initial path {k}"))
             for k, init in enumerate(initial)]
    if not global_seeds and not given:
        raise InputError("global_seeds=False needs at least one initial path")
    res = _solve_pairs(m, np.stack([s, g])[None], n, plan, [given], bool(global_seeds), how,
                       device, minmax)[0]
    res.wall_time = time.perf_counter() - t0
    if strict and not (res.converged and (res.minmax is None or res.minmax.converged)):
        raise SolverError(
            f"{m.name}: solve did not converge (status {res.status.label}"
            + (f", min-max {res.minmax.status.label}" if res.minmax is not None else "")
            + ")",
            res,
        )
    return res


def resolve_method(m: Metric, method: Any) -> str:
    """``"newton"`` or ``"ipopt"`` for ``method`` (``"auto"``: Newton where it covers the
    metric, :func:`solvers.batched.covers`)."""
    if method not in ("auto", "newton", "ipopt"):
        raise InputError(f"method must be 'auto', 'newton' or 'ipopt', got {method!r}")
    if method == "auto":
        return "newton" if covers(m) else "ipopt"
    if method == "newton" and not covers(m):
        raise InputError(f"{m.name}: the Newton method needs a smooth F (the metric declares "
                         "smooth = False); use method='ipopt' or 'auto'")
    return method


def _short_result(m: Metric, s: np.ndarray, g: np.ndarray, n: int, minmax: bool
                  ) -> GeodesicResult:
    same = np.array_equal(s, g)
    pts = s + np.linspace(0.0, 1.0, n + 1)[:, None] * (g - s)
    pts[-1] = g
    st = Status.TRIVIAL if same else Status.SHORT
    res = GeodesicResult(metric=m.name, points=pts, status=st, iterations=0, wall_time=0.0,
                         seeds_tried=0, seeds_agreeing=0, method="none", **_finish(m, pts))
    if minmax:
        res.minmax = MinMaxResult(pts, res.segment_costs, res.max_segment_cost, st, 0, 0.0,
                                  False)
    return res


def _solve_pairs(m: Metric, pairs: np.ndarray, n: int, plan: SeedPlan,
                 given: list[list[tuple[str, np.ndarray]]], global_seeds: bool, method: str,
                 device: Any, minmax: bool, warm: bool = False,
                 options: BatchOptions | None = None) -> list[GeodesicResult]:
    """Results for ``pairs`` ``(K, 2, dim)`` (validated, in the domain): short pairs as
    straight segments, the others by the batched Newton method (IPOPT finishing what it
    cannot) or by IPOPT alone; ``warm``: the given paths are nearly converged (IPOPT's warm
    options)."""
    t0 = time.perf_counter()
    K = pairs.shape[0]
    out: list[GeodesicResult | None] = [None] * K
    short = np.max(np.abs(pairs[:, 1] - pairs[:, 0]), axis=1) <= SHORT_PAIR * domain_scale(m)
    long_ = [int(k) for k in np.flatnonzero(~short)]
    for k in np.flatnonzero(short):
        out[k] = _short_result(m, pairs[k, 0], pairs[k, 1], n, minmax)
    if long_ and method == "newton":
        opts = options or BatchOptions(device=device)
        sol = solve_pairs_batched(m, pairs[long_], n, plan, opts, [given[k] for k in long_],
                                  global_seeds)
        for k, r in zip(long_, _from_batch(m, sol, global_seeds), strict=True):
            out[k] = r
    elif long_:
        for k in long_:
            out[k] = _solve_ipopt(m, pairs[k, 0], pairs[k, 1], n, plan, given[k],
                                  global_seeds, warm)
    share = (time.perf_counter() - t0) / max(len(long_), 1)
    for k in long_:
        out[k].wall_time = share
    res = [r for r in out if r is not None]
    if minmax:
        for r in res:
            if r.minmax is None:
                r.minmax = refine_minmax(m, r)
    return res


def _from_batch(m: Metric, sol: BatchSolution, global_seeds: bool
                ) -> list[GeodesicResult]:
    """The results of a batch's pairs: per pair the lowest energy among its Newton-
    converged rows; rows the Newton method could not finish (an active domain constraint,
    a stall, the iteration cap) are finished by IPOPT when they could be lower than that
    (or when none converged), from the three lowest. Figures computed for all pairs at
    once."""
    rows = sol.final
    K = len(sol.best)
    ok = rows.ok
    per = sol.rows_of()
    best_ok = np.full(K, np.inf)
    np.minimum.at(best_ok, rows.pair[ok], rows.energy[ok])
    lower = ~ok & np.isfinite(rows.energy) & (rows.energy < best_ok[rows.pair])
    needs = np.zeros(K, bool)
    needs[rows.pair[lower]] = True
    needs |= ~np.isfinite(best_ok)
    picked: list[_Solve | None] = [None] * K
    extra: list[list[_Solve]] = [[] for _ in range(K)]
    ipopt_its = np.zeros(K, dtype=np.int64)
    for k in np.flatnonzero(needs):
        mine = per[k]
        cand = mine[lower[mine]] if lower[mine].any() else mine
        cand = cand[np.argsort(rows.energy[cand])][:3]
        for i in cand:
            r = _solve_warm(m, rows.names[i], _onto_domain(m, rows.points[i]))
            ipopt_its[k] += max(r.iterations, 0)
            extra[k].append(r)
        pool = ([r for r in extra[k] if r.ok and r.energy < best_ok[k]]
                or ([] if np.isfinite(best_ok[k]) else
                    [r for r in extra[k] if r.feasible and np.isfinite(r.energy)] or extra[k]))
        if pool:
            picked[k] = min(pool, key=lambda r: r.energy)
    # the Newton answers: their points are in the domain up to 1e-12 of its size
    newton = [k for k in range(K) if picked[k] is None]
    if newton:
        idx = sol.best[newton]
        pts = np.asarray(m.domain.project(rows.points[idx].reshape(-1, m.dim)),
                         dtype=np.float64).reshape(len(newton), -1, m.dim)
        pts[:, 0], pts[:, -1] = rows.points[idx, 0], rows.points[idx, -1]
        for j, k in enumerate(newton):
            i = idx[j]
            picked[k] = _Solve(rows.names[i], pts[j], Status.SUCCESS if ok[i] else
                               Status.MAX_ITERATIONS, int(rows.iterations[i]),
                               float(rows.energy[i]), True, "newton")
    # the Newton method's residual is the same measure (at points in the domain to 1e-12)
    known = np.full(K, np.nan)
    if newton:
        known[newton] = rows.residual[sol.best[newton]]
    figures = _finish_many(m, np.stack([picked[k].points for k in range(K)]), known)
    out = []
    for k in range(K):
        best = picked[k]
        energies = {rows.names[i]: (float(rows.energy[i]) if ok[i] else float("nan"))
                    for i in per[k]}
        energies.update({r.name + ("~ipopt" if r.name in energies else ""):
                         (r.energy if r.status.converged else float("nan")) for r in extra[k]})
        agree = int(sol.seeds_agreeing[k])
        if not global_seeds:
            agree = sum(1 for e in energies.values() if np.isfinite(e) and abs(
                e - best.energy) <= AGREE_RTOL * max(best.energy, 1e-300))
        out.append(GeodesicResult(
            metric=m.name,
            points=best.points,
            status=best.status,
            iterations=int(sol.iterations[k] + ipopt_its[k]),
            wall_time=0.0,
            seeds_tried=int(sol.seeds_tried[k]),
            seeds_agreeing=agree,
            seed_energies=energies,
            best_seed=best.name,
            levels=sol.levels_of(k),
            method=best.method,
            **figures[k],
        ))
    return out


def _solve_ipopt(m: Metric, s: np.ndarray, g: np.ndarray, n: int, plan: SeedPlan,
                 given: list[tuple[str, np.ndarray]], global_seeds: bool, warm: bool
                 ) -> GeodesicResult:
    """One pair by IPOPT alone: the seed plan's ladder (:func:`_ladder`), or only the given
    paths (``global_seeds=False``; ``warm``: nearly converged, IPOPT's warm options)."""
    if global_seeds:
        solved, levels, n_seeds, agree, total_iter = _ladder(m, s, g, n, plan, given)
    else:
        solved, levels, total_iter = [], [], 0
        nlp = energy_nlp(m, n)
        for name, seed in given:
            solved.append(_solve_warm(m, name, seed) if warm
                          else _solve_one(m, nlp, name, seed))
            total_iter += max(solved[-1].iterations, 0)
        n_seeds, agree = len(given), 0
    ok = [r for r in solved if r.ok]
    pool = ok or [r for r in solved if r.feasible and np.isfinite(r.energy)] or solved
    best = min(pool, key=lambda r: r.energy)
    if not global_seeds:
        agree = sum(1 for r in ok if abs(r.energy - best.energy)
                    <= AGREE_RTOL * max(best.energy, 1e-300))
    return GeodesicResult(
        metric=m.name,
        points=best.points,
        status=best.status,
        iterations=total_iter,
        wall_time=0.0,
        seeds_tried=n_seeds,
        seeds_agreeing=agree,
        seed_energies={r.name: (r.energy if r.status.converged else float("nan"))
                       for r in solved},
        best_seed=best.name,
        levels=levels,
        method="ipopt",
        **_finish(m, best.points),
    )


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
    """:func:`richardson` over the sizes solved so far; through non-convex regions of ``F``
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


def _solve_to_tol(m: Metric, start: Any, goal: Any, n: int, tol: Any, max_segments: Any,
                  t0: float, *, minmax: bool, strict: bool, method: str, device: Any,
                  **kw: Any) -> GeodesicResult:
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not (
            np.isfinite(tol) and 0 < tol < 1):
        raise InputError(f"tol must be a relative tolerance in (0, 1), got {tol!r}")
    if isinstance(max_segments, bool) or not isinstance(max_segments, (int, np.integer)) \
            or max_segments < n:
        raise InputError(f"max_segments must be an integer >= segments ({n}), got "
                         f"{max_segments!r}")
    check_segments(m, int(max_segments))
    s = _point(m, start, "start")
    g = _point(m, goal, "goal")
    res = first = solve_geodesic(m, s, g, n, method=method, device=device, **kw)
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
        res = _solve_pairs(m, np.stack([s, g])[None], nxt, SeedPlan.default(m, method), [warm],
                           False, method, device, False, warm=True)[0]
        iterations += res.iterations
    # the seeding happened at the first size; later sizes are warm starts of its winner
    res.seeds_tried, res.seeds_agreeing = first.seeds_tried, first.seeds_agreeing
    res.seed_energies, res.best_seed = first.seed_energies, first.best_seed
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
        res.minmax = refine_minmax(m, res)
    res.wall_time = time.perf_counter() - t0
    if strict and not (res.converged and res.tol_reached
                       and (res.minmax is None or res.minmax.converged)):
        raise SolverError(f"{m.name}: tol {tol:g} not reached (estimate "
                          f"{res.error_estimate:.3e} at {res.segments} segments, status "
                          f"{res.status.label})", res)
    return res


def refine_minmax(metric: Metric | str, result: GeodesicResult) -> MinMaxResult:
    """Minimise the largest segment cost, warm started from ``result`` (epigraph form, cap
    on the max just above its starting value, relaxed if IPOPT finds that infeasible).

    The returned points are the refined ones if they lie in the domain and lower the max,
    else the starting points (the status then tells why); costs are recomputed in float64.
    """
    t0 = time.perf_counter()
    m = _metric(metric)
    if result.status in (Status.TRIVIAL, Status.SHORT):
        return MinMaxResult(result.points, result.segment_costs, result.max_segment_cost,
                            result.status, 0, 0.0, False)
    n = result.segments
    nlp = minmax_nlp(m, n)
    pts, status, its, relaxed = nlp.solve(result.points, result.max_segment_cost)
    pts = _onto_domain(m, pts)
    costs = m.path_costs(pts[None])[0]
    feasible = bool(np.all(m.domain.contains(pts, tol=1e-9))) and np.all(np.isfinite(costs))
    if not feasible or float(np.max(costs)) > result.max_segment_cost:
        pts, costs = result.points, result.segment_costs
    return MinMaxResult(
        points=pts,
        segment_costs=costs,
        max_segment_cost=float(np.max(costs)),
        status=status,
        iterations=its,
        wall_time=time.perf_counter() - t0,
        cap_relaxed=relaxed,
    )


def midpoint(
    metric: Metric | str,
    start: Any,
    goal: Any,
    segments: int | None = None,
    **kwargs: Any,
) -> MidpointResult:
    """Midpoint ``p_{n/2}`` of the discrete geodesic (``n`` even; default ``2**D``); keyword
    arguments go to :func:`solve_geodesic`."""
    m = _metric(metric)
    n = check_segments(m, segments)
    if n % 2:
        raise InputError(f"midpoint needs an even number of segments, got {n}")
    res = solve_geodesic(m, start, goal, n, **kwargs)
    return MidpointResult(point=res.points[n // 2].copy(), geodesic=res)


# ----------------------------------------------------------------------------------------
# batches
# ----------------------------------------------------------------------------------------
def _metric_spec(m: Metric) -> MetricSpec:
    """What a worker process rebuilds the metric from (finsler's identity of a metric)."""
    return MetricSpec.of(m)


def _chunk_worker(args: tuple) -> list[tuple[int, GeodesicResult]]:
    """Solve one chunk of pairs in a worker process or Ray task: ``args`` = (metric spec,
    pair indices, pairs ``(k, 2, dim)``, segments, plan, minmax, initial paths or None,
    global_seeds, tol, method, device) -> ``[(index, result)]``."""
    spec, ks, pairs, n, plan, minmax, inits, global_seeds, tol, method, device = args
    m = _cached_metric(spec)
    return _solve_chunk(m, ks, pairs, n, plan, minmax, inits, global_seeds, tol, method,
                        device)


def _solve_chunk(m: Metric, ks: Sequence[int], pairs: np.ndarray, n: int, plan: SeedPlan,
                 minmax: bool, inits: np.ndarray | None, global_seeds: bool,
                 tol: float | None, method: str, device: Any
                 ) -> list[tuple[int, GeodesicResult]]:
    """The pairs of a chunk: one batched solve (each pair refined on its own with
    ``tol``)."""
    if tol is not None:
        return [(k, solve_geodesic(m, p[0], p[1], n, seeds=plan, minmax=minmax,
                                   initial=() if inits is None else (inits[i],),
                                   global_seeds=global_seeds, tol=tol, method=method,
                                   device=device))
                for i, (k, p) in enumerate(zip(ks, pairs, strict=True))]
    given = [[] if inits is None else [("initial0", inits[i])] for i in range(len(ks))]
    res = _solve_pairs(m, np.asarray(pairs), n, plan, given, global_seeds, method, device,
                       minmax)
    return list(zip(ks, res, strict=True))


_METRICS: dict[MetricSpec, Metric] = {}


def _cached_metric(spec: MetricSpec) -> Metric:
    if spec not in _METRICS:
        _METRICS[spec] = spec.build()
    return _METRICS[spec]


#: Rows (pair x seed problems) per batched Newton solve of :func:`solve_batch`: enough
#: that array operations dominate Python overhead (measured with ``benchmarks/peers.py
#: --throughput``: Randers, 3 seeds per pair, 0.53 / 0.35 / 0.27 ms per pair with 192 /
#: 384 / 1536 rows); the pairs of a chunk are saved together.
NEWTON_ROWS = 16384
#: Segments per call of the adaptive quadrature of the reported lengths (its worst-case
#: memory is checked against the limit).
QUAD_SEGMENTS = 4096


def _chunk_pairs(plan: SeedPlan, global_seeds: bool) -> int:
    """Pairs per batched chunk: :data:`NEWTON_ROWS` over the plan's seeds per pair."""
    seeds = (1 + 2 * len(plan.bulges) + plan.random + int(plan.graph) + plan.restarts
             if global_seeds else 1)
    return int(np.clip(NEWTON_ROWS // max(seeds, 1), 16, 4096))
#: ``solve_batch`` with the Newton method uses worker processes by default only from this
#: many pairs on (starting a process costs seconds of imports).
NEWTON_POOL_MIN = 1024


class _BatchStore:
    """Per-pair result files of a resumable :func:`solve_batch` (pickle, atomic rename)."""

    def __init__(self, folder: Any, metric: Metric, n: int, plan: SeedPlan, minmax: bool,
                 global_seeds: bool = True, tol: float | None = None):
        import pathlib

        self.folder = pathlib.Path(folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f"cannot create the folder of resumable parts {self.folder}: "
                              f"{err.strerror}") from err
        self.key = (repr(metric), int(n), repr(plan), bool(minmax), bool(global_seeds),
                    None if tol is None else float(tol))

    def _path(self, k: int) -> Any:
        return self.folder / f"pair_{k:07d}.pkl"

    def load(self, k: int, pair: np.ndarray, init: np.ndarray | None = None
             ) -> GeodesicResult | None:
        """The saved result of pair ``k`` if it was solved from the same pair ``(2, dim)``
        and initial path (``None``: none), else ``None``."""
        import pickle

        path = self._path(k)
        if not path.is_file():
            return None
        try:
            with path.open("rb") as fh:
                key, saved_pair, saved_init, result = pickle.load(fh)
        except Exception:  # a corrupt or foreign file is recomputed, never trusted
            return None
        if key != self.key or not np.array_equal(saved_pair, pair):
            return None
        if (saved_init is None) != (init is None) or (
                init is not None and not np.array_equal(saved_init, init)):
            return None
        return result

    def save(self, k: int, pair: np.ndarray, result: GeodesicResult,
             init: np.ndarray | None = None) -> None:
        import pickle

        saved_init = None if init is None else np.array(init)
        atomic_write_bytes(self._path(k), pickle.dumps((self.key, np.array(pair), saved_init,
                                                        result)), "resumable part")


def solve_batch(
    metric: Metric | str,
    pairs: Any,
    segments: int | None = None,
    *,
    seeds: SeedPlan | None = None,
    minmax: bool = False,
    workers: int | None = None,
    progress: bool = True,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    ray_address: str | None = None,
    chunk_size: int | None = None,
    initial_paths: Any = None,
    global_seeds: bool = True,
    tol: float | None = None,
    method: str = "auto",
    device: Any = None,
) -> list[GeodesicResult]:
    """Solve every pair of ``pairs`` ``(K, 2, dim)``; results in the order of the pairs.

    ``workers`` processes (default: the CPU count, at most ``K``; ``1`` runs in this
    process); each worker builds the NLP once and reuses it for all its pairs. A tqdm bar
    shows progress unless ``progress=False``. Same inputs give the same results.

    With ``checkpoint_dir``, every finished pair is saved there at once (written, then
    renamed), and a rerun with the same pairs, segments, seeds and ``minmax`` reuses
    them: an interrupted batch resumes without losing finished work. Files saved for
    other inputs are ignored and recomputed.

    With ``ray_address`` (``"local"`` starts a local Ray instance of ``workers`` CPUs;
    ``"auto"`` or ``"HOST:6379"`` joins a running cluster) the pairs are solved as Ray
    tasks of ``chunk_size`` pairs (default: about four chunks per CPU of the cluster, at
    most 64 pairs) by :mod:`solvers.distributed`; every finished chunk's pairs are saved
    as the same parts as above, and the results equal the local ones.

    ``initial_paths`` ``(K, m+1, dim)``: one caller-given initial path per pair (e.g. a
    learned policy's paths, or exact paths of another size ``m``: resampled to ``n + 1``
    points), solved as ``solve_geodesic(initial=[path])``. With ``global_seeds=False`` only
    that path is solved (the fast warm-start mode: a good path converges in a few IPOPT
    iterations); with ``True`` the global seeds are solved too and the lowest energy kept.
    ``tol``: every pair solved to that relative accuracy of its length
    (:func:`solve_geodesic`).

    ``method`` / ``device``: as in :func:`solve_geodesic`. With the batched Newton method
    (the default where it covers the metric) the pairs are solved in chunks of about
    :data:`NEWTON_ROWS` (pair, seed) problems, every problem of a chunk in one batch; the
    default ``workers`` is then 1 below :data:`NEWTON_POOL_MIN` pairs (the batch is
    vectorised; processes pay off only for many chunks), else the CPU count.
    """
    from tqdm.auto import tqdm

    m = _metric(metric)
    arr = check_pairs(m, pairs)
    n = check_segments(m, segments)
    how = resolve_method(m, method)
    if device is not None:
        backend_for(device)  # a bad device fails here, before any work
    plan = seeds if seeds is not None else SeedPlan.default(m, how)
    if not isinstance(plan, SeedPlan):
        raise InputError(f"seeds must be a SeedPlan, got {type(plan).__name__}")
    if workers is None:
        workers = os.cpu_count() or 1
        if how == "newton" and arr.shape[0] < NEWTON_POOL_MIN:
            workers = 1
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    if chunk_size is not None and (isinstance(chunk_size, bool)
                                   or not isinstance(chunk_size, (int, np.integer))
                                   or chunk_size < 1):
        raise InputError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    if ray_address is not None:
        from finsler.cluster import probe_address, require_ray

        require_ray()  # before any file is made
        probe_address(ray_address)  # a wrong address fails in seconds
    if not isinstance(global_seeds, (bool, np.bool_)):
        raise InputError(f"global_seeds must be True or False, got {global_seeds!r}")
    inits = check_initial_paths(m, arr, n, initial_paths)
    if not global_seeds and inits is None:
        raise InputError("global_seeds=False needs initial_paths (one path per pair)")
    if tol is not None and (isinstance(tol, bool) or not isinstance(tol, (int, float))
                            or not (np.isfinite(tol) and 0 < tol < 1)):
        raise InputError(f"tol must be a relative tolerance in (0, 1), got {tol!r}")
    store = (_BatchStore(checkpoint_dir, m, n, plan, minmax, bool(global_seeds), tol)
             if checkpoint_dir else None)
    results: list[GeodesicResult | None] = [None] * arr.shape[0]

    def init_of(k: int) -> np.ndarray | None:
        return None if inits is None else inits[k]

    if store is not None:
        for k in range(arr.shape[0]):
            results[k] = store.load(k, arr[k], init_of(k))
    todo = [k for k in range(arr.shape[0]) if results[k] is None]
    size = 1
    if how == "newton":
        size = _chunk_pairs(plan, bool(global_seeds))
        if workers > 1:  # several chunks per worker: balanced, and finished work is kept
            size = max(1, min(size, -(-len(todo) // (4 * workers))))
    chunks = [todo[i:i + size] for i in range(0, len(todo), size)]
    workers = int(min(workers, max(len(chunks), 1)))
    spec = _metric_spec(m)

    def job(ks: list[int]) -> tuple:
        return (spec, ks, arr[ks], n, plan, minmax, None if inits is None else inits[ks],
                bool(global_seeds), tol, how, device)

    bar = tqdm(total=arr.shape[0], desc=f"solve {m.name}", disable=not progress, unit="pair",
               initial=arr.shape[0] - len(todo))

    def take(done: list[tuple[int, GeodesicResult]]) -> None:
        for k, res in done:
            results[k] = res
            if store is not None:
                store.save(k, arr[k], res, init_of(k))
        bar.update(len(done))

    try:
        if ray_address is not None and todo:
            from solvers.distributed import solve_chunks_ray

            local_cpus = int(min(workers, len(todo)))
            for done in solve_chunks_ray(ray_address, _chunk_worker, job, todo,
                                         chunk_size, num_cpus=local_cpus):
                take(done)
        elif workers == 1 or len(chunks) <= 1:
            for ks in chunks:
                take(_solve_chunk(m, ks, arr[ks], n, plan, minmax,
                                  None if inits is None else inits[ks], bool(global_seeds),
                                  tol, how, device))
        else:
            with ProcessPool(workers) as pool:
                for done in pool.map_unordered(_chunk_worker, [job(ks) for ks in chunks]):
                    take(done)
    finally:
        bar.close()
    return [r for r in results if r is not None]
