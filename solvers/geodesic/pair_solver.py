"""The solve of validated (start, goal) pairs behind `solve_geodesic`
and `solve_batch`: seeds, solver, selection, reported figures.

`solve_pairs` takes pairs already checked against the metric's domain: short pairs
become straight segments, the others are solved by the batched Newton method
(`solvers.newton.driver`; IPOPT finishes the rows it cannot) or by IPOPT alone from every
seed of a `SeedPlan` (the multiresolution ladder,
`_ladder`), and per pair the lowest energy among the converged solves is kept
(selection by energy, not by length: a car-like local minimum can hide a cheap turn in
one long segment, which the energy penalises). Every result's figures (length by
quadrature with its error, largest segment cost, residual) are computed here, and
`refine_minmax` minimises the largest segment cost: the exact ceiling of the
paper's task. `solve_pair` is one pair's solve without ``tol`` or ``strict``.

Input is checked once, at the public boundary (`solve_geodesic`,
`solve_batch`, `refine_minmax`); the functions here take the
checked objects (a `Metric`, float64 points in the domain, a checked size)
and do not check them again.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from finsler.domains import as_real
from finsler.errors import InputError, short
from finsler.metrics.base import Metric
from solvers.geodesic.request import SolveRequest
from solvers.inputs import SHORT_PAIR, as_metric, domain_scale
from solvers.newton.driver import (
    BatchOptions,
    BatchSolution,
    covers,
    covers_opt_in,
    solve_pairs_batched,
)
from solvers.newton.kkt import optimality_residual
from solvers.result import GeodesicResult, MinMaxResult, Status
from solvers.seeding.plans import (
    SeedPlan,
    alternative_gap,
    family_stats,
    graph_seeds,
    perturbed_curves,
    resample,
    seed_curves,
    warped_batch,
)
from solvers.transcription import energy_nlp, minmax_nlp

__all__ = [
    "check_initial_paths",
    "refine_checked_minmax",
    "refine_minmax",
    "resolve_method",
    "solve_pair",
    "solve_pairs",
]

#: Relative energy difference under which two seeds count as agreeing with the best.
AGREE_RTOL = 1e-6


def check_initial_paths(metric: Metric, pairs: np.ndarray, n: int, paths: Any
                        ) -> np.ndarray | None:
    """Validate caller-given initial paths ``(K, m+1, dim)`` for ``pairs`` ``(K, 2, dim)``
    (one per pair, finite, in the domain, ending at the pair's start and goal) and resample
    them to ``(K, n+1, dim)``; ``None`` passes through."""
    if paths is None:
        return None
    arr = np.array(as_real(paths, "initial_paths",
                           f"a real numeric array of shape (K, m+1, {metric.dim})"))
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
    everywhere), optimality residual (`solvers.newton.kkt.optimality_residual`: the
    KKT residual where ``F`` is not smooth; ``residual``: known ones, NaN where unknown)."""
    k, n1, dim = paths.shape
    costs = metric.path_costs(paths, check=False)
    # adaptive quadrature with its error (in parts that fit the memory limit)
    quad = metric.path_length_error(paths, check=False)
    quad_value, quad_error = np.atleast_1d(quad.value), np.atleast_1d(quad.error)
    nonconvex = np.zeros(k, dtype=np.int64)
    if not metric.convex_everywhere:
        nonconvex = np.sum(metric.convexity(paths.reshape(-1, dim)).reshape(k, n1) < 0.0, 1)
    res = np.full(k, np.nan) if residual is None else np.asarray(residual, dtype=float)
    unknown = np.flatnonzero(~np.isfinite(res))
    if unknown.size:
        res[unknown] = optimality_residual(metric, paths[unknown], domain_scale(metric))
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
    return _onto_domain_many(m, np.asarray(pts)[None])[0]


def _onto_domain_many(m: Metric, paths: np.ndarray) -> np.ndarray:
    """`_onto_domain` for paths ``(B, n+1, dim)`` in one call of the projection (the
    batched methods' points are in the domain up to 1e-12 of its size)."""
    out = np.asarray(m.domain.project(paths.reshape(-1, m.dim)),
                     dtype=np.float64).reshape(paths.shape)
    out[:, 0], out[:, -1] = paths[:, 0], paths[:, -1]
    return out


#: Endpoints of a given initial path may differ from start/goal by this much (relative to
#: the domain size; float32 paths of a learned policy), then they are replaced exactly.
INITIAL_END_RTOL = 1e-5


def _initial_path(m: Metric, path: Any, s: np.ndarray, g: np.ndarray, n: int,
                  name: str) -> np.ndarray:
    """Validate a caller-given initial path ``(k+1, dim)`` (finite, in the domain, ends at
    ``s`` and ``g``) and resample it to ``(n+1, dim)`` at equal parameter spacing (the
    given points are kept when ``k`` divides ``n``)."""
    arr = np.array(as_real(path, name, f"a real numeric array of shape (k+1, {m.dim})"))
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


def _ladder(req: SolveRequest, s: np.ndarray, g: np.ndarray,
            given: list[tuple[str, np.ndarray]]
            ) -> tuple[list[_Solve], list[dict[str, Any]], int, int, int, list[_Solve]]:
    """Multiresolution energy stage: every seed of ``plan`` solved at the plan's coarse
    size, ``plan.restarts`` perturbed copies of the best coarse optimum added, then only
    the ``plan.refine_top`` best distinct optima carried up the ladder ``plan.ladder(n)``
    (each level warm started from the previous one by interpolation, losing candidates
    dropped at every level); caller-given paths join at the final size.

    Returns (solves at the final size, per-level summaries, seeds tried, starts (seeds and
    restarts) agreeing with the best coarse energy, total IPOPT iterations, the solves
    from the seeds at the first size)."""
    m, n, plan = req.metric, req.segments, req.plan
    sizes = plan.ladder(n)
    n0 = sizes[0]
    t0 = time.perf_counter()
    seeds = seed_curves(m, s, g, n0, plan)
    seeds += graph_seeds(m, s[None], g[None], n0, plan)[0]
    n_seeds = len(seeds)  # the plan's seeds; caller-given paths are not counted here
    if len(sizes) == 1:
        seeds += given
    nlp = energy_nlp(m, n0)
    solved = [_solve_one(m, nlp, name, seed) for name, seed in seeds]
    # restarts and polish perturb the best of the plan's own solves: a caller-given path (a
    # learned warm start) is one more candidate and changes nothing they do
    given_names = {name for name, _ in given}

    def plan_best(rows: list[_Solve]) -> _Solve | None:
        return min((r for r in rows if r.name not in given_names), key=lambda r: r.rank,
                   default=None)

    if plan.restarts:
        best = plan_best(solved)
        if best is not None and best.ok:
            for k, curve in enumerate(perturbed_curves(m, best.points, plan.restarts,
                                                       plan.restart_scale, plan.seed)):
                solved.append(_solve_one(m, nlp, f"{best.name}~{k}", curve))
    total_iter = sum(max(r.iterations, 0) for r in solved)
    first = list(solved)
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
        best = plan_best(solved)
        tries = []
        if best is not None and best.ok:
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
    return solved, levels, n_seeds, agree, total_iter, first


def resolve_method(m: Metric, method: Any) -> str:
    """``"newton"`` or ``"ipopt"`` for ``method`` (``"auto"``: Newton where it covers the
    metric, `solvers.newton.driver.covers`; ``"newton"`` also for a metric that is not
    smooth but provides ``smooth_square_sx``, `solvers.newton.driver.covers_opt_in`)."""
    if method not in ("auto", "newton", "ipopt"):
        raise InputError(f"method must be 'auto', 'newton' or 'ipopt', got "
                         f"{short(repr(method), 80)}")
    if method == "auto":
        return "newton" if covers(m) else "ipopt"
    if method == "newton" and not covers_opt_in(m):
        raise InputError(f"{m.name}: the Newton method needs a smooth F or the "
                         "smooth_square_sx hook (the metric declares smooth = False without "
                         "it); use method='ipopt' or 'auto'")
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


def solve_pairs(req: SolveRequest, pairs: np.ndarray,
                given: list[list[tuple[str, np.ndarray]]],
                options: BatchOptions | None = None) -> list[GeodesicResult]:
    """Results for ``pairs`` ``(K, 2, dim)`` (validated, in the domain) as ``req`` asks:
    short pairs as straight segments, the others by the batched Newton method (IPOPT
    finishing what it cannot) or by IPOPT alone. ``given``: per pair, caller-given paths
    at the request's size (names, ``(n+1, dim)``); ``options``: the Newton batch's
    settings (default: on the request's device)."""
    t0 = time.perf_counter()
    m, n, minmax = req.metric, req.segments, req.minmax
    K = pairs.shape[0]
    out: list[GeodesicResult | None] = [None] * K
    short = np.max(np.abs(pairs[:, 1] - pairs[:, 0]), axis=1) <= SHORT_PAIR * domain_scale(m)
    long_ = [int(k) for k in np.flatnonzero(~short)]
    for k in np.flatnonzero(short):
        out[k] = _short_result(m, pairs[k, 0], pairs[k, 1], n, minmax)
    if long_ and req.method == "newton":
        opts = options or BatchOptions(device=req.device)
        sol = solve_pairs_batched(m, pairs[long_], n, req.plan, opts,
                                  [given[k] for k in long_], req.global_seeds)
        for k, r in zip(long_, _from_batch(m, sol, req.global_seeds), strict=True):
            out[k] = r
    elif long_:
        ladders = [_ipopt_solves(req, pairs[k, 0], pairs[k, 1], given[k]) for k in long_]
        for k, lad in zip(long_, ladders, strict=True):
            out[k] = _ipopt_result(m, lad)
    share = (time.perf_counter() - t0) / max(len(long_), 1)
    for k in long_:
        out[k].wall_time = share
    res = [r for r in out if r is not None]
    if minmax:
        for r in res:
            if r.minmax is None:
                r.minmax = refine_checked_minmax(m, r)
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
        pts = _onto_domain_many(m, rows.points[idx])
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
        fam: dict[str, dict[str, Any]] = {}
        if sol.first is not None:
            mine0 = np.flatnonzero(sol.first.pair == k)
            fam = family_stats([sol.first.names[i] for i in mine0], sol.first.energy[mine0],
                               sol.first.ok[mine0], energies, AGREE_RTOL)
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
            seed_families=fam,
            alternative_gap=alternative_gap(energies, best.energy, AGREE_RTOL),
            **figures[k],
        ))
    return out


@dataclasses.dataclass
class _Ladder:
    """One pair's solves before its result is assembled (`_ipopt_solves`): every solve,
    the per-level summaries, seeds tried, seeds agreeing, total iterations, the solves
    from the seeds (first size), the chosen one and the best of the plan's own solves
    (``own``: caller-given paths excluded; the base of the warps, so that a learned warm
    start changes nothing the plan does)."""

    solved: list[_Solve]
    levels: list[dict[str, Any]]
    n_seeds: int
    agree: int
    total_iter: int
    first: list[_Solve]
    best: _Solve
    own: _Solve | None = None


def _ipopt_solves(req: SolveRequest, s: np.ndarray, g: np.ndarray,
                  given: list[tuple[str, np.ndarray]]) -> _Ladder:
    """One pair by IPOPT: the seed plan's ladder (`_ladder`), or only the given
    paths (``global_seeds=False``; ``warm``: nearly converged, IPOPT's warm options)."""
    m, n, plan, global_seeds = req.metric, req.segments, req.plan, req.global_seeds
    if global_seeds:
        solved, levels, n_seeds, agree, total_iter, first = _ladder(req, s, g, given)
    else:
        solved, levels, total_iter, first = [], [], 0, []
        nlp = energy_nlp(m, n)
        for name, seed in given:
            solved.append(_solve_warm(m, name, seed) if req.warm
                          else _solve_one(m, nlp, name, seed))
            total_iter += max(solved[-1].iterations, 0)
        n_seeds, agree = len(given), 0
        first = solved
    ok = [r for r in solved if r.ok]
    pool = ok or [r for r in solved if r.feasible and np.isfinite(r.energy)] or solved
    best = min(pool, key=lambda r: r.energy)
    if global_seeds and best.ok:
        # one warm re-solve of the chosen optimum (a few iterations): on car-like a
        # solve from a seed with a heading jump stopped "converged" 2.8e-7 (relative
        # energy) above the point a second solve reaches and keeps
        again = _solve_warm(m, best.name, best.points, fallback=False)
        total_iter += max(again.iterations, 0)
        if again.ok and again.energy < best.energy:
            solved = [again if r is best else r for r in solved]
            best = again
    if not global_seeds:
        agree = sum(1 for r in ok if abs(r.energy - best.energy)
                    <= AGREE_RTOL * max(best.energy, 1e-300))
    given_names = {name for name, _ in given}
    own = min((r for r in solved if r.ok and r.name not in given_names),
              key=lambda r: r.energy, default=None)
    if global_seeds and plan.warps and own is not None:
        t1 = time.perf_counter()
        tries = _warp_rounds(m, own, plan)
        its = sum(max(r.iterations, 0) for r in tries)
        solved += tries
        total_iter += its
        levels.append({"segments": n, "solved": len(tries), "iterations": its,
                       "wall_time": time.perf_counter() - t1, "polish": True, "warp": True})
        win = min((r for r in tries if r.ok), key=lambda r: r.energy, default=None)
        if win is not None and win.energy < best.energy * (1.0 - 1e-12):
            best = win
    return _Ladder(solved, levels, n_seeds, agree, total_iter, first, best, own)


def _warp_rounds(m: Metric, base: _Solve, plan: SeedPlan) -> list[_Solve]:
    """The plan's warped copies (`SeedPlan.warps`) of ``base``, solved by IPOPT from its
    warm options (a warped copy is a converged path with its points slid along it: a small
    barrier keeps the solve near the phase switch the warp moved), round after round from
    the best so far, until ``plan.warp_rounds`` rounds or a round that lowers nothing
    (rows ``<base>~w<round>.<j>``)."""
    nlp = energy_nlp(m, base.points.shape[0] - 1, warm=True)
    tries: list[_Solve] = []
    best, stem = base, base.name.split("~")[0]
    for rnd in range(plan.warp_rounds):
        lowered = False
        copies = warped_batch(m, best.points[None], plan.warps, plan.warp_scale)[0]
        for j, curve in enumerate(copies):
            r = _solve_one(m, nlp, f"{stem}~w{rnd}.{j}", curve)
            tries.append(r)
            if r.rank < best.energy * (1.0 - 1e-9):
                best, lowered = r, True
        if not lowered:
            break
    return tries


def _ipopt_result(m: Metric, L: _Ladder) -> GeodesicResult:
    """The result of one pair's solves (`_Ladder`)."""
    best, solved, first = L.best, L.solved, L.first
    energies = {r.name: (r.energy if r.status.converged else float("nan")) for r in solved}
    return GeodesicResult(
        metric=m.name,
        points=best.points,
        status=best.status,
        iterations=L.total_iter,
        wall_time=0.0,
        seeds_tried=L.n_seeds,
        seeds_agreeing=L.agree,
        seed_energies=energies,
        best_seed=best.name,
        levels=L.levels,
        method=best.method,
        seed_families=family_stats([r.name for r in first], np.array([r.energy for r in first]),
                                   np.array([r.ok for r in first], bool), energies,
                                   AGREE_RTOL),
        alternative_gap=alternative_gap(energies, best.energy, AGREE_RTOL),
        **_finish(m, best.points),
    )


def solve_pair(req: SolveRequest, s: np.ndarray, g: np.ndarray,
               initial: Sequence[np.ndarray] = ()) -> GeodesicResult:
    """One pair as `solve_geodesic` solves it without ``tol`` and ``strict``, from
    checked input (``s`` / ``g`` float64 points in the request's domain,
    `solvers.inputs.check_point`): the request's seed plan and the ``initial`` paths
    ``(m+1, dim)`` (resampled to the request's size) solved."""
    m, n = req.metric, req.segments
    given = [(f"initial{k}", _initial_path(m, init, s, g, n, f"initial path {k}"))
             for k, init in enumerate(initial)]
    if not req.global_seeds and not given:
        raise InputError("global_seeds=False needs at least one initial path")
    return solve_pairs(req, np.stack([s, g])[None], [given])[0]


def refine_minmax(metric: Metric | str, result: GeodesicResult) -> MinMaxResult:
    """Minimise the largest segment cost, warm started from ``result`` (epigraph form, cap
    on the max just above its starting value, relaxed if IPOPT finds that infeasible).

    The returned points are the refined ones if they lie in the domain and lower the max,
    else the starting points (the status then tells why); costs are recomputed in float64.
    """
    if not isinstance(result, GeodesicResult):
        raise InputError(f"result must be a GeodesicResult (of solve_geodesic), got "
                         f"{type(result).__name__}")
    return refine_checked_minmax(as_metric(metric), result)


def refine_checked_minmax(m: Metric, result: GeodesicResult) -> MinMaxResult:
    """`refine_minmax` from checked input (``m`` a metric): what the solvers call on their
    own results."""
    t0 = time.perf_counter()
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
