"""A conformal factor that is a sum, bounded part by part.

When the factor is a sum ``f = sum_k a_k`` of nonnegative parts, a path's length splits the
same way, ``int f |q'| = sum_k int a_k |q'|``, so ``d(x, y) >= sum_k lower_k`` where
``lower_k`` bounds the ``a_k``-length of every path that can matter (those of ``F``-length
at most the upper bound ``U``). A part depending on fewer coordinates is bounded in fewer
dimensions, where the boxes of `solvers.certificates.conformal.certificate.certify_conformal`
resolve it: its other coordinates are cyclic for it (Clairaut's momentum), and its region is the
ellipsoid of paths whose Euclidean length is at most ``U / m`` (``m`` the smallest ``f``
the full run proved over its region). A constant part ``c`` contributes exactly ``c |y - x|``.

The Panda pole factor (eq. 60) is ``1 + 7.5 + sum_i rho_i**(-1/2)`` over the seven moving
frames: frame 3 depends on ``q1, q2``, frame 4 on ``q1..q3``, frames 5 and 6 on ``q1..q4``,
the last three on ``q1..q6``. The parts are found in the factor's CasADi expression (its
top-level sum, terms grouped by the coordinates they depend on), not from the metric's name.

The constant is shared among the parts (in proportion to their lengths along the solver's
path): a part ``a_k + c_k`` prefers straighter paths, so the parts disagree less. Beside
the split, the whole factor is bounded the same way in at most 4 coordinates (the others
it varies least with, on Panda ``q5, q6``, spanning their whole range): no split loss,
only the projection's. The bound is the largest of the split one, that one and the full
run's own (on Panda each of the three is the best on some pairs; the figures are in
``docs/guides/certify.md`` and the ``certify_panda`` results under ``benchmarks/results/``,
written by ``benchmarks/certify_panda.py``). Soundness: each part's
bound is that module's (verified potential, outward-rounded enclosures) for the part's
factor; a part whose enclosure over the domain dips below 0 (an outward-rounded square)
is raised by that minimum and the constant lowered as much (rounded down), so every part
is >= 0 (the enclosures' clamp at 0 stays sound); if the constant would go negative the
factor is not split. Limits: the parts choose their paths independently (``sum_k min <=
min sum_k``), so the split bound is below the distance by what the parts disagree on.

Grouping (default): parts whose coordinates are nested (Panda: ``q1, q2`` in ``q1..q3`` in
``q1..q4``) are bounded as one part in the largest one's coordinates: no extra dimension,
and they no longer disagree (on Panda two groups bound more than four parts at the same
budget).

Front door: `certify_conformal_best` (what `solvers.certify` and ``geodesics
certify`` run on a conformal metric of dimension > 3) shares one work budget among the
runs and returns a `SplitCertifyResult` (a `ConformalCertifyResult` whose
bound is the best of the three) whether or not the factor has parts.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from finsler.enclosures.intervals import Interval, enclose
from finsler.errors import InputError
from finsler.lowering import lower
from finsler.metrics.base import Metric
from finsler.status import CertifyStatus
from solvers.certificates.conformal.certificate import (
    ConformalCertifyResult,
    ConformalSpec,
    certify_conformal,
)
from solvers.inputs import as_metric

__all__ = ["SplitCertifyResult", "certify_conformal_best", "certify_conformal_split",
           "factor_parts"]

_SLACK = 1e-9


@dataclass
class SplitCertifyResult(ConformalCertifyResult):
    """A `ConformalCertifyResult` (its fields those of the full run, except the
    bound and the work, which are the combination's) with the runs it combines: ``full``
    (the whole factor in all its coordinates), the split bound ``split_lower`` (the sum of
    the parts' bounds ``parts``, part ``k`` in ``part_dims[k]`` coordinates with the share
    ``shares[k]`` of the constant ``constant``; ``constant |y - x|`` when the factor has no
    other part), ``merged`` the run on the whole factor with its weakest coordinates
    projected out (None when it has at most ``max_dims``). ``lower = max(full.lower,
    min(split_lower, upper), merged.lower)``, ``bound_by`` which of them (``full`` |
    ``split`` | ``merged``); ``method`` and ``stopped_by`` are that run's; ``enclosures``,
    ``boxes``, ``cells``, ``rounds``, ``cone_programs`` and ``times`` add up all runs.
    ``status``: ``certified`` when the gap is at most the spec's ``target_gap``,
    ``lp_failed`` when the counting bound's cone program failed (the bound is then the
    trivial one, still sound), else ``budget_reached``."""

    split_lower: float
    constant: float
    full: ConformalCertifyResult = field(repr=False)
    parts: list[ConformalCertifyResult] = field(repr=False)
    part_dims: list[int]
    shares: list[float]
    merged: ConformalCertifyResult | None = field(repr=False)
    bound_by: str


def factor_parts(metric: Metric) -> tuple[float, list[tuple[tuple[int, ...], Any]]]:
    """The conformal factor's top-level sum: ``(constant, [(coordinates, expression)])``,
    the nonconstant terms grouped by the coordinates they depend on, as SX expressions of
    a symbol ``q`` (returned as the callables' closure), each part raised by its proven
    minimum over the domain where that is below 0 and the constant lowered as much;
    ``(0, [])`` when the constant would then be negative (or the factor is one term)."""
    def build() -> Any:
        q = ca.SX.sym("q", metric.dim)
        f = ca.SX(metric.conformal_factor_sx(q))

        def terms(e: ca.SX) -> list[ca.SX]:
            if e.is_op(ca.OP_ADD):
                return terms(e.dep(0)) + terms(e.dep(1))
            return [e]

        const, groups = 0.0, {}
        for t in terms(f):
            if t.is_constant():
                const += float(ca.DM(t))
                continue
            dep = tuple(i for i in range(metric.dim) if ca.depends_on(t, q[i]))
            groups[dep] = groups.get(dep, ca.SX(0.0)) + t
        if len(groups) < 2 and const == 0.0:
            return 0.0, []
        lo, hi = (np.asarray(b, float)[None] for b in metric.domain.bounds())
        low = {}
        for dep, expr in groups.items():  # each part's proven minimum over the domain
            with np.errstate(all="ignore"):
                (val,) = enclose(lower(ca.Function("part", [q], [expr])), Interval(lo, hi))
            low[dep] = float(np.min(val[0].lo))
            if not math.isfinite(low[dep]):
                return 0.0, []
        # a part below 0 somewhere (an outward-rounded -1e-300 of a square, say) is raised
        # by its minimum, taken from the constant: parts >= 0 (their enclosures' clamp),
        # the constant rounded down, the same sum
        shift = {dep: min(v, 0.0) for dep, v in low.items()}
        total = const + sum(shift.values())
        if shift and min(shift.values()) < 0.0:
            total -= 4 * (len(shift) + 1) * 2.0**-53 * (abs(const) + sum(map(abs,
                                                                            shift.values())))
        if not total >= 0.0:
            return 0.0, []
        return max(total, 0.0), [(dep, ca.Function(f"part_{k}", [q], [e - shift[dep]]))
                                 for k, (dep, e) in enumerate(sorted(groups.items()))]
    return metric.derived("certify.conformal_parts", build)


def _shares(const: float, parts: list[tuple[tuple[int, ...], Any]], path: np.ndarray
            ) -> np.ndarray:
    """The constant shared among the parts in proportion to their lengths along the
    solver's path (midpoint rule; any shares summing to at most the constant are sound: a
    part with a constant ``c_k`` is bounded by at least ``c_k |y - x|`` more, and the
    constant pulls each part's own best path towards the others')."""
    mids = 0.5 * (path[1:] + path[:-1])
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    lengths = np.array([float(np.sum(np.asarray(fn(mids.T), float).reshape(-1) * seg))
                        for _, fn in parts])
    lengths = np.where(np.isfinite(lengths) & (lengths > 0.0), lengths, 0.0)
    lengths[lengths <= 1e-12 * float(np.sum(lengths))] = 0.0  # none along the path
    if not float(np.sum(lengths)) > 0.0:
        return np.full(len(parts), const / len(parts)) * (1.0 - _SLACK)
    return const * lengths / float(np.sum(lengths)) * (1.0 - _SLACK)


def _projected(metric: Metric, dep: tuple[int, ...], fn: ca.Function, max_dims: int
               ) -> tuple[int, ...]:
    """The coordinates of a part to bound over their whole range so that at most
    ``max_dims`` remain: those the part varies least with (mean ``|da/dq_j|`` times the
    domain's width, on 256 points of a fixed sample)."""
    if len(dep) <= max_dims:
        return ()
    q = ca.SX.sym("q", metric.dim)
    grad = ca.Function("grad", [q], [ca.gradient(fn(q), q)])
    pts = metric.domain.sample(256, np.random.default_rng(0))
    g = np.abs(np.asarray(grad(pts.T), float))  # (dim, 256)
    lo, hi = (np.asarray(b, float) for b in metric.domain.bounds())
    weight = np.nanmean(g, axis=1) * (hi - lo)
    order = sorted(dep, key=lambda j: (weight[j], j))
    return tuple(sorted(order[:len(dep) - max_dims]))


def _grouped(parts: list[tuple[tuple[int, ...], Any]], max_dims: int
             ) -> list[tuple[tuple[int, ...], Any]]:
    """Parts merged (in the order of their coordinate tuples) while their coordinates are
    nested (one part's among the other's) and number at most ``max_dims``: the merged
    part is bounded in the coordinates its largest member needs anyway, and loses nothing
    to its members choosing different paths (Panda: the frames on ``q1, q2``, ``q1..q3``
    and ``q1..q4`` become one part). Parts on disjoint coordinates stay apart (merged,
    each would need the other's dimensions)."""
    out: list[tuple[tuple[int, ...], list[Any]]] = []
    for dep, fn in parts:
        if out and (set(out[-1][0]) <= set(dep) or set(dep) <= set(out[-1][0])) and len(
                set(out[-1][0]) | set(dep)) <= max_dims:
            out[-1] = (tuple(sorted(set(out[-1][0]) | set(dep))), [*out[-1][1], fn])
        else:
            out.append((dep, [fn]))
    merged = []
    for dep, fns in out:
        if len(fns) == 1:
            merged.append((dep, fns[0]))
            continue
        q = ca.SX.sym("q", fns[0].size1_in(0))
        merged.append((dep, ca.Function("_and_".join(f.name() for f in fns), [q],
                                        [sum((f(q) for f in fns), ca.SX(0.0))])))
    return merged


def certify_conformal_split(metric: Metric | str, start: Any, goal: Any,
                            spec: ConformalSpec | None = None, *, part_spec:
                            ConformalSpec | None = None, path: Any = None,
                            max_dims: int = 4, merged_spec: ConformalSpec | None = None,
                            group: bool = True) -> SplitCertifyResult:
    """Lower bound of ``d(start, goal)`` on a conformal metric whose factor is a sum of
    parts (see the module docstring): the full run with ``spec``, then every part with
    ``part_spec`` (default ``spec``) on the full run's path and region, in at most
    ``max_dims`` coordinates (the others it varies least with are bounded over their whole
    range: the part's minimum over them, a smaller factor in fewer dimensions); with
    ``group``, parts whose coordinates together number at most ``max_dims`` are bounded
    as one. Then the whole factor the same way (``merged``, with ``merged_spec``, default
    ``part_spec``): no loss from the parts choosing different paths, only the
    projection's. A factor without parts (one term, or a constant) gets the full run
    alone, in the same result type."""
    t0 = time.perf_counter()
    m = as_metric(metric)
    spec = spec or ConformalSpec()
    full = certify_conformal(m, start, goal, spec, path=path)
    x, y = np.asarray(start, float), np.asarray(goal, float)
    dist = float(np.linalg.norm(y - x))
    const, parts = factor_parts(m)
    if group:
        parts = _grouped(parts, max_dims)
    upper = full.upper
    results: list[ConformalCertifyResult] = []
    dims: list[int] = []
    shares: Any = []
    split = const * dist * (1.0 - _SLACK)
    euclid = (upper / full.min_factor * (1.0 + _SLACK)  # any path of F-length <= U
              if full.min_factor > 0.0 else math.inf)
    if not parts and const == 0.0:
        split = 0.0
    elif full.min_factor > 0.0:
        shares = _shares(const, parts, full.path) if parts else []
        split = 0.0 if parts else split
        # a part without length along the solver's path has no share either: left out
        # (bound 0, sound; it could add at most its length along that path, 0)
        parts = [p for p, c in zip(parts, shares, strict=True) if c > 0.0]
        shares = [c for c in shares if c > 0.0]
        for k, (dep, fn) in enumerate(parts):
            project = _projected(m, dep, fn, max_dims)
            c = float(shares[k])
            r = certify_conformal(
                m, x, y, part_spec or spec, path=full.path,
                part=(lambda q, fn=fn, c=c: fn(q) + c, f".part{k}.{fn.name()}.{c!r}",
                      euclid, project))
            results.append(r)
            dims.append(len(dep) - len(project))
            split += r.lower
    merged = None
    if full.min_factor > 0.0:  # the whole factor, its weakest coordinates projected out
        q = ca.SX.sym("q", m.dim)
        whole = ca.Function("whole", [q], [ca.SX(m.conformal_factor_sx(q))])
        dep = tuple(i for i in range(m.dim) if ca.depends_on(whole(q), q[i]))
        project = _projected(m, dep, whole, max_dims)
        if project:
            merged = certify_conformal(m, x, y, merged_spec or part_spec or spec,
                                       path=full.path, part=(None, ".merged", euclid,
                                                             project))
    return _combine(full, split, const, results, dims, [float(c) for c in shares], merged,
                    spec, time.perf_counter() - t0)


def _combine(full: ConformalCertifyResult, split: float, const: float,
             parts: list[ConformalCertifyResult], dims: list[int], shares: list[float],
             merged: ConformalCertifyResult | None, spec: ConformalSpec, wall: float
             ) -> SplitCertifyResult:
    """The result: the largest of the three bounds, the work of all runs."""
    upper = full.upper
    bounds = {"full": full.lower, "split": min(split, upper),
              "merged": merged.lower if merged is not None else -math.inf}
    bound_by = max(bounds, key=lambda k: (bounds[k], k == "full"))
    lower_ = bounds[bound_by]
    runs = [full, *parts, *([merged] if merged is not None else [])]
    # the run behind the bound: the full run's, the merged run's, or (split) the part
    # run that stopped first among the parts (all parts count)
    lead = {"full": full, "merged": merged}.get(bound_by) or (parts[0] if parts else full)
    failed = [r for r in runs if r.status is CertifyStatus.LP_FAILED]
    ratio = lower_ / upper
    if 1.0 - ratio <= spec.target_gap:
        status = CertifyStatus.CERTIFIED
    elif (bound_by == "full" and full.status is CertifyStatus.LP_FAILED) or (
            bound_by == "split" and any(r.status is CertifyStatus.LP_FAILED for r in parts)):
        status = CertifyStatus.LP_FAILED
    else:
        status = CertifyStatus.BUDGET_REACHED
    message = "; ".join(r.message for r in failed if r.message)
    described = {
        "full": full.method,
        "split": (f"the factor split into a constant {const:g} (shared) and {len(parts)} "
                  f"part(s) in {dims} coordinates, each part's length bounded by: "
                  f"{lead.method}"),
        "merged": f"the whole factor in {merged.active_dims} coordinates (the others over "
                  f"their whole range): {merged.method}" if merged is not None else "",
    }
    method = (f"largest of the full run ({full.lower / upper:.3f} of upper), the split "
              f"({min(split, upper) / upper:.3f})"
              + (f", the whole factor projected ({merged.lower / upper:.3f})"
                 if merged is not None else "")
              + f"; {bound_by}: {described[bound_by]}")
    times = {k: float(sum(r.times.get(k, 0.0) for r in runs))
             for k in ("solve", "boxes", "lp")}
    times["total"] = wall
    base = {f.name: getattr(full, f.name) for f in dataclasses.fields(ConformalCertifyResult)}
    base.update(
        lower=lower_, ratio=ratio, gap=1.0 - ratio,
        potential_lower=max(full.potential_lower, split,
                            merged.potential_lower if merged is not None else 0.0),
        momentum=lead.momentum, stopped_by=lead.stopped_by, status=status,
        message=message, method=method,
        boxes=int(sum(r.boxes for r in runs)),
        enclosures=int(sum(r.enclosures for r in runs)),
        cells=int(sum(r.cells for r in runs)), rounds=int(sum(r.rounds for r in runs)),
        cone_programs=int(sum(r.cone_programs for r in runs)),
        spec={**full.spec, "part_max_boxes": [r.spec["max_boxes"] for r in parts],
              "merged_max_boxes": merged.spec["max_boxes"] if merged is not None else None},
        times=times, wall_time=wall)
    return SplitCertifyResult(**base, split_lower=split, constant=const, full=full,
                              parts=parts, part_dims=dims, shares=shares, merged=merged,
                              bound_by=bound_by)


#: Shares of the work budget: the full run, each part, the whole factor projected (equal:
#: on Panda the full run is the best bound of nearly straight pairs once its boxes prove
#: the factor's minimum, the parts that of the others).
BUDGET_WEIGHTS = (1.0, 1.0, 1.0)


def certify_conformal_best(metric: Metric | str, start: Any, goal: Any,
                           spec: ConformalSpec | None = None, *, path: Any = None
                           ) -> SplitCertifyResult:
    """The best sound lower bound this toolkit has for a conformal metric
    (`solvers.certify` and ``geodesics certify`` use it): the split bound where the
    factor is a sum of parts or depends on more than 4 coordinates, else the full run
    alone, always as a `SplitCertifyResult`. ``spec.max_boxes`` is the work budget
    of all runs together, shared as ``BUDGET_WEIGHTS`` (full run : each part : whole
    factor projected); the other settings apply to every run."""
    m = as_metric(metric)
    spec = spec or ConformalSpec()
    if not isinstance(spec, ConformalSpec):
        raise InputError(f"spec must be a ConformalSpec, got {type(spec).__name__}")
    if not m.provides("conformal_factor_sx"):  # the clear error, before any parts
        return certify_conformal_split(m, start, goal, spec, path=path)
    _, parts = factor_parts(m)
    parts = _grouped(parts, 4)
    q = ca.SX.sym("q", m.dim)
    dep = [i for i in range(m.dim) if ca.depends_on(ca.SX(m.conformal_factor_sx(q)), q[i])]
    w_full, w_part, w_merged = BUDGET_WEIGHTS
    total = w_full + w_part * len(parts) + (w_merged if len(dep) > 4 else 0.0)

    def share(w: float) -> ConformalSpec:
        return dataclasses.replace(spec, max_boxes=max(2, int(spec.max_boxes * w / total)))

    return certify_conformal_split(m, start, goal, share(w_full), part_spec=share(w_part),
                                   merged_spec=share(w_merged), path=path)
