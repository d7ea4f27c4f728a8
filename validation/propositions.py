"""Numerical checks of the paper's theory: Proposition 1, Proposition 2 with Lemma 1
items 3-4, Remark 3 (eqs. 9-13), and the convexification that predicts where
Proposition 1 fails.

Proposition 2 is checked by *exact* dynamic programming of eqs. (9)-(11) on a finite
grid of a 2-D metric: ``V`` is a ``(G, G)`` matrix over all ordered grid pairs, ``pi`` a
``(G, G)`` index matrix, and each iteration takes, for all ``(x, y)`` at once, the
argmin over grid points ``z`` of ``V(x, z)**2 + V(z, y)**2`` (eq. 10), chunked over rows
to bound memory (``O(G**3)`` work, ``O(chunk * G**2)`` memory). Ties are broken towards
``z = x`` (an element of the argmin whenever it attains the minimum), so that a pair that
cannot be split keeps its value.

A grid has only approximate midpoints, so the continuum statements are checked in their
grid form: Lemma 1 item 3 holds verbatim on any finite set; item 4's induction step
holds with the grid's best approximate midpoint in place of the true one (see
`check_lemma1`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.spatial import ConvexHull

from finsler import Metric
from finsler.errors import InputError
from finsler.status import PropertyOutcome, Result

__all__ = [
    "GridDP",
    "Lemma1Report",
    "Prop1Result",
    "Remark3Result",
    "check_lemma1",
    "convexified_F",
    "format_table",
    "grid_distance",
    "grid_points",
    "midpoint_errors",
    "nonconvex_direction",
    "polygon_distance",
    "proposition1_nonconvex",
    "proposition1_rate",
    "proposition2_table",
    "remark3",
    "remark3_f",
    "run_grid_dp",
    "two_segment_distance",
]

_TIE_RTOL = 1e-12


# ----------------------------------------------------------------------------------------
# Grids and exact dynamic programming of eqs. (9)-(11) / (13)
# ----------------------------------------------------------------------------------------
def grid_points(metric: Metric, n: int, margin: float = 0.0) -> np.ndarray:
    """Regular lattice with ``n`` points per axis over the domain's bounding box, keeping
    the points inside the domain (shrunk by ``margin`` in relative terms) -> ``(G, 2)``."""
    if metric.dim != 2:
        raise InputError(f"grid dynamic programming needs a 2-D metric, {metric.name} is "
                         f"{metric.dim}-D")
    if not isinstance(n, (int, np.integer)) or n < 3:
        raise InputError(f"grid size n must be an integer >= 3, got {n!r}")
    if not (0.0 <= margin < 0.5):
        raise InputError(f"margin must be in [0, 0.5), got {margin!r}")
    lo, hi = metric.domain.bounds()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise InputError(f"the domain of {metric.name} is unbounded: no grid")
    c, r = 0.5 * (lo + hi), 0.5 * (hi - lo) * (1.0 - margin)
    axes = [np.linspace(c[k] - r[k], c[k] + r[k], int(n)) for k in range(2)]
    pts = np.stack(np.meshgrid(*axes, indexing="xy"), -1).reshape(-1, 2)
    # shrink towards the centre by the margin before the membership test
    inside = metric.domain.contains(c + (pts - c) / (1.0 - margin), tol=1e-12)
    return np.ascontiguousarray(pts[inside])


def _pair_matrix(fn: Callable[[np.ndarray, np.ndarray], np.ndarray], pts: np.ndarray) -> np.ndarray:
    g = len(pts)
    a = np.repeat(pts, g, axis=0)
    b = np.tile(pts, (g, 1))
    out = np.array(fn(a, b), dtype=np.float64).reshape(g, g)
    np.fill_diagonal(out, 0.0)
    return out


def grid_cost(metric: Metric, pts: np.ndarray) -> np.ndarray:
    """``C(x_a, x_b)`` (eq. 4) for all ordered grid pairs -> ``(G, G)``, zero diagonal."""
    return _pair_matrix(metric.cost, pts)


def grid_distance(metric: Metric, pts: np.ndarray) -> np.ndarray:
    """Exact ``d(x_a, x_b)`` of a closed-form metric for all grid pairs -> ``(G, G)``."""
    if not metric.provides("distance"):
        raise InputError(f"{metric.name} has no closed-form distance")
    return _pair_matrix(metric.distance, pts)


def _argmin_split(
    v: np.ndarray, rule: str, chunk_bytes: float = 64e6
) -> tuple[np.ndarray, np.ndarray]:
    """For all ``(a, b)``: ``z* = argmin_z S(a, z, b)`` with ``S = V[a,z]**2 + V[z,b]**2``
    (rule ``"squared"``, eq. 10) or ``V[a,z] + V[z,b]`` (rule ``"sum"``, eq. 13).

    Returns ``(pi, best)``, both ``(G, G)``. Ties towards ``z = a``.
    """
    g = v.shape[0]
    w = v * v if rule == "squared" else v
    wt = np.ascontiguousarray(w.T)  # wt[b, z] = w[z, b]
    pi = np.empty((g, g), dtype=np.int64)
    best = np.empty((g, g))
    step = max(1, int(chunk_bytes // (8 * g * g)))
    rows = np.arange(g)
    for s in range(0, g, step):
        a = rows[s : s + step]
        tot = w[a][:, None, :] + wt[None, :, :]  # (A, b, z)
        idx = np.argmin(tot, axis=2)
        val = np.take_along_axis(tot, idx[..., None], axis=2)[..., 0]
        # z = a gives S = W[a, a] + W[a, b] = W[a, b] (V(a, a) = 0): keep a if it is minimal
        at_a = w[a]
        keep = at_a <= val * (1.0 + _TIE_RTOL)
        idx = np.where(keep, a[:, None], idx)
        val = np.where(keep, at_a, val)
        pi[a] = idx
        best[a] = val
    return pi, best


@dataclass
class GridDP:
    """Exact dynamic programming on a grid.

    ``points (G, 2)``; ``V[i] (G, G)`` is ``V_i`` (``V[0] = C``); ``pi[i] (G, G)`` is the
    index of ``pi_i(x, y)``; ``rule`` is ``"squared"`` (eq. 10) or ``"sum"`` (eq. 13).
    """

    points: np.ndarray
    V: list[np.ndarray]
    pi: list[np.ndarray]
    rule: str
    spacing: float


def run_grid_dp(
    metric: Metric | None,
    n: int | None = None,
    iterations: int = 6,
    rule: str = "squared",
    points: np.ndarray | None = None,
    cost: np.ndarray | None = None,
) -> GridDP:
    """Iterate eqs. (9)-(11) (or (13) with ``rule="sum"``) exactly on a grid.

    Either ``metric`` and ``n`` (the lattice of `grid_points`, ``V_0 = C`` of eq. 4),
    or ``points (G, 2)`` and a custom ``cost (G, G)`` for ``V_0`` (e.g. Remark 3's
    ``f o d``). Returns ``iterations + 1`` value matrices and ``iterations`` policies.
    """
    if rule not in ("squared", "sum"):
        raise InputError(f"rule must be 'squared' (eq. 10) or 'sum' (eq. 13), got {rule!r}")
    if not isinstance(iterations, (int, np.integer)) or iterations < 0:
        raise InputError(f"iterations must be a non-negative integer, got {iterations!r}")
    if points is None:
        if metric is None or n is None:
            raise InputError("give either metric and n, or points and cost")
        points = grid_points(metric, n)
    points = np.asarray(points, dtype=np.float64)
    if cost is None:
        if metric is None:
            raise InputError("a cost matrix or a metric is needed for V_0")
        cost = grid_cost(metric, points)
    cost = np.asarray(cost, dtype=np.float64)
    g = len(points)
    if cost.shape != (g, g) or not np.all(np.isfinite(cost)) or np.any(cost < 0):
        raise InputError(f"V_0 must be a finite non-negative ({g}, {g}) matrix")
    if np.any(np.diag(cost) != 0):
        raise InputError("V_0(x, x) must be 0")
    diffs = np.diff(np.unique(np.round(points[:, 0], 12)))
    spacing = float(diffs.min()) if diffs.size else float("nan")
    vs, pis = [cost], []
    rows = np.arange(g)[:, None]
    cols = np.arange(g)[None, :]
    for _ in range(int(iterations)):
        v = vs[-1]
        pi, _best = _argmin_split(v, rule)
        vs.append(v[rows, pi] + v[pi, cols])  # eq. (11)
        pis.append(pi)
    return GridDP(points=points, V=vs, pi=pis, rule=rule, spacing=spacing)


# ----------------------------------------------------------------------------------------
# Proposition 2: error tables
# ----------------------------------------------------------------------------------------
def midpoint_errors(d: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """Relative midpoint error of a policy on a grid:
    ``max(|d(x,z) - d(x,y)/2|, |d(z,y) - d(x,y)/2|) / d(x,y)`` with ``z = pi(x, y)``
    -> ``(G, G)`` (NaN on the diagonal)."""
    g = d.shape[0]
    rows = np.arange(g)[:, None]
    cols = np.arange(g)[None, :]
    half = 0.5 * d
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.maximum(np.abs(d[rows, pi] - half), np.abs(d[pi, cols] - half)) / d
    return e


def _grid_midpoint_floor(d: np.ndarray, chunk_bytes: float = 64e6) -> np.ndarray:
    """Best midpoint error any grid point achieves, per pair -> ``(G, G)``."""
    g = d.shape[0]
    dt = np.ascontiguousarray(d.T)
    out = np.empty((g, g))
    step = max(1, int(chunk_bytes // (8 * g * g)))
    for s in range(0, g, step):
        a = slice(s, s + step)
        half = 0.5 * d[a][:, :, None]  # (A, b, 1)
        e = np.maximum(np.abs(d[a][:, None, :] - half), np.abs(dt[None, :, :] - half))
        out[a] = e.min(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return out / d


def proposition2_table(
    metric: Metric,
    sizes: tuple[int, ...] = (11, 15, 21),
    iterations: int = 5,
    d_min: float | None = None,
) -> list[dict[str, Any]]:
    """Error of ``V_i`` against the exact ``d`` and of ``pi_i`` against true midpoints, per
    grid size and iteration, over grid pairs with ``d(x, y) >= d_min`` (default: a third of
    the largest grid distance, the same absolute threshold on every grid).

    Each row: ``n``, ``G`` (points), ``h`` (spacing), ``i``, ``V_err_max``/``V_err_mean``
    (``|V_i - d| / d``), ``mid_err_max``/``mid_err_mean`` (`midpoint_errors`,
    ``i < iterations``), ``mid_floor_max`` (the best any grid point can do), and
    ``mid_coord_max``: coordinate distance from ``pi_i(x, y)`` to the exact midpoint.
    """
    if not metric.provides("distance"):
        raise InputError("proposition2_table needs a closed-form metric (exact d)")
    rows: list[dict[str, Any]] = []
    if d_min is None:
        pts = grid_points(metric, max(sizes))
        d_min = float(grid_distance(metric, pts).max()) / 3.0
    for n in sizes:
        dp = run_grid_dp(metric, n, iterations)
        d = grid_distance(metric, dp.points)
        mask = d >= d_min
        if not mask.any():
            raise InputError(f"no grid pair with d >= {d_min} on the {n}-grid")
        a_idx, b_idx = np.nonzero(mask)
        true_mid = metric.geodesic(dp.points[a_idx], dp.points[b_idx], [0.5])[:, 0]
        floor = _grid_midpoint_floor(d)[mask]
        for i in range(iterations + 1):
            err = np.abs(dp.V[i] - d)[mask] / d[mask]
            row: dict[str, Any] = {
                "metric": metric.name,
                "n": int(n),
                "G": len(dp.points),
                "h": dp.spacing,
                "i": i,
                "pairs": int(mask.sum()),
                "V_err_max": float(err.max()),
                "V_err_mean": float(err.mean()),
            }
            if i < iterations:
                me = midpoint_errors(d, dp.pi[i])[mask]
                z = dp.points[dp.pi[i][a_idx, b_idx]]
                row.update(
                    mid_err_max=float(me.max()),
                    mid_err_mean=float(me.mean()),
                    mid_floor_max=float(floor.max()),
                    mid_coord_max=float(np.linalg.norm(z - true_mid, axis=1).max()),
                )
            rows.append(row)
    return rows


# ----------------------------------------------------------------------------------------
# Lemma 1 items 3 and 4 on a grid
# ----------------------------------------------------------------------------------------
@dataclass
class Lemma1Report(Result):
    """Worst slack of Lemma 1's bounds over all iterations and thresholds (<= 0: holds).
    A [`finsler.status.Result`][finsler.status.Result]: ``status`` is ``passed`` if `holds`, else
    ``failed`` ([`finsler.status.PropertyOutcome`][finsler.status.PropertyOutcome]).

    ``item3[i][k]``: ``max_{V_i < delta_k} (d/V_i - 1) - eps_0(delta_k)``, where
    ``eps_0(delta) = max_{V_0 < delta} (d/V_0 - 1)`` (eq. 34 -> 35).
    ``item4[i][k]``: ``max_{d < delta_k} (V_{i+1} - (1 + eps_i) D~) / d`` where
    ``eps_i = max_{d < delta} V_i/d - 1`` and ``D~(x,y) = sqrt(2 min_z (d(x,z)^2 +
    d(z,y)^2))`` over grid points with ``d(x,z), d(z,y) < delta`` (eq. 43 with the grid's best
    approximate midpoint; ``D~ = d`` where the grid holds an exact midpoint).
    ``eps[i][k]``: ``eps_i(delta_k)`` of item 4, the growth factor the grid allows.
    ``grid_defect[k]``: ``max D~/d`` over pairs with ``d < delta_k``.
    """

    deltas: list[float]
    item3: list[list[float]]
    item4: list[list[float]]
    eps: list[list[float]]
    grid_defect: list[float]
    wall_time: float = field(default=0.0, kw_only=True)
    """Seconds the check took."""

    @property
    def status(self) -> PropertyOutcome:  # type: ignore[override]
        return PropertyOutcome.PASSED if self.holds else PropertyOutcome.FAILED

    @property
    def holds(self) -> bool:
        tol = 1e-9
        return all(s <= tol for r in self.item3 + self.item4 for s in r)


def _dtilde(d: np.ndarray, delta: float, chunk_bytes: float = 64e6) -> np.ndarray:
    g = d.shape[0]
    sq = np.where(d < delta, d * d, np.inf)
    sqt = np.ascontiguousarray(sq.T)
    out = np.empty((g, g))
    step = max(1, int(chunk_bytes // (8 * g * g)))
    for s in range(0, g, step):
        a = slice(s, s + step)
        out[a] = (sq[a][:, None, :] + sqt[None, :, :]).min(axis=2)
    return np.sqrt(2.0 * out)


def check_lemma1(dp: GridDP, d: np.ndarray, deltas: list[float]) -> Lemma1Report:
    """Check Lemma 1 items 3 and 4 at every iteration of ``dp`` on its grid, for each
    threshold ``delta``, against the exact grid distances ``d (G, G)``."""
    t0 = time.perf_counter()
    off = ~np.eye(d.shape[0], dtype=bool)
    item3, item4, eps_all = [], [], []
    dts = [_dtilde(d, dl) for dl in deltas]
    defect = []
    for dl, dt in zip(deltas, dts):
        m = off & (d < dl)
        defect.append(float((dt[m] / d[m]).max()) if m.any() else float("nan"))
    v0 = dp.V[0]
    for i, v in enumerate(dp.V):
        r3, r4, re = [], [], []
        for dl, dt in zip(deltas, dts):
            m0 = off & (v0 < dl)
            eps0 = float((d[m0] / v0[m0] - 1).max()) if m0.any() else -np.inf
            mi = off & (v < dl)
            r3.append(float((d[mi] / v[mi] - 1).max()) - eps0 if mi.any() else -np.inf)
            md = off & (d < dl)
            eps_i = float((v[md] / d[md]).max() - 1) if md.any() else 0.0
            re.append(eps_i)
            if i + 1 < len(dp.V) and md.any():
                nxt = dp.V[i + 1]
                r4.append(float(((nxt[md] - (1 + eps_i) * dt[md]) / d[md]).max()))
        item3.append(r3)
        if r4:
            item4.append(r4)
        eps_all.append(re)
    return Lemma1Report(list(map(float, deltas)), item3, item4, eps_all, defect,
                        wall_time=time.perf_counter() - t0)


# ----------------------------------------------------------------------------------------
# Remark 3
# ----------------------------------------------------------------------------------------
def remark3_f(h: np.ndarray) -> np.ndarray:
    """``f(h) = 2 sqrt(h + 1) - 2``: non-decreasing, subadditive, ``f(h)/h -> 1`` at 0."""
    return 2.0 * np.sqrt(np.asarray(h, float) + 1.0) - 2.0


@dataclass
class Remark3Result(Result):
    """Remark 3 on a grid with ``C = f o d`` (a `finsler.status.Result`: ``status``
    is ``passed`` if the remark's claim ``stays`` holds, else ``failed``).

    ``sum_rule``: the eq.-(13) DP; ``stays``: ``V_i == C`` and ``pi_i(x, y) == x`` for all
    pairs and iterations; ``x_in_argmin_gap``: the largest amount by which ``z = x``
    exceeds the minimum of eq. (13) (<= rounding: ``x`` is in the argmin);
    ``gap_to_d``: ``max |C - d| / d`` (``V != d``). ``squared_rule_err[i]``: ``max |V_i - d| / d``
    of the eq.-(10) DP from the same ``V_0`` (over pairs with ``d >= d_min``).
    """

    sum_rule: GridDP
    stays: bool
    x_in_argmin_gap: float
    gap_to_d: float
    squared_rule_err: list[float] = field(default_factory=list)
    wall_time: float = field(default=0.0, kw_only=True)
    """Seconds the two DPs took."""

    @property
    def status(self) -> PropertyOutcome:  # type: ignore[override]
        return PropertyOutcome.PASSED if self.stays else PropertyOutcome.FAILED


def remark3(metric: Metric, n: int = 15, iterations: int = 4) -> Remark3Result:
    """Run Remark 3's counterexample (eq. 13 with ``C = f o d``) and, for contrast, the
    eq.-(10) DP from the same ``V_0``."""
    t0 = time.perf_counter()
    pts = grid_points(metric, n)
    d = grid_distance(metric, pts)
    c = remark3_f(d)
    dp = run_grid_dp(None, iterations=iterations, rule="sum", points=pts, cost=c)
    g = len(pts)
    stays = all(np.array_equal(v, c) for v in dp.V) and all(
        np.array_equal(p, np.repeat(np.arange(g)[:, None], g, 1)) for p in dp.pi
    )
    # how far z = x is from the true minimum of eq. (13) (no tie-break)
    tot = c[:, :, None] + c.T[None, :, :]  # (a, b, z) = C(a, z) + C(z, b)
    gap = float((c - tot.min(axis=2)).max())
    off = ~np.eye(g, dtype=bool)
    gap_to_d = float((np.abs(c - d)[off] / d[off]).max())
    sq = run_grid_dp(None, iterations=iterations, rule="squared", points=pts, cost=c)
    mask = d >= d.max() / 3
    errs = [float((np.abs(v - d)[mask] / d[mask]).max()) for v in sq.V]
    return Remark3Result(dp, stays, gap, gap_to_d, errs, wall_time=time.perf_counter() - t0)


# ----------------------------------------------------------------------------------------
# Reference distances for Proposition 1 (independent of `solvers`)
# ----------------------------------------------------------------------------------------
def polygon_distance(
    metric: Metric, x: np.ndarray, y: np.ndarray, segments: int = 8, order: int = 8
) -> float:
    """Length of the shortest ``segments``-gon from ``x`` to ``y``, each side measured by
    quadrature (eq. 58), minimised by BFGS from the straight line: an upper bound of
    ``d(x, y)`` that converges to it as ``segments`` grows (for short pairs in a region
    where ``F`` is convex, the straight start is in the basin of the geodesic)."""
    x = np.asarray(x, float).reshape(-1)
    y = np.asarray(y, float).reshape(-1)
    t = np.linspace(0, 1, segments + 1)[1:-1, None]
    z0 = (x + t * (y - x)).ravel()
    scale = max(float(np.linalg.norm(y - x)), 1e-300)

    def length(z: np.ndarray) -> float:
        p = np.vstack([x, (x + scale * z.reshape(-1, x.size)), y])
        return float(np.sum(metric.segment_length(p[:-1], p[1:], order=order)))

    def f(zr: np.ndarray) -> float:
        return length(zr) / scale

    zr0 = (z0 - np.tile(x, segments - 1)) / scale
    res = minimize(f, zr0, method="BFGS", options={"gtol": 1e-12, "maxiter": 2000})
    return min(float(res.fun), f(zr0)) * scale


def two_segment_distance(
    metric: Metric, x: np.ndarray, y: np.ndarray, n_angles: int = 720
) -> float:
    """``min_z C(x, z) + C(z, y)`` over ``z`` (2-D): an upper bound of ``d(x, y)`` up to the
    ``O(|y - x|**2)`` error of ``C``. Global search over ``z = x + r u`` on a polar grid,
    then Nelder-Mead refinement. Captures the zig-zag that realises the convexification
    ``F**`` in directions where ``F(x, .)`` is not convex."""
    x = np.asarray(x, float).reshape(2)
    y = np.asarray(y, float).reshape(2)
    s = float(np.linalg.norm(y - x))
    ang = np.linspace(0, 2 * np.pi, n_angles, endpoint=False)
    rad = s * np.linspace(0.02, 2.0, 100)
    rr, aa = np.meshgrid(rad, ang)
    z = x + np.stack([rr.ravel() * np.cos(aa.ravel()), rr.ravel() * np.sin(aa.ravel())], 1)
    z = np.vstack([z, 0.5 * (x + y)])
    tot = metric.cost(np.broadcast_to(x, z.shape), z) + metric.cost(z, np.broadcast_to(y, z.shape))
    z0 = z[int(np.argmin(tot))]

    def f(w: np.ndarray) -> float:
        zz = z0 + s * w
        return float(metric.cost(x, zz) + metric.cost(zz, y))

    res = minimize(f, np.zeros(2), method="Nelder-Mead",
                   options={"xatol": 1e-10, "fatol": 1e-14 * s, "maxiter": 4000})
    return min(float(res.fun), float(tot.min()))


# ----------------------------------------------------------------------------------------
# Proposition 1: C/d -> 1, its rate, and its failure without convexity
# ----------------------------------------------------------------------------------------
@dataclass
class Prop1Result(Result):
    """``C(x, x + t u) / d(x, x + t u)`` for shrinking ``t`` (a
    `finsler.status.Result`: ``status`` is ``passed`` if every ratio is finite and
    the ratio at the smallest ``t`` is no farther from ``limit`` than at the largest,
    ``failed`` if it is farther, ``inconclusive`` if a ratio is not finite).

    ``t (K,)``, ``ratio (K,)``, ``err = |ratio - 1|``; ``rate``: least-squares slope of
    ``log err`` against ``log t`` (``nan`` where ``err`` is at rounding level: ``C = d``);
    ``limit``: the predicted limit of the ratio (1 where ``F`` is Finsler).
    """

    metric: str
    x: np.ndarray
    u: np.ndarray
    t: np.ndarray
    ratio: np.ndarray
    err: np.ndarray
    rate: float
    limit: float
    wall_time: float = field(default=0.0, kw_only=True)
    """Seconds the measurement took."""

    @property
    def status(self) -> PropertyOutcome:  # type: ignore[override]
        ratio = np.asarray(self.ratio, dtype=np.float64)
        if ratio.size == 0 or not np.all(np.isfinite(ratio)):
            return PropertyOutcome.INCONCLUSIVE
        t = np.asarray(self.t, dtype=np.float64)
        small_t = abs(ratio[int(np.argmin(t))] - self.limit)
        large_t = abs(ratio[int(np.argmax(t))] - self.limit)
        ok = small_t <= large_t + 1e-12 * abs(self.limit)  # rounding level: C = d
        return PropertyOutcome.PASSED if ok else PropertyOutcome.FAILED


def _slope(t: np.ndarray, e: np.ndarray) -> float:
    ok = e > 1e-13
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(t[ok]), np.log(e[ok]), 1)[0])


def proposition1_rate(
    metric: Metric,
    x: np.ndarray,
    u: np.ndarray,
    ts: np.ndarray,
    distance: Callable[[np.ndarray, np.ndarray], float] | None = None,
) -> Prop1Result:
    """Measure ``C(x, y)/d(x, y) -> 1`` along ``y = x + t u``. ``d`` is the closed form if the
    metric has one, else ``distance(x, y)`` (default: `polygon_distance`)."""
    t0 = time.perf_counter()
    x = np.asarray(x, float).reshape(-1)
    u = np.asarray(u, float).reshape(-1)
    ts = np.asarray(ts, float)
    ys = x + ts[:, None] * u
    metric.domain.check(ys, "x + t u")
    c = metric.cost(np.broadcast_to(x, ys.shape), ys)
    if distance is None and metric.provides("distance"):
        d = metric.distance(np.broadcast_to(x, ys.shape), ys)
    else:
        fn = distance or (lambda a, b: polygon_distance(metric, a, b))
        d = np.array([fn(x, y) for y in ys])
    ratio = c / d
    err = np.abs(ratio - 1.0)
    return Prop1Result(metric.name, x, u, ts, ratio, err, _slope(ts, err), 1.0,
                       wall_time=time.perf_counter() - t0)


def convexified_F(metric: Metric, x: np.ndarray, v: np.ndarray, n_angles: int = 4096) -> np.ndarray:
    """``F**(x, v)``: the gauge of the convex hull of the indicatrix ``{F(x, .) <= 1}`` (the
    largest convex 1-homogeneous function below ``F(x, .)``), 2-D, for ``v (K, 2)`` -> ``(K,)``."""
    if metric.dim != 2:
        raise InputError("convexified_F is implemented for 2-D metrics")
    x = np.asarray(x, float).reshape(2)
    a = np.linspace(0, 2 * np.pi, n_angles, endpoint=False)
    dirs = np.stack([np.cos(a), np.sin(a)], 1)
    fx = metric.F(np.broadcast_to(x, dirs.shape), dirs)
    if np.any(fx <= 0):
        raise InputError("F(x, .) must be positive on unit vectors")
    hull = ConvexHull(dirs / fx[:, None])
    normals, offsets = hull.equations[:, :2], -hull.equations[:, 2]  # n . u <= b
    v = np.atleast_2d(np.asarray(v, float))
    return (v @ normals.T / offsets).max(axis=1)


def nonconvex_direction(
    metric: Metric, x: np.ndarray, n_angles: int = 720
) -> tuple[np.ndarray, float]:
    """Unit direction ``u`` maximising ``F(x, u) / F**(x, u)`` and that ratio (> 1 where
    ``F(x, .)`` is not convex)."""
    a = np.linspace(0, 2 * np.pi, n_angles, endpoint=False)
    dirs = np.stack([np.cos(a), np.sin(a)], 1)
    r = metric.F(np.broadcast_to(np.asarray(x, float), dirs.shape), dirs) / convexified_F(
        metric, x, dirs
    )
    k = int(np.argmax(r))
    return dirs[k], float(r[k])


def proposition1_nonconvex(metric: Metric, x: np.ndarray, ts: np.ndarray) -> Prop1Result:
    """Proposition 1 where ``F(x, .)`` is not convex: along the direction ``u`` where ``F``
    exceeds its convexification most, ``C/d`` does not tend to 1 but to ``F/F** > 1``. ``d`` is
    bounded above by the best two-segment zig-zag (`two_segment_distance`), so the
    reported ``ratio`` is a lower bound of ``C/d``; ``limit`` is the predicted ``F/F**``."""
    t0 = time.perf_counter()
    u, lim = nonconvex_direction(metric, x)
    x = np.asarray(x, float).reshape(2)
    ts = np.asarray(ts, float)
    ys = x + ts[:, None] * u
    metric.domain.check(ys, "x + t u")
    c = metric.cost(np.broadcast_to(x, ys.shape), ys)
    d_up = np.array([two_segment_distance(metric, x, y) for y in ys])
    ratio = c / d_up
    err = np.abs(ratio - 1.0)
    return Prop1Result(metric.name, x, u, ts, ratio, err, _slope(ts, np.abs(ratio - lim)), lim,
                       wall_time=time.perf_counter() - t0)


def _fmt(x: float) -> str:
    return "nan" if not math.isfinite(x) else f"{x:.3g}"


def format_table(rows: list[dict[str, Any]], keys: list[str]) -> str:
    """Markdown table of ``rows`` restricted to ``keys``."""
    head = "| " + " | ".join(keys) + " |\n|" + "---|" * len(keys) + "\n"
    body = "".join(
        "| "
        + " | ".join(
            _fmt(r[k]) if isinstance(r.get(k), float) else str(r.get(k, "")) for k in keys
        )
        + " |\n"
        for r in rows
    )
    return head + body
