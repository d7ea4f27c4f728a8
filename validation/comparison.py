"""Learned versus exact geodesics on a pair set: the numbers of the benchmark report.

``compare(policy, metric, pairs)`` evaluates three path sets on the same pairs, at the
task's resolution ``n = 2**D`` and threshold ``eps`` (section 5.1):

* the **learned** policy (recursive midpoint insertion, deterministic means);
* the **exact** discrete geodesics from `solvers` (globally seeded energy minimisers;
  their min-max refinement gives the success *ceiling* of the task);
* the **straight** baseline: the coordinate segment cut into ``n`` equal pieces.

and reports success rates, per-pair length ratios (method / exact, by ``sum C`` and by
quadrature), the first-level midpoint error, where paths leave the Finsler region, and
time per path. ``midpoint_error(policy, metric, pairs)`` is the midpoint part alone.

A *policy* is any object with ``generate(starts (K, dim), goals (K, dim), depth=None) ->
(K, 2**D + 1, dim)`` and ``midpoint(starts, goals) -> (K, dim)`` (e.g.
``learn.load_policy(...)``, `StraightLine`, `ExactPolicy`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import finsler
import solvers
from finsler import Metric
from finsler.errors import InputError

__all__ = [
    "Comparison",
    "ExactPolicy",
    "ExactSet",
    "MidpointErrors",
    "PathSet",
    "StraightLine",
    "compare",
    "evaluate_path_set",
    "exact_reference",
    "midpoint_error",
    "ratio_stats",
    "time_exact_single",
    "time_policy",
]


# ----------------------------------------------------------------------------------------
# policies with the learned policy's interface
# ----------------------------------------------------------------------------------------
def _check_points(metric: Metric, x: Any, name: str) -> np.ndarray:
    return metric.domain.check(x, name).astype(np.float64)


class StraightLine:
    """Trivial baseline: the straight coordinate segment cut into ``2**D`` equal pieces."""

    def __init__(self, metric: Metric, depth: int | None = None) -> None:
        self.metric = metric
        self.depth = metric.task.depth if depth is None else int(depth)
        self.eps = metric.task.eps
        self.source = "straight line"

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        """``(K, dim)`` x2 -> ``(K, 2**D + 1, dim)``."""
        s = _check_points(self.metric, starts, "starts")
        g = _check_points(self.metric, goals, "goals")
        if s.shape != g.shape:
            raise InputError(f"starts and goals differ in shape: {s.shape} vs {g.shape}")
        n = 2 ** (self.depth if depth is None else int(depth))
        t = np.linspace(0.0, 1.0, n + 1)[None, :, None]
        return s[:, None] + t * (g - s)[:, None]

    def midpoint(self, starts: Any, goals: Any) -> np.ndarray:
        """Coordinate midpoints ``(K, dim)``."""
        return self.generate(starts, goals, depth=1)[:, 1]


class ExactPolicy:
    """The exact solver seen as a policy: ``midpoint`` is ``p_{n/2}`` of the discrete
    geodesic at the task's resolution (a reference for the midpoint error: it is 0 up to
    the solver's tolerance), ``generate`` the discrete geodesic itself."""

    def __init__(self, metric: Metric, segments: int | None = None) -> None:
        self.metric = metric
        self.segments = solvers.check_segments(metric, segments)
        self.depth = self.segments.bit_length() - 1
        self.eps = metric.task.eps
        self.source = "exact (solvers)"

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        s = _check_points(self.metric, starts, "starts")
        g = _check_points(self.metric, goals, "goals")
        n = self.segments if depth is None else 2 ** int(depth)
        return np.stack([solvers.solve_geodesic(self.metric, a, b, n).points
                         for a, b in zip(s, g)])

    def midpoint(self, starts: Any, goals: Any) -> np.ndarray:
        s = _check_points(self.metric, starts, "starts")
        g = _check_points(self.metric, goals, "goals")
        return np.stack([solvers.midpoint(self.metric, a, b, self.segments).point
                         for a, b in zip(s, g)])


# ----------------------------------------------------------------------------------------
# path sets
# ----------------------------------------------------------------------------------------
@dataclass
class PathSet:
    """Paths of one method on ``K`` pairs, evaluated in float64.

    ``paths (K, n+1, dim)``; ``segment_costs (K, n)``; ``length (K,)`` = ``sum C`` (eq. 4);
    ``length_quadrature (K,)`` (eq. 58 per segment, an upper bound of the length where
    ``F`` is Finsler); ``max_segment_cost (K,)``; ``success (K,)`` iff every cost ``<= eps``;
    ``nonconvex_fraction (K,)``: share of path points where ``F(x, .)`` is not convex;
    ``seconds_per_path``: wall time to produce one path.
    """

    name: str
    paths: np.ndarray
    segment_costs: np.ndarray
    length: np.ndarray
    length_quadrature: np.ndarray
    max_segment_cost: np.ndarray
    success: np.ndarray
    nonconvex_fraction: np.ndarray
    seconds_per_path: float

    @property
    def success_rate(self) -> float:
        return float(np.mean(self.success))


def evaluate_path_set(
    metric: Metric, name: str, paths: np.ndarray, eps: float, seconds_per_path: float = np.nan
) -> PathSet:
    """Evaluate paths ``(K, n+1, dim)`` with the task threshold ``eps``."""
    if not (np.isfinite(eps) and eps > 0):
        raise InputError(f"eps must be positive and finite, got {eps!r}")
    paths = np.asarray(paths, dtype=np.float64)
    if paths.ndim != 3 or paths.shape[2] != metric.dim or paths.shape[1] < 2:
        raise InputError(f"paths must have shape (K, n+1, {metric.dim}), got {paths.shape}")
    if not np.all(np.isfinite(paths)):
        raise InputError(f"{name} paths contain NaN or inf")
    costs = metric.path_costs(paths)
    k, m, dim = paths.shape
    # eq. (58) lengths by adaptive quadrature to 1e-10 (Metric.path_length_error), not a
    # fixed order that can be percent-wrong on long segments
    quad = np.asarray(metric.path_length_error(paths).value).reshape(k)
    if metric.convex_everywhere:
        ncf = np.zeros(k)
    else:
        conv = metric.convexity(metric.domain.project(paths.reshape(-1, dim)), n_directions=32)
        ncf = (conv.reshape(k, m) < 0).mean(axis=1)
    mx = costs.max(axis=1)
    return PathSet(name, paths, costs, costs.sum(1), quad, mx, mx <= eps, ncf,
                   float(seconds_per_path))


@dataclass
class ExactSet(PathSet):
    """Exact discrete geodesics (energy minimisers) with their solver diagnostics.

    ``minmax_max_segment_cost (K,)``: largest segment cost after the min-max refinement;
    ``ceiling (K,)``: the task is solvable at this resolution (that cost ``<= eps``);
    ``status``: solver status per pair (`solvers.Status.label`); ``converged (K,)``;
    ``seeds_tried``/``seeds_agreeing``.
    """

    minmax_max_segment_cost: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ceiling: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    status: list[str] = field(default_factory=list)
    converged: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    seeds_tried: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    seeds_agreeing: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    wall_time: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def ceiling_rate(self) -> float:
        return float(np.mean(self.ceiling))


def exact_reference(
    metric: Metric,
    pairs: np.ndarray,
    segments: int | None = None,
    eps: float | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> ExactSet:
    """Solve every pair with [`solvers.solve_batch`][solvers.solve_batch] (min-max refinement on) at
    ``segments`` (default ``2**D``) and evaluate the paths; ``eps`` defaults to the task's."""
    arr = solvers.check_pairs(metric, pairs)
    n = solvers.check_segments(metric, segments)
    eps = metric.task.eps if eps is None else float(eps)
    results = solvers.solve_batch(metric, arr, n, minmax=True, workers=workers,
                                  progress=progress)
    paths = np.stack([r.points for r in results])
    wall = np.array([r.wall_time for r in results])
    base = evaluate_path_set(metric, "exact", paths, eps, float(wall.mean()))
    mm = np.array([r.minmax.max_segment_cost if r.minmax is not None else r.max_segment_cost
                   for r in results])
    return ExactSet(
        **{f: getattr(base, f) for f in PathSet.__dataclass_fields__},
        minmax_max_segment_cost=mm,
        ceiling=mm <= eps,
        status=[r.status.label for r in results],
        converged=np.array([r.converged for r in results]),
        seeds_tried=np.array([r.seeds_tried for r in results]),
        seeds_agreeing=np.array([r.seeds_agreeing for r in results]),
        wall_time=wall,
    )


def ratio_stats(r: np.ndarray) -> dict[str, float]:
    """``mean``, ``median``, ``p95``, ``max``, ``min`` and ``count`` of finite ratios."""
    r = np.asarray(r, float)
    r = r[np.isfinite(r)]
    if r.size == 0:
        return {k: float("nan") for k in ("mean", "median", "p95", "max", "min")} | {"count": 0}
    return {
        "mean": float(r.mean()),
        "median": float(np.median(r)),
        "p95": float(np.percentile(r, 95)),
        "max": float(r.max()),
        "min": float(r.min()),
        "count": int(r.size),
    }


# ----------------------------------------------------------------------------------------
# midpoint error
# ----------------------------------------------------------------------------------------
@dataclass
class MidpointErrors:
    """First-level midpoint error of ``m = pi(s, g)``.

    ``d_sg`` is the exact discrete geodesic length at ``segments`` (``n``); ``d_sm`` and
    ``d_mg`` those of the halves at ``n/2`` (the same resolution: for the exact discrete
    midpoint ``p_{n/2}`` they add up to ``d_sg`` and the error is 0).
    ``err_start = |d_sm - d_sg/2| / d_sg``, ``err_goal = |d_mg - d_sg/2| / d_sg`` (all
    ``(K,)``). ``ok (K,)``: all three solves converged (statistics use these pairs).
    ``continuum_*``: the same with [`solvers.distance`][solvers.distance] where it converged (the
    metric is Finsler along the path), NaN elsewhere; ``continuum_status`` per pair.
    """

    midpoints: np.ndarray
    segments: int
    d_sg: np.ndarray
    d_sm: np.ndarray
    d_mg: np.ndarray
    err_start: np.ndarray
    err_goal: np.ndarray
    ok: np.ndarray
    status: list[tuple[str, str, str]]
    continuum_d_sg: np.ndarray | None = None
    continuum_d_sm: np.ndarray | None = None
    continuum_d_mg: np.ndarray | None = None
    continuum_err_start: np.ndarray | None = None
    continuum_err_goal: np.ndarray | None = None
    continuum_status: list[str] | None = None

    @property
    def err_max(self) -> np.ndarray:
        """``max(err_start, err_goal)`` per pair ``(K,)``."""
        return np.maximum(self.err_start, self.err_goal)

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "segments": self.segments,
            "pairs_used": int(self.ok.sum()),
            "pairs": len(self.ok),
            "err_start": ratio_stats(self.err_start[self.ok]),
            "err_goal": ratio_stats(self.err_goal[self.ok]),
            "err_max": ratio_stats(self.err_max[self.ok]),
        }
        if self.continuum_err_start is not None:
            e = np.maximum(self.continuum_err_start, self.continuum_err_goal)
            out["continuum"] = {
                "pairs_used": int(np.isfinite(e).sum()),
                "err_max": ratio_stats(e),
                "status_counts": _counts(self.continuum_status or []),
            }
        return out


def _counts(items: list[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for s in items:
        out[s] = out.get(s, 0) + 1
    return out


def _policy_midpoints(policy: Any, metric: Metric, pairs: np.ndarray) -> np.ndarray:
    m = np.asarray(policy.midpoint(pairs[:, 0], pairs[:, 1]), dtype=np.float64)
    if m.shape != (len(pairs), metric.dim):
        raise InputError(f"policy.midpoint returned shape {m.shape}, expected "
                         f"({len(pairs)}, {metric.dim})")
    return _check_points(metric, m, "predicted midpoints")


def _continuum(metric: Metric, s: np.ndarray, g: np.ndarray) -> tuple[float, str]:
    try:
        r = solvers.distance(metric, s, g)
    except NotImplementedError:
        return float("nan"), "unavailable"
    return (float(r.distance) if r.converged else float("nan")), r.status.label


def midpoint_error(
    policy: Any,
    metric: Metric | str,
    pairs: Any = None,
    *,
    segments: int | None = None,
    exact: ExactSet | None = None,
    continuum: bool = False,
    workers: int | None = None,
    progress: bool = True,
) -> MidpointErrors:
    """Midpoint error of the first-level prediction ``m = policy.midpoint(s, g)`` on
    ``pairs (K, 2, dim)`` (default: the environment's evaluation set), against exact
    discrete geodesic lengths (``exact`` may supply ``d(s, g)`` already solved at
    ``segments``). ``continuum=True`` adds the continuum distances of
    [`solvers.distance`][solvers.distance] where they converge."""
    m = finsler.get_metric(metric)
    arr = solvers.check_pairs(m, finsler.default_pairs(m) if pairs is None else pairs)
    n = solvers.check_segments(m, segments)
    if n % 2:
        raise InputError(f"the midpoint error needs an even number of segments, got {n}")
    mids = _policy_midpoints(policy, m, arr)
    if exact is None:
        exact = exact_reference(m, arr, n, workers=workers, progress=progress)
    elif exact.paths.shape[:2] != (len(arr), n + 1) or not np.allclose(
        exact.paths[:, [0, -1]], arr
    ):
        raise InputError("the exact reference does not match the pairs and segments")
    halves = np.concatenate([np.stack([arr[:, 0], mids], 1), np.stack([mids, arr[:, 1]], 1)])
    res = solvers.solve_batch(m, halves, n // 2, workers=workers, progress=progress)
    k = len(arr)
    d_sm = np.array([r.length for r in res[:k]])
    d_mg = np.array([r.length for r in res[k:]])
    d_sg = exact.length
    ok = exact.converged & np.array([r.converged for r in res[:k]]) & np.array(
        [r.converged for r in res[k:]]
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        e_s = np.abs(d_sm - 0.5 * d_sg) / d_sg
        e_g = np.abs(d_mg - 0.5 * d_sg) / d_sg
    out = MidpointErrors(
        midpoints=mids, segments=n, d_sg=d_sg, d_sm=d_sm, d_mg=d_mg, err_start=e_s,
        err_goal=e_g, ok=ok & (d_sg > 0),
        status=[(exact.status[i], res[i].status.label, res[k + i].status.label)
                for i in range(k)],
    )
    if continuum:
        cs, cm, cg, st = [], [], [], []
        for i in range(k):
            a, sa = _continuum(m, arr[i, 0], arr[i, 1])
            b, sb, c, sc = np.nan, sa, np.nan, sa
            if np.isfinite(a):  # the halves only where d(s, g) itself converged
                b, sb = _continuum(m, arr[i, 0], mids[i])
                c, sc = _continuum(m, mids[i], arr[i, 1])
            cs.append(a)
            cm.append(b)
            cg.append(c)
            st.append(sa if sa != "converged" else (sb if sb != "converged" else sc))
        cs_, cm_, cg_ = np.array(cs), np.array(cm), np.array(cg)
        with np.errstate(invalid="ignore", divide="ignore"):
            out.continuum_d_sg, out.continuum_d_sm, out.continuum_d_mg = cs_, cm_, cg_
            out.continuum_err_start = np.abs(cm_ - 0.5 * cs_) / cs_
            out.continuum_err_goal = np.abs(cg_ - 0.5 * cs_) / cs_
        out.continuum_status = st
    return out


# ----------------------------------------------------------------------------------------
# the comparison
# ----------------------------------------------------------------------------------------
@dataclass
class Comparison:
    """Everything `compare` measured; `to_dict` is the ``report.json`` body."""

    metric: str
    eps: float
    depth: int
    pairs: np.ndarray
    learned: PathSet
    straight: PathSet
    exact: ExactSet
    midpoint: MidpointErrors | None
    policy_source: str = ""
    timing: dict[str, float] = field(default_factory=dict)
    searched: PathSet | None = None
    """The policy's paths with the route search (`learn.Policy.search`), if asked."""
    search: dict[str, Any] | None = None
    """The search's settings and its evaluations of C per path."""

    @property
    def success_rate(self) -> dict[str, float]:
        """Share of pairs whose every segment cost is ``<= eps``: ``learned``,
        ``exact_ceiling`` (the min-max refined exact path: the task's ceiling),
        ``exact_energy_path``, ``straight`` and, with the route search, ``searched`` (the
        same numbers as ``to_dict()["success_rate"]``)."""
        out = {"learned": self.learned.success_rate, "exact_ceiling": self.exact.ceiling_rate,
               "exact_energy_path": self.exact.success_rate,
               "straight": self.straight.success_rate}
        if self.searched is not None:
            out["searched"] = self.searched.success_rate
        return out

    def __repr__(self) -> str:
        sr = self.success_rate
        med = ratio_stats(self.ratios("learned"))["median"]
        search = f", searched {sr['searched']:.0%}" if "searched" in sr else ""
        return (f"Comparison(metric={self.metric!r}, pairs={len(self.pairs)}, "
                f"segments={2**self.depth}, eps={self.eps:g}: success learned "
                f"{sr['learned']:.0%}{search}, exact ceiling {sr['exact_ceiling']:.0%}, "
                f"straight {sr['straight']:.0%}; learned/exact length median {med:.4g})")

    @property
    def methods(self) -> tuple[str, ...]:
        """The path sets compared with the exact ones."""
        return ("learned", "searched", "straight") if self.searched is not None else (
            "learned", "straight")

    def _means(self, attr: str) -> dict[str, float]:
        """Mean of one per-pair field for every path set."""
        return {w: float(getattr(getattr(self, w), attr).mean())
                for w in (*self.methods, "exact")}

    def ratios(self, which: str, measure: str = "length") -> np.ndarray:
        """Per-pair ratio ``which / exact`` of ``length`` or ``length_quadrature`` ``(K,)``
        (NaN where the exact solve did not converge or the exact length is 0)."""
        if which not in self.methods:
            raise InputError(f"no {which!r} paths in this comparison; have "
                             f"{', '.join(self.methods)}")
        ps = getattr(self, which)
        num = getattr(ps, measure)
        den = getattr(self.exact, measure)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = num / den
        return np.where(self.exact.converged & (den > 0), r, np.nan)

    def to_dict(self) -> dict[str, Any]:
        ratios = {
            w: {ms: ratio_stats(self.ratios(w, ms)) for ms in ("length", "length_quadrature")}
            for w in self.methods
        }
        per_pair = []
        for i in range(len(self.pairs)):
            row = {
                "start": self.pairs[i, 0].tolist(),
                "goal": self.pairs[i, 1].tolist(),
                "learned_success": bool(self.learned.success[i]),
                "learned_length": float(self.learned.length[i]),
                "learned_length_quadrature": float(self.learned.length_quadrature[i]),
                "learned_max_segment_cost": float(self.learned.max_segment_cost[i]),
                "straight_success": bool(self.straight.success[i]),
                "straight_length": float(self.straight.length[i]),
                "exact_length": float(self.exact.length[i]),
                "exact_length_quadrature": float(self.exact.length_quadrature[i]),
                "exact_max_segment_cost": float(self.exact.max_segment_cost[i]),
                "exact_minmax_max_segment_cost": float(self.exact.minmax_max_segment_cost[i]),
                "exact_ceiling": bool(self.exact.ceiling[i]),
                "exact_status": self.exact.status[i],
                "exact_seconds": float(self.exact.wall_time[i]),
            }
            if self.searched is not None:
                row["searched_success"] = bool(self.searched.success[i])
                row["searched_length"] = float(self.searched.length[i])
                row["searched_max_segment_cost"] = float(self.searched.max_segment_cost[i])
            if self.midpoint is not None:
                row["midpoint_err_start"] = _num(self.midpoint.err_start[i])
                row["midpoint_err_goal"] = _num(self.midpoint.err_goal[i])
            per_pair.append(row)
        out: dict[str, Any] = {
            "metric": self.metric,
            "eps": self.eps,
            "depth": self.depth,
            "segments": 2**self.depth,
            "pairs": len(self.pairs),
            "policy": self.policy_source,
            "success_rate": self.success_rate,
            "mean_length": self._means("length"),
            "mean_max_segment_cost": self._means("max_segment_cost"),
            "length_ratio": ratios,
            "exact_solver": {
                "converged": int(self.exact.converged.sum()),
                "status_counts": _counts(self.exact.status),
                "mean_seeds_tried": float(self.exact.seeds_tried.mean()),
                "mean_seeds_agreeing": float(self.exact.seeds_agreeing.mean()),
            },
            "nonconvex_point_fraction": self._means("nonconvex_fraction"),
            "timing": dict(self.timing),
            "per_pair": per_pair,
        }
        if self.searched is not None:
            out["search"] = dict(self.search or {})
        if self.midpoint is not None:
            out["midpoint_error"] = self.midpoint.summary()
        return out


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


#: Batch sizes at which `time_policy` times a policy (the report's table).
TIMING_BATCHES = (1, 100, 10_000)
#: torch threads while timing: one, so that a time does not depend on what else the
#: machine runs (a shared machine's other jobs take the other cores).
TIMING_THREADS = 1


def time_policy(policy: Any, pairs: np.ndarray, depth: int,
                batches: tuple[int, ...] = TIMING_BATCHES, repeats: int = 5,
                threads: int = TIMING_THREADS, progress: bool = False) -> dict[str, Any]:
    """Seconds per path of ``policy.generate`` at each batch size of ``batches``: the
    pairs ``(K, 2, dim)`` repeated up to the batch size, one warm-up call, then the median
    of ``repeats`` timed calls (21 single-pair calls over different pairs for batch 1),
    with torch limited to ``threads`` threads (restored after); ``progress``: a bar over
    the batch sizes. Returns ``{"threads", "repeats", "seconds_per_path": {batch:
    seconds}}``."""
    from tqdm.auto import tqdm

    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency of learn
        torch = None
    old = torch.get_num_threads() if torch is not None else None
    if torch is not None:
        torch.set_num_threads(int(threads))
    per_path: dict[int, float] = {}
    try:
        for b in tqdm(batches, desc="time the policy (batches)", disable=not progress,
                      leave=False):
            idx = np.arange(b) % len(pairs)
            calls = [idx] * repeats if b > 1 else [np.array([i % len(pairs)])
                                                   for i in range(21)]
            policy.generate(pairs[calls[0], 0], pairs[calls[0], 1], depth=depth)  # warm up
            times = []
            for sel in calls:
                t0 = time.perf_counter()
                policy.generate(pairs[sel, 0], pairs[sel, 1], depth=depth)
                times.append((time.perf_counter() - t0) / len(sel))
            per_path[int(b)] = float(np.median(times))
    finally:
        if torch is not None:
            torch.set_num_threads(old)
    return {"threads": int(threads), "repeats": int(repeats), "seconds_per_path": per_path}


def time_exact_single(metric: Metric, pairs: np.ndarray, segments: int, k: int = 3) -> float:
    """Median wall time of `solvers.solve_geodesic` (min-max on, as the report's exact
    set) on the first ``k`` pairs one at a time: the exact time per path at batch 1."""
    times = []
    for s, g in pairs[:k]:
        t0 = time.perf_counter()
        solvers.solve_geodesic(metric, s, g, segments, minmax=True)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def compare(
    policy: Any,
    metric: Metric | str | None = None,
    pairs: Any = None,
    *,
    eps: float | None = None,
    depth: int | None = None,
    exact: ExactSet | None = None,
    midpoint: bool = True,
    continuum: bool = False,
    workers: int | None = None,
    progress: bool = True,
    search: Any = None,
    timing_batches: tuple[int, ...] = TIMING_BATCHES,
    timing_repeats: int = 5,
    exact_single: int = 0,
) -> Comparison:
    """Compare ``policy`` with exact geodesics and the straight baseline on ``pairs``
    ``(K, 2, dim)`` (default: ``finsler.default_pairs``), at depth ``D`` (default: the
    policy's, else the task's) and threshold ``eps`` (default: the policy's, else the
    task's). ``exact`` reuses solved references; ``midpoint`` adds the first-level midpoint
    error; ``continuum`` adds continuum distances where the metric is Finsler. ``search``
    (a [`learn.SearchSpec`][learn.SearchSpec], for a policy with a ``search`` method) adds the paths
    of the policy-guided route search as a fourth set, ``searched``.

    ``timing``: the policy's seconds per path at each of ``timing_batches``
    (`time_policy`: warm, median of ``timing_repeats``, one torch thread), the exact
    batched solve's share per path, the exact solve of one pair at a time (median over
    ``exact_single`` pairs; 0: not measured) and the speed-ups."""
    m = finsler.get_metric(metric if metric is not None else policy.metric)
    arr = solvers.check_pairs(m, finsler.default_pairs(m) if pairs is None else pairs)
    d = int(depth if depth is not None else getattr(policy, "depth", m.task.depth))
    e = float(eps if eps is not None else getattr(policy, "eps", m.task.eps))
    if d < 1:
        raise InputError(f"depth must be >= 1, got {d}")
    if not (np.isfinite(e) and e > 0):
        raise InputError(f"eps must be positive and finite, got {e!r}")
    n = 2**d
    policy.generate(arr[:1, 0], arr[:1, 1], depth=d)  # warm up (lazy compilation)
    paths = np.asarray(policy.generate(arr[:, 0], arr[:, 1], depth=d), dtype=np.float64)
    learned_time = time_policy(policy, arr, d, timing_batches, timing_repeats,
                               progress=progress)
    per_batch = learned_time["seconds_per_path"]
    per_path = per_batch.get(len(arr), per_batch[max(per_batch)])
    if paths.shape != (len(arr), n + 1, m.dim):
        raise InputError(f"policy.generate returned shape {paths.shape}, expected "
                         f"({len(arr)}, {n + 1}, {m.dim})")
    learned = evaluate_path_set(m, "learned", paths, e, per_path)
    searched, search_info, search_time = None, None, {}
    if search is not None:
        if not callable(getattr(policy, "search", None)):
            raise InputError(f"the route search needs a midpoint policy with a search "
                             f"method; {type(policy).__name__} has none")
        t0 = time.perf_counter()
        res = policy.search(arr[:, 0], arr[:, 1], search, depth=d, eps=e)
        sec = (time.perf_counter() - t0) / len(arr)
        searched = evaluate_path_set(m, "searched", res.paths, e, sec)
        search_info = {**search.to_dict(), "evaluations_of_C_per_path":
                       res.evaluations_per_path, "candidates_per_level": search.candidates,
                       "uses_derivative_of_C": False}
        search_time = {"searched_seconds_per_path_batched": sec}
    straight_pol = StraightLine(m, d)
    t0 = time.perf_counter()
    spaths = straight_pol.generate(arr[:, 0], arr[:, 1])
    straight = evaluate_path_set(m, "straight", spaths, e, (time.perf_counter() - t0) / len(arr))
    if exact is None:
        exact = exact_reference(m, arr, n, e, workers=workers, progress=progress)
    else:
        if exact.paths.shape != (len(arr), n + 1, m.dim) or not np.allclose(
            exact.paths[:, [0, -1]], arr
        ):
            raise InputError("the exact reference does not match the pairs and depth")
        exact.ceiling = exact.minmax_max_segment_cost <= e
    mid = None
    if midpoint:
        mid = midpoint_error(policy, m, arr, segments=n, exact=exact, continuum=continuum,
                             workers=workers, progress=progress)
    exact_batch = float(exact.wall_time.mean())
    exact_one = time_exact_single(m, arr, n, exact_single) if exact_single > 0 else None
    single = per_batch.get(1)
    largest = max(per_batch)
    timing: dict[str, Any] = {
        "threads": learned_time["threads"],
        "repeats": learned_time["repeats"],
        "learned_seconds_per_path": {str(b): t for b, t in per_batch.items()},
        "learned_seconds_per_path_batched": per_batch[largest],
        "learned_batch": largest,
        "learned_seconds_per_path_single": single,
        "exact_seconds_per_path": exact_batch,
        "exact_batch": len(arr),
        "exact_seconds_per_path_single": exact_one,
        "speedup_batched": exact_batch / per_batch[largest],
        "speedup_single": (exact_one if exact_one is not None else exact_batch) / single
        if single else None,
        **search_time,
    }
    if searched is not None:
        timing["speedup_searched"] = float(exact.wall_time.mean()
                                           / timing["searched_seconds_per_path_batched"])
    return Comparison(m.name, e, d, arr, learned, straight, exact, mid,
                      str(getattr(policy, "source", type(policy).__name__)), timing,
                      searched, search_info)
