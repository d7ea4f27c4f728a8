"""The 2-D certificate: a certified interval ``lower <= d(start, goal) <= upper``.

Lower bound by convex duality. If a potential ``phi`` satisfies ``dphi_z(v) <= F(z, v)`` for
every point ``z`` and every vector ``v`` (the dual norm ``F*(z, dphi_z) <= 1``), then for
every curve ``gamma`` from ``x`` to ``y``, ``phi(y) - phi(x) = int dphi(gamma') <=
int F(gamma, gamma')``, hence ``d(x, y) >= phi(y) - phi(x)``. `certify_plane` maximises
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
(`finsler.enclosures.intervals`, outward rounding) of the CasADi Hessians of the metric's own
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
the returned lower bound satisfies every row exactly whatever the LP solver's tolerance
(a round short of the target only by a few broken rows is first mended locally,
`solvers.certificates.plane.repair`, and checked the same way).

Convexity: where ``F(z, .)`` is not convex (Matsumoto outside ``|p| = 1/(2 sqrt 3)``) the
condition ``dphi(v) <= F(z, v)`` for all ``v`` is the same as for the convexification
``F**(z, .)``; the lower bound is valid for the distance (an infimum of lengths, which the
convexification does not change), and the result says which case applies.

Upper bound: the length of the solver's path (`solvers.solve_geodesic`), PROVEN by
interval arithmetic (`finsler.Metric.path_length_bounds`: midpoint rule plus an
enclosure of the second derivative along each piece); ``length`` / ``length_error`` also
give the adaptive-quadrature estimate of the same length.

Refinement: triangles are refined (edge midpoints, Delaunay again) where the LP's dual
solution says the corrections cost most (``sum_rows y_r c_r``, the bound's sensitivity),
starting from a mesh graded around the solver's path, until the gap reaches
``MeshSpec.target_gap`` or a size / round limit.

Region: the rows are needed only on the triangles a curve no longer than the upper bound
can reach (a proven speed floor ``F >= m |v|`` bounds the region by an ellipse around start
and goal, `solvers.certificates.plane.reach`); the others are dropped from the mesh, and the bound
is then ``min(phi(goal) - phi(start), upper)``.

Layout: this module holds the refinement loop; the bound code (values of F, enclosures
of its second derivatives, bounded first over groups of directions and then direction by
direction where the LP needs it, the corrections and rows) is in
`solvers.certificates.plane.bounds`, the meshes in `solvers.certificates.plane.mesh`, the LPs in
`solvers.certificates.plane.lp`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from finsler.domains import as_real
from finsler.errors import InputError
from finsler.infra.limits import check_memory, check_number
from finsler.metrics.base import Metric
from finsler.status import Status
from solvers.certificates.plane.bounds import (
    _PointData,
    _RowBounds,
    direction_group,
)
from solvers.certificates.plane.lp import LP_SOLVER, LPFailure, _initial_modes, _solve_lp
from solvers.certificates.plane.mesh import _initial_points, _Mesh, _outline, _zigzag
from solvers.certificates.plane.reach import reachable_triangles, speed_floor
from solvers.inputs import (
    SHORT_PAIR,
    check_segments,
    domain_scale,
    is_short_pair,
)
from solvers.result import CertifyResult
from solvers.status import CertifyStatus

__all__ = ["MeshSpec", "certify_plane"]

_LOG = logging.getLogger(__name__)

#: Refinements of triangles whose corrections exceed half of F, before the first LP.
MAX_PRE_REFINE = 8
#: Goal-oriented marking (`_marked`): refine only what brings the dual-weighted
#: corrections to ``GOAL_SAFETY`` x the target, assuming a refined triangle's weight falls
#: by ``GOAL_RHO`` (measured 3.3-4.3 on tuning pairs), never less than ``GOAL_FLOOR``.
GOAL_MARKING = True
GOAL_SAFETY = 0.7
GOAL_RHO = 3.0
GOAL_FLOOR = 0.3


@dataclass(frozen=True)
class MeshSpec:
    """Mesh and refinement settings of the 2-D certificate (`certify_plane`).

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
    """Largest spacing (far from the path); the default and fine presets use 0.1."""
    directions: int = 128
    """Number K of sampled unit directions per triangle (>= 8). 128: as certain as 256 at
    the 1e-2 target and faster; 64 leaves chord corrections above half of F on
    Matsumoto's steep rim (``docs/guides/certify.md``)."""
    target_gap: float = 1e-2
    """Stop refining once the relative gap (upper - lower) / upper is at most this."""
    max_triangles: int = 12000
    """Stop refining before the mesh would exceed this many triangles."""
    max_rounds: int = 12
    """Largest number of refinement rounds (LP solves). 12: room for the slowest tuning
    pairs, which reach the 1e-2 target after 10."""
    mark_fraction: float = 0.9
    """Refine the triangles that carry this fraction of the dual-weighted corrections (less
    once they are near the target: only what the target needs, `GOAL_MARKING`)."""
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
            # h_far 0.1: smaller far triangles need fewer sub-box splits and
            # pre-refinements: 15-25 % less CPU on the tuning pairs
            "default": cls(h_far=0.1),
            "fine": cls(h_path=0.04, h_far=0.1, directions=512, target_gap=1e-3,
                        max_rounds=12, max_triangles=40000, mark_fraction=0.99),
        }
        if name not in presets:
            raise InputError(f"unknown mesh preset {name!r}; choose one of "
                             f"{', '.join(presets)}")
        return presets[name]


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


def certify_plane(
    m: Metric,
    start: Any,
    goal: Any,
    mesh: MeshSpec | str | None = None,
    *,
    path: Any = None,
    time_limit: float | None = None,
) -> CertifyResult:
    """Certified interval ``lower <= d(start, goal) <= upper`` on a 2-D metric (what
    [`solvers.certify`][solvers.certify] runs for one, after its check of the metric:
    ``m`` is a `Metric` object).

    ``start``, ``goal``: points ``(2,)`` in the domain. ``mesh``: a `MeshSpec` or a
    preset name (``"coarse"``, ``"default"`` (also for None), ``"fine"``). ``path``
    ``(n+1, 2)``: a curve from start to goal for the upper bound and the first mesh
    (default: solved with `solvers.solve_geodesic` at ``mesh.segments`` segments).
    ``time_limit`` (seconds): no new refinement round starts after it. The upper bound is
    the path's length plus its quadrature error estimate; the lower bound is the dual
    bound described in the module docstring. Raises `InputError` for a metric that is
    not 2-D (or whose domain is not a box or a disk), points outside the domain, or bad
    options.

    The input is checked here, once (`_check_request`); the steps below trust it:
    `_upper_bound` (the solve, or the given path), `_lower_bound` (the
    refinement rounds), `_outcome` (status and message) and `_result`.
    """
    t_start = time.perf_counter()
    if m.dim != 2:
        raise InputError(f"the plane certificate is for 2-D metrics; {m.name} is {m.dim}-D "
                         "(solvers.certify picks the certificate by dimension)")
    spec, poly, s, g = _check_request(m, start, goal, mesh, time_limit)
    up = _upper_bound(m, s, g, spec, path)
    low = _lower_bound(m, poly, up, s, g, spec, time_limit, t_start)
    return _result(m, s, g, spec, poly, up, low, t_start)


def _check_request(m: Metric, start: Any, goal: Any, mesh: MeshSpec | str | None,
                   time_limit: float | None
                   ) -> tuple[MeshSpec, np.ndarray, np.ndarray, np.ndarray]:
    """The one check of a 2-D certify request: the mesh spec, the time limit, the domain's
    outline, start and goal (in the domain, distinct, not a short pair) and the mesh
    sizes against the domain's size -> ``(spec, outline, start, goal)``."""
    spec = MeshSpec.preset(mesh if isinstance(mesh, str) else "default") if (
        mesh is None or isinstance(mesh, str)) else mesh
    if not isinstance(spec, MeshSpec):
        raise InputError(f"mesh must be a MeshSpec or a preset name, got {type(mesh).__name__}")
    if time_limit is not None:
        check_number(time_limit, "time_limit (seconds)", 0.0, low_open=True)
    poly = _outline(m)
    s, g = (m.domain.check(p, name) for p, name in ((start, "start"), (goal, "goal")))
    for pts, name in ((s, "start"), (g, "goal")):
        if pts.shape[0] != 1:
            raise InputError(f"{name} must be a single point of shape ({m.dim},), got "
                             f"{pts.shape[0]} points")
    s, g = s[0], g[0]
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
    return spec, poly, s, g


@dataclass
class _Upper:
    """The upper bound: the solver's (or the given) path ``pts``, its status, the proven
    bound of its length ``path_upper``, and the bound used (``upper``, of ``path`` with
    the length estimate ``est``: the same path, or a zigzag where that is shorter)."""

    pts: np.ndarray
    solver_status: Status
    path_upper: float
    upper: float
    source: str
    path: np.ndarray
    est: Any
    seconds: float


def _upper_bound(m: Metric, s: np.ndarray, g: np.ndarray, spec: MeshSpec,
                 path: Any) -> _Upper:
    """A curve's length with its quadrature error: the solve at ``spec.segments`` segments
    from the checked pair (no second check), or the given ``path`` (checked here: its
    shape, its ends, the domain)."""
    t0 = time.perf_counter()
    if path is None:
        from solvers.geodesic.pair_solver import resolve_method, solve_pair
        from solvers.geodesic.request import SolveRequest, seed_plan

        n = check_segments(m, spec.segments if spec.segments is not None
                           else 4 * m.task.segments)
        how = resolve_method(m, "auto")
        sol = solve_pair(SolveRequest(m, n, seed_plan(m, None, how), how), s, g)
        pts = np.asarray(sol.points, float)
        solver_status = sol.status
    else:
        pts = np.array(as_real(path, "path", "a real numeric array of shape (n+1, dim)"))
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
            raise InputError(f"path must have shape (n+1, 2), got {pts.shape}")
        if not (np.allclose(pts[0], s, rtol=0, atol=1e-12)
                and np.allclose(pts[-1], g, rtol=0, atol=1e-12)):
            raise InputError("path must run from start to goal")
        m.domain.check(pts, "path")
        solver_status = Status.GIVEN
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
    return _Upper(pts, solver_status, solver_upper, upper, upper_source, upper_path, est,
                  time.perf_counter() - t0)


@dataclass
class _Lower:
    """What the refinement rounds found: the best LP (``best``, with its mesh; None if the
    first round failed), the last mesh, the rounds, what stopped them, a failure (status,
    message) and the seconds of meshing and LPs, and the point data (its seconds count
    as ``bounds``)."""

    best: dict[str, Any] | None
    last_mesh: _Mesh | None
    rounds: list[dict[str, Any]]
    stopped_by: str
    failure: tuple[CertifyStatus, str] | None
    t_mesh: float
    t_lp: float
    data: _PointData
    reach: tuple[float, float] = (0.0, math.inf)
    """The proven speed floor ``m`` and the reach ``upper / m`` (`certify_reach`)."""


def _pre_refine(msh: _Mesh, data: _PointData, spec: MeshSpec,
                region: Callable[[np.ndarray], np.ndarray] | None = None
                ) -> tuple[_Mesh, _RowBounds, tuple[CertifyStatus, str] | None, float]:
    """Row bounds of ``msh``; triangles whose corrections eat half of F somewhere (after
    tightening those rows direction by direction) are refined before any LP (at most
    `MAX_PRE_REFINE` times) -> the mesh, its rows, a failure if the corrections do
    not shrink, the meshing seconds."""
    t_mesh = 0.0
    failure: tuple[CertifyStatus, str] | None = None
    rb = _bad_tightened(msh, data)
    for _ in range(MAX_PRE_REFINE):
        bad = np.min(rb.b / rb.f, axis=(1, 2)) < 0.5
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
        msh = _Mesh(msh.refine(np.flatnonzero(bad)), region)
        t_mesh += time.perf_counter() - t0
        rb = _bad_tightened(msh, data)
    if failure is None and np.min(rb.b) <= 0.0:
        failure = (CertifyStatus.CORRECTIONS_TOO_LARGE,
                   f"{int(np.sum(np.min(rb.b, axis=(1, 2)) <= 0))} triangles keep "
                   f"second-order corrections above F after {MAX_PRE_REFINE} "
                   "refinements; use a smaller h_path / h_far")
    return msh, rb, failure, t_mesh


def _bad_tightened(msh: _Mesh, data: _PointData) -> _RowBounds:
    """The rows of ``msh``, those whose corrections eat half of F tightened."""
    rb = _RowBounds(msh, data)
    t, kk = np.nonzero(np.min(rb.b / rb.f, axis=1) < 0.5)
    if t.size:
        rb.tighten(t, kk)
    return rb


def _marked(lp: dict[str, Any], corr: np.ndarray, n_tri: int, spec: MeshSpec,
            upper: float) -> np.ndarray | None:
    """Doerfler marking by the dual-weighted corrections ``sum_r y_r c_r`` per triangle:
    the triangles to refine (their weight reaching a fraction of the total), or None if no
    triangle carries weight.

    The fraction is ``spec.mark_fraction``, less when the total weight ``W`` is close to
    the target: the LP value falls short of the distance by about ``W`` (to first order in
    the corrections), and refining a triangle cuts its weight by about ``GOAL_RHO``, so
    ``theta W (1 - 1 / GOAL_RHO)`` of it must go to bring ``W`` to ``GOAL_SAFETY`` times
    the target gap: a fraction ``theta`` that does, and no more (the refined mesh's LP is
    the last and costs by its rows).
    """
    rows, y = lp["rows"], np.maximum(lp["duals"], 0.0)
    weight = np.bincount(rows[:, 0], weights=y * corr[rows[:, 0], rows[:, 2]],
                         minlength=n_tri)
    order = np.argsort(-weight)
    cum = np.cumsum(weight[order])
    if cum[-1] <= 0:
        return None
    fraction = spec.mark_fraction
    if GOAL_MARKING:
        need = (1.0 - GOAL_SAFETY * spec.target_gap * upper / cum[-1]) / (1.0 - 1.0 / GOAL_RHO)
        fraction = min(fraction, max(need, GOAL_FLOOR))
    n_mark = int(np.searchsorted(cum, fraction * cum[-1]) + 1)
    return order[:n_mark]


def _last_round(lp: dict[str, Any], corr: np.ndarray, msh: _Mesh, spec: MeshSpec,
                upper: float) -> bool:
    """Whether the refinement would stop after this LP (nothing to mark, or too many
    triangles): then its rounds go on to the end (`_solve_lp` without ``settle``)."""
    marked = _marked(lp, corr, msh.n_tri, spec, upper)
    return marked is None or msh.n_tri + 3 * len(marked) > spec.max_triangles


def _lower_bound(m: Metric, poly: np.ndarray, up: _Upper, s: np.ndarray, g: np.ndarray,
                 spec: MeshSpec, time_limit: float | None, t_start: float) -> _Lower:
    """The dual LP on meshes refined where the corrections cost most, round after round,
    until the target gap, a budget of ``spec``, the time limit or a failure."""
    t0 = time.perf_counter()
    points = _initial_points(poly, up.pts, s, g, spec)
    t_mesh = time.perf_counter() - t0
    data = _PointData(m, spec.directions, direction_group(spec.directions))
    out = _Lower(None, None, [], "max_rounds", None, t_mesh, 0.0, data)
    # rows only on the triangles a curve no longer than the upper bound can reach
    floor = speed_floor(m, poly)
    reach = up.upper / floor if floor > 0 else math.inf
    out.reach = (floor, reach)

    def region(corners: np.ndarray) -> np.ndarray:
        return reachable_triangles(corners, s, g, reach)

    previous = None
    for rnd in range(spec.max_rounds):
        t0 = time.perf_counter()
        msh = _Mesh(points, region)
        out.t_mesh += time.perf_counter() - t0
        msh, rb, out.failure, t_pre = _pre_refine(msh, data, spec, region)
        b, corr = rb.b, rb.corr
        out.t_mesh += t_pre
        if out.failure is not None:
            out.last_mesh = msh
            break
        t0 = time.perf_counter()
        start = _initial_modes(msh, spec.directions, previous, up.pts, 2.0 * spec.h_path)
        try:
            # short of the target, a mesh that will be refined stops its LP rounds early
            lp = _solve_lp(msh, b, data.dirs, 0, 1, up.upper, spec.target_gap, start=start,
                           settle=rnd + 1 < spec.max_rounds, tighten=rb.tighten)
            if lp["settled"] and _last_round(lp, corr, msh, spec, up.upper):
                lp = _solve_lp(msh, b, data.dirs, 0, 1, up.upper, spec.target_gap,
                               start={"exact": lp["exact"], "active": lp["active"]},
                               tighten=rb.tighten)
        except LPFailure as err:
            out.failure, out.last_mesh = (CertifyStatus.LP_FAILED, str(err)), msh
            break
        previous = (msh, lp)
        out.t_lp += time.perf_counter() - t0
        # a curve shorter than the potential's rise stays in the region only if it is no
        # longer than the upper bound (certify_reach): the bound is min(rise, upper)
        if math.isfinite(reach):
            lp["lower"] = min(lp["lower"], up.upper)
        gap = (up.upper - lp["lower"]) / up.upper
        out.rounds.append({"triangles": msh.n_tri, "unknowns": msh.n_dofs,
                           "rows": lp["n_rows"], "row_rounds": lp["iterations"],
                           "lower": lp["lower"], "gap": gap,
                           "seconds": time.perf_counter() - t_start})
        if out.best is None or lp["lower"] > out.best["lower"]:
            out.best = {**lp, "mesh": msh}
        if gap <= spec.target_gap:
            out.stopped_by = "target_gap"
            break
        if time_limit is not None and time.perf_counter() - t_start > time_limit:
            out.stopped_by = "time_limit"
            break
        marked = _marked(lp, corr, msh.n_tri, spec, up.upper)
        if marked is None:
            out.stopped_by = "no_refinement"
            break
        if msh.n_tri + 3 * len(marked) > spec.max_triangles:
            out.stopped_by = "max_triangles"
            break
        t0 = time.perf_counter()
        points = msh.refine(marked)
        out.t_mesh += time.perf_counter() - t0
    return out


def _outcome(low: _Lower) -> tuple[str, CertifyStatus, str]:
    """``(stopped_by, status, message)`` of the refinement: a failure's label and message,
    else the status the stop means."""
    if low.failure is not None:
        status, message = low.failure
        return status.label, status, message
    status = {"target_gap": CertifyStatus.CERTIFIED,
              "time_limit": CertifyStatus.TIME_LIMIT}.get(low.stopped_by,
                                                         CertifyStatus.BUDGET_REACHED)
    return low.stopped_by, status, ""


def _result(m: Metric, s: np.ndarray, g: np.ndarray, spec: MeshSpec, poly: np.ndarray,
            up: _Upper, low: _Lower, t_start: float) -> CertifyResult:
    """The `CertifyResult` of the bounds found (the trivial lower bound 0 if the
    first round failed)."""
    stopped_by, status, message = _outcome(low)
    best = low.best
    if best is None:  # failed in the first round: the trivial bound d >= 0 holds
        assert low.last_mesh is not None
        best = {"lower": 0.0, "mesh": low.last_mesh, "n_rows": 0, "status": "not_solved",
                "solver": LP_SOLVER, "ratio": float("nan")}
    final: _Mesh = best["mesh"]
    lower = best["lower"]
    kind, note = _convexity(m, final.points)
    upper, total = up.upper, time.perf_counter() - t_start
    return CertifyResult(
        metric=m.name, start=s, goal=g, lower=lower, upper=upper, length=float(up.est.value),
        length_error=float(up.est.error), gap=(upper - lower) / upper,
        upper_source=up.source, path_upper=up.path_upper,
        path_gap=(up.path_upper - lower) / up.path_upper, triangles=final.n_tri,
        vertices=int(final.points.shape[0]), unknowns=final.n_dofs,
        directions=spec.directions, lp_rows=best["n_rows"],
        lp_rows_total=int(3 * final.n_tri * spec.directions), lp_status=best["status"],
        lp_solver=best["solver"], max_row_ratio=best["ratio"], convexity=kind,
        convexity_note=note, solver_status=up.solver_status,
        mesh={**asdict(spec), "element": "P2", "domain_polygon_vertices": int(poly.shape[0]),
              "speed_floor": low.reach[0], "reach": low.reach[1]},
        times={"solve": up.seconds, "mesh": low.t_mesh, "bounds": low.data.seconds,
               "lp": low.t_lp, "total": total},
        rounds=low.rounds, path=up.path, stopped_by=stopped_by, status=status,
        message=message,
    )
