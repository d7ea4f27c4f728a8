"""The `Metric` base: one symbolic ``F(x, v)``, every numeric method derived from it.

A concrete metric is a small frozen dataclass holding its parameters and
implementing `Metric.F_sx`, the CasADi SX expression of ``F(x, v)``.
From that single expression the class derives

* the CasADi function used by IPOPT (``casadi_F``, exact derivatives), the fundamental
  tensor ``casadi_hessian`` (Hessian in ``v`` of ``F**2 / 2``) and the Hessian of ``F`` in
  ``x`` ``casadi_hessian_x``, each derived once (the spray of `finsler.geometry` is
  built on the fundamental tensor),
* vectorised numpy / torch evaluators obtained by *lowering* the SX
  instruction list (`finsler.lowering`), compiled once and cached,
* the local costs of the paper: ``cost`` (eq. 4), ``cost_symmetric`` (eq. 59)
  and ``segment_length`` (eq. 58, Gauss-Legendre quadrature of a fixed order), and
  lengths with an error estimate: ``segment_length_error`` / ``path_length_error``
  (adaptive Gauss-Kronrod to a tolerance),
* a numerical convexity check of ``F(x, .)`` (the Finsler condition).

Derived objects are built once per metric: ``functools.cached_property`` for what this
class derives, `Metric.derived` for what other packages derive (the spray, the
solvers' NLPs and graphs), never a module-level cache keyed by a metric.

A metric's OPTIONAL capabilities (a smooth form of a non-smooth ``F``, a seeding plan, a
height map or kinematics for figures, a closed-form distance) are declared, with their
meaning, in `finsler.hooks` (`MetricHooks`, a base of
`Metric`); the toolkit asks ``metric.provides(hook)``.
"""

from __future__ import annotations

import dataclasses
import functools
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from finsler.domains import Domain, _as_batch, as_real, is_torch
from finsler.errors import InputError, short
from finsler.hooks import MetricHooks
from finsler.infra.limits import check_count, check_memory, check_seed, rows_that_fit
from finsler.lowering import LoweredFunction, lower
from finsler.metrics.checks import (
    _check_field_types,
    _metric_name,
    _ndim,
    _raise_non_finite,
    _same_kind,
    _scalar_F_sx,
    _typed_post_init,
    _value_samples,
)
from finsler.metrics.quadrature import _adaptive_gk, _gauss_legendre01

__all__ = ["LengthBounds", "LengthEstimate", "Metric", "Task", "TrainingSettings"]

#: Largest number of halvings of a segment in `Metric.path_length_bounds`.
MAX_LENGTH_HALVINGS = 14
#: `Metric.path_length_bounds` halves no further once this many pieces are pending.
MAX_LENGTH_PIECES = 1 << 18


@dataclass(frozen=True)
class Task:
    """The midpoint-tree task of section 5.1: ``2**depth`` segments, success iff every
    ``C(p_i, p_{i+1}) <= eps``."""

    depth: int
    eps: float

    def __post_init__(self) -> None:
        if not isinstance(self.depth, (int, np.integer)) or self.depth < 1:
            raise InputError(f"task depth must be a positive integer, got {self.depth!r}")
        if not (np.isfinite(self.eps) and self.eps > 0):
            raise InputError(f"task eps must be positive and finite, got {self.eps!r}")

    @property
    def segments(self) -> int:
        return 2**self.depth


@dataclass(frozen=True)
class TrainingSettings:
    """Data for `learn` about a metric's task (``Metric.training``; finsler only holds
    it): the paper's settings (appendix B: ``paper_lr``, the learning rate, and
    ``paper_timesteps``, the budget, used by the paper's configuration and by Seq), the
    toolkit's measured training ``defaults`` (fields of ``learn.TrainConfig`` over its
    common defaults) and the ``model_free`` overrides Algorithm 1 alone (values of C only)
    was measured best with, and ``pg_cycles``, the PG baseline's schedule (cycles of
    pi_1, cycles of every other pi_D; appendix B.3). A metric that declares nothing gets
    the Matsumoto settings of the paper and the common defaults with a 2e7 budget. The
    mappings are read-only."""

    paper_lr: float = 3e-5
    paper_timesteps: int = 20_000_000
    defaults: Mapping[str, Any] = field(default_factory=lambda: {"timesteps": 20_000_000})
    model_free: Mapping[str, Any] = field(default_factory=dict)
    pg_cycles: tuple[int, int] = (1000, 538)

    def __post_init__(self) -> None:
        for name in ("defaults", "model_free"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))


#: Tolerance of the domain check of the numeric API (solver paths satisfy the domain
#: constraints to IPOPT's tolerance, not exactly).
DOMAIN_TOL = 1e-6

#: Most directions per point of `Metric.convexity` (the spacing of 4096 directions on
#: the circle is 0.0015 rad; more resolve nothing a finer point set would not).
MAX_DIRECTIONS = 1 << 12

#: Highest Gauss-Legendre order accepted by `Metric.segment_length`.
MAX_QUADRATURE_ORDER = 2048



#: Default relative tolerance of `Metric.segment_length_error`.
LENGTH_RTOL = 1e-10
#: Default cap on the subintervals per segment of `Metric.segment_length_error`.
MAX_LENGTH_INTERVALS = 1024


@dataclass(frozen=True)
class LengthBounds:
    """PROVEN bounds ``lower <= length <= upper`` of a polyline (interval arithmetic, see
    `Metric.path_length_bounds`); ``pieces`` counts the pieces the segments were
    cut into, ``converged`` says whether every piece's enclosure reached ``rtol``."""

    lower: float
    upper: float
    pieces: int
    converged: bool

    def to_dict(self) -> dict[str, Any]:
        return {"lower": float(self.lower), "upper": float(self.upper),
                "pieces": int(self.pieces), "converged": bool(self.converged)}


@dataclass(frozen=True)
class LengthEstimate:
    """Curve or segment lengths with an error estimate, from adaptive Gauss-Kronrod.

    ``value`` and ``error`` have the shape of the batch (``(N,)`` for segments, ``(K,)`` for
    paths, ``()`` for one); ``converged`` is True where ``error <= max(atol, rtol * value)``
    was reached within the cap on subintervals; ``intervals`` counts the subintervals used.
    ``lower`` / ``upper`` are ``value -/+ error``: ``upper`` bounds the curve's length,
    hence the distance, from above (under the estimate's assumption, see
    `Metric.segment_length_error`).
    """

    value: Any
    error: Any
    converged: Any
    intervals: Any

    @property
    def lower(self) -> Any:
        return self.value - self.error

    @property
    def upper(self) -> Any:
        return self.value + self.error

    def to_dict(self) -> dict[str, Any]:
        def py(a: Any) -> Any:
            return np.asarray(a).tolist()

        return {"value": py(self.value), "error": py(self.error),
                "converged": py(self.converged), "intervals": py(self.intervals)}




class Metric(MetricHooks, ABC):
    """A Finsler-type metric ``F(x, v)`` on a coordinate domain.

    Subclasses are frozen dataclasses; their fields are the metric's parameters (its
    identity is its registered name plus those parameters: `finsler.MetricSpec`).
    They implement `domain` and `F_sx`, and may provide the optional hooks of
    `finsler.hooks` (``metric.provides(hook)``, ``metric.hooks()``).
    Class attributes describe it:

    * ``name``: registry name; ``task``: default `Task`;
    * ``reversible``: ``F(x, -v) == F(x, v)``;
    * ``smooth``: ``F`` is smooth on ``TM \\ 0``;
    * ``convex_everywhere``: ``F(x, .)`` is convex at every point of the domain
      (for ``smooth`` metrics: strongly convex, i.e. Finsler);
    * ``convexity_note``: a sentence for docs and the CLI;
    * ``training``: `TrainingSettings`, data for `learn` (the paper's learning
      rate and budget for the task, the toolkit's measured training defaults);
    * ``unique_geodesics``: every two points of the domain are joined by exactly one
      geodesic, which is the shortest curve (e.g. a constant norm, a Hadamard manifold, a
      cap smaller than a hemisphere): solvers then need no global seeding (the straight
      line converges to it). Declare it only where it is a theorem for every parameter.
    """

    name: ClassVar[str]
    task: ClassVar[Task]
    reversible: ClassVar[bool] = False
    smooth: ClassVar[bool] = True
    convex_everywhere: ClassVar[bool] = True
    convexity_note: ClassVar[str] = "Finsler (strongly convex) on the whole domain"
    unique_geodesics: ClassVar[bool] = False
    training: ClassVar[TrainingSettings] = TrainingSettings()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Every ``F_sx`` a subclass defines is wrapped once so that what it returns is
        checked to be a scalar CasADi expression (`_scalar_F_sx`), wherever it is used."""
        super().__init_subclass__(**kwargs)
        own = cls.__dict__.get("F_sx")
        if callable(own) and not getattr(own, "__isabstractmethod__", False) and not getattr(
                own, "_scalar_checked", False):
            cls.F_sx = _scalar_F_sx(own)  # type: ignore[method-assign]
        post = cls.__dict__.get("__post_init__")
        if callable(post) and not getattr(post, "_types_checked", False):
            cls.__post_init__ = _typed_post_init(post)  # type: ignore[attr-defined]

    def __post_init__(self) -> None:
        """A dataclass metric's parameters checked against their annotations
        (`_check_field_types`) before its own checks run."""
        _check_field_types(self)

    # -- to implement -------------------------------------------------------------------
    @property
    @abstractmethod
    def domain(self) -> Domain:
        """The coordinate domain."""

    @abstractmethod
    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        """``F(x, v)`` as a scalar CasADi SX expression of ``x``, ``v`` (each ``(dim, 1)``)."""

    # -- derived symbolic objects ---------------------------------------------------------
    @property
    def dim(self) -> int:
        domain = self.domain
        if not isinstance(domain, Domain):
            raise InputError(f"metric {_metric_name(self)!r}: domain must be a finsler Domain "
                             f"(Box, Disk, Product, ...), got {type(domain).__name__}")
        return domain.dim

    @property
    def _ident(self) -> str:
        """The name as a CasADi identifier (letters, digits, single underscores)."""
        return "".join(c if c.isalnum() else "_" for c in self.name).strip("_")

    @functools.cached_property
    def casadi_F(self) -> ca.Function:
        """CasADi function ``F(x, v)`` of two ``dim``-vectors."""
        x = ca.SX.sym("x", self.dim)
        v = ca.SX.sym("v", self.dim)
        return ca.Function(f"F_{self._ident}", [x, v], [self.F_sx(x, v)], ["x", "v"], ["F"])

    @functools.cached_property
    def casadi_cost(self) -> ca.Function:
        """CasADi function ``C(x, y) = F(x, y - x)`` (eq. 4; the chart is the identity)."""
        x = ca.SX.sym("x", self.dim)
        y = ca.SX.sym("y", self.dim)
        return ca.Function(f"C_{self._ident}", [x, y], [self.F_sx(x, y - x)], ["x", "y"], ["C"])

    @functools.cached_property
    def casadi_hessian(self) -> ca.Function:
        """CasADi function: Hessian in ``v`` of ``F(x, v)**2 / 2`` (the fundamental tensor
        ``g(x, v)``, ``(dim, dim)``, dense). The spray (`finsler.geometry`) and the
        convexity check use this one graph; call it on SX symbols to build on it."""
        x = ca.SX.sym("x", self.dim)
        v = ca.SX.sym("v", self.dim)
        e = 0.5 * self.F_sx(x, v) ** 2
        h, _ = ca.hessian(e, v)
        return ca.Function(f"g_{self._ident}", [x, v], [ca.densify(h)], ["x", "v"], ["g"])

    @functools.cached_property
    def casadi_hessian_x(self) -> ca.Function:
        """CasADi function: Hessian in ``x`` of ``F(x, v)`` ``(dim, dim)``, dense (the
        second derivative of a segment's length integrand, `path_length_bounds`).
        Call it on SX symbols to differentiate further (``h = m.casadi_hessian_x(x, v)``)."""
        x = ca.SX.sym("x", self.dim)
        v = ca.SX.sym("v", self.dim)
        h, _ = ca.hessian(self.F_sx(x, v), x)
        return ca.Function(f"hx_{self._ident}", [x, v], [ca.densify(h)], ["x", "v"], ["hx"])

    def derived(self, key: str, build: Callable[[], Any]) -> Any:
        """The toolkit's one cache of derived geometry: ``build()`` once per metric and
        ``key``, then the same object. The derived objects of this class are
        ``functools.cached_property`` attributes (the same per-instance storage); other
        packages keep theirs here under a key naming their module (``"certify.second_derivatives"``,
        ``"geometry.spray"``), never in module-level caches keyed by metric (which keep
        metrics alive and are a second scheme). Keys are strings; the object lives as long
        as the metric. Thread-safe enough for the toolkit: two threads racing on a key
        build it twice and keep one."""
        if not isinstance(key, str) or not key:
            raise InputError(f"derived: key must be a non-empty string, got {key!r}")
        cache = self.__dict__.setdefault("_derived", {})
        if key not in cache:
            cache.setdefault(key, build())
        return cache[key]

    def __getstate__(self) -> dict[str, Any]:
        """Pickle the parameters only: derived objects (lowered programs, CasADi
        functions, `derived` entries) are rebuilt on demand in the other process."""
        if dataclasses.is_dataclass(self):
            return {f.name: self.__dict__[f.name] for f in dataclasses.fields(self)
                    if f.name in self.__dict__}
        return {}

    @functools.cached_property
    def lowered_F(self) -> LoweredFunction:
        """Vectorised numpy/torch program of ``F``, lowered from `casadi_F`."""
        return lower(self.casadi_F)

    @functools.cached_property
    def lowered_hessian(self) -> LoweredFunction:
        return lower(self.casadi_hessian)

    @functools.cached_property
    def segment_derivatives(self) -> LoweredFunction:
        """Vectorised program ``(x, y) -> (phi, grad, hess)`` of one segment's squared cost
        ``phi = C(x, y)**2 = F(x, y - x)**2`` (the summand of the discrete energy, eq. 7):
        ``grad`` ``(2 dim,)`` its gradient in ``(x, y)``, ``hess`` the upper triangle of its
        Hessian in ``(x, y)``, row by row (entries ``(i, j)``, ``i <= j``). Derived
        symbolically from `F_sx` and lowered once (the batched Newton solver of
        `solvers.newton.energy` evaluates it for every segment of every problem at once)."""
        x = ca.SX.sym("x", self.dim)
        y = ca.SX.sym("y", self.dim)
        z = ca.vertcat(x, y)
        phi = self.F_sx(x, y - x) ** 2
        grad = ca.gradient(phi, z)
        hess, _ = ca.hessian(phi, z)
        upper = [hess[i, j] for i in range(2 * self.dim) for j in range(i, 2 * self.dim)]
        return lower(ca.Function(f"seg_{self._ident}", [x, y],
                                 [ca.densify(phi), ca.densify(grad),
                                  ca.densify(ca.vertcat(*upper))]))

    # -- numeric batch methods ------------------------------------------------------------
    # Points given to the numeric methods below are checked (finite, inside the domain up
    # to DOMAIN_TOL) when they are numpy arrays or lists: the user-facing API refuses what
    # the CLI refuses. torch tensors are the training loop's fast path (on any device,
    # differentiable, already projected into the domain) and are not checked; ``check``
    # forces either behaviour.
    def _check_points(self, check: bool | None, **arrays: Any) -> None:
        for name, a in arrays.items():
            if check or (check is None and not is_torch(a)):
                self.check_values()
                self.domain.check(a, name, tol=DOMAIN_TOL)

    def check_values(self) -> None:
        """Raise `InputError` naming the metric and the point unless ``F(x, v)`` is finite
        and ``> 0`` at a few points of the domain (seeded) and unit directions ``v``: the
        cheap first look at a metric every checked entry point takes (the numeric methods
        on checked points, the solvers), made once per metric (``geodesics check`` searches
        thoroughly, property by property)."""
        if self.__dict__.get("_values_checked"):
            return
        _ = self.dim  # a domain that is not a Domain is refused first
        x, v = _value_samples(self.domain)
        with np.errstate(all="ignore"):
            f = np.asarray(self.casadi_F.map(x.shape[0])(x.T, v.T), dtype=float).reshape(-1)
        bad = ~(np.isfinite(f) & (f > 0))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"metric {short(self.name, 80)!r}: F(x, v) = {f[i]:.6g} at x = "
                f"{short(str(x[i].tolist()), 80)}, v = {short(str(v[i].tolist()), 80)}, a "
                "point of its domain: F must be finite and > 0 for v != 0 on the whole "
                "domain (fix F there or declare a smaller domain; `geodesics check` "
                "searches for the region)")
        self.__dict__["_values_checked"] = True

    def F(self, x: Any, v: Any, check: bool | None = None) -> Any:
        """``F(x, v)`` for ``x, v`` of shape ``(N, dim)`` (or ``(dim,)``) -> ``(N,)`` (or ``()``).

        numpy in, numpy (float64) out; torch in, torch out (same device, differentiable).
        ``x`` is checked (inside the domain, finite) unless it is a torch tensor or
        ``check=False``.
        """
        single = _ndim(x) == 1 and _ndim(v) == 1
        xb = _as_batch(x, self.dim, "x", check_finite=False)
        vb = _as_batch(v, self.dim, "v", check_finite=False)
        _same_kind(xb, vb)
        self._check_points(check, x=xb)
        out = self._eval_F(xb, vb)
        return out[0] if single else out

    def cost(self, x: Any, y: Any, check: bool | None = None) -> Any:
        """Local cost ``C(x, y) = F(x, y - x)`` of eq. (4), batch ``(N, dim)`` -> ``(N,)``.
        Points are checked unless they are torch tensors or ``check=False``."""
        xb, yb, single = self._pair(x, y)
        self._check_points(check, x=xb, y=yb)
        out = self._eval_F(xb, yb - xb)
        return out[0] if single else out

    def cost_symmetric(self, x: Any, y: Any, check: bool | None = None) -> Any:
        """Symmetrised cost of eq. (59): ``(F(x, y - x) + F(y, y - x)) / 2``."""
        xb, yb, single = self._pair(x, y)
        self._check_points(check, x=xb, y=yb)
        d = yb - xb
        out = 0.5 * (self._eval_F(xb, d) + self._eval_F(yb, d))
        return out[0] if single else out

    def segment_length(self, x: Any, y: Any, order: int = 8,
                       check: bool | None = None) -> Any:
        """Length (eq. 58) of the coordinate segment from ``x`` to ``y`` by Gauss-Legendre
        quadrature of the given order; an upper bound of the distance ``d(x, y)``."""
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
            raise InputError(f"quadrature order must be a positive integer, got "
                             f"{short(repr(order), 80)}")
        if order > MAX_QUADRATURE_ORDER:
            raise InputError(f"quadrature order {order} is above {MAX_QUADRATURE_ORDER}: its "
                             "nodes cost O(order^2) memory and O(order^3) time, and a "
                             f"Gauss-Legendre rule of order {MAX_QUADRATURE_ORDER} is already "
                             f"exact for polynomials of degree {2 * MAX_QUADRATURE_ORDER - 1}")
        xb, yb, single = self._pair(x, y)
        self._check_points(check, x=xb, y=yb)
        # points, directions and the lowered program's intermediate values per node
        check_memory((int(order), xb.shape[0], self.dim), f"quadrature of order {order}",
                     hint="use a lower order", copies=16)
        t, w = _gauss_legendre01(int(order))
        d = yb - xb
        n = xb.shape[0]
        if is_torch(xb):
            import torch

            tt = torch.as_tensor(t, dtype=xb.dtype, device=xb.device)[:, None, None]
            ww = torch.as_tensor(w, dtype=xb.dtype, device=xb.device)
            pts = (xb[None] + tt * d[None]).reshape(-1, self.dim)
            dirs = d[None].expand(len(t), n, self.dim).reshape(-1, self.dim)
            f = self._eval_F(pts, dirs)
            out = (f.reshape(len(t), n) * ww[:, None]).sum(0)
        else:
            pts = (xb[None] + t[:, None, None] * d[None]).reshape(-1, self.dim)
            dirs = np.broadcast_to(d[None], (len(t), n, self.dim)).reshape(-1, self.dim)
            f = self._eval_F(pts, dirs)
            out = w @ f.reshape(len(t), n)
        return out[0] if single else out

    def segment_length_error(self, x: Any, y: Any, rtol: float = LENGTH_RTOL,
                             atol: float = 0.0, max_intervals: int = MAX_LENGTH_INTERVALS,
                             check: bool | None = None) -> LengthEstimate:
        """Length (eq. 58) of the coordinate segments from ``x`` to ``y`` (``(N, dim)`` or
        ``(dim,)``, numpy) with an error estimate, by adaptive Gauss-Kronrod (G7-K15).

        Every segment's parameter interval ``[0, 1]`` is bisected where the local error
        estimate ``|K15 - G7|`` of a subinterval exceeds its share ``tol * width`` of the
        tolerance ``tol = max(atol, rtol * |length|)``, until no subinterval does or the
        segment has ``max_intervals`` subintervals. ``error`` is the sum of ``|K15 - G7|``
        over the final subintervals plus a rounding term (``1e2 * machine eps * length``):
        the error of the 7-point Gauss rule, which over-estimates the error of the returned
        15-point Kronrod value wherever the integrand is smooth on the subinterval (the
        classical assumption of QUADPACK, without its down-scaling of the estimate). Kinks
        of ``F`` (non-smooth metrics) are resolved by bisection, the estimate stays
        honest there because the kink makes ``|K15 - G7|`` large.

        Returns a `LengthEstimate` (``value``, ``error``, ``converged``,
        ``intervals``), float64 numpy. Torch input is refused (not a training-loop path).
        """
        for name, val in (("rtol", rtol), ("atol", atol)):
            if isinstance(val, bool) or not isinstance(val, (int, float, np.floating)) or not (
                    np.isfinite(val) and val >= 0):
                raise InputError(f"{name} must be a finite number >= 0, got {val!r}")
        if rtol == 0 and atol == 0:
            raise InputError("rtol and atol are both 0: no tolerance can be reached")
        if (isinstance(max_intervals, bool) or not isinstance(max_intervals, (int, np.integer))
                or max_intervals < 1):
            raise InputError(f"max_intervals must be a positive integer, got {max_intervals!r}")
        if is_torch(x) or is_torch(y):
            raise InputError("segment_length_error takes numpy arrays (float64), not torch")
        xb, yb, single = self._pair(x, y)
        self._check_points(check, x=xb, y=yb)
        n = max(xb.shape[0], yb.shape[0])
        xb = np.broadcast_to(xb, (n, self.dim))
        d = np.broadcast_to(yb, (n, self.dim)) - xb
        # segments are independent: evaluated in parts whose worst case (every segment
        # bisected to max_intervals) fits the memory limit; one segment must fit
        rows = rows_that_fit((int(max_intervals), 15, self.dim), "adaptive quadrature",
                             hint="use a smaller max_intervals", copies=2)
        parts = [_adaptive_gk(self._eval_F, xb[a:a + rows], d[a:a + rows], float(rtol),
                              float(atol), int(max_intervals)) for a in range(0, max(n, 1), rows)]
        value, error, intervals = (np.concatenate(c) for c in zip(*parts, strict=True))
        tol = np.maximum(atol, rtol * np.abs(value))
        converged = error <= tol
        if single:
            return LengthEstimate(float(value[0]), float(error[0]), bool(converged[0]),
                                  int(intervals[0]))
        return LengthEstimate(value, error, converged, intervals)

    def path_length_error(self, points: Any, rtol: float = LENGTH_RTOL, atol: float = 0.0,
                          max_intervals: int = MAX_LENGTH_INTERVALS,
                          check: bool | None = None) -> LengthEstimate:
        """Length of polylines ``(n+1, dim)`` (or a batch ``(K, n+1, dim)``) with an error
        estimate: `segment_length_error` of every segment (relative tolerance ``rtol``
        of the whole path's length, shared by its segments in proportion to their
        lengths), summed. Returns a `LengthEstimate` of shape ``()`` (or ``(K,)``).
        """
        p = as_real(points, "points")
        single = p.ndim == 2
        if single:
            p = p[None]
        if p.ndim != 3 or p.shape[-1] != self.dim or p.shape[1] < 2:
            raise InputError(f"points must have shape (n+1, {self.dim}) or (K, n+1, "
                             f"{self.dim}) with n >= 1, got {np.shape(points)}")
        k, m, _ = p.shape
        seg = self.segment_length_error(p[:, :-1].reshape(-1, self.dim),
                                        p[:, 1:].reshape(-1, self.dim), rtol=rtol, atol=atol,
                                        max_intervals=max_intervals, check=check)
        value = np.asarray(seg.value).reshape(k, m - 1).sum(1)
        error = np.asarray(seg.error).reshape(k, m - 1).sum(1)
        intervals = np.asarray(seg.intervals).reshape(k, m - 1).sum(1)
        converged = error <= np.maximum(atol, rtol * np.abs(value))
        if single:
            return LengthEstimate(float(value[0]), float(error[0]), bool(converged[0]),
                                  int(intervals[0]))
        return LengthEstimate(value, error, converged, intervals)

    @functools.cached_property
    def _length_enclosure(self) -> LoweredFunction:
        """``(x, v) -> (F(x, v), v' Hess_x F(x, v) v)``: the integrand of a segment's length
        and its second derivative along the segment."""
        x = ca.SX.sym("x", self.dim)
        v = ca.SX.sym("v", self.dim)
        f = self.F_sx(x, v)
        h = self.casadi_hessian_x(x, v)
        return lower(ca.Function(f"len_{self._ident}", [x, v],
                                 [f, ca.densify(ca.mtimes([v.T, h, v]))]))

    def path_length_bounds(self, points: Any, rtol: float = 1e-9) -> LengthBounds:
        """Proven bounds of the length (eq. 58 summed) of a polyline ``(n+1, dim)``.

        On a piece ``[t0, t0 + tau]`` of a segment ``x(t) = a + t d`` the length is
        ``int F(x(t), d) dt = tau F(x(c), d) + tau**3 / 24 f''(xi)`` (midpoint rule,
        ``f'' = d' Hess_x F(x, d) d``), so it lies in ``tau [F(x(c), d)] + tau**3 / 24
        [f''(box)]`` where the brackets are interval enclosures (`finsler.enclosures.intervals`,
        outward rounding) at the piece's midpoint and over its bounding box. Pieces whose
        enclosure is wider than ``rtol`` of their length are halved, up to
        ``MAX_LENGTH_HALVINGS`` times (and no further once ``MAX_LENGTH_PIECES`` are
        pending: the bound then holds, ``converged`` is False); the pieces are summed with
        ``math.fsum`` (correctly rounded) and widened by a unit in the last place. Sound
        where F is twice differentiable in ``x`` along the path. Where the enclosure of
        ``f''`` is infinite (a kink of a C^0 metric such as car-like's ``max``), the piece
        takes the zeroth-order enclosure ``tau [F(box, d)]`` instead (the integrand lies in
        it on the whole piece, for any F), whose width shrinks linearly under halving; an
        infinite enclosure of F gives an infinite bound, never a wrong one.
        """
        import math

        from finsler.enclosures.intervals import Interval, enclose

        p = as_real(points, "points")
        if p.ndim != 2 or p.shape[-1] != self.dim or p.shape[0] < 2:
            raise InputError(f"points must have shape (n+1, {self.dim}) with n >= 1, got "
                             f"{np.shape(points)}")
        self.domain.check(p, "points")
        if isinstance(rtol, bool) or not (isinstance(rtol, (int, float)) and 0 < rtol < 1):
            raise InputError(f"rtol must be in (0, 1), got {rtol!r}")
        fn = self._length_enclosure
        a, d = p[:-1], p[1:] - p[:-1]
        t0, tau = np.zeros(len(a)), np.ones(len(a))
        los: list[np.ndarray] = []
        his: list[np.ndarray] = []
        converged = True
        for level in range(MAX_LENGTH_HALVINGS + 1):
            # the piece [t0, t0 + tau] of the segment a + t d, in outward-rounded intervals
            ta, tb = Interval(t0), Interval(t0) + Interval(tau)
            tc = Interval(t0) + Interval(0.5) * Interval(tau)
            vel = [Interval(d[:, i]) for i in range(self.dim)]
            at = [[Interval(a[:, i]) + t * vel[i] for i in range(self.dim)] for t in (ta, tb, tc)]
            box = [Interval(np.minimum(u.lo, w.lo), np.maximum(u.hi, w.hi))
                   for u, w in zip(at[0], at[1], strict=True)]
            (f_c, _) = enclose(fn, at[2], vel)
            (f_box, q_box) = enclose(fn, box, vel)
            t = Interval(tau)
            piece = t * f_c[0] + (t * t * t) * (Interval(1.0) / Interval(24.0)) * q_box[0]
            kink = ~(np.isfinite(piece.lo) & np.isfinite(piece.hi))
            if np.any(kink):  # zeroth order: int F(x(t), d) dt in tau [F(box, d)]
                zero = t * f_box[0]
                piece = Interval(np.where(kink, zero.lo, piece.lo),
                                 np.where(kink, zero.hi, piece.hi))
            loose = ~(piece.hi - piece.lo <= rtol * np.maximum(piece.lo, 0.0))
            last = level == MAX_LENGTH_HALVINGS or 2 * np.count_nonzero(loose) > MAX_LENGTH_PIECES
            done = np.ones(len(t0), bool) if last else ~loose
            los.append(piece.lo[done])
            his.append(piece.hi[done])
            if done.all():
                converged = not np.any(loose)
                break
            idx = np.flatnonzero(~done)
            half = 0.5 * tau[idx]
            a, d = np.repeat(a[idx], 2, axis=0), np.repeat(d[idx], 2, axis=0)
            t0 = np.stack([t0[idx], t0[idx] + half], 1).reshape(-1)
            tau = np.repeat(half, 2)
        lo_all, hi_all = np.concatenate(los), np.concatenate(his)
        lo = math.fsum(lo_all.tolist()) if np.all(np.isfinite(lo_all)) else -math.inf
        hi = math.fsum(hi_all.tolist()) if np.all(np.isfinite(hi_all)) else math.inf
        return LengthBounds(lower=max(math.nextafter(lo, -math.inf), 0.0),
                            upper=math.nextafter(hi, math.inf), pieces=int(lo_all.size),
                            converged=bool(converged))

    def path_costs(self, points: Any, check: bool | None = None) -> Any:
        """Segment costs ``C(p_i, p_{i+1})`` of paths ``(K, n+1, dim)`` -> ``(K, n)``
        (points checked unless torch or ``check=False``)."""
        points = as_real(points, "paths", f"a real numeric array of shape (K, n+1, {self.dim})")
        if _ndim(points) != 3 or points.shape[-1] != self.dim or points.shape[1] < 2:
            raise InputError(
                f"paths must have shape (K, n+1, {self.dim}) with n >= 1, got "
                f"{tuple(points.shape)}"
            )
        k, m, _ = points.shape
        a = points[:, :-1].reshape(-1, self.dim)
        b = points[:, 1:].reshape(-1, self.dim)
        return self.cost(a, b, check=check).reshape(k, m - 1)

    # -- convexity (the Finsler condition) ------------------------------------------------
    def convexity(self, x: Any, n_directions: int = 64, seed: int = 0) -> np.ndarray:
        """Smallest eigenvalue of the fundamental tensor ``Hess_v F(x, v)**2 / 2`` over unit
        directions ``v`` at each point ``x`` ``(N, dim)`` -> ``(N,)``.

        Positive means ``F(x, .)`` is strongly convex along the sampled directions; a
        negative value certifies non-convexity. Directions: evenly spaced on the circle in
        2-D, uniformly random (seeded) unit vectors otherwise. For non-smooth metrics the
        Hessian is taken where ``F`` is smooth (a.e.).
        """
        n_directions = check_count(n_directions, "n_directions", 1, MAX_DIRECTIONS)
        self.check_values()
        seed = check_seed(seed)
        xn = self.domain.check(x, "x")
        # the directions at every point and their fundamental tensors
        check_memory((xn.shape[0], n_directions, self.dim + 1, self.dim),
                     f"convexity at {xn.shape[0]} points x {n_directions} directions",
                     hint="pass fewer points or directions", copies=4)
        if self.dim == 2:
            a = np.linspace(0.0, 2 * np.pi, n_directions, endpoint=False)
            dirs = np.stack([np.cos(a), np.sin(a)], 1)
        else:
            g = np.random.default_rng(seed).normal(size=(n_directions, self.dim))
            dirs = g / np.linalg.norm(g, axis=1, keepdims=True)
        n = xn.shape[0]
        xs = np.repeat(xn, len(dirs), axis=0)
        vs = np.tile(dirs, (n, 1))
        (h,) = self.lowered_hessian(xs, vs)
        h = h.reshape(-1, self.dim, self.dim).transpose(0, 2, 1)  # CasADi is column-major
        if self.dim == 2:  # closed form of the smaller eigenvalue (10x LAPACK's batch)
            a, b, c = h[:, 0, 0], 0.5 * (h[:, 0, 1] + h[:, 1, 0]), h[:, 1, 1]
            lam = 0.5 * (a + c) - np.hypot(0.5 * (a - c), b)
        else:
            lam = np.linalg.eigvalsh(0.5 * (h + h.transpose(0, 2, 1)))[:, 0]
        return lam.reshape(n, len(dirs)).min(axis=1)

    def midpoint_convexity_gap(self, x: Any, v: Any, w: Any) -> np.ndarray:
        """``F(x, (v + w) / 2) - (F(x, v) + F(x, w)) / 2``: positive values violate convexity."""
        v, w = as_real(v, "v"), as_real(w, "w")
        return self.F(x, 0.5 * (v + w)) - 0.5 * (
            self.F(x, v) + self.F(x, w)
        )

    # -- helpers --------------------------------------------------------------------------
    def _eval_F(self, x: Any, v: Any) -> Any:
        """Lowered ``F`` on shape-checked batches -> ``(N,)``.

        Finiteness is checked on the output (one pass over N values instead of 2N inputs):
        a non-finite result is traced back to non-finite inputs (`InputError`), or
        to zero vectors, where ``F(x, 0) = 0`` exactly (formulas such as Matsumoto's
        ``alpha**2 / (alpha - beta)`` are 0/0 there).
        """
        if is_torch(v):
            import torch

            (out,) = self.lowered_F(x, v)
            out = out[..., 0]
            if not bool(torch.isfinite(out).all()):
                _raise_non_finite(x, v)
                out = torch.where((v == 0).all(dim=-1), torch.zeros_like(out), out)
            return out
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            (out,) = self.lowered_F(x, v)
        out = out[..., 0]
        if not np.isfinite(out).all():
            _raise_non_finite(x, v)
            out = self._rescaled(x, v, out)
            out = np.where(np.all(v == 0, axis=-1), 0.0, out)
        return out

    def _rescaled(self, x: np.ndarray, v: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``out`` with its non-finite entries recomputed as ``F(x, v / s) * s``, ``s = max
        |v|`` (``F`` is positively 1-homogeneous in ``v``): huge vectors whose squares
        overflow float64 get their finite length (``F(0, (1e308, 1e308)) = 1.41e308``)."""
        scale = np.max(np.abs(v), axis=-1)
        redo = ~np.isfinite(out) & (scale > 0) & np.isfinite(scale)
        if not redo.any():
            return out
        out = np.array(out, dtype=np.float64)
        s = scale[redo]
        xs = np.broadcast_to(x, v.shape)[redo]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
            (unit,) = self.lowered_F(xs, v[redo] / s[:, None])
            unit = unit[..., 0]
            out[redo] = unit * s
        over = np.isfinite(unit) & ~np.isfinite(out[redo])
        if over.any():  # the length itself is beyond float64, not an intermediate
            i = int(np.flatnonzero(over)[0])
            raise InputError(f"F(x, v) = {unit[i]:.6g} * {s[i]:.6g} at v = "
                             f"{short(str(v[redo][i].tolist()), 80)} exceeds the largest "
                             "float64 (1.8e308): scale v down (F is 1-homogeneous in v)")
        return out

    def _pair(self, x: Any, y: Any) -> tuple[Any, Any, bool]:
        single = _ndim(x) == 1 and _ndim(y) == 1
        xb = _as_batch(x, self.dim, "x", check_finite=False)
        yb = _as_batch(y, self.dim, "y", check_finite=False)
        _same_kind(xb, yb)
        rows = (xb.shape[0], yb.shape[0])
        if rows[0] != rows[1]:
            if 1 not in rows:
                raise InputError(
                    f"x and y must have the same number of rows, got {rows[0]} and {rows[1]}")
            # one point against a batch (also an empty one): the same rows on both sides
            n = rows[1] if rows[0] == 1 else rows[0]
            if is_torch(xb):
                xb, yb = xb.expand(n, self.dim), yb.expand(n, self.dim)
            else:
                xb = np.broadcast_to(xb, (n, self.dim))
                yb = np.broadcast_to(yb, (n, self.dim))
        return xb, yb, single

    def info(self) -> dict[str, Any]:
        """Summary used by ``geodesics metrics``."""
        return {
            "name": self.name,
            "dim": self.dim,
            "domain": self.domain.describe(),
            "depth": self.task.depth,
            "eps": self.task.eps,
            "reversible": self.reversible,
            "convexity": self.convexity_note,
            "hooks": list(self.hooks()),
        }
