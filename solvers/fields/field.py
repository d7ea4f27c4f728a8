"""`DistanceField`: the distance from one source on a grid, with its error estimate, its
interpolation at any point and the geodesic to any point by backtracking."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from finsler.domains import as_real
from finsler.errors import InputError
from finsler.infra.limits import check_count, check_number
from finsler.metrics.base import Metric
from finsler.status import DistanceStatus, Result, json_ready
from solvers.fields.eikonal import (
    Grid,
    Stencil,
    box_stencil,
    depends_on,
    make_grid,
    solve_eikonal,
    step_costs,
)

__all__ = ["DEFAULT_RESOLUTION", "DistanceField", "FieldGeodesic", "distance_field"]

#: Cells along the longest side of the bounding box by dimension: the errors they give on
#: the closed forms, and the CPU time, are in benchmarks/results/distance-fields/distance_field-*.md.
DEFAULT_RESOLUTION = {2: 100, 3: 40}
#: Stencil half widths by dimension: half width 2 (16 directions in 2-D, 98 vertices in
#: 3-D) against 1 lowered the errors several times on Poincare, Matsumoto and
#: poincare-slab (where the worst nodes lie near the disk's rim) for two to three times
#: the time (measured in benchmarks/results/distance-fields/distance_field-*.md).
DEFAULT_STENCIL = {2: 2, 3: 2}
#: Barycentric samples per face edge, by dimension (2-D: with the parabolic refinement).
DEFAULT_ORDER = {2: 8, 3: 4}
#: Nodes near the source that start from the straight segment's length (cells).
INIT_RADIUS = 3
#: Cells around the source where the factored correction is applied, by dimension (in 2-D
#: the whole grid at the default resolution).
FACTOR_RADIUS = {2: 400, 3: 12}
#: Width of the update band in cheapest step costs (`eikonal.solve_eikonal`): a few step
#: costs keep the front's nodes from being updated again and again (about a third of the
#: node updates on car-like, the same values) without one band per node.
DEFAULT_BAND = 3.0
#: Largest resolution accepted (a grid also has `eikonal.MAX_NODES` as a limit).
MAX_RESOLUTION = 4096


def _metric(metric: Metric | str) -> Metric:
    if isinstance(metric, str):
        from finsler.registry import get_metric

        metric = get_metric(metric)
    if not isinstance(metric, Metric):
        raise InputError(f"metric must be a finsler.Metric or a registered name, got "
                         f"{type(metric).__name__}")
    if metric.dim not in (2, 3):
        raise InputError(f"distance fields are for metrics of dimension 2 or 3; "
                         f"{metric.name!r} has dimension {metric.dim}")
    metric.check_values()
    return metric


def _point(metric: Metric, x: Any, name: str) -> np.ndarray:
    arr = as_real(x, name, f"a point: a real numeric array of shape ({metric.dim},)")
    if arr.shape not in ((metric.dim,), (1, metric.dim)):
        raise InputError(f"{name} must be a single point of shape ({metric.dim},), got "
                         f"shape {tuple(arr.shape)}")
    return metric.domain.check(arr.reshape(1, -1), name)[0].astype(np.float64)


def interpolate(grid: Grid, values: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Multilinear interpolation of grid ``values`` at ``points`` ``(N, dim)`` -> ``(N,)``;
    corners with infinite values (outside the domain, unreached) are left out and the
    others' weights renormalised; ``inf`` where no corner is finite."""
    dim = grid.dim
    rel = (points - grid.low) / grid.h
    base = np.clip(np.floor(rel).astype(int), 0, np.array(grid.shape) - 2)
    frac = np.clip(rel - base, 0.0, 1.0)
    num = np.zeros(points.shape[0])
    den = np.zeros(points.shape[0])
    for corner in np.ndindex(*(2,) * dim):
        c = np.array(corner)
        w = np.prod(np.where(c, frac, 1.0 - frac), axis=1)
        v = values[tuple((base + c).T)]
        ok = np.isfinite(v)
        num += np.where(ok, w * np.where(ok, v, 0.0), 0.0)
        den += np.where(ok, w, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    out[den <= 1e-12] = np.inf
    return out


@dataclass(frozen=True, eq=False)
class FieldGeodesic(Result):
    """A path from the field's source to a goal found by backtracking the field (steps
    down its values), optionally polished by the exact solver.

    ``points`` ``(M, dim)`` from source to goal; ``length`` its length (eq. 58 quadrature
    of each segment, an upper bound of the distance); ``value`` the field at the goal;
    ``exact`` the `solvers.GeodesicResult` of the exact solve seeded with it (None unless
    asked for)."""

    points: np.ndarray
    length: float
    value: float
    status: DistanceStatus
    wall_time: float
    exact: Any = None


@dataclass(frozen=True, eq=False)
class DistanceField(Result):
    """``d(source, .)`` on a grid (see `distance_field`).

    ``values`` (grid ``shape``): the distance at each node, ``inf`` outside the domain;
    ``error`` (same shape, or None): the estimated absolute error at each node, the
    difference from a field at half the resolution (first-order scheme: that difference is
    about the error of the finer field); ``grid``: the nodes (``low``, ``h``, ``shape``,
    ``inside``); ``status``: ``converged`` when the iteration reached its fixed point (at
    both resolutions), ``solver_failed`` otherwise. Call it on points ``(N, dim)`` for
    interpolated values.
    """

    metric: Metric = field(repr=False)
    source: np.ndarray
    values: np.ndarray = field(repr=False)
    error: np.ndarray | None = field(repr=False)
    grid: Grid = field(repr=False)
    resolution: Any
    stencil: Stencil = field(repr=False)
    iterations: int
    status: DistanceStatus
    wall_time: float
    cpu_time: float

    def _points(self, points: Any, name: str = "points") -> np.ndarray:
        arr = as_real(points, name, f"a real numeric array of shape (N, {self.metric.dim}) "
                                    f"or ({self.metric.dim},)")
        if arr.ndim not in (1, 2) or arr.shape[-1] != self.metric.dim:
            raise InputError(f"{name} must have shape (N, {self.metric.dim}) or "
                             f"({self.metric.dim},), got {tuple(arr.shape)}")
        return self.metric.domain.check(arr.reshape(-1, self.metric.dim), name)

    def __call__(self, points: Any) -> np.ndarray:
        """Interpolated distance from the source at ``points`` ``(N, dim)`` -> ``(N,)``
        (or ``(dim,)`` -> a float)."""
        p = self._points(points)
        out = interpolate(self.grid, self.values, p)
        return float(out[0]) if np.ndim(points) == 1 else out

    def error_at(self, points: Any) -> np.ndarray:
        """Interpolated error estimate at ``points`` (``nan`` without an estimate)."""
        p = self._points(points)
        if self.error is None:
            out = np.full(p.shape[0], np.nan)
        else:
            out = interpolate(self.grid, self.error, p)
        return float(out[0]) if np.ndim(points) == 1 else out

    @property
    def relative_error(self) -> dict[str, float]:
        """Median, 99th percentile and maximum of the estimated relative error over the
        nodes farther than `INIT_RADIUS` cells from the source (nan without an
        estimate)."""
        if self.error is None:
            return {"median": float("nan"), "p99": float("nan"), "max": float("nan")}
        pts = self.grid.points()
        far = np.max(np.abs(pts - self.source) / self.grid.h, axis=1) > INIT_RADIUS
        v = self.values.ravel()
        e = self.error.ravel()
        ok = far & np.isfinite(v) & np.isfinite(e) & (v > 0)
        if not ok.any():
            return {"median": float("nan"), "p99": float("nan"), "max": float("nan")}
        r = e[ok] / v[ok]
        return {"median": float(np.median(r)), "p99": float(np.percentile(r, 99)),
                "max": float(r.max())}

    def geodesic(self, goal: Any, exact: bool = False, segments: int | None = None,
                 max_steps: int | None = None) -> FieldGeodesic:
        """The path from the source to ``goal`` ``(dim,)`` by backtracking: from the goal,
        repeatedly the stencil step ``w`` that minimises ``field(y - h w) + F(y, h w)``,
        until within a few cells of the source. ``exact=True``: the path seeds one exact
        solve (`solvers.solve_geodesic` with ``initial=`` the path and no other seeds)
        of ``segments`` segments (default the metric's task), attached as ``exact``."""
        t0 = time.perf_counter()
        m = self.metric
        g = _point(m, goal, "goal")
        if not isinstance(exact, (bool, np.bool_)):
            raise InputError(f"exact must be True or False, got {exact!r}")
        h = self.grid.h
        w = np.unique(np.round(self.stencil.directions().reshape(-1, m.dim), 12), axis=0)
        limit = (max_steps if max_steps is not None
                 else 4 * int(sum(self.grid.shape)) * int(self.stencil.radius.max()) + 50)
        path = [g]
        p = g
        status = DistanceStatus.CONVERGED
        for _ in range(limit):
            if np.max(np.abs(p - self.source) / h) <= INIT_RADIUS:
                break
            q = p[None] - h * w
            with np.errstate(all="ignore"):
                inside = m.domain.contains(q, tol=1e-12)
                val = interpolate(self.grid, self.values, q)
                (f,) = m.lowered_F(p[None] - 0.5 * h * w, h * w)
            total = np.where(inside, val + np.asarray(f, float).reshape(-1), np.inf)
            k = int(np.argmin(total))
            if not np.isfinite(total[k]):
                status = DistanceStatus.SOLVER_FAILED
                break
            p = q[k]
            path.append(p)
        else:
            status = DistanceStatus.SOLVER_FAILED
        path.append(self.source)
        pts = np.array(path[::-1])
        # drop repeated points (a step of zero length)
        keep = np.r_[True, np.any(np.abs(np.diff(pts, axis=0)) > 1e-15, axis=1)]
        pts = pts[keep]
        if pts.shape[0] < 2:
            pts = np.stack([self.source, g])
        length = float(np.sum(m.segment_length(pts[:-1], pts[1:], order=4, check=False)))
        value = float(interpolate(self.grid, self.values, g[None])[0])
        result = None
        if exact:
            from solvers import solve_geodesic

            result = solve_geodesic(m, self.source, g, segments, initial=[pts],
                                    global_seeds=False)
        return FieldGeodesic(points=pts, length=length, value=value, status=status,
                             wall_time=time.perf_counter() - t0, exact=result)

    def to_dict(self, values: bool = False) -> dict[str, Any]:
        """JSON-ready summary: metric, source, grid (low, spacing, shape), resolution,
        iterations, status, times, the relative error summary; with ``values=True`` also
        the grid values and error estimates (nested lists, ``None`` outside the domain)."""
        out: dict[str, Any] = {
            "metric": self.metric.name,
            "source": self.source,
            "grid": {"low": self.grid.low, "spacing": self.grid.h, "shape": self.grid.shape,
                     "nodes_inside": int(self.grid.inside.sum())},
            "resolution": self.resolution,
            "stencil_radius": self.stencil.radius,
            "iterations": self.iterations,
            "relative_error": self.relative_error,
            "status": self.status,
            "wall_time": self.wall_time,
            "cpu_time": self.cpu_time,
            "converged": self.converged,
        }
        if values:
            out["values"] = self.values
            out["error"] = self.error
        return json_ready(out)


def _check_resolution(resolution: Any, dim: int) -> int | tuple[int, ...]:
    if isinstance(resolution, (list, tuple, np.ndarray)):
        r = tuple(resolution)
        if len(r) != dim:
            raise InputError(f"resolution must be an integer or {dim} integers (cells per "
                             f"coordinate), got {len(r)} entries")
        return tuple(check_count(k, "resolution", 4, MAX_RESOLUTION) for k in r)
    return check_count(resolution, "resolution", 4, MAX_RESOLUTION)


def _check_radius(stencil: Any, dim: int) -> tuple[int, ...]:
    if isinstance(stencil, (int, np.integer)) and not isinstance(stencil, bool):
        stencil = (int(stencil),) * dim
    try:
        r = tuple(stencil)
    except TypeError:
        raise InputError(f"stencil must be an integer or {dim} integers (the box's half "
                         f"widths in cells), got {stencil!r}") from None
    if len(r) != dim:
        raise InputError(f"stencil must have {dim} entries, got {len(r)}")
    return tuple(check_count(k, "stencil radius", 1, 16) for k in r)


#: grids whose step costs a metric keeps (a field's own and its error estimate's)
_COSTS_KEPT = 2


def _step_costs(m: Metric, grid: Grid, st: Any, dep: np.ndarray) -> tuple[np.ndarray,
                                                                           np.ndarray]:
    """`step_costs` of the grid, kept on the metric for its last `_COSTS_KEPT` grids: the
    table depends on the grid and the stencil, not on the source, so the fields of one
    metric and resolution (a distance matrix's K sources, repeated calls) build it once."""
    store: dict = m.derived("solvers.fields.step_costs", dict)
    key = (grid.shape, grid.low.tobytes(), grid.h.tobytes(), st.offsets.tobytes(),
           st.faces.tobytes(), st.bary.tobytes(), dep.tobytes())
    if key not in store:
        while len(store) >= _COSTS_KEPT:
            store.pop(next(iter(store)))
        tables = step_costs(m, grid, st, dep, m.domain)
        for t in tables:
            t.setflags(write=False)  # shared by every field of this grid
        store[key] = tables
    return store[key]


def distance_field(metric: Metric | str, source: Any, resolution: int | None = None, *,
                   stencil: Any = None, order: int | None = None,
                   box: tuple[Any, Any] | None = None, error_estimate: bool = True,
                   factor_radius: int | None = None, prune: float | None = None,
                   band: float | None = DEFAULT_BAND) -> DistanceField:
    """The distance ``d(source, y)`` for every node ``y`` of a grid over the domain
    (metrics of dimension 2 or 3).

    ``resolution``: cells along the longest side of the domain's bounding box (or of
    ``box``), the same spacing in every coordinate (default `DEFAULT_RESOLUTION`); or one
    number of cells per coordinate (e.g. finer in position than in heading).
    ``stencil``: half widths (cells, an integer or one per coordinate; default
    `DEFAULT_STENCIL`) of the box of offsets whose boundary the update minimises over:
    wider for strongly anisotropic metrics (thin unit balls), at a cost growing like its
    surface. ``order``: samples per face edge (default `DEFAULT_ORDER`). ``factor_radius``:
    cells around the source where the factored correction applies (default
    `FACTOR_RADIUS`; 0: none). ``box``: ``(low, high)`` of the grid instead of the
    bounding box (nodes outside the domain are left out). ``error_estimate``: also solve at half the
    resolution and keep the difference as the error estimate. ``prune``: leave out, per
    point, the faces whose directions cost more than ``prune`` times the cheapest per unit
    of step length: faster, exact when the pruned directions are never the best over a
    grid step, an upper bound otherwise (off by default: on car-like the interpolation
    uses dear faces, and pruning raised the values).
    ``band``: nodes are updated in bands of this many cheapest step costs above the least
    pending value (None: every pending node at once); the fixed point is the same.

    The scheme (`solvers.fields.eikonal`) converges to the viscosity solution for any
    metric whose ``F`` is continuous, smooth or not; where ``F(x, .)`` is not convex it
    computes the distance of the convexified metric (the convex hull of the unit ball),
    which is the infimum of lengths over curves the discrete problems approach but not a
    length any one smooth curve attains.
    """
    t0 = time.perf_counter()
    c0 = time.process_time()
    m = _metric(metric)
    s = _point(m, source, "source")
    dim = m.dim
    res = _check_resolution(DEFAULT_RESOLUTION[dim] if resolution is None else resolution,
                            dim)
    radius = _check_radius(DEFAULT_STENCIL[dim] if stencil is None else stencil, dim)
    order_ = DEFAULT_ORDER[dim] if order is None else check_count(order, "order", 1, 16)
    if not isinstance(error_estimate, (bool, np.bool_)):
        raise InputError(f"error_estimate must be True or False, got {error_estimate!r}")
    fr = FACTOR_RADIUS[dim] if factor_radius is None else check_count(
        factor_radius, "factor_radius", 0, 100_000)
    pr = None if prune is None else check_number(prune, "prune", 1.0, np.inf)
    band = None if band is None else check_number(band, "band", 0.0, np.inf, low_open=True)
    if box is not None:
        try:
            lo, hi = box
        except (TypeError, ValueError):
            raise InputError("box must be a pair (low, high) of points") from None
        lo = as_real(lo, "box low").reshape(-1)
        hi = as_real(hi, "box high").reshape(-1)
        if lo.shape != (dim,) or hi.shape != (dim,):
            raise InputError(f"box low and high must have shape ({dim},)")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise InputError("box must be finite with high > low in every coordinate")
        if not (np.all(s >= lo) and np.all(s <= hi)):
            raise InputError(f"source {s.tolist()} lies outside the box")
        box = (lo, hi)
    st = box_stencil(radius, order_)
    dep = depends_on(m)

    def solve(r: int) -> tuple[Grid, Any]:
        grid = make_grid(m.domain, r, box)
        if np.any(np.array(grid.shape) < 2 * np.array(radius) + 1):
            raise InputError(f"resolution {r} gives a grid of shape {grid.shape}, too small "
                             f"for the stencil of half widths {radius}: raise the resolution")
        cost, cls = _step_costs(m, grid, st, dep)
        sweep = solve_eikonal(m, grid, st, s, cost, cls, factor_radius=fr, prune=pr,
                              band=band)
        return grid, sweep

    grid, sweep = solve(res)
    ok = sweep.converged
    err = None
    if error_estimate:
        half = tuple(max(k // 2, 2) for k in res) if isinstance(res, tuple) else max(res // 2, 2)
        coarse_grid, coarse = solve(half)
        ok = ok and coarse.converged
        coarse_at_fine = interpolate(coarse_grid, coarse.values, grid.points())
        with np.errstate(invalid="ignore"):
            err = np.abs(sweep.values.ravel() - coarse_at_fine).reshape(grid.shape)
        err[~np.isfinite(sweep.values)] = np.inf
    status = DistanceStatus.CONVERGED if ok else DistanceStatus.SOLVER_FAILED
    return DistanceField(metric=m, source=s, values=sweep.values, error=err, grid=grid,
                         resolution=res, stencil=st, iterations=sweep.iterations,
                         status=status, wall_time=time.perf_counter() - t0,
                         cpu_time=time.process_time() - c0)
