"""The geodesic equation of a metric (its spray), derived once from ``F`` on the metric.

With the energy ``E = F**2 / 2`` and the fundamental tensor ``g_ij = d2E / dv_i dv_j``
(`finsler.Metric.casadi_hessian`), the Euler-Lagrange equation
``d/dt (dE/dv) = dE/dx`` of a curve ``x(t)`` reads::

    g(x, x') x'' = dE/dx - (d2E / dv dx) x'      i.e.  x''^i + 2 G^i(x, x') = 0

with the spray ``G = -1/2 g^{-1} (dE/dx - (d2E / dv dx) v)``. `Spray` holds CasADi
functions of ``g`` and of the right-hand side ``b`` and their derivatives in ``(x, v)``,
exact; the linear solve with ``g`` is numeric (a 7-D metric needs no symbolic inverse).
The equation describes shortest curves only where ``g`` is positive definite (``F``
strongly convex): `Spray.pd_ratio` measures it. `spray` builds it once per
metric (`finsler.Metric.derived`) and refuses a metric whose ``F`` is not smooth.
The exp/log maps of `solvers.continuum.expmap` integrate it.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from finsler.errors import InputError
from finsler.metrics.base import Metric

__all__ = ["Spray", "spray"]


class Spray:
    """CasADi functions of the geodesic equation of ``metric``.

    ``parts(x, v) -> (F, g (dim, dim), b (dim,))`` with ``g x'' = b`` the geodesic equation
    (``g`` is the metric's fundamental tensor, `Metric.casadi_hessian`, not derived a
    second time); ``parts_jac(x, v) -> (dg/dz (dim*dim, 2 dim), db/dz (dim, 2 dim))`` with
    ``z = (x, v)`` (``g`` flattened column-major, as CasADi stores it); ``margin(x)`` the
    domain's constraints as values that are ``>= 0`` inside (``n_margin`` of them). Build it
    with `spray` (once per metric).
    """

    def __init__(self, metric: Metric) -> None:
        d = metric.dim
        self.dim = d
        x = ca.SX.sym("x", d)
        v = ca.SX.sym("v", d)
        z = ca.vertcat(x, v)
        f = metric.F_sx(x, v)
        e = 0.5 * f * f
        g = metric.casadi_hessian(x, v)  # the fundamental tensor's graph, called on x, v
        b = ca.gradient(e, x) - ca.mtimes(ca.jacobian(ca.gradient(e, v), x), v)
        self.parts = ca.Function("spray_parts", [x, v], [f, g, b])
        self.parts_jac = ca.Function(
            "spray_parts_jac", [x, v],
            [ca.densify(ca.jacobian(ca.vec(g), z)), ca.densify(ca.jacobian(b, z))])
        lo, hi = metric.domain.bounds()
        rows = [x[i] - lo[i] for i in range(d) if np.isfinite(lo[i])]
        rows += [hi[i] - x[i] for i in range(d) if np.isfinite(hi[i])]
        for expr, lb, ub in metric.domain.constraints_sx(x):
            if np.isfinite(float(ub)):
                rows.append(ub - expr)
            if np.isfinite(float(lb)):
                rows.append(expr - lb)
        self.n_margin = len(rows)
        self.margin = ca.Function("margin", [x], [ca.vertcat(*rows) if rows else ca.SX(1, 1)])

    def acceleration(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``x'' = g^{-1} b`` ``(dim,)`` and ``g`` ``(dim, dim)`` at ``x``, ``v`` ``(dim,)``."""
        _, g, b = self.parts(x, v)
        g = np.asarray(g)
        return np.linalg.solve(g, np.asarray(b).reshape(-1)), g

    def pd_ratio(self, x: np.ndarray, v: np.ndarray) -> float:
        """Smallest over largest eigenvalue of ``g(x, v)`` (<= 0: not positive definite)."""
        _, g, _ = self.parts(x, v)
        g = np.asarray(g)
        lam = np.linalg.eigvalsh(0.5 * (g + g.T))
        return float(lam[0] / lam[-1]) if lam[-1] > 0 else -1.0


def spray(metric: Metric) -> Spray:
    """The `Spray` of ``metric``, built once per metric (``metric.derived``).

    Raises `InputError` if ``F`` is not smooth (``metric.smooth`` False): the
    geodesic equation differentiates ``F**2`` twice and is not defined there."""
    if not metric.smooth:
        raise InputError(f"{metric.name}: F is not smooth ({metric.convexity_note}); the "
                         "geodesic equation (spray) is not defined, so exp/log maps are not "
                         "available for this metric")
    return metric.derived("geometry.spray", lambda: Spray(metric))
