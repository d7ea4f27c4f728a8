"""Certified intervals ``lower <= d(start, goal) <= upper`` for 2-D metrics (issue 10).

Lower bound by convex duality. If a potential ``phi`` satisfies ``dphi_z(v) <= F(z, v)`` for
every point ``z`` and every vector ``v`` (the dual norm ``F*(z, dphi_z) <= 1``), then for
every curve ``gamma`` from ``x`` to ``y``, ``phi(y) - phi(x) = int dphi(gamma') <=
int F(gamma, gamma')``, hence ``d(x, y) >= phi(y) - phi(x)``. :func:`certify` maximises
``phi(goal) - phi(start)`` over continuous piecewise-quadratic (P2) potentials on a Delaunay
triangulation that covers the whole domain (a convex polygon containing it), a linear
program solved with cvxpy (Clarabel).

The condition must hold at EVERY ``z`` of a triangle and EVERY direction, not only at
samples. With ``K`` unit directions ``v_k`` and the chords ``w(t) = (1 - t) v_j + t v_{j+1}``
between them (every direction is a positive multiple of a chord point, and both sides are
1-homogeneous in ``v``), the rows are, at each vertex ``z_m`` of each triangle ``T``::

    grad phi_T(z_m) . v_k  <=  F(z_m, v_k) - Hz_{T,k} R_T**2 / 2 - max(Ht_{T,k-1}, Ht_{T,k}) / 8

``grad phi_T`` is affine on ``T`` (P2), so ``F(z, v_k) - grad phi_T(z) . v_k`` differs from
its linear interpolant by at most ``Hz R**2 / 2`` (``Hz`` >= the largest eigenvalue of
``Hess_z F(., v_k)`` on ``T``, ``R`` the circumradius: ``sum_i lambda_i |z_i - z|**2 <= R**2``),
and along a chord ``F(z, w(t))`` lies above the chord's linear interpolant minus
``Ht / 8`` (``Ht`` >= ``d2/dt2 F(z, w(t))`` on ``T`` x the arc). Neither bound needs
``F(z, .)`` to be convex. ``Hz`` and ``Ht`` are PROVEN upper bounds: interval enclosures
(:mod:`finsler.intervals`, outward rounding) of the CasADi Hessians of the metric's own
``F`` over the triangle's bounding box (x the chord's box for ``Ht``), the tighter of the
natural extension and the mean-value form (third derivatives over the box); where a
direction's correction is above ``SPLIT_FRACTION`` of F and its enclosure overestimates
(above ``SPLIT_OVERESTIMATE`` times the value at the box's centre, or infinite), the max
over the 2 x 2 sub-boxes that meet the triangle, recursively (``SPLIT_DEPTH`` levels). The
values ``F(z_m, v_k)`` are lowered by 16 ulp (numpy's float64 F is within a few ulp of the
exact one) and the corrections raised by 1e-12 relative: the rows hold in exact
arithmetic, up to the accuracy of numpy's elementary functions (documented at <= 4 ulp).
The LP keeps the vertices away from the path inside inner polygons
of the rows' sets (they can never violate a row) and gives the vertices near the path the
sampled rows themselves, adding violated directions in rounds; every round's potential is
checked against ALL rows and divided by the largest ratio ``(grad phi . v_k) / bound``, so
the returned lower bound satisfies every row exactly whatever the LP solver's tolerance.

Convexity: where ``F(z, .)`` is not convex (Matsumoto outside ``|p| = 1/(2 sqrt 3)``) the
condition ``dphi(v) <= F(z, v)`` for all ``v`` is the same as for the convexification
``F**(z, .)``; the lower bound is valid for the distance (an infimum of lengths, which the
convexification does not change), and the result says which case applies.

Upper bound: the length of the solver's path (:func:`solvers.solve_geodesic`), PROVEN by
interval arithmetic (:meth:`finsler.Metric.path_length_bounds`: midpoint rule plus an
enclosure of the second derivative along each piece); ``length`` / ``length_error`` also
give the adaptive-quadrature estimate of the same length.

Refinement: triangles are refined (edge midpoints, Delaunay again) where the LP's dual
solution says the corrections cost most (``sum_rows y_r c_r``, the bound's sensitivity),
starting from a mesh graded around the solver's path, until the gap reaches
``MeshSpec.target_gap`` or a size / round limit.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import casadi as ca
import numpy as np

from finsler.domains import Box, Disk
from finsler.errors import InputError, short
from finsler.intervals import Interval, enclose, isqrt
from finsler.limits import check_memory
from finsler.lowering import LoweredFunction, lower
from finsler.metric import Metric
from solvers.inputs import SHORT_PAIR, as_metric, domain_scale, is_short_pair
from solvers.status import CertifyStatus

__all__ = ["CertifyResult", "MeshSpec", "certify"]

_LOG = logging.getLogger(__name__)

#: cvxpy solver of the LPs (Clarabel: an interior-point method, far faster here than HiGHS).
LP_SOLVER = "CLARABEL"
#: Rows whose dual exceeds this fraction of the largest dual count as tight (refined).
TIGHT_DUAL = 1e-7
#: Refinements of triangles whose corrections exceed half of F, before the first LP.
MAX_PRE_REFINE = 8
#: Sub-box splitting (2 x 2 per level) of triangles whose enclosures are infinite or loose.
SPLIT_DEPTH = 2
#: A triangle's box is split where its correction exceeds this fraction of F and its
#: enclosures exceed this multiple of their values at the box's centre.
SPLIT_FRACTION = 0.25
SPLIT_OVERESTIMATE = 1.5
#: Evenly spaced rays of the inner polygons that keep the vertices away from the path safe.
INITIAL_DIRECTIONS = 8
#: Directions an exact vertex starts with around the path's (or a tight edge's) direction:
#: this fraction of the K sampled directions on each side (violated ones are added later).
WINDOW_FRACTION = 1 / 64


class LPFailure(RuntimeError):
    """The LP solver failed on one round (turned into :attr:`CertifyStatus.LP_FAILED`)."""


def _window(k: int) -> int:
    return max(1, int(k * WINDOW_FRACTION))


@dataclass(frozen=True)
class MeshSpec:
    """Mesh and refinement settings of :func:`certify`.

    Lengths are in coordinates. The first mesh has spacing ``h_path`` within ``corridor`` of
    the solver's path, growing by ``grade`` per unit distance beyond, up to ``h_far``.
    """

    h_path: float = 0.05
    """Spacing of the first mesh along the solver's path."""
    corridor: float = 0.1
    """Half-width of the band around the path meshed at ``h_path``."""
    grade: float = 0.6
    """Growth of the spacing per unit distance outside the band."""
    h_far: float = 0.25
    """Largest spacing (far from the path)."""
    directions: int = 256
    """Number K of sampled unit directions per triangle (>= 8)."""
    target_gap: float = 1e-2
    """Stop refining once the relative gap (upper - lower) / upper is at most this."""
    max_triangles: int = 12000
    """Stop refining before the mesh would exceed this many triangles."""
    max_rounds: int = 8
    """Largest number of refinement rounds (LP solves)."""
    mark_fraction: float = 0.9
    """Refine the triangles that carry this fraction of the dual-weighted corrections."""
    segments: int | None = None
    """Segments of the solver's path (the upper bound); default: 4 x the task's 2**D."""

    def __post_init__(self) -> None:
        for name in ("h_path", "corridor", "grade", "h_far", "target_gap", "mark_fraction"):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not (
                    math.isfinite(val) and val > 0):
                raise InputError(f"MeshSpec.{name} must be positive and finite, got {val!r}")
        if self.h_path > self.h_far:
            raise InputError(f"MeshSpec.h_path ({self.h_path}) must be <= h_far ({self.h_far})")
        if self.mark_fraction > 1:
            raise InputError(f"MeshSpec.mark_fraction must be <= 1, got {self.mark_fraction}")
        for name, low in (("directions", 8), ("max_triangles", 2), ("max_rounds", 1)):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < low:
                raise InputError(f"MeshSpec.{name} must be an integer >= {low}, got {val!r}")
        # per mesh point and direction: F, and per triangle: two bounds (float64 each)
        check_memory((3 * self.max_triangles, self.directions), "MeshSpec.directions x "
                     "max_triangles", hint="fewer directions or triangles", copies=4)
        if self.segments is not None and (isinstance(self.segments, bool) or not isinstance(
                self.segments, (int, np.integer)) or self.segments < 2):
            raise InputError(f"MeshSpec.segments must be an integer >= 2, got "
                             f"{self.segments!r}")

    @classmethod
    def preset(cls, name: str) -> MeshSpec:
        """``"coarse"`` (gap ~ a few 1e-2, fast), ``"default"`` (target 1e-2) or ``"fine"``
        (target 1e-3, more directions and triangles)."""
        presets = {
            "coarse": cls(h_path=0.1, h_far=0.3, directions=128, target_gap=5e-2,
                          max_rounds=3, max_triangles=3000),
            "default": cls(),
            "fine": cls(h_path=0.04, directions=512, target_gap=1e-3, max_rounds=12,
                        max_triangles=40000, mark_fraction=0.99),
        }
        if name not in presets:
            raise InputError(f"unknown mesh preset {name!r}; choose one of "
                             f"{', '.join(presets)}")
        return presets[name]


@dataclass
class CertifyResult:
    """A certified interval ``lower <= d(start, goal) <= upper``.

    ``gap = (upper - lower) / upper``. ``upper`` is a proven upper bound of the length of
    ``path`` ``(n+1, 2)`` (:meth:`finsler.Metric.path_length_bounds`; ``length`` and
    ``length_error`` are the adaptive-quadrature estimate of it): the solver's (or the
    given) path
    (``upper_source == "path"``) or, where ``F(z, .)`` is not convex, the same path with
    every segment replaced by a zigzag along the two directions of the convexification
    when that is shorter (``"zigzag"``: switchbacks, the curves whose lengths approach the
    infimum there). ``path_upper`` / ``path_gap`` are the bound and gap of the solver's
    path itself: a small ``path_gap`` certifies that path near-globally optimal.
    ``convexity`` is ``"convex"``
    (``F(z, .)`` convex on the whole domain) or ``"convexified"`` (not convex somewhere:
    the dual condition equals that of the convexification, see the module docstring);
    ``convexity_note`` says it in words. ``rounds`` lists, per LP solve, the triangles,
    rows used, lower bound and gap. ``times`` in seconds: ``solve`` (upper bound), ``mesh``,
    ``bounds`` (F and its Hessians), ``lp`` and ``total``. ``lp_status`` is cvxpy's status
    of the last LP; ``max_row_ratio`` the largest ``grad phi . v / bound`` over every row
    of the last potential before the final check (``<= 1`` up to the LP solver's
    feasibility tolerance; the potential is divided by it when above 1). ``lp_rows`` counts
    the rows of the last LP (edges of the inner polygons), ``lp_rows_total`` the sampled
    rows they imply (3 x triangles x directions). ``stopped_by`` says what ended the
    refinement: ``target_gap`` (reached), ``max_rounds`` or ``max_triangles`` (the work
    budgets of :class:`MeshSpec`), ``no_refinement`` (no triangle left to refine), or
    ``time_limit`` (the caller's wall-clock limit: only then can the result depend on the
    machine's speed), or the failure's label. ``status`` (:class:`solvers.CertifyStatus`)
    says the same in the toolkit's one family of statuses: a failure of the refinement (an
    LP solver failure, corrections that do not shrink) is a status with the best interval
    proven so far (lower bound 0 if none) and ``message``, never an exception.
    ``solver_status`` is the label of the upper-bound solve's status (or ``given``).
    """

    metric: str
    start: np.ndarray
    goal: np.ndarray
    lower: float
    upper: float
    length: float
    length_error: float
    gap: float
    upper_source: str
    path_upper: float
    path_gap: float
    triangles: int
    vertices: int
    unknowns: int
    directions: int
    lp_rows: int
    lp_rows_total: int
    lp_status: str
    lp_solver: str
    max_row_ratio: float
    convexity: str
    convexity_note: str
    solver_status: str
    mesh: dict[str, Any]
    times: dict[str, float]
    rounds: list[dict[str, Any]] = field(default_factory=list)
    path: np.ndarray | None = None
    stopped_by: str = "target_gap"
    status: CertifyStatus = CertifyStatus.CERTIFIED
    message: str = ""

    @property
    def converged(self) -> bool:
        """True if the refinement reached its target gap (``status`` is ``CERTIFIED``)."""
        return self.status.converged

    @property
    def certified(self) -> bool:
        """True if both bounds are finite and ``lower <= upper``."""
        return bool(np.isfinite(self.lower) and np.isfinite(self.upper)
                    and self.lower <= self.upper)

    def to_dict(self, with_path: bool = False) -> dict[str, Any]:
        """JSON-ready dict (keys ``lower``, ``upper``, ``gap`` first; ``path`` only if
        ``with_path``)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            val = getattr(self, f.name)
            if f.name == "path" and not with_path:
                continue
            if isinstance(val, np.ndarray):
                val = val.tolist()
            out[f.name] = val.label if isinstance(val, CertifyStatus) else val
        return out


# ----------------------------------------------------------------------------------------
# derivatives of F (CasADi, lowered once per metric)
# ----------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=8)
def _values(metric: Metric) -> LoweredFunction:
    """Lowered ``(x, v) -> F``, batch ``(N, 2)`` -> ``(N, 1)``."""
    x = ca.SX.sym("x", 2)
    v = ca.SX.sym("v", 2)
    return lower(ca.Function(f"certify_F_{metric._ident}", [x, v], [metric.F_sx(x, v)]))


@functools.lru_cache(maxsize=8)
def _second_derivatives(metric: Metric) -> tuple[LoweredFunction, ...]:
    """Lowered functions whose interval enclosures bound the corrections:

    * ``(x, v) -> (h, dh)``: ``h`` the entries ``(H11, H12, H22)`` of ``Hess_x F(x, v)``,
      ``dh`` their gradients in ``x`` (``dh[2 j + i] = d h_j / d x_i``);
    * ``(x, v, d) -> (q, dq)``: ``q = d' Hess_v F(x, v) d`` (the second derivative of F
      along a chord of direction ``d``) and its gradient in ``(x, v)``;
    * ``(x, v) -> h`` and ``(x, v, d) -> q`` alone (the centres of the mean-value forms).
    """
    x = ca.SX.sym("x", 2)
    v = ca.SX.sym("v", 2)
    d = ca.SX.sym("d", 2)
    f = metric.F_sx(x, v)
    hx, _ = ca.hessian(f, x)
    h = ca.vertcat(hx[0, 0], hx[0, 1], hx[1, 1])
    dh = ca.vertcat(*[ca.gradient(h[j], x) for j in range(3)])
    hv, _ = ca.hessian(f, v)
    q = ca.mtimes([d.T, hv, d])
    dq = ca.gradient(q, ca.vertcat(x, v))
    tag = metric._ident
    return (lower(ca.Function(f"certify_hz_{tag}", [x, v], [ca.densify(h), ca.densify(dh)])),
            lower(ca.Function(f"certify_ht_{tag}", [x, v, d], [ca.densify(q), ca.densify(dq)])),
            lower(ca.Function(f"certify_h_{tag}", [x, v], [ca.densify(h)])),
            lower(ca.Function(f"certify_q_{tag}", [x, v, d], [ca.densify(q)])))


def _eval_values(metric: Metric, x: np.ndarray, v: np.ndarray,
                 chunk: int = 200_000) -> np.ndarray:
    fun = _values(metric)
    fs = []
    for a in range(0, x.shape[0], chunk):
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            (f,) = fun(x[a:a + chunk], v[a:a + chunk])
        fs.append(np.asarray(f, float).reshape(-1))
    out = np.concatenate(fs)
    if not np.all(np.isfinite(out)):
        raise InputError(f"{metric.name}: F is not finite on the mesh (the polygon covering "
                         "the domain reaches a singularity of F?)")
    # a lower bound of the exact value: numpy's float64 F is within a few ulp of it
    return out - np.abs(out) * (16 * np.finfo(float).eps)


def _lam_max_upper(h: list[Interval]) -> np.ndarray:
    """Upper bound of the largest eigenvalue of every symmetric 2x2 matrix whose entries
    ``(H11, H12, H22)`` lie in the intervals ``h`` (increasing in H11, H22 and |H12|)."""
    a, b, c = Interval(h[0].hi), Interval(h[1].magnitude()), Interval(h[2].hi)
    lam = 0.5 * (a + c) + isqrt(0.25 * (a - c).square() + b.square())
    return lam.hi


def _centered(at_centre: Interval, slopes: list[Interval], offsets: list[Interval]) -> Interval:
    """Mean-value form ``f(c) + sum_i df/dx_i(X) (X_i - c_i)``."""
    out = at_centre
    for s, o in zip(slopes, offsets, strict=True):
        out = out + s * o
    return out


def _bounds_on_boxes(metric: Metric, lo: np.ndarray, hi: np.ndarray, v: np.ndarray,
                     w: np.ndarray, with_centre: bool = False) -> tuple[np.ndarray, ...]:
    """Enclosure upper bounds, for boxes ``[lo, hi]`` ``(M, 2)`` of points, each with a
    sampled direction ``v`` ``(M, 2)`` and the next one ``w``: ``Hz`` ``(M,)`` >=
    ``lambda_max(Hess_z F(z, v))`` and ``Ht`` ``(M,)`` >= ``d' Hess_v F(z, u) d`` for all
    ``z`` in the box and ``u`` on the chord from ``v`` to ``w`` (``d = w - v``), both >= 0
    (``inf`` where an enclosure is not finite). Each is the tighter of the natural interval
    extension and the mean-value form (interval arithmetic with outward rounding,
    :mod:`finsler.intervals`). ``with_centre``: also the same two quantities at the box's
    centre (what the bounds would be without any variation over the box)."""
    fz, ft, fz_centre, ft_centre = _second_derivatives(metric)
    xbox = Interval(lo, hi)
    centre = 0.5 * (lo + hi)
    dx = [Interval(lo[:, i], hi[:, i]) - Interval(centre[:, i]) for i in range(2)]
    # Hz: Hess_z F at the sampled direction (an exact float64 vector)
    h_box, dh_box = enclose(fz, xbox, Interval(v))
    (h_c,) = enclose(fz_centre, Interval(centre), Interval(v))
    h = [h_box[j].intersect(_centered(h_c[j], dh_box[2 * j:2 * j + 2], dx)) for j in range(3)]
    hz = np.maximum(_lam_max_upper(h), 0.0)
    # Ht: the chord from v to w
    wl, wh = np.minimum(v, w), np.maximum(v, w)
    wc = 0.5 * (wl + wh)
    d = [Interval(w[:, i]) - Interval(v[:, i]) for i in range(2)]
    dw = [Interval(wl[:, i], wh[:, i]) - Interval(wc[:, i]) for i in range(2)]
    q_box, dq_box = enclose(ft, xbox, Interval(wl, wh), d)
    (q_c,) = enclose(ft_centre, Interval(centre), Interval(wc), d)
    q = q_box[0].intersect(_centered(q_c[0], dq_box, dx + dw))
    ht = np.maximum(q.hi, 0.0)
    bad = ~(np.isfinite(hz) & np.isfinite(ht))
    hz[bad] = np.inf
    ht[bad] = np.inf
    if with_centre:
        return hz, ht, np.maximum(_lam_max_upper(h_c), 0.0), np.maximum(q_c[0].hi, 0.0)
    return hz, ht


def _box_meets_triangle(lo: np.ndarray, hi: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Whether the boxes ``[lo, hi]`` ``(M, 2)`` meet the triangles ``tri`` ``(M, 3, 2)``
    (separating axes: the box's two axes and the triangle's three edge normals; touching
    counts as meeting)."""
    meets = np.all(tri.max(axis=1) >= lo, axis=1) & np.all(tri.min(axis=1) <= hi, axis=1)
    corners = np.stack([lo, np.stack([hi[:, 0], lo[:, 1]], 1), hi,
                        np.stack([lo[:, 0], hi[:, 1]], 1)], axis=1)  # (M, 4, 2)
    for a in range(3):
        p, q, r = tri[:, a], tri[:, (a + 1) % 3], tri[:, (a + 2) % 3]
        normal = np.stack([q[:, 1] - p[:, 1], p[:, 0] - q[:, 0]], 1)
        side = np.einsum("mi,mi->m", r - p, normal)  # the third vertex's side
        proj = np.einsum("mci,mi->mc", corners - p[:, None], normal)
        beyond = np.where(side[:, None] > 0, proj < 0, proj > 0)  # opposite to the vertex
        meets &= ~np.all(beyond, axis=1)
    return meets


def _index_new(keys: list[bytes], index: dict[bytes, int]) -> list[int]:
    """Give the keys not yet in ``index`` the next row numbers; their positions in
    ``keys`` (in order, each key once)."""
    new = []
    for i, key in enumerate(keys):
        if key not in index:
            index[key] = len(index)
            new.append(i)
    return new


class _PointData:
    """Per-point values ``F(p, v_k)`` ``(K,)`` (lowered by a few ulp), computed once per
    point and reused across refinement rounds, and per-triangle second-order bounds
    (:func:`_bounds_on_boxes` on the triangle's bounding box; where a direction's
    correction is above ``SPLIT_FRACTION`` of F and its enclosure above
    ``SPLIT_OVERESTIMATE`` times its centre value (or infinite), on the 2 x 2 sub-boxes
    that meet the triangle, down to ``SPLIT_DEPTH`` levels), cached by the triangle's
    vertices."""

    def __init__(self, metric: Metric, k: int) -> None:
        self.metric = metric
        ang = 2 * np.pi * np.arange(k) / k
        self.dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
        self.index: dict[bytes, int] = {}
        self.F = np.zeros((0, k))
        self.tri_index: dict[bytes, int] = {}
        self.Hz = np.zeros((0, k))
        self.Ht = np.zeros((0, k))
        self.seconds = 0.0

    def rows(self, pts: np.ndarray) -> np.ndarray:
        """Row indices of ``pts`` ``(P, 2)``, computing the values of new points."""
        keys = [p.tobytes() for p in np.ascontiguousarray(pts)]
        new = _index_new(keys, self.index)
        if new:
            t0 = time.perf_counter()
            p = pts[new]
            k = self.dirs.shape[0]
            f = _eval_values(self.metric, np.repeat(p, k, axis=0),
                             np.tile(self.dirs, (len(new), 1)))
            self.F = np.concatenate([self.F, f.reshape(len(new), k)])
            self.seconds += time.perf_counter() - t0
        return np.fromiter((self.index[key] for key in keys), dtype=np.int64, count=len(keys))

    def triangle_bounds(self, corners: np.ndarray, fmin: np.ndarray, r2: np.ndarray,
                        chunk: int = 32768) -> tuple[np.ndarray, np.ndarray]:
        """``Hz``, ``Ht`` ``(T, K)`` of the triangles with vertices ``corners`` ``(T, 3, 2)``,
        circumradii squared ``r2`` ``(T,)`` and smallest vertex values ``fmin`` ``(T, K)``
        of F."""
        srt = np.sort(np.ascontiguousarray(corners).view(np.complex128)[..., 0], axis=1)
        keys = [row.tobytes() for row in srt]
        new = _index_new(keys, self.tri_index)
        if new:
            t0 = time.perf_counter()
            k = self.dirs.shape[0]
            n = len(new)
            tri = np.repeat(corners[new], k, axis=0)  # (n K, 3, 2): element = (triangle, k)
            kidx = np.tile(np.arange(k), n)
            fm, rr = fmin[new].reshape(-1), np.repeat(r2[new], k)
            hz = np.empty(n * k)
            ht = np.empty(n * k)
            for a in range(0, n * k, chunk):
                sl = slice(a, a + chunk)
                hz[sl], ht[sl] = self._split_bounds(tri[sl].min(axis=1), tri[sl].max(axis=1),
                                                    tri[sl], kidx[sl], fm[sl], rr[sl], 0)
            self.Hz = np.concatenate([self.Hz, hz.reshape(n, k)])
            self.Ht = np.concatenate([self.Ht, ht.reshape(n, k)])
            self.seconds += time.perf_counter() - t0
        rows = np.fromiter((self.tri_index[key] for key in keys), dtype=np.int64,
                           count=len(keys))
        return self.Hz[rows], self.Ht[rows]

    def _split_bounds(self, lo: np.ndarray, hi: np.ndarray, tri: np.ndarray, kidx: np.ndarray,
                      fmin: np.ndarray, r2: np.ndarray, depth: int
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of elements ``(M,)``: box ``[lo, hi]`` within triangle ``tri``, direction
        ``kidx``; a loose element is bounded by the max over its sub-boxes meeting the
        triangle."""
        k = self.dirs.shape[0]
        hz, ht, hz_c, ht_c = _bounds_on_boxes(self.metric, lo, hi, self.dirs[kidx],
                                              self.dirs[(kidx + 1) % k], with_centre=True)
        if depth >= SPLIT_DEPTH:
            return hz, ht
        with np.errstate(invalid="ignore"):
            # split where the correction matters AND the enclosure overestimates (where F
            # truly curves that much, smaller boxes cannot help: the mesh is refined instead)
            large = ~(0.5 * hz * r2 + ht / 8.0 <= SPLIT_FRACTION * fmin)
            over = ~((hz <= SPLIT_OVERESTIMATE * hz_c + 1e-12 * fmin)
                     & (ht <= SPLIT_OVERESTIMATE * ht_c + 1e-12 * fmin))
            loose = large & over
        if not np.any(loose):
            return hz, ht
        idx = np.flatnonzero(loose)
        lo_l, hi_l = lo[idx], hi[idx]
        mid = 0.5 * (lo_l + hi_l)
        sub_lo, sub_hi, parent = [], [], []
        for ax, bx in ((lo_l[:, 0], mid[:, 0]), (mid[:, 0], hi_l[:, 0])):
            for ay, by in ((lo_l[:, 1], mid[:, 1]), (mid[:, 1], hi_l[:, 1])):
                sl, sh = np.stack([ax, ay], 1), np.stack([bx, by], 1)
                keep = _box_meets_triangle(sl, sh, tri[idx])
                sub_lo.append(sl[keep])
                sub_hi.append(sh[keep])
                parent.append(idx[keep])
        par = np.concatenate(parent)
        shz, sht = self._split_bounds(np.concatenate(sub_lo), np.concatenate(sub_hi),
                                      tri[par], kidx[par], fmin[par], r2[par], depth + 1)
        hz[idx] = -np.inf
        ht[idx] = -np.inf
        np.maximum.at(hz, par, shz)
        np.maximum.at(ht, par, sht)
        return hz, ht


def _zigzag(m: Metric, pts: np.ndarray, k: int, teeth: int = 2) -> np.ndarray | None:
    """The polyline ``pts`` ``(n+1, 2)`` with each segment whose direction ``u`` is cheaper
    as a combination ``a v_j + b v_l`` (``a, b >= 0``, two of ``k`` sampled directions;
    ``a F(z, v_j) + b F(z, v_l) < F(z, u)`` at the segment's midpoint ``z``) replaced by
    ``teeth`` zigzags along ``v_j`` and ``v_l``, projected into the domain; None if no
    segment is. Any curve's length bounds the distance from above, so the zigzag is only a
    candidate: its length is measured, not assumed."""
    ang = 2 * np.pi * np.arange(k) / k
    dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
    d = pts[1:] - pts[:-1]
    n = d.shape[0]
    length = np.linalg.norm(d, axis=1)
    mids = 0.5 * (pts[1:] + pts[:-1])
    ok = length > 0
    fv = m.F(np.repeat(mids, k, axis=0), np.tile(dirs, (n, 1)), check=False).reshape(n, k)
    u = d / np.where(ok, length, 1.0)[:, None]
    fu = m.F(mids, u, check=False)
    # every pair (j, l): solve a v_j + b v_l = u, keep a, b >= 0
    cross = dirs[:, 0][:, None] * dirs[:, 1][None] - dirs[:, 1][:, None] * dirs[:, 0][None]
    good = np.abs(cross) > 1e-9
    safe = np.where(good, cross, 1.0)
    out = [pts[:1]]
    changed = False
    for i in range(n):
        if not ok[i]:
            out.append(pts[i + 1:i + 2])
            continue
        # Cramer: a = (u x v_l) / (v_j x v_l), b = (v_j x u) / (v_j x v_l)
        ux = u[i, 0] * dirs[:, 1] - u[i, 1] * dirs[:, 0]  # u x v
        a = ux[None, :] / safe
        b = -ux[:, None] / safe
        cost = np.where(good & (a >= 0) & (b >= 0), a * fv[i][:, None] + b * fv[i][None, :],
                        np.inf)
        j, l_ = np.unravel_index(int(np.argmin(cost)), cost.shape)
        if not cost[j, l_] < fu[i] * (1 - 1e-9):
            out.append(pts[i + 1:i + 2])
            continue
        changed = True
        step_a = length[i] * a[j, l_] * dirs[j] / teeth
        step_b = length[i] * b[j, l_] * dirs[l_] / teeth
        pieces = np.tile(np.stack([step_a, step_b]), (teeth, 1))
        seg = pts[i] + np.cumsum(pieces, axis=0)
        seg[-1] = pts[i + 1]
        out.append(seg)
    if not changed:
        return None
    zig = np.concatenate(out)
    zig = np.asarray(m.domain.project(zig), dtype=np.float64)
    zig[0], zig[-1] = pts[0], pts[-1]
    return zig


# ----------------------------------------------------------------------------------------
# meshes
# ----------------------------------------------------------------------------------------
def _outline(metric: Metric) -> np.ndarray:
    """Vertices ``(M, 2)`` (counter-clockwise) of a convex polygon containing the domain."""
    dom = metric.domain
    if isinstance(dom, Box):
        (x0, y0), (x1, y1) = dom.low, dom.high
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)
    if isinstance(dom, Disk):
        m = 64
        r = dom.radius / math.cos(math.pi / m)  # circumscribed: the disk lies inside
        a = 2 * np.pi * (np.arange(m) + 0.5) / m
        return np.asarray(dom.center, float) + r * np.stack([np.cos(a), np.sin(a)], 1)
    raise InputError(f"certify needs a 2-D box or disk domain, {metric.name} has "
                     f"{dom.describe()}")


def _inside_polygon(pts: np.ndarray, poly: np.ndarray, margin: float) -> np.ndarray:
    """Points at least ``margin`` inside the convex counter-clockwise polygon."""
    ok = np.ones(pts.shape[0], bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        e = b - a
        normal = np.array([e[1], -e[0]]) / np.linalg.norm(e)  # outward for ccw
        ok &= (pts - a) @ normal <= -margin
    return ok


def _distance_to_path(pts: np.ndarray, path: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Euclidean distance of ``pts`` ``(P, 2)`` to the polyline ``path`` ``(n+1, 2)``."""
    a, b = path[:-1], path[1:]
    e = b - a
    ee = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
    out = np.empty(pts.shape[0])
    for s in range(0, pts.shape[0], chunk):
        p = pts[s:s + chunk, None, :]
        t = np.clip(np.einsum("pij,ij->pi", p - a[None], e) / ee, 0.0, 1.0)
        d = p - (a[None] + t[..., None] * e[None])
        out[s:s + chunk] = np.sqrt(np.min(np.einsum("pij,pij->pi", d, d), axis=1))
    return out


def _spacing(dist: np.ndarray, spec: MeshSpec) -> np.ndarray:
    return np.minimum(spec.h_far, spec.h_path + spec.grade * np.maximum(dist - spec.corridor,
                                                                          0.0))


def _hex_lattice(lo: np.ndarray, hi: np.ndarray, h: float) -> np.ndarray:
    """Hexagonal lattice of spacing ``h`` through the origin, covering ``[lo, hi]``; the
    lattice of spacing ``2h`` is a subset of it (levels nest)."""
    dy = h * math.sqrt(3) / 2
    j = np.arange(math.floor(lo[1] / dy) - 1, math.ceil(hi[1] / dy) + 2)
    i = np.arange(math.floor(lo[0] / h) - 2, math.ceil(hi[0] / h) + 3)
    ii, jj = np.meshgrid(i, j)
    x = h * (ii + 0.5 * jj)
    y = dy * jj
    pts = np.stack([x.ravel(), y.ravel()], 1)
    keep = np.all((pts >= lo - h) & (pts <= hi + h), axis=1)
    return pts[keep]


def _initial_points(poly: np.ndarray, path: np.ndarray, s: np.ndarray, g: np.ndarray,
                    spec: MeshSpec) -> np.ndarray:
    lo, hi = poly.min(0), poly.max(0)
    levels = max(0, math.ceil(math.log2(spec.h_far / spec.h_path)))
    pieces = []
    for lev in range(levels + 1):
        h = spec.h_path * 2**lev
        pts = _hex_lattice(lo, hi, h)
        pts = pts[_inside_polygon(pts, poly, 0.3 * h)]
        level = np.ceil(np.log2(_spacing(_distance_to_path(pts, path), spec) / spec.h_path
                                - 1e-9))
        level = np.clip(level, 0, levels)
        pieces.append(pts[level == lev] if lev < levels else pts[level >= lev])
    # the boundary: every polygon edge sampled at the local spacing
    bnd = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        length = float(np.linalg.norm(b - a))
        t = np.linspace(0.0, 1.0, max(2, math.ceil(length / (0.5 * spec.h_path)) + 1))
        cand = a + t[:, None] * (b - a)
        h = _spacing(_distance_to_path(cand, path), spec)
        keep, last = [0], 0.0
        for i in range(1, len(t) - 1):
            if (t[i] - last) * length >= h[i]:
                keep.append(i)
                last = t[i]
        bnd.append(cand[keep])
    pts = np.concatenate(pieces + bnd)
    far = (np.linalg.norm(pts - s, axis=1) > 0.4 * spec.h_path) & (
        np.linalg.norm(pts - g, axis=1) > 0.4 * spec.h_path)
    return np.concatenate([s[None], g[None], pts[far]])


class _Mesh:
    """Delaunay triangulation with P2 unknowns: vertices, then one per edge (midpoint)."""

    def __init__(self, points: np.ndarray) -> None:
        from scipy.spatial import Delaunay, QhullError

        self.points = points
        try:
            self.delaunay = Delaunay(points)
        except QhullError as err:  # e.g. fewer than 3 distinct points
            raise InputError(f"certify: the mesh of {points.shape[0]} points cannot be "
                             "triangulated (is the spacing larger than the domain?)") from err
        tri = self.delaunay.simplices
        z = points[tri]
        area2 = ((z[:, 1, 0] - z[:, 0, 0]) * (z[:, 2, 1] - z[:, 0, 1])
                 - (z[:, 1, 1] - z[:, 0, 1]) * (z[:, 2, 0] - z[:, 0, 0]))
        keep = np.abs(area2) > 1e-14 * np.max(np.abs(area2))  # drop slivers of zero area
        self.simplex_row = np.cumsum(keep) - 1
        self.simplex_row[~keep] = -1
        tri = tri[keep]
        self.tri = tri
        nv = points.shape[0]
        local = np.array([[0, 1], [1, 2], [2, 0]])
        e = np.sort(tri[:, local].reshape(-1, 2), axis=1)
        edges, inverse = np.unique(e, axis=0, return_inverse=True)
        self.edges = edges
        self.dofs = np.concatenate([tri, nv + inverse.reshape(-1, 3)], axis=1)  # (T, 6)
        self.n_dofs = nv + edges.shape[0]
        z = points[tri]  # (T, 3, 2)
        jac = np.stack([z[:, 1] - z[:, 0], z[:, 2] - z[:, 0]], axis=2)  # columns
        inv = np.linalg.inv(jac)  # rows: grad lambda_1, grad lambda_2
        gl = np.stack([-(inv[:, 0] + inv[:, 1]), inv[:, 0], inv[:, 1]], axis=1)  # (T, 3, 2)
        # gradient of the P2 potential at vertex m: C[T, m] (2, 6) times the local unknowns
        c = np.zeros((tri.shape[0], 3, 2, 6))
        for m in range(3):
            for i in range(3):
                c[:, m, :, i] = (4.0 * (i == m) - 1.0) * gl[:, i]
            for e_idx, (i, j) in enumerate(local):
                c[:, m, :, 3 + e_idx] = 4.0 * ((j == m) * gl[:, i] + (i == m) * gl[:, j])
        self.grad = c
        # circumradius squared
        a = np.linalg.norm(z[:, 1] - z[:, 2], axis=1)
        b = np.linalg.norm(z[:, 2] - z[:, 0], axis=1)
        cc = np.linalg.norm(z[:, 0] - z[:, 1], axis=1)
        area = 0.5 * np.abs(jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0])
        self.r2 = (a * b * cc / (4.0 * area)) ** 2
        self.midpoints = 0.5 * (points[edges[:, 0]] + points[edges[:, 1]])
        self.centroids = z.mean(axis=1)

    @property
    def n_tri(self) -> int:
        return int(self.tri.shape[0])

    def gradients(self, phi: np.ndarray) -> np.ndarray:
        """Gradient of the potential at the vertices of every triangle ``(T, 3, 2)``."""
        return np.einsum("tmid,td->tmi", self.grad, phi[self.dofs])

    def locate(self, pts: np.ndarray) -> np.ndarray:
        """Triangle (row of ``tri``) holding each point, -1 if none."""
        simplex = self.delaunay.find_simplex(pts)
        return np.where(simplex >= 0, self.simplex_row[simplex], -1)

    def refine(self, marked: np.ndarray) -> np.ndarray:
        """Points of a refined mesh: the marked triangles' edge midpoints added."""
        e = np.unique(self.dofs[marked, 3:].ravel()) - self.points.shape[0]
        return np.concatenate([self.points, self.midpoints[e]])


# ----------------------------------------------------------------------------------------
# the LP
# ----------------------------------------------------------------------------------------
def _row_bounds(mesh: _Mesh, data: _PointData) -> tuple[np.ndarray, np.ndarray]:
    """Right-hand sides ``b`` ``(T, 3, K)`` and the corrections ``c`` ``(T, K)`` (infinite
    where the enclosures are)."""
    vert_rows = data.rows(mesh.points)
    f = data.F[vert_rows[mesh.tri]]  # (T, 3, K)
    hz, ht = data.triangle_bounds(mesh.points[mesh.tri], f.min(axis=1), mesh.r2)
    with np.errstate(invalid="ignore"):
        corr = _corrections(hz, ht, mesh.r2)
    return f - corr[:, None, :], corr


def _corrections(hz: np.ndarray, ht: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """``Hz R**2 / 2 + max(Ht_{k-1}, Ht_k) / 8`` ``(T, K)``, inflated for the float64
    rounding of this line and of ``R**2``."""
    corr = 0.5 * hz * r2[:, None] + np.maximum(ht, np.roll(ht, 1, axis=1)) / 8.0
    return corr * (1.0 + 1e-12)


class _Rays:
    """Inner polygons of the rows' feasible sets, one per triangle vertex ``(T, 3)``.

    At vertex ``m`` of triangle ``T`` the rows allow the gradient set
    ``P = {g : g . v_k <= b[T, m, k] for all k}``, convex and containing 0 (``b > 0``).
    A ray from 0 at angle ``a`` leaves ``P`` at ``r(a) u(a)``,
    ``r(a) = min_{k : u . v_k > 0} b_k / (u . v_k)``; the polygon through the exit points of
    a few rays (in angular order, gaps below pi) lies inside ``P`` (it is a union of
    triangles ``0, g_i, g_{i+1}``, each inside the convex ``P``), and so does the
    intersection of its edges' half-planes. The LP uses those edges as rows: every
    potential it returns satisfies every sampled row by construction (used for the vertices
    away from the path; see :func:`_solve_lp`).
    """

    def __init__(self, n_vertices: int, rays: int = INITIAL_DIRECTIONS) -> None:
        i = np.arange(rays)
        self.vid = np.repeat(np.arange(n_vertices), rays)
        self.ang = np.tile(2 * np.pi * i / rays + 1e-3, n_vertices)  # off the sampled angles
        self.next = (self.vid * rays + np.tile((i + 1) % rays, n_vertices)).astype(np.int64)

    def facets(self, b_flat: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``normal . g <= rhs`` (normals ``(R, 2)``, rhs ``(R,)``), one per ray (the edge
        from this ray's exit point to the next's) of vertex ``vid``."""
        u = np.stack([np.cos(self.ang), np.sin(self.ang)], 1)
        r = np.full(self.vid.size, np.inf)
        for a in range(0, self.vid.size, 20000):
            sl = slice(a, a + 20000)
            proj = u[sl] @ dirs.T  # (R, K)
            with np.errstate(divide="ignore"):
                q = np.where(proj > 1e-12, b_flat[self.vid[sl]] / np.where(proj > 1e-12, proj,
                                                                             1.0), np.inf)
            r[sl] = q.min(axis=1)
        pts = r[:, None] * u
        e = pts[self.next] - pts
        normal = np.stack([e[:, 1], -e[:, 0]], 1)  # outward for counter-clockwise order
        return normal, np.einsum("ri,ri->r", normal, pts)


def _solve_lp(mesh: _Mesh, b: np.ndarray, dirs: np.ndarray, s_idx: int, g_idx: int,
              upper: float, target: float, start: dict[str, np.ndarray],
              max_iter: int = 30) -> dict[str, Any]:
    """Maximise ``phi[g] - phi[s]`` under the rows ``(T, 3, K)`` (``g . v_k <= b``) at every
    triangle vertex, in rounds.

    A vertex is either SAFE: its gradient is kept in the inner polygon of 8 rays
    (:class:`_Rays`), inside the rows' set, so it can never violate a row; or EXACT: it
    has sampled rows ``g . v_k <= b_k`` directly, a set of directions grown in rounds by the
    violated ones. A safe vertex whose polygon edge is tight (positive dual) becomes exact,
    with the directions near that edge's normal and 16 evenly spaced ones. Each round's
    potential, divided by its largest row ratio over ALL rows, is a valid potential; the
    best one is returned. Stops when no vertex changes mode and no row is violated beyond
    ``0.1 target``, when a potential certifies ``target``, or after ``max_iter`` rounds.
    ``start``: ``exact`` ``(T*3,)`` bool and ``active`` ``(T*3, K)`` bool, the first
    exact vertices and their directions.
    """
    import warnings

    import cvxpy as cp
    import scipy.sparse as sp

    k = b.shape[2]
    nv = 3 * mesh.n_tri
    b_flat = b.reshape(nv, k)
    gradc = mesh.grad.reshape(nv, 2, 6)
    dofs = np.repeat(mesh.dofs, 3, axis=0)  # (T*3, 6)
    rays = _Rays(nv)
    safe_normal, safe_rhs = rays.facets(b_flat, dirs)
    exact = start["exact"].copy()
    active = start["active"].copy()
    active[~exact] = False
    coarse = np.zeros(k, bool)
    coarse[:: max(1, k // 16)] = True
    best: dict[str, Any] = {"lower": -np.inf}
    n_iter = 0
    lp_seconds = 0.0
    while n_iter < max_iter:
        n_iter += 1
        safe_rows = ~exact[rays.vid]
        s_vid = rays.vid[safe_rows]
        s_normal, s_rhs = safe_normal[safe_rows], safe_rhs[safe_rows]
        e_vid, e_k = np.nonzero(active & exact[:, None])
        normal = np.concatenate([s_normal, dirs[e_k]])
        rhs = np.concatenate([s_rhs, b_flat[e_vid, e_k]])
        vid = np.concatenate([s_vid, e_vid])
        coef = np.einsum("ri,rij->rj", normal, gradc[vid])
        a = sp.csr_matrix((coef.ravel(), (np.repeat(np.arange(rhs.size), 6),
                                          dofs[vid].ravel())), shape=(rhs.size, mesh.n_dofs))
        x = cp.Variable(mesh.n_dofs)
        cons = [a @ x <= rhs, x[s_idx] == 0]
        prob = cp.Problem(cp.Maximize(x[g_idx]), cons)
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "inaccurate" is in the status, checked below
                prob.solve(solver=LP_SOLVER)
        except cp.error.SolverError as err:
            raise LPFailure(f"the LP solver failed: {short(str(err))}") from err
        lp_seconds += time.perf_counter() - t0
        status = str(prob.status)
        if x.value is None:
            raise LPFailure(f"the LP ended with status {status}")
        phi = np.asarray(x.value, float)
        duals = np.maximum(np.asarray(cons[0].dual_value, float), 0.0)
        ratio = np.einsum("vi,ki->vk", np.einsum("vid,vd->vi", gradc, phi[dofs]), dirs) / b_flat
        ratio_max = float(np.max(ratio))
        scale = max(ratio_max, 1.0) * (1.0 + 1e-12)
        lower = float(phi[g_idx] - phi[s_idx]) / scale
        _LOG.debug("LP rows %d (%d exact vertices) %.2f s: value %.8f, max row ratio %.6f "
                   "-> bound %.8f", rhs.size, int(exact.sum()), time.perf_counter() - t0,
                   phi[g_idx] - phi[s_idx], ratio_max, lower)
        if lower > best["lower"]:
            ang = np.arctan2(normal[:, 1], normal[:, 0])
            kk = np.mod(np.rint(ang / (2 * np.pi / k)).astype(np.int64), k)
            best = {"phi": (phi - phi[s_idx]) / scale, "lower": lower, "status": status,
                    "rows": np.stack([vid // 3, vid % 3, kk], 1), "duals": duals,
                    "n_rows": int(rhs.size), "ratio": ratio_max}
        if upper - lower <= target * upper:
            break
        # safe vertices with a tight edge become exact; violated exact rows are added
        thr = TIGHT_DUAL * max(float(duals.max(initial=0.0)), 1e-300)
        tight_safe = np.flatnonzero(duals[: s_vid.size] > thr)
        promote = np.zeros(nv, bool)
        promote[s_vid[tight_safe]] = True
        promote &= ~exact
        if promote.any():
            pv = s_vid[tight_safe]
            ang = np.arctan2(s_normal[tight_safe, 1], s_normal[tight_safe, 0])
            kc = np.rint(ang / (2 * np.pi / k)).astype(np.int64)
            for off in range(-_window(k), _window(k) + 1):
                active[pv, (kc + off) % k] = True
            active[promote] |= coarse
            exact |= promote
        viol = exact[:, None] & (ratio > 1.0 + 0.1 * target) & ~active
        worst = np.argmax(np.where(exact[:, None], ratio, -np.inf), axis=1)
        bad = exact & (ratio[np.arange(nv), worst] > 1.0 + 0.1 * target)
        for off in (-1, 0, 1):
            active[np.flatnonzero(bad), (worst[bad] + off) % k] = True
        active |= viol
        if not promote.any() and not bad.any():
            break
    best.update({"iterations": n_iter, "lp_seconds": lp_seconds, "solver": LP_SOLVER,
                 "exact": exact, "active": active})
    return best


def _initial_modes(mesh: _Mesh, k: int, previous: tuple[_Mesh, dict[str, Any]] | None,
                   path: np.ndarray, width: float) -> dict[str, np.ndarray]:
    """Exact vertices and directions of the first LP of a mesh. First mesh: the vertices of
    the triangles whose centroid is within ``width`` of the path, with 16 evenly spaced
    directions and those within pi/8 of the path's local direction. After a refinement:
    every vertex of a new triangle whose centroid lies in an old triangle with an exact
    vertex, with the union of that triangle's directions."""
    nv = 3 * mesh.n_tri
    exact = np.zeros(nv, bool)
    active = np.zeros((nv, k), bool)
    if previous is None:
        near = _distance_to_path(mesh.centroids, path) <= width
        # the path's direction at the nearest path point of each near triangle
        seg = path[1:] - path[:-1]
        mids = 0.5 * (path[1:] + path[:-1])
        c = mesh.centroids[near]
        nearest = np.argmin(((c[:, None, :] - mids[None]) ** 2).sum(-1), axis=1)
        ang = np.arctan2(seg[nearest, 1], seg[nearest, 0])
        kc = np.rint(ang / (2 * np.pi / k)).astype(np.int64)
        act = np.zeros((int(near.sum()), k), bool)
        act[:, :: max(1, k // 16)] = True
        rows = np.arange(act.shape[0])
        for off in range(-_window(k), _window(k) + 1):
            act[rows, (kc + off) % k] = True
        tri_exact = near
        exact = np.repeat(tri_exact, 3)
        active[exact] = np.repeat(act, 3, axis=0)
    else:
        old, lp = previous
        host = old.locate(mesh.centroids)
        ok = host >= 0
        old_exact = lp["exact"].reshape(-1, 3).any(axis=1)
        old_active = (lp["active"] & lp["exact"][:, None]).reshape(-1, 3, k).any(axis=1)
        new_exact = np.zeros(mesh.n_tri, bool)
        new_exact[ok] = old_exact[host[ok]]
        exact = np.repeat(new_exact, 3)
        act = np.zeros((mesh.n_tri, k), bool)
        act[ok] = old_active[host[ok]]
        active = np.repeat(act, 3, axis=0)
    return {"exact": exact, "active": active}


def _convexity(m: Metric, points: np.ndarray) -> tuple[str, str]:
    if m.convex_everywhere:
        return "convex", f"F(x, .) is convex on the whole domain ({m.convexity_note})"
    inside = points[m.domain.contains(points, tol=0.0)]
    bad = int(np.sum(m.convexity(inside) < 0.0)) if inside.size else 0
    return ("convexified",
            f"F(x, .) is not convex at {bad} of {inside.shape[0]} mesh vertices "
            f"({m.convexity_note}); the dual condition dphi(v) <= F(x, v) for all v equals "
            "that of the convexification F**, so the lower bound holds for the distance "
            "(an infimum of lengths, unchanged by convexification)")


def certify(
    metric: Metric | str,
    start: Any,
    goal: Any,
    mesh: MeshSpec | str | None = None,
    *,
    path: Any = None,
    time_limit: float | None = None,
) -> CertifyResult:
    """Certified interval ``lower <= d(start, goal) <= upper`` on a 2-D metric.

    ``start``, ``goal``: points ``(2,)`` in the domain. ``mesh``: a :class:`MeshSpec` or a
    preset name (``"coarse"``, ``"default"``, ``"fine"``). ``path`` ``(n+1, 2)``: a curve
    from start to goal for the upper bound and the first mesh (default: solved with
    :func:`solvers.solve_geodesic` at ``mesh.segments`` segments). ``time_limit``
    (seconds): no new refinement round starts after it. The upper bound is the path's
    length plus its quadrature error estimate; the lower bound is the dual bound
    described in the module docstring. Raises :class:`InputError` for a metric that is
    not 2-D (or whose domain is not a box or a disk), points outside the domain, or bad
    options.
    """
    t_start = time.perf_counter()
    m = as_metric(metric)
    if m.dim != 2:
        raise InputError(f"certify works on 2-D metrics; {m.name} has dimension {m.dim}")
    spec = MeshSpec.preset(mesh) if isinstance(mesh, str) else (mesh or MeshSpec())
    if not isinstance(spec, MeshSpec):
        raise InputError(f"mesh must be a MeshSpec or a preset name, got {type(mesh).__name__}")
    if time_limit is not None and not (isinstance(time_limit, (int, float))
                                       and math.isfinite(time_limit) and time_limit > 0):
        raise InputError(f"time_limit must be a positive number of seconds, got {time_limit!r}")
    poly = _outline(m)
    s = m.domain.check(np.asarray(start, float), "start")[0]
    g = m.domain.check(np.asarray(goal, float), "goal")[0]
    if np.array_equal(s, g):
        raise InputError("start equals goal: the distance is 0, nothing to certify")
    scale = domain_scale(m)
    if is_short_pair(m, s, g):
        raise InputError(f"start and goal are {float(np.max(np.abs(g - s))):.3g} apart, below "
                         f"{SHORT_PAIR:g} x the domain's size: too close for a mesh to "
                         "separate them, nothing to certify (their distance is "
                         "F(start, goal - start) to within O(|goal - start|**2))")
    for name in ("h_path", "h_far", "corridor"):
        if getattr(spec, name) > scale:
            raise InputError(f"mesh {name} = {getattr(spec, name):g} is larger than the "
                             f"domain (size {scale:g}); give at most {scale:g}")

    # upper bound: a curve's length with its quadrature error
    t0 = time.perf_counter()
    if path is None:
        from solvers.geodesic import solve_geodesic

        n = spec.segments if spec.segments is not None else 4 * m.task.segments
        sol = solve_geodesic(m, s, g, n)
        pts = np.asarray(sol.points, float)
        solver_status = sol.status.label
    else:
        pts = np.array(path, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
            raise InputError(f"path must have shape (n+1, 2), got {pts.shape}")
        if not (np.allclose(pts[0], s, rtol=0, atol=1e-12)
                and np.allclose(pts[-1], g, rtol=0, atol=1e-12)):
            raise InputError("path must run from start to goal")
        m.domain.check(pts, "path")
        solver_status = "given"
    est = m.path_length_error(pts)
    solver_upper = m.path_length_bounds(pts).upper
    upper, upper_source, upper_path = solver_upper, "path", pts
    if not m.convex_everywhere:
        zig = _zigzag(m, pts, spec.directions)
        if zig is not None:
            zig_upper = m.path_length_bounds(zig).upper
            if zig_upper < upper:
                est, upper_path = m.path_length_error(zig), zig
                upper, upper_source = zig_upper, "zigzag"
    t_solve = time.perf_counter() - t0

    # lower bound: dual LP on meshes refined where the corrections cost most
    t0 = time.perf_counter()
    points = _initial_points(poly, pts, s, g, spec)
    t_mesh = time.perf_counter() - t0
    data = _PointData(m, spec.directions)
    t_lp = 0.0
    best: dict[str, Any] | None = None
    rounds: list[dict[str, Any]] = []
    previous = None
    stopped_by = "max_rounds"
    failure: tuple[CertifyStatus, str] | None = None
    last_mesh: _Mesh | None = None
    for _ in range(spec.max_rounds):
        t0 = time.perf_counter()
        msh = _Mesh(points)
        t_mesh += time.perf_counter() - t0
        b, corr = _row_bounds(msh, data)
        # triangles whose corrections eat half of F somewhere are refined before any LP
        for _ in range(MAX_PRE_REFINE):
            bad = np.min(b / data.F[data.rows(msh.points)][msh.tri], axis=(1, 2)) < 0.5
            if not np.any(bad):
                break
            if msh.n_tri + 3 * int(bad.sum()) > spec.max_triangles:
                # the corrections do not shrink with the triangles: the chord term (fixed
                # by the number of directions) or a singularity of F; stop, do not grow
                failure = (CertifyStatus.CORRECTIONS_TOO_LARGE,
                           f"{int(bad.sum())} triangles keep second-order corrections above "
                           f"half of F, and refining them would exceed max_triangles "
                           f"({spec.max_triangles}); use more directions (e.g. the default "
                           "or fine mesh preset) or a smaller h_path / h_far")
                break
            t0 = time.perf_counter()
            msh = _Mesh(msh.refine(np.flatnonzero(bad)))
            t_mesh += time.perf_counter() - t0
            b, corr = _row_bounds(msh, data)
        if failure is None and np.min(b) <= 0.0:
            failure = (CertifyStatus.CORRECTIONS_TOO_LARGE,
                       f"{int(np.sum(np.min(b, axis=(1, 2)) <= 0))} triangles keep "
                       f"second-order corrections above F after {MAX_PRE_REFINE} "
                       "refinements; use a smaller h_path / h_far")
        if failure is not None:
            last_mesh = msh
            break
        t0 = time.perf_counter()
        try:
            lp = _solve_lp(msh, b, data.dirs, 0, 1, upper, spec.target_gap,
                           start=_initial_modes(msh, spec.directions, previous, pts,
                                                2.0 * spec.h_path))
        except LPFailure as err:
            failure, last_mesh = (CertifyStatus.LP_FAILED, str(err)), msh
            break
        previous = (msh, lp)
        t_lp += time.perf_counter() - t0
        gap = (upper - lp["lower"]) / upper
        rounds.append({"triangles": msh.n_tri, "unknowns": msh.n_dofs, "rows": lp["n_rows"],
                       "row_rounds": lp["iterations"], "lower": lp["lower"], "gap": gap,
                       "seconds": time.perf_counter() - t_start})
        if best is None or lp["lower"] > best["lower"]:
            best = {**lp, "mesh": msh}
        if gap <= spec.target_gap:
            stopped_by = "target_gap"
            break
        if time_limit is not None and time.perf_counter() - t_start > time_limit:
            stopped_by = "time_limit"
            break
        # Doerfler marking by the dual-weighted corrections sum_r y_r c_r per triangle
        rows, y = lp["rows"], np.maximum(lp["duals"], 0.0)
        weight = np.bincount(rows[:, 0], weights=y * corr[rows[:, 0], rows[:, 2]],
                             minlength=msh.n_tri)
        order = np.argsort(-weight)
        cum = np.cumsum(weight[order])
        if cum[-1] <= 0:
            stopped_by = "no_refinement"
            break
        n_mark = int(np.searchsorted(cum, spec.mark_fraction * cum[-1]) + 1)
        if msh.n_tri + 3 * n_mark > spec.max_triangles:
            stopped_by = "max_triangles"
            break
        t0 = time.perf_counter()
        points = msh.refine(order[:n_mark])
        t_mesh += time.perf_counter() - t0
    if failure is not None:
        stopped_by = failure[0].label
        status, message = failure
    else:
        status = {"target_gap": CertifyStatus.CERTIFIED,
                  "time_limit": CertifyStatus.TIME_LIMIT}.get(stopped_by,
                                                             CertifyStatus.BUDGET_REACHED)
        message = ""
    if best is None:  # failed in the first round: the trivial bound d >= 0 holds
        assert last_mesh is not None
        best = {"lower": 0.0, "mesh": last_mesh, "n_rows": 0, "status": "not_solved",
                "solver": LP_SOLVER, "ratio": float("nan")}
    final: _Mesh = best["mesh"]
    lower = best["lower"]
    kind, note = _convexity(m, final.points)
    total = time.perf_counter() - t_start
    return CertifyResult(
        metric=m.name, start=s, goal=g, lower=lower, upper=upper, length=float(est.value),
        length_error=float(est.error), gap=(upper - lower) / upper,
        upper_source=upper_source, path_upper=solver_upper,
        path_gap=(solver_upper - lower) / solver_upper, triangles=final.n_tri,
        vertices=int(final.points.shape[0]), unknowns=final.n_dofs,
        directions=spec.directions, lp_rows=best["n_rows"],
        lp_rows_total=int(3 * final.n_tri * spec.directions), lp_status=best["status"],
        lp_solver=best["solver"], max_row_ratio=best["ratio"], convexity=kind,
        convexity_note=note, solver_status=solver_status,
        mesh={**asdict(spec), "element": "P2", "domain_polygon_vertices": int(poly.shape[0])},
        times={"solve": t_solve, "mesh": t_mesh, "bounds": data.seconds,
               "lp": t_lp, "total": total},
        rounds=rounds, path=upper_path, stopped_by=stopped_by, status=status,
        message=message,
    )
