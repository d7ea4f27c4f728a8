"""`distance_matrix`: the distances between K points, from K distance fields, optionally
made exact by the exact solver seeded with the fields' geodesics."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from finsler.domains import as_real
from finsler.errors import InputError
from finsler.status import DistanceStatus, Result
from solvers.fields.field import DistanceField, _metric, distance_field

__all__ = ["DistanceMatrix", "distance_matrix"]

#: Most points of one matrix (K fields, and K**2 exact solves with ``exact=True``).
MAX_POINTS = 2000


@dataclass(frozen=True, eq=False)
class DistanceMatrix(Result):
    """``values[i, j] = d(points[i], points[j])`` ``(K, K)`` (not symmetric for an
    irreversible metric), ``error`` the fields' error estimates there (None without
    them), ``exact`` the `solvers.GeodesicResult` of each off-diagonal pair with
    ``exact=True`` (row-major, None otherwise); ``status`` ``converged`` when every field
    (and every exact solve) converged."""

    points: np.ndarray
    values: np.ndarray
    error: np.ndarray | None
    status: DistanceStatus
    wall_time: float
    cpu_time: float
    fields: list[DistanceField] = field(repr=False, default_factory=list)
    exact: list[Any] | None = field(repr=False, default=None)

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out.pop("fields", None)
        if self.exact is not None:
            out["exact"] = [r.to_dict() for r in self.exact]
        return out


def _resample(path: np.ndarray, n: int) -> np.ndarray:
    """``path`` ``(M, dim)`` as ``n + 1`` points equally spaced in coordinate arc length
    (the exact solver's initial paths share one size)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    if s[-1] <= 0:
        return np.linspace(path[0], path[-1], n + 1)
    t = np.linspace(0.0, s[-1], n + 1)
    return np.stack([np.interp(t, s, path[:, d]) for d in range(path.shape[1])], -1)


def distance_matrix(metric: Any, points: Any, *, exact: bool = False,
                    resolution: int | None = None, progress: bool = True,
                    segments: int | None = None, **field_options: Any) -> DistanceMatrix:
    """Distances between every ordered pair of ``points`` ``(K, dim)``: one
    `distance_field` per point (``resolution`` and ``field_options`` passed on), read at
    the other points. ``exact=True``: the exact solver on every ordered pair
    (`solvers.solve_batch` with no global seeds), each seeded with the backtracked
    geodesic of its field, and the matrix holds the exact lengths. A progress bar shows
    the fields (``progress``)."""
    t0 = time.perf_counter()
    c0 = time.process_time()
    m = _metric(metric)
    pts = as_real(points, "points", f"a real numeric array of shape (K, {m.dim})")
    if pts.ndim != 2 or pts.shape[1] != m.dim:
        raise InputError(f"points must have shape (K, {m.dim}), got {tuple(pts.shape)}")
    k = pts.shape[0]
    if not 1 <= k <= MAX_POINTS:
        raise InputError(f"points must hold between 1 and {MAX_POINTS} points, got {k}")
    pts = m.domain.check(pts, "points")
    for name, flag in (("exact", exact), ("progress", progress)):
        if not isinstance(flag, (bool, np.bool_)):
            raise InputError(f"{name} must be True or False, got {flag!r}")
    from tqdm.auto import tqdm

    values = np.zeros((k, k))
    error = np.zeros((k, k))
    fields = []
    ok = True
    for i in tqdm(range(k), desc=f"fields {m.name}", disable=not progress, unit="field",
                  leave=False):
        f = distance_field(m, pts[i], resolution, **field_options)
        fields.append(f)
        values[i] = f(pts)
        error[i] = f.error_at(pts)
        values[i, i] = 0.0
        error[i, i] = 0.0
        ok = ok and f.converged
    results = None
    if exact and k > 1:
        from solvers import solve_batch

        pairs, seeds = [], []
        for i in range(k):
            for j in range(k):
                if i != j:
                    pairs.append((pts[i], pts[j]))
                    seeds.append(_resample(fields[i].geodesic(pts[j]).points, 64))
        results = solve_batch(m, np.array(pairs), segments, initial_paths=np.array(seeds),
                              global_seeds=False, progress=progress)
        it = iter(results)
        for i in range(k):
            for j in range(k):
                if i != j:
                    r = next(it)
                    values[i, j] = r.length
                    ok = ok and r.converged
    status = DistanceStatus.CONVERGED if ok else DistanceStatus.SOLVER_FAILED
    has_error = all(f.error is not None for f in fields)
    return DistanceMatrix(points=pts, values=values, error=error if has_error else None,
                          status=status, wall_time=time.perf_counter() - t0,
                          cpu_time=time.process_time() - c0, fields=fields, exact=results)
