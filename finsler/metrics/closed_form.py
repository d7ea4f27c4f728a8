"""Closed-form references: metrics whose distance and minimising geodesics are known
exactly (Euclidean, Minkowski norms, Randers with constant wind, the Poincare disk and
slab, a chart of the round sphere), used to test everything else.

Each metric is written exactly once, as the CasADi SX expression returned by
``F_sx``; every numeric evaluator is derived from it (`finsler.metrics.base`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from finsler.domains import Box, Disk, Domain, Product
from finsler.errors import InputError
from finsler.metrics.base import Metric, Task, TrainingSettings

__all__ = [
    "ClosedFormMetric",
    "Euclidean",
    "Minkowski",
    "Poincare",
    "PoincareSlab",
    "Randers",
    "Sphere",
]


def _norm_sx(v: ca.SX) -> ca.SX:
    return ca.sqrt(ca.dot(v, v))


def _factor_from_F(metric: Metric, x: ca.SX) -> ca.SX:
    """``F_sx(x, e_1)`` for a conformal metric ``F(x, v) = f(x) |v|``: ``f(x)``."""
    unit = np.zeros(metric.dim)
    unit[0] = 1.0
    return metric.F_sx(x, ca.SX(unit))


class ClosedFormMetric(Metric):
    """A metric whose distance and minimising geodesics are known in closed form: it
    provides the hooks ``distance`` and ``geodesic`` (from ``_distance`` and
    ``_geodesic``, which subclasses write)."""

    def distance(self, x: Any, y: Any) -> np.ndarray:
        """Exact distance ``d(x, y)`` for ``(N, dim)`` arrays -> ``(N,)``."""
        xb = self.domain.check(x, "x")
        yb = self.domain.check(y, "y")
        return self._distance(xb, yb)

    def geodesic(self, x: Any, y: Any, t: Any) -> np.ndarray:
        """Points of the minimising geodesic at arc-length fractions ``t`` ``(T,)``:
        ``(N, dim)`` pairs -> ``(N, T, dim)``."""
        xb = self.domain.check(x, "x")
        yb = self.domain.check(y, "y")
        t = np.asarray(t, float).reshape(-1)
        return self._geodesic(xb, yb, t)

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def _geodesic(self, x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
        # Constant metrics (Minkowski norms): straight lines at constant speed.
        return x[:, None] + t[None, :, None] * (y - x)[:, None]


#: Largest dimension of the Euclidean metric: its symbolic F has n entries per vector and
#: the solvers' Hessians n**2, so far larger n exhausts memory before a first solve.
MAX_EUCLIDEAN_DIM = 1024


@dataclass(frozen=True)
class Euclidean(ClosedFormMetric):
    """Euclidean metric ``F(x, v) = |v|`` on the box ``[-1, 1]**dim``."""

    n: int = 2

    name: ClassVar[str] = "euclidean"
    # Training defaults for the small test task (learn.config.default_config); the paper's
    # settings are the base class's (Matsumoto's).
    training: ClassVar[TrainingSettings] = TrainingSettings(
        defaults=dict(timesteps=400_000, lr=3e-3, collection_size=4096, minibatch_size=512,
                      eval_every=10),
    )
    unique_geodesics: ClassVar[bool] = True  # straight lines
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if isinstance(self.n, bool) or not isinstance(self.n, (int, np.integer)) or not (
                1 <= self.n <= MAX_EUCLIDEAN_DIM):
            raise InputError(f"euclidean dimension n must be an integer in [1, "
                             f"{MAX_EUCLIDEAN_DIM}], got {self.n!r}")

    @property
    def domain(self) -> Domain:
        return Box((-1.0,) * self.n, (1.0,) * self.n)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return _norm_sx(v)

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        """Hook: ``F(x, v) = 1 |v|``."""
        return _factor_from_F(self, x)

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.linalg.norm(y - x, axis=1)


@dataclass(frozen=True)
class Minkowski(ClosedFormMetric):
    """Constant asymmetric (Randers-type) norm ``F(v) = sqrt(v^T A v) + <b, v>`` on
    ``[-1, 1]**2`` with ``A = [[a11, a12], [a12, a22]]`` positive definite and
    ``|b|_{A^-1} < 1``. Geodesics are straight lines and ``d(x, y) = F(y - x)``."""

    a11: float = 1.0
    a12: float = 0.3
    a22: float = 2.0
    b1: float = 0.4
    b2: float = -0.2

    name: ClassVar[str] = "minkowski"
    unique_geodesics: ClassVar[bool] = True  # a constant norm: straight lines
    task: ClassVar[Task] = Task(depth=4, eps=0.3)
    reversible: ClassVar[bool] = False

    def __post_init__(self) -> None:
        a = self._a()
        if not np.all(np.linalg.eigvalsh(a) > 0):
            raise InputError("minkowski: A must be positive definite")
        b = np.array([self.b1, self.b2])
        if not b @ np.linalg.solve(a, b) < 1.0:
            raise InputError("minkowski: need |b|_{A^-1} < 1 for a norm")

    def _a(self) -> np.ndarray:
        return np.array([[self.a11, self.a12], [self.a12, self.a22]])

    @property
    def domain(self) -> Domain:
        return Box((-1.0, -1.0), (1.0, 1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        q = self.a11 * v[0] * v[0] + 2 * self.a12 * v[0] * v[1] + self.a22 * v[1] * v[1]
        return ca.sqrt(q) + self.b1 * v[0] + self.b2 * v[1]

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        d = y - x
        q = np.einsum("ni,ij,nj->n", d, self._a(), d)
        return np.sqrt(q) + d @ np.array([self.b1, self.b2])


@dataclass(frozen=True)
class Randers(ClosedFormMetric):
    """Zermelo navigation on the Euclidean plane with a constant wind ``W`` (``|W| < 1``):
    the travel-time metric ``F(v) = (sqrt(lam |v|**2 + <W, v>**2) - <W, v>) / lam`` with
    ``lam = 1 - |W|**2``, on ``[-1, 1]**2``. Straight-line geodesics; ``d(x, y) = F(y - x)``
    is the time to travel from ``x`` to ``y`` at unit speed relative to the wind."""

    wind_x: float = 0.5
    wind_y: float = 0.2

    name: ClassVar[str] = "randers"
    unique_geodesics: ClassVar[bool] = True  # constant wind: straight lines
    task: ClassVar[Task] = Task(depth=4, eps=0.4)
    reversible: ClassVar[bool] = False

    def __post_init__(self) -> None:
        if not (self.wind_x**2 + self.wind_y**2 < 1.0):
            raise InputError("randers: the wind speed |W| must be < 1")

    @property
    def domain(self) -> Domain:
        return Box((-1.0, -1.0), (1.0, 1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        lam = 1.0 - self.wind_x**2 - self.wind_y**2
        wv = self.wind_x * v[0] + self.wind_y * v[1]
        vv = ca.dot(v, v)
        # = (sqrt(lam |v|^2 + <W, v>^2) - <W, v>) / lam, written without the cancellation
        # (which made F slightly negative for tiny v against the wind)
        return vv / (ca.sqrt(lam * vv + wv * wv) + wv)

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        # Independent of the formula above: the time T with |d - T W| = T (unit speed in
        # the moving medium), the positive root of (1 - |W|^2) T^2 + 2 <d, W> T - |d|^2 = 0.
        w = np.array([self.wind_x, self.wind_y])
        d = y - x
        a = 1.0 - w @ w
        bq = 2.0 * (d @ w)
        c = -np.einsum("ni,ni->n", d, d)
        return (-bq + np.sqrt(bq * bq - 4 * a * c)) / (2 * a)


@dataclass(frozen=True)
class Poincare(ClosedFormMetric):
    """Hyperbolic plane, Poincare disk model: ``F(x, v) = 2 |v| / (1 - |x|**2)`` on the disk
    ``|x| <= radius < 1`` (a hyperbolic ball, hence geodesically convex)."""

    radius: float = 0.8

    name: ClassVar[str] = "poincare"
    unique_geodesics: ClassVar[bool] = True  # a Hadamard manifold (curvature -1)
    task: ClassVar[Task] = Task(depth=5, eps=0.3)
    reversible: ClassVar[bool] = True
    convexity_note: ClassVar[str] = "Riemannian: Finsler everywhere"

    def __post_init__(self) -> None:
        if not (0.0 < self.radius < 1.0):
            raise InputError(f"poincare radius must be in (0, 1), got {self.radius!r}")

    @property
    def domain(self) -> Domain:
        return Disk(radius=self.radius)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return 2.0 * _norm_sx(v) / (1.0 - ca.dot(x, x))

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        """Hook: ``F(x, v) = 2 |v| / (1 - |x|**2)``."""
        return _factor_from_F(self, x)

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        num = 2.0 * np.sum((x - y) ** 2, axis=1)
        den = (1 - np.sum(x * x, axis=1)) * (1 - np.sum(y * y, axis=1))
        return np.arccosh(1.0 + num / den)

    def _geodesic(self, x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
        # Moebius map sending x to 0: geodesics through 0 are diameters.
        zx = x[:, 0] + 1j * x[:, 1]
        zy = y[:, 0] + 1j * y[:, 1]
        w = (zy - zx) / (1 - np.conj(zx) * zy)
        d = self._distance(x, y)
        direction = np.where(np.abs(w) > 0, w / np.where(np.abs(w) > 0, np.abs(w), 1), 0)
        u = np.tanh(t[None, :] * d[:, None] / 2.0) * direction[:, None]
        z = (u + zx[:, None]) / (1 + np.conj(zx)[:, None] * u)
        return np.stack([z.real, z.imag], -1)


@dataclass(frozen=True)
class Sphere(ClosedFormMetric):
    """Unit sphere in the stereographic chart from the south pole:
    ``F(u, v) = 2 |v| / (1 + |u|**2)`` on the disk ``|u| <= radius`` (a spherical cap of
    polar angle ``2 atan(radius)``, geodesically convex for ``radius < 1``). Distances are
    great-circle angles."""

    radius: float = 0.8

    name: ClassVar[str] = "sphere"
    unique_geodesics: ClassVar[bool] = True  # a cap smaller than a hemisphere
    task: ClassVar[Task] = Task(depth=5, eps=0.2)
    reversible: ClassVar[bool] = True
    convexity_note: ClassVar[str] = "Riemannian: Finsler everywhere"

    def __post_init__(self) -> None:
        if not (0.0 < self.radius < 1.0):
            raise InputError(f"sphere chart radius must be in (0, 1), got {self.radius!r}")

    @property
    def domain(self) -> Domain:
        return Disk(radius=self.radius)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return 2.0 * _norm_sx(v) / (1.0 + ca.dot(x, x))

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        """Hook: ``F(u, v) = 2 |v| / (1 + |u|**2)``."""
        return _factor_from_F(self, x)

    @staticmethod
    def to_sphere(u: np.ndarray) -> np.ndarray:
        """Inverse stereographic projection ``(N, 2)`` -> unit vectors ``(N, 3)``."""
        s = np.sum(u * u, axis=-1, keepdims=True)
        return np.concatenate([2 * u, 1 - s], -1) / (1 + s)

    @staticmethod
    def from_sphere(p: np.ndarray) -> np.ndarray:
        """Stereographic projection from the south pole, unit vectors -> chart."""
        return p[..., :2] / (1 + p[..., 2:3])

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        a, b = self.to_sphere(x), self.to_sphere(y)
        cross = np.linalg.norm(np.cross(a, b), axis=1)
        return np.arctan2(cross, np.sum(a * b, axis=1))

    def _geodesic(self, x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
        a, b = self.to_sphere(x), self.to_sphere(y)
        ang = self._distance(x, y)
        s = np.sin(ang)[:, None, None]
        big = s > 1e-15  # slerp; linear interpolation for (nearly) equal points
        safe = np.where(big, s, 1.0)
        ta, an = t[None, :, None], ang[:, None, None]
        wa = np.where(big, np.sin((1 - ta) * an) / safe, 1 - ta)
        wb = np.where(big, np.sin(ta * an) / safe, ta)
        p = wa * a[:, None] + wb * b[:, None]
        p /= np.linalg.norm(p, axis=-1, keepdims=True)
        return self.from_sphere(p)


@dataclass(frozen=True)
class PoincareSlab(ClosedFormMetric):
    """A 3-D closed-form reference with a metric that varies in space: the Riemannian
    product of the Poincare disk and a line, ``F(x, v) = sqrt((2 |v_p| / (1 - |p|**2))**2
    + v_z**2)`` with ``x = (p, z)`` on (disk ``|p| <= radius``) x ``[-1, 1]``. Both factors
    are geodesically convex, so ``d = sqrt(d_H(p, q)**2 + (z - w)**2)`` (``d_H`` the
    hyperbolic distance) and geodesics are a hyperbolic geodesic and a uniform motion in
    ``z``, both at constant speed. Registered to check 3-D certificates against."""

    radius: float = 0.7

    name: ClassVar[str] = "poincare-slab"
    unique_geodesics: ClassVar[bool] = True  # a product of Hadamard manifolds
    task: ClassVar[Task] = Task(depth=5, eps=0.3)
    reversible: ClassVar[bool] = True
    convexity_note: ClassVar[str] = "Riemannian: Finsler everywhere"

    def __post_init__(self) -> None:
        if not (0.0 < self.radius < 1.0):
            raise InputError(f"poincare-slab radius must be in (0, 1), got {self.radius!r}")

    @property
    def domain(self) -> Domain:
        return Product((Disk(radius=self.radius), Box((-1.0,), (1.0,), names=("z",))))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        lam = 2.0 / (1.0 - x[0] * x[0] - x[1] * x[1])
        return ca.sqrt(lam * lam * (v[0] * v[0] + v[1] * v[1]) + v[2] * v[2])

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        dh = Poincare._distance(Poincare(radius=self.radius), x[:, :2], y[:, :2])
        return np.hypot(dh, y[:, 2] - x[:, 2])

    def _geodesic(self, x: np.ndarray, y: np.ndarray, t: np.ndarray) -> np.ndarray:
        disk = Poincare(radius=self.radius)._geodesic(x[:, :2], y[:, :2], t)
        z = x[:, None, 2] + t[None, :] * (y - x)[:, None, 2]
        return np.concatenate([disk, z[..., None]], -1)
