"""The domain's constraints over boxes, for the certificates: a box that certainly misses
the domain holds no point of any path, so no potential needs to be verified on it.

Used by `solvers.certificates.conformal.certificate` (2-D) and `solvers.certificates.nd.parts` (3-D
and up); imports neither.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from finsler.enclosures.intervals import Interval, enclose
from finsler.lowering import LoweredFunction, lower
from finsler.metrics.base import Metric

_CHUNK = 100_000


def domain_constraints(metric: Metric, active: np.ndarray | None = None
                       ) -> tuple[LoweredFunction, np.ndarray, np.ndarray] | None:
    """The domain's constraints on the coordinates ``active`` (default: all) alone,
    ``q_A -> g`` with bounds ``lb <= g <= ub`` (those involving other coordinates are left
    out: a superset), or None when there are none (a box domain)."""
    act = np.ones(metric.dim, bool) if active is None else np.asarray(active, bool)

    def build() -> Any:
        q = ca.SX.sym("q", metric.dim)
        free = [q[i] for i in range(metric.dim) if not act[i]]
        cons = [c for c in metric.domain.constraints_sx(q)
                if not any(ca.depends_on(ca.SX(c[0]), v) for v in free)]
        if not cons:
            return None
        qa = ca.vertcat(*[q[i] for i in range(metric.dim) if act[i]])
        g = ca.vertcat(*[ca.SX(c[0]) for c in cons])
        return (lower(ca.Function(f"domain_{metric._ident}", [qa], [ca.densify(g)])),
                np.array([c[1] for c in cons], float), np.array([c[2] for c in cons], float))
    return metric.derived(f"certify.domain_constraints.{act.tobytes().hex()}", build)


def outside_domain(cons: Any, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """True where a box ``[lo, hi]`` ``(N, n)`` certainly misses the domain (a constraint's
    enclosure lies outside its bounds, or the box is empty: ``lo > hi`` somewhere);
    ``cons`` from `domain_constraints`."""
    out = np.any(lo > hi, axis=1)
    if cons is None:
        return out
    lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
    fn, lb, ub = cons
    for a in range(0, lo.shape[0], _CHUNK):
        sl = slice(a, a + _CHUNK)
        with np.errstate(all="ignore"):
            (vals,) = enclose(fn, Interval(lo[sl], hi[sl]))
        for k, v in enumerate(vals):
            out[sl] |= np.broadcast_to((v.lo > ub[k]) | (v.hi < lb[k]), out[sl].shape)
    return out
