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

The bound is the larger of the split one and the full run's own. Soundness: each part's
bound is that module's (verified potential, outward-rounded enclosures) for the part's
factor; a part's enclosures are checked nonnegative over the domain first (a negative part
would make the clamp at 0 unsound: then the factor is not split). Limits: the parts choose
their paths independently (``sum_k min <= min sum_k``), so the split bound is below the
distance by what the parts disagree on.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from finsler.intervals import Interval, enclose
from finsler.lowering import lower
from finsler.metric import Metric
from solvers.certify_conformal import ConformalCertifyResult, ConformalSpec, certify_conformal
from solvers.inputs import as_metric

__all__ = ["SplitCertifyResult", "certify_conformal_split", "factor_parts"]

_SLACK = 1e-9


@dataclass
class SplitCertifyResult:
    """The full run (``full``, its lower bound, upper bound and status), the split bound
    ``split_lower`` (``constant |y - x|`` plus the parts' bounds ``parts``), and ``lower =
    max(full.lower, min(split_lower, upper))``; ``ratio = lower / upper``."""

    lower: float
    upper: float
    ratio: float
    split_lower: float
    constant: float
    full: ConformalCertifyResult
    parts: list[ConformalCertifyResult] = field(repr=False)
    part_dims: list[int]
    enclosures: int
    wall_time: float


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
                            max_dims: int = 4) -> SplitCertifyResult:
    """Lower bound of ``d(start, goal)`` on a conformal metric whose factor is a sum of
    parts (see the module docstring): the full run with ``spec``, then every part with
    ``part_spec`` (default ``spec``) on the full run's path and region, in at most
    ``max_dims`` coordinates (the others it varies least with are bounded over their whole
    range: the part's minimum over them, a smaller factor in fewer dimensions)."""
    t0 = time.perf_counter()
    m = as_metric(metric)
    full = certify_conformal(m, start, goal, spec, path=path)
    x, y = np.asarray(start, float), np.asarray(goal, float)
    dist = float(np.linalg.norm(y - x))
    const, parts = factor_parts(m)
    upper = full.upper
    results: list[ConformalCertifyResult] = []
    dims: list[int] = []
    split = const * dist * (1.0 - _SLACK)
    work = full.enclosures
    if not parts and const == 0.0:
        split = 0.0
    elif full.min_factor > 0.0:
        euclid = upper / full.min_factor * (1.0 + _SLACK)  # any path of F-length <= U
        for k, (dep, fn) in enumerate(parts):
            project = _projected(m, dep, fn, max_dims)
            r = certify_conformal(
                m, x, y, part_spec or spec, path=full.path,
                part=(lambda q, fn=fn: fn(q), f".part{k}.{fn.name()}", euclid, project))
            results.append(r)
            dims.append(len(dep) - len(project))
            split += r.lower
            work += r.enclosures
    lower_ = max(full.lower, min(split, upper))
    return SplitCertifyResult(lower=lower_, upper=upper, ratio=lower_ / upper,
                              split_lower=split, constant=const, full=full, parts=results,
                              part_dims=dims, enclosures=work,
                              wall_time=time.perf_counter() - t0)


