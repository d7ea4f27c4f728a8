"""A conformal factor that is a sum, bounded part by part (issue 46, item 3).

When the factor is a sum ``f = sum_k a_k`` of nonnegative parts, a path's length splits the
same way, ``int f |q'| = sum_k int a_k |q'|``, so ``d(x, y) >= sum_k lower_k`` where
``lower_k`` bounds the ``a_k``-length of every path that can matter (those of ``F``-length
at most the upper bound ``U``). A part depending on fewer coordinates is bounded in fewer
dimensions, where the boxes of :func:`solvers.certify_conformal.certify_conformal` resolve
it: its other coordinates are cyclic for it (Clairaut's momentum), and its region is the
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
run's own. Tuning pair 3 of seed 20261150 (budgets 3e5): full run 0.560 of the upper
bound, split 0.643 (0.674 with the constant shared), whole factor in ``q1..q4`` 0.686
(0.692 at 1e6; in ``q1..q3`` 0.608). Ten fresh pairs (seed 20261211, budgets 5e4 / 1e5
per part / 3e5 for the whole factor, about 30-40 s CPU a pair): median 0.777 of the upper
bound, lowest 0.683, above the trivial bound's ceiling on all ten; the full run alone
0.587-0.767 (``benchmarks/results/certify_panda-2026-11-28-2.md``). Soundness: each part's
bound is that module's (verified potential, outward-rounded enclosures) for the part's
factor; a part's enclosures are checked nonnegative over the domain first (a negative part
would make the clamp at 0 unsound: then the factor is not split). Limits: the parts choose
their paths independently (``sum_k min <= min sum_k``), so the split bound is below the
distance by what the parts disagree on.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from finsler.intervals import Interval, enclose
from finsler.lowering import lower
from finsler.metric import Metric
from finsler.status import CertifyStatus, Result
from solvers.certify_conformal import ConformalCertifyResult, ConformalSpec, certify_conformal
from solvers.inputs import as_metric

__all__ = ["SplitCertifyResult", "certify_conformal_split", "factor_parts"]

_SLACK = 1e-9


@dataclass
class SplitCertifyResult(Result):
    """The full run (``full``, its lower bound, upper bound and status), the split bound
    ``split_lower`` (the sum of the parts' bounds ``parts``, part ``k`` with the share
    ``shares[k]`` of the constant ``constant``; ``constant |y - x|`` when the factor has no
    other part), ``merged`` the run on the whole factor with its weakest coordinates
    projected out (None when it has at most ``max_dims``), and ``lower = max(full.lower,
    min(split_lower, upper), merged.lower)``; ``ratio = lower / upper``; ``part_dims`` the
    coordinates each part was bounded in; ``gap = 1 - ratio``; ``status`` ``certified``
    when the gap is at most the spec's ``target_gap``, else ``budget_reached`` (the
    bound is sound either way)."""

    lower: float
    upper: float
    ratio: float
    split_lower: float
    constant: float
    full: ConformalCertifyResult
    parts: list[ConformalCertifyResult] = field(repr=False)
    part_dims: list[int]
    shares: list[float]
    merged: ConformalCertifyResult | None
    enclosures: int
    wall_time: float
    gap: float = math.nan
    status: CertifyStatus = CertifyStatus.BUDGET_REACHED


def factor_parts(metric: Metric) -> tuple[float, list[tuple[tuple[int, ...], Any]]]:
    """The conformal factor's top-level sum: ``(constant, [(coordinates, expression)])``,
    the nonconstant terms grouped by the coordinates they depend on, as SX expressions of
    a symbol ``q`` (returned as the callables' closure); ``(0, [])`` when the factor is not
    a sum of parts proven nonnegative over the domain (or is one term)."""
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
        if const < 0.0 or (len(groups) < 2 and const == 0.0):
            return 0.0, []
        lo, hi = (np.asarray(b, float)[None] for b in metric.domain.bounds())
        for expr in groups.values():  # each part must be >= 0 (its enclosure's clamp)
            with np.errstate(all="ignore"):
                (val,) = enclose(lower(ca.Function("part", [q], [expr])), Interval(lo, hi))
            if not float(np.min(val[0].lo)) >= 0.0:
                return 0.0, []
        return const, [(dep, ca.Function(f"part_{k}", [q], [e]))
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


def certify_conformal_split(metric: Metric | str, start: Any, goal: Any,
                            spec: ConformalSpec | None = None, *, part_spec:
                            ConformalSpec | None = None, path: Any = None,
                            max_dims: int = 4, merged_spec: ConformalSpec | None = None
                            ) -> SplitCertifyResult:
    """Lower bound of ``d(start, goal)`` on a conformal metric whose factor is a sum of
    parts (see the module docstring): the full run with ``spec``, then every part with
    ``part_spec`` (default ``spec``) on the full run's path and region, in at most
    ``max_dims`` coordinates (the others it varies least with are bounded over their whole
    range: the part's minimum over them, a smaller factor in fewer dimensions). Then the
    whole factor the same way (``merged``, with ``merged_spec``, default ``part_spec``):
    no loss from the parts choosing different paths, only the projection's."""
    t0 = time.perf_counter()
    m = as_metric(metric)
    full = certify_conformal(m, start, goal, spec, path=path)
    x, y = np.asarray(start, float), np.asarray(goal, float)
    dist = float(np.linalg.norm(y - x))
    const, parts = factor_parts(m)
    upper = full.upper
    results: list[ConformalCertifyResult] = []
    dims: list[int] = []
    shares: Any = []
    split = const * dist * (1.0 - _SLACK)
    work = full.enclosures
    euclid = (upper / full.min_factor * (1.0 + _SLACK)  # any path of F-length <= U
              if full.min_factor > 0.0 else math.inf)
    if not parts and const == 0.0:
        split = 0.0
    elif full.min_factor > 0.0:
        shares = _shares(const, parts, full.path) if parts else []
        split = 0.0 if parts else split
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
            work += r.enclosures
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
            work += merged.enclosures
    lower_ = max(full.lower, min(split, upper), merged.lower if merged else 0.0)
    target = (spec or ConformalSpec()).target_gap
    status = (CertifyStatus.CERTIFIED if 1.0 - lower_ / upper <= target
              else CertifyStatus.BUDGET_REACHED)
    return SplitCertifyResult(lower=lower_, upper=upper, ratio=lower_ / upper,
                              split_lower=split, constant=const, full=full, parts=results,
                              part_dims=dims, shares=[float(c) for c in shares],
                              merged=merged,
                              enclosures=work,
                              wall_time=time.perf_counter() - t0,
                              gap=1.0 - lower_ / upper, status=status)


