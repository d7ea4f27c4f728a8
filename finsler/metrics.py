"""The registered metrics: the paper's environments and closed-form references.

Each metric is written exactly once, as the CasADi SX expression returned by
``F_sx``; every numeric evaluator is derived from it (:mod:`finsler.metric`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from finsler.domains import Box, Disk, Domain, JointBox, Product, _as_batch
from finsler.errors import InputError
from finsler.metric import Metric, Task

__all__ = [
    "CarLike",
    "ClosedFormMetric",
    "Euclidean",
    "Matsumoto",
    "Minkowski",
    "PandaPole",
    "Poincare",
    "PoincareSlab",
    "Randers",
    "Sphere",
]

#: Radius below which the paper's Matsumoto metric (h = -|p|^2) is strongly convex:
#: ||beta||_alpha < 1/2  <=>  |grad h| < 1/sqrt(3)  <=>  |p| < 1/(2 sqrt 3).
MATSUMOTO_CONVEX_RADIUS = 1.0 / (2.0 * math.sqrt(3.0))


def _norm_sx(v: ca.SX) -> ca.SX:
    return ca.sqrt(ca.dot(v, v))


def _factor_from_F(metric: Metric, x: ca.SX) -> ca.SX:
    """``F_sx(x, e_1)`` for a conformal metric ``F(x, v) = f(x) |v|``: ``f(x)``."""
    unit = np.zeros(metric.dim)
    unit[0] = 1.0
    return metric.F_sx(x, ca.SX(unit))


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"parameter {name} must be positive and finite, got {value!r}")


# ----------------------------------------------------------------------------------------
# The paper's environments
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Matsumoto(Metric):
    """Matsumoto slope metric, eqs. (20)-(21): ``F = alpha**2 / (alpha - beta)`` with
    ``beta = <grad h(p), v>``, ``alpha = sqrt(|v|**2 + beta**2)`` and the height
    ``h(p) = -height * |p|**2`` (a mountain at the centre) on the unit disk.

    Not Finsler everywhere: ``F(p, .)`` is strongly convex only where
    ``||beta||_alpha < 1/2``, i.e. ``|grad h| < 1/sqrt(3)``; for the default
    ``height = 1`` that is ``|p| < 1/(2 sqrt 3) ~ 0.2887`` (about 8% of the disk).
    """

    height: float = 1.0
    radius: float = 1.0

    name: ClassVar[str] = "matsumoto"
    task: ClassVar[Task] = Task(depth=6, eps=0.1)
    reversible: ClassVar[bool] = False
    convex_everywhere: ClassVar[bool] = False
    convexity_note: ClassVar[str] = (
        "NOT Finsler everywhere: F(x,.) convex only for |p| < 1/(2*sqrt(3)*height) "
        "(~0.2887 at height 1)"
    )

    def __post_init__(self) -> None:
        _positive("height", self.height)
        _positive("radius", self.radius)

    @property
    def domain(self) -> Domain:
        return Disk(radius=self.radius)

    @property
    def convex_radius(self) -> float:
        """Hook: analytic radius of the region where ``F(p, .)`` is strongly convex."""
        return MATSUMOTO_CONVEX_RADIUS / self.height

    def height_map(self, points: Any) -> np.ndarray:
        """Hook: the height ``h(p) = -height |p|**2`` of eq. (21), ``(N, 2) -> (N,)``
        (``F_sx`` uses its gradient ``-2 height p``)."""
        p = np.asarray(points, dtype=np.float64)
        return -self.height * np.sum(p * p, axis=-1)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        grad_h = -2.0 * self.height * x  # the gradient of height_map's h
        beta = ca.dot(grad_h, v)
        alpha = ca.sqrt(ca.dot(v, v) + beta * beta)
        return alpha * alpha / (alpha - beta)


@dataclass(frozen=True)
class CarLike(Metric):
    """Unidirectional car-like metric, eqs. (22)-(24), on (unit disk) x [-pi, pi]:
    ``F = sqrt(vx**2 + vy**2 + c_p (h**2 + xi**2))`` with the sideways motion
    ``h = -vx sin(th) + vy cos(th)`` and ``xi = max(r_min |v_th| - vx cos(th) - vy sin(th), 0)``.

    A C^0-Finsler structure (appendix D): ``F(x, .)`` is convex but not smooth.
    theta is a plain coordinate (not identified at +-pi).
    """

    c_p: float = 100.0
    r_min: float = 0.5
    radius: float = 1.0

    name: ClassVar[str] = "carlike"
    task: ClassVar[Task] = Task(depth=8, eps=0.1)
    reversible: ClassVar[bool] = False
    smooth: ClassVar[bool] = False
    convexity_note: ClassVar[str] = "C^0-Finsler: convex but not smooth (max, abs)"

    def __post_init__(self) -> None:
        _positive("c_p", self.c_p)
        _positive("r_min", self.r_min)
        _positive("radius", self.radius)

    @property
    def domain(self) -> Domain:
        return Product(
            (Disk(radius=self.radius), Box((-math.pi,), (math.pi,), names=("theta",)))
        )

    def _square_sx(self, x: ca.SX, v: ca.SX, xi: ca.SX | None = None
                   ) -> tuple[ca.SX, ca.SX, ca.SX]:
        """The formula, written once for ``F_sx`` and the smooth hook: returns
        ``(vx**2 + vy**2 + c_p (h**2 + xi**2), u, excess)`` with the forward speed
        ``u = vx cos(th) + vy sin(th)``, the excess turning rate
        ``excess = max(r_min |v_th| - u, 0)``, and ``xi = excess`` unless given (then the
        first entry is ``F**2`` exactly when ``xi == excess``)."""
        th = x[2]
        c, s = ca.cos(th), ca.sin(th)
        h = -v[0] * s + v[1] * c
        u = v[0] * c + v[1] * s
        excess = ca.fmax(self.r_min * ca.fabs(v[2]) - v[0] * c - v[1] * s, 0.0)
        w = excess if xi is None else xi
        return v[0] * v[0] + v[1] * v[1] + self.c_p * (h * h + w * w), u, excess

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return ca.sqrt(self._square_sx(x, v)[0])

    def smooth_square_sx(self, x: ca.SX, v: ca.SX, tag: str = "") -> dict[str, Any]:
        """Hook (:mod:`finsler.hooks`) for optimisers that need C^2 functions (solvers'
        transcriptions): ``F**2`` as a smooth expression of ``(x, v, xi)`` with one slack
        ``xi``, exact at any minimiser of an objective increasing in ``F**2``.

        ``max(r_min |v_th| - u, 0)`` becomes ``xi >= 0``, ``xi >= r_min v_th - u``,
        ``xi >= -r_min v_th - u``: the objective increases with ``xi**2``, so at a minimiser
        ``xi`` equals the max. Returns a dict: ``f2`` (SX scalar), ``w`` (slack symbols
        ``(1, 1)``) with bounds ``lbw``/``ubw``, ``w_value`` (the exact slack as an
        expression of ``(x, v)``, for initial points), constraints ``g`` ``(2, 1)`` with
        bounds ``lbg``/``ubg``.
        """
        xi = ca.SX.sym(f"xi{tag}")
        f2, u, excess = self._square_sx(x, v, xi)
        g = ca.vertcat(xi - (self.r_min * v[2] - u), xi - (-self.r_min * v[2] - u))
        return {"f2": f2, "w": xi, "w_value": excess, "lbw": [0.0],
                "ubw": [ca.inf], "g": g, "lbg": [0.0, 0.0], "ubg": [ca.inf, ca.inf]}

    #: Tangent lengths (times ``radius``) of the Hermite seed curves, and how their
    #: heading is laid (see :meth:`seed_curves`). Chosen on 30 tuning pairs
    #: (``sample_pairs(carlike, 30, 11)``, 256 segments, IPOPT from each curve alone): the
    #: default seeds without these missed the best energy found by 1e-4 on 5 pairs (by up
    #: to 4.7x); four of these curves (shift 0.5 and 1, track 1, linear 0.5) found all 5.
    #: ``raw`` (12-15 of 30 pairs) and ``clip`` (16-18) found no basin the others missed
    #: and cost twice the solve time, so they are not in the default set.
    SEED_TANGENTS: ClassVar[tuple[float, ...]] = (0.25, 0.5, 1.0, 2.0)
    SEED_HEADINGS: ClassVar[tuple[str, ...]] = ("track", "shift", "linear")

    def seed_curves(self, starts: Any, goals: Any, t: Any) -> dict[str, np.ndarray]:
        """Hook (:mod:`finsler.hooks`): cubic Hermite curves in the plane whose end
        tangents follow the start and goal headings (forward motion), one per tangent
        length of ``SEED_TANGENTS``, for each way of laying the heading along them
        (family ``hermite-<way>``): ``track`` follows the curve's tangent direction,
        the winding left at the goal spread evenly; ``shift`` follows it and drops the
        winding at the middle (the solve then chooses which way to turn); ``linear``
        interpolates the end headings; ``raw`` wraps the tangent direction into
        ``[-pi, pi]``; ``clip`` clips it there. The heading is a plain coordinate here
        (not identified at +-pi), so these are distinct ways of turning."""
        s = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
        g = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
        tt = np.asarray(t, dtype=np.float64).reshape(-1)
        tc = tt[None, None, :, None]  # (1, 1, T, 1)
        lengths = self.radius * np.asarray(self.SEED_TANGENTS)[None, :, None, None]
        d0 = np.stack([np.cos(s[:, 2]), np.sin(s[:, 2])], -1)[:, None, None]  # (K,1,1,2)
        d1 = np.stack([np.cos(g[:, 2]), np.sin(g[:, 2])], -1)[:, None, None]
        p0, p1 = s[:, None, None, :2], g[:, None, None, :2]
        h00, h10 = 2 * tc**3 - 3 * tc**2 + 1, tc**3 - 2 * tc**2 + tc
        h01, h11 = -2 * tc**3 + 3 * tc**2, tc**3 - tc**2
        p = h00 * p0 + h10 * lengths * d0 + h01 * p1 + h11 * lengths * d1  # (K, S, T, 2)
        # the tangent's direction (the derivative in closed form: exact at the ends)
        dp = ((6 * tc**2 - 6 * tc) * p0 + (3 * tc**2 - 4 * tc + 1) * lengths * d0
              + (-6 * tc**2 + 6 * tc) * p1 + (3 * tc**2 - 2 * tc) * lengths * d1)
        raw = np.arctan2(dp[..., 1], dp[..., 0])  # (K, S, T)
        track = np.unwrap(raw, axis=-1)
        track = track - track[..., :1] + s[:, None, None, 2]
        th0, th1 = s[:, None, None, 2], g[:, None, None, 2]
        tp = tt[None, None, :]
        ways = {
            "track": track + tp * (th1 - track[..., -1:]),
            "shift": track - 2 * np.pi * np.round((track[..., -1:] - th1) / (2 * np.pi))
            * (tp > 0.5),
            "linear": np.broadcast_to(th0 + tp * (th1 - th0), track.shape),
            "raw": raw,
            "clip": np.clip(track, -np.pi, np.pi),
        }
        out = {}
        for way in self.SEED_HEADINGS:
            c = np.concatenate([p, ways[way][..., None]], -1)
            c = np.asarray(self.domain.project(c.reshape(-1, 3))).reshape(c.shape)
            c[:, :, 0], c[:, :, -1] = s[:, None], g[:, None]
            out[f"hermite-{way}"] = c
        return out


@dataclass(frozen=True)
class PandaPole(Metric):
    """Franka Panda joint space with a pole obstacle, eq. (60):
    ``F(q, v) = (1 + sum_i ((p_i(q)_x - o_x)**2 + (p_i(q)_y - o_y)**2)**(-1/2)) |v|`` with
    ``p_i`` the positions of the frames panda_link0..panda_link8, panda_hand (Pinocchio's
    Panda model from example-robot-data) and the joint-limit box as domain.
    """

    pole_x: float = 0.4
    pole_y: float = 0.0

    name: ClassVar[str] = "panda-pole"
    task: ClassVar[Task] = Task(depth=5, eps=20.0)
    reversible: ClassVar[bool] = True
    convexity_note: ClassVar[str] = "Riemannian (conformal): Finsler everywhere"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pole_x) and math.isfinite(self.pole_y)):
            raise InputError("pole position must be finite")

    @property
    def domain(self) -> Domain:
        from finsler import panda

        return JointBox(
            tuple(panda.JOINT_LIMITS_LOW.tolist()),
            tuple(panda.JOINT_LIMITS_HIGH.tolist()),
            names=tuple(f"q{i + 1}" for i in range(7)),
        )

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        from finsler import panda

        return panda.pole_metric_sx(x, v, pole=(self.pole_x, self.pole_y))

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        """Hook: ``F(q, v) = f(q) |v|`` with ``f`` eq. (60)'s weight ``1 + sum_i
        rho_i**(-1/2)``, ``rho_i`` the squared horizontal distances of the frames to the
        pole. Written with the power ``-1/2`` rather than ``1 / sqrt``: its interval
        enclosure on boxes where a frame may reach the pole's axis is the half-line
        ``[rho_max**(-1/2), inf]``, not the whole line (tests check it equals ``F_sx``)."""
        from finsler import panda

        p = panda.frame_positions_sx(x)
        squared = (p[:, 0] - self.pole_x) ** 2 + (p[:, 1] - self.pole_y) ** 2
        return 1 + ca.sum1(squared ** -0.5)

    def landmarks(self) -> dict[str, tuple[float, ...]]:
        """Hook: the pole's position in the world frame (x, y)."""
        return {"pole": (float(self.pole_x), float(self.pole_y))}

    def frame_positions(self, q: Any) -> Any:
        """Hook: world positions of the ten frames, ``(N, 7)`` -> ``(N, 10, 3)`` (lowered CasADi
        forward kinematics; numpy or torch)."""
        from finsler import panda

        qb = _as_batch(q, 7, "q")
        (p,) = panda.lowered_frame_positions()(qb)
        p = p.reshape(-1, 3, 10)  # CasADi stores the (10, 3) matrix column-major
        return p.transpose(1, 2) if hasattr(p, "detach") else p.transpose(0, 2, 1)


# ----------------------------------------------------------------------------------------
# Closed-form references
# ----------------------------------------------------------------------------------------
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


@dataclass(frozen=True)
class Euclidean(ClosedFormMetric):
    """Euclidean metric ``F(x, v) = |v|`` on the box ``[-1, 1]**dim``."""

    n: int = 2

    name: ClassVar[str] = "euclidean"
    unique_geodesics: ClassVar[bool] = True  # straight lines
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not isinstance(self.n, (int, np.integer)) or self.n < 1:
            raise InputError(f"euclidean dimension must be a positive integer, got {self.n!r}")

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
