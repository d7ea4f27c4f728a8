"""Sound lower bounds of distances for conformal metrics in any dimension.

For a conformal metric ``F(q, v) = f(q) |v|`` (the hook ``conformal_factor_sx``; the Panda
pole metric, eq. 60, is one in 7-D) `certify_conformal` proves ``lower <= d(x, y) <=
upper``. The upper bound is the solver's path length, proven by interval arithmetic
(`finsler.Metric.path_length_bounds`). The lower bound needs only enclosures of ``f``
over boxes (`finsler.enclosures.intervals.enclose`, outward rounding) and three facts:

1. **The region.** A path of length at most ``U`` (the upper bound) on which ``f >= m`` has
   Euclidean length at most ``U / m``, so it lies in the ellipsoid ``E = {q : |q - x| +
   |q - y| <= U / m}``. Boxes covering the domain are split (branch and bound); a box that
   misses ``E`` (``dist(x, box) + dist(y, box) > U / m``) or the domain (an enclosure of a
   domain constraint outside its bounds) is dropped. ``m`` is the smallest enclosure of
   ``f`` over the kept boxes, so the kept boxes cover every point of every path shorter
   than ``U`` (induction over the rounds: each round's boxes cover the previous ``E``).
   ``m |y - x|`` is the trivial bound the result reports beside the real one.
2. **A 2-D reduction.** With ``u = (y - x) / |y - x|``, the map ``q -> (s, r)``, ``s = u .
   (q - x)`` (along the chord) and ``r = |q - x - s u|`` (distance from the chord's line),
   is 1-Lipschitz, and ``E`` maps onto an ellipse. On a grid of ``(s, r)`` cells, ``g(c)``
   is the smallest enclosure of ``f`` over the boxes whose ``(s, r)`` range meets cell
   ``c`` (``f >= g`` wherever a path can project into ``c``). A path's length is then at
   least the length of its projection in the 2-D conformal metric ``g |w|``.
3. **A verified potential on the plane.** A continuous piecewise-linear ``Phi(s, r)`` on
   the grid's triangles with ``|grad Phi| <= g`` on every triangle of a cell that any box
   meets gives ``d(x, y) >= Phi(|y - x|, 0) - Phi(0, 0)`` (``Phi o (s, r)`` is a
   subsolution of the eikonal equation on the region). ``Phi`` maximises that difference,
   a second-order cone program through cvxpy; its gradients are then checked exactly in
   float64 and ``Phi`` divided by the largest ratio ``|grad Phi| / g`` (times ``1 +
   1e-9``), so the bound holds whatever the solver's tolerance. The 1-D chord potential
   (``Phi(s)`` alone) is the special case ``r_cells = 1``: the plane adds that a path must
   pay to leave the chord for the cheap regions away from it.
4. **Cyclic coordinates.** Coordinates ``f`` does not depend on (the Panda's last joint)
   are left out of the boxes: with ``q = (q_A, q_F)``, ``phi = p e_F . q_F + Psi(s, r)``
   (``s, r`` of ``q_A``) is a subsolution when ``|grad Psi| <= sqrt(g**2 - p**2)``
   (Clairaut), so ``d >= p |y_F - x_F| + Psi(goal) - Psi(start)``, best over a few
   momenta ``p`` in ``[0, m]``; and a path shorter than ``U`` has ``L_A <= sqrt(U**2 -
   (m |y_F - x_F|)**2)`` (Minkowski), a smaller ellipsoid in fewer dimensions.

Refinement: a box's priority is how far its enclosure holds a cell below ``1 -
refine_tol`` times the smallest value of ``f`` seen at a box centre there, times that
cell's weight in the bound (the cone program's dual, solved again whenever the boxes grew
by 30 %); the boxes carrying ``mark_fraction`` of the priority, and those holding the
region's smallest bound ``m`` down, are bisected along their widest side each round, within
the work budget ``max_boxes`` (boxes enclosed in all): budgets, never wall clock, decide
the result.

Parts and projections (``part``, used by `solvers.certificates.conformal.split`): the same
machinery bounds the length of a part ``a <= f`` of the factor over the paths of ``F``-length
at most ``U``, and can take coordinates over their whole range (the factor's minimum over
them: fewer dimensions, those coordinates then free with the momentum).

Limits: the bound is only as good as the enclosures of ``f`` over boxes (affine arithmetic,
`finsler.enclosures.affine`: about 1 % below the true minimum on 0.1-rad Panda boxes, 3 % on
0.2-rad ones) and as the ``(s, r)`` reduction, which keeps only the distance to the chord's
line: two regions at the same ``(s, r)`` share one bound. In 6-D the cells next to the
chord meet boxes whose ``(s, r)`` range spills over them, so every cell may be bounded
near the region's global minimum and the bound stays near the trivial one's ceiling
(the split of `solvers.certificates.conformal.split` is the remedy). It proves a lower
bound, not a tight interval; the ratio also carries the upper bound's own slack. The
measurements: ``docs/guides/certify.md`` and the ``certify_panda`` results under
``benchmarks/results/``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from finsler.domains import as_real
from finsler.enclosures.affine import enclose_affine
from finsler.enclosures.intervals import Interval, enclose
from finsler.errors import InputError
from finsler.lowering import LoweredFunction, lower
from finsler.metrics.base import Metric
from finsler.status import CertifyStop, LPStatus, Status
from solvers.certificates.conformal.grid import SLACK as _SLACK
from solvers.certificates.conformal.grid import (
    Grid,
    best_potential,
    cell_bounds,
    expand,
    potential,
    reduced,
)
from solvers.certificates.domain import domain_constraints, outside_domain
from solvers.inputs import as_metric
from solvers.result import Certificate
from solvers.status import CertifyStatus

__all__ = ["ConformalCertifyResult", "ConformalSpec", "certify_conformal"]

#: Boxes enclosed per call of the lowered program (memory).
_CHUNK = 100_000
#: Check every new box's enclosure against the factor's value at its centre (a wrong
#: enclosure raises instead of giving a bound; tests switch it off to see the bound fail).
CHECK_VALUES = True
#: Grid points per projected coordinate for the values at box centres (``_Projected``).
PROJECT_GRID = 5
#: Fewest boxes split per round (the enclosures are vectorised: small rounds are slow).
MIN_SPLIT = 2000
#: A box is bisected along the side ``j`` maximising ``w_j (1 + SPLIT_ALIGN (|u_j| +
#: |e_j|))`` (``w`` its widths, ``u`` the chord's direction, ``e`` the unit vector across
#: the chord to its centre): sides that widen its ``(s, r)`` ranges go first (10: the
#: largest bounds on the Panda tuning pairs; 0 is the widest side alone).
SPLIT_ALIGN = 10.0
#: Box enclosures of the ``"coarse"`` preset (all runs of
#: `solvers.certificates.conformal.split.certify_conformal_best` together).
COARSE_BOXES = 100_000


@dataclass(frozen=True)
class ConformalSpec:
    """Work budgets and resolution of `certify_conformal`."""

    max_boxes: int = 2_000_000
    """Budget: boxes enclosed in all (each split encloses two)."""
    max_live: int = 600_000
    """Budget: boxes kept at once (memory)."""
    max_rounds: int = 200
    """Budget: refinement rounds."""
    s_cells: int = 32
    """Cells along the chord between start and goal (more beyond them, same size)."""
    r_cells: int = 12
    """Cells across, from the chord's line to the edge of the ellipse (1: the chord-only
    1-D potential)."""
    mark_fraction: float = 0.7
    """Split, per round, the boxes carrying this fraction of the priorities (at least
    ``MIN_SPLIT``)."""
    refine_tol: float = 0.01
    """Split a box while its enclosure is below ``1 - refine_tol`` times the best value
    seen in its cells."""
    target_gap: float = 0.2
    """Status ``certified`` when ``(upper - lower) / upper`` is at most this."""
    segments: int | None = None
    """Segments of the solver's path (the upper bound); default: the task's."""

    def __post_init__(self) -> None:
        for name, low in (("max_boxes", 2), ("max_live", 2), ("max_rounds", 1),
                          ("s_cells", 1), ("r_cells", 1)):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < low:
                raise InputError(f"ConformalSpec.{name} must be an integer >= {low}, got "
                                 f"{val!r}")
        for name in ("refine_tol", "target_gap", "mark_fraction"):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not (
                    math.isfinite(val) and 0 < val < 1):
                raise InputError(f"ConformalSpec.{name} must be in (0, 1), got {val!r}")
        if self.segments is not None and (isinstance(self.segments, bool) or not isinstance(
                self.segments, (int, np.integer)) or self.segments < 2):
            raise InputError(f"ConformalSpec.segments must be an integer >= 2, got "
                             f"{self.segments!r}")

    @classmethod
    def preset(cls, name: str) -> ConformalSpec:
        """The presets by name, as `solvers.certificates.plane.certificate.MeshSpec`'s:
        ``"coarse"`` (a
        work budget of ``COARSE_BOXES`` box enclosures for all runs together: the quick
        report's), ``"default"`` (the defaults above) or ``"fine"`` (4 x their boxes)."""
        presets = {"coarse": cls(max_boxes=COARSE_BOXES), "default": cls(),
                   "fine": cls(max_boxes=4 * cls.max_boxes, max_live=2 * cls.max_live)}
        if name not in presets:
            raise InputError(f"unknown mesh preset {name!r}; choose one of "
                             f"{', '.join(presets)}")
        return presets[name]


@dataclass
class ConformalCertifyResult(Certificate):
    """A proven interval ``lower <= d(start, goal) <= upper`` for a conformal metric.

    ``lower`` is the larger of ``potential_lower`` (the verified planar potential) and
    ``trivial`` (``min_factor * |goal - start|``, ``min_factor`` the proven smallest value
    of ``f`` over the reachable region); ``ratio = lower / upper``, ``gap = 1 - ratio``.
    ``min_factor_seen`` is the smallest value of ``f`` at a box centre: ``min_factor_seen
    * |goal - start|`` is at least the trivial bound with the exact minimum.
    ``boxes`` are the boxes kept at the end, ``enclosures`` the boxes enclosed in all (the
    work), ``cells`` the ``(s, r)`` cells with a bound, ``scale`` the factor the potential
    was divided by after the exact check of its gradients (1 + the solver's tolerance).
    ``active_dims``: the coordinates ``f`` depends on (the boxes live there; the others
    are cyclic and carry the ``momentum`` of the best potential); ``cone_programs`` the
    potentials solved. ``stopped_by``: ``no_refinement`` (no box holds a cell down), ``max_boxes``,
    ``max_live`` or ``max_rounds`` (the budgets), or a failure's label. ``times`` in
    seconds (solve, boxes, lp, total); ``wall_time`` their total."""

    rigour: ClassVar[dict[str, str]] = {
        "upper": "proven: path length with interval bound of the quadrature error "
                 "(Metric.path_length_bounds)",
        "lower": "proven: a planar potential on the chord's (s, r) plane whose gradients are "
                 "checked exactly against interval enclosures of the conformal factor over "
                 "boxes (outward rounding); a lower bound only, the upper is the path's",
        "region": "proven: boxes dropped only outside the ellipsoid a path shorter than the "
                  "upper bound cannot leave (the factor's proven minimum over kept boxes)",
    }
    """What each part of the interval rests on (as ``NDResult.rigour``)."""

    metric: str
    start: np.ndarray
    goal: np.ndarray
    lower: float
    upper: float
    ratio: float
    gap: float
    trivial: float
    potential_lower: float
    min_factor: float
    min_factor_seen: float
    euclidean: float
    ellipse: float
    boxes: int
    enclosures: int
    cells: int
    rounds: int
    active_dims: int
    momentum: float
    cone_programs: int
    scale: float
    lp_status: LPStatus
    solver_status: Status
    stopped_by: CertifyStop
    status: CertifyStatus
    message: str
    method: str
    spec: dict[str, Any]
    times: dict[str, float]
    wall_time: float
    path: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        # members of the status family (words are accepted and converted)
        self.stopped_by = CertifyStop(self.stopped_by)
        self.lp_status = LPStatus.from_solver(self.lp_status)
        self.solver_status = Status.from_label(self.solver_status)

    def to_dict(self, with_path: bool = False) -> dict[str, Any]:
        out = super().to_dict()
        if not with_path:
            out.pop("path", None)
        return out


def _factor_function(metric: Metric, reduce: bool, factor: Any = None, key: str = "",
                     project: tuple[int, ...] = ()) -> tuple[LoweredFunction, np.ndarray]:
    """The lowered conformal factor ``q_A -> f`` and the mask of its coordinates ``A``:
    with ``reduce``, only those ``f`` depends on (cached on the metric). ``factor``: a
    callable ``q (SX) -> SX`` used instead of the metric's hook (a part of it, cached
    under ``key``). ``project``: coordinates left out of ``A`` although ``f`` depends on
    them; the program then takes ``q_(A + project)`` (in coordinate order) and the caller
    encloses it with those coordinates over their whole range."""
    factor_sx = factor if factor is not None else metric.conformal_factor_sx

    def build() -> tuple[LoweredFunction, np.ndarray]:
        q = ca.SX.sym("q", metric.dim)
        f = ca.SX(factor_sx(q))
        if f.numel() != 1:
            raise InputError(f"{metric.name}: conformal_factor_sx must return a scalar, got "
                             f"shape {f.shape}")
        active = np.array([(not reduce or bool(ca.depends_on(f, q[i])))
                           and i not in project for i in range(metric.dim)])
        if not active.any():
            active[0] = True
        inputs = active.copy()
        inputs[list(project)] = True
        qa = ca.SX.sym("qa", int(inputs.sum()))
        full = ca.vertcat(*[qa[int(inputs[:i].sum())] if inputs[i] else ca.SX(0.0)
                            for i in range(metric.dim)])
        fa = ca.substitute(f, q, full)
        return lower(ca.Function(f"conformal_factor_{metric._ident}", [qa], [fa])), active
    return metric.derived(f"certify.conformal_factor.{reduce}{key}.{project}", build)


class _Projected:
    """Enclosures and values of ``f`` over boxes in the active coordinates, the projected
    ones spanning their whole range: enclosures over the product box, values the smallest
    over a grid of ``PROJECT_GRID`` points per projected coordinate (an upper bound of the
    minimum: all the refinement needs, and never below a sound enclosure)."""

    def __init__(self, fn: LoweredFunction, active: np.ndarray, project: tuple[int, ...],
                 dom_lo: np.ndarray, dom_hi: np.ndarray) -> None:
        self.fn = fn
        inputs = active.copy()
        inputs[list(project)] = True
        idx = np.flatnonzero(inputs)
        self.a_pos = np.flatnonzero(active[idx])
        self.p_pos = np.flatnonzero(~active[idx])
        self.n_in = idx.size
        self.p_lo, self.p_hi = dom_lo[idx[self.p_pos]], dom_hi[idx[self.p_pos]]
        axes = [np.linspace(a, b, PROJECT_GRID) for a, b in zip(self.p_lo, self.p_hi,
                                                                  strict=True)]
        self.p_grid = (np.stack([g.reshape(-1) for g in np.meshgrid(*axes)], axis=1)
                       if axes else np.zeros((1, 0)))

    def enclose(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        if self.p_pos.size == 0:
            return _enclose_factor(self.fn, lo, hi)
        flo, fhi = np.empty((lo.shape[0], self.n_in)), np.empty((lo.shape[0], self.n_in))
        flo[:, self.a_pos], fhi[:, self.a_pos] = lo, hi
        flo[:, self.p_pos], fhi[:, self.p_pos] = self.p_lo, self.p_hi
        return _enclose_factor(self.fn, flo, fhi)

    def value(self, pts: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            if self.p_pos.size == 0:
                return np.asarray(self.fn(pts)[0], float).reshape(-1)
            k = self.p_grid.shape[0]
            full = np.empty((pts.shape[0] * k, self.n_in))
            full[:, self.a_pos] = np.repeat(pts, k, axis=0)
            full[:, self.p_pos] = np.tile(self.p_grid, (pts.shape[0], 1))
            val = np.asarray(self.fn(full)[0], float).reshape(pts.shape[0], k)
            return np.min(np.where(np.isfinite(val), val, np.inf), axis=1)


def _enclose_factor(fn: LoweredFunction, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Proven lower bounds ``(N,)`` of ``f`` over the boxes ``[lo, hi]``: affine
    arithmetic intersected with the natural interval extension (the natural one alone for
    a program with an operation affine arithmetic lacks), clamped at 0 (``f > 0`` on the
    domain)."""
    out = np.empty(lo.shape[0])
    for a in range(0, lo.shape[0], _CHUNK):
        sl = slice(a, a + _CHUNK)
        with np.errstate(all="ignore"):
            try:
                (val,) = enclose_affine(fn, lo[sl], hi[sl])
            except NotImplementedError:
                (val,) = enclose(fn, Interval(lo[sl], hi[sl]))[0]
        out[sl] = np.broadcast_to(val.lo, (lo[sl].shape[0],))
    return np.maximum(np.nan_to_num(out, nan=0.0, neginf=0.0), 0.0)


def _box_point_distance(lo: np.ndarray, hi: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Lower bounds of the Euclidean distances from ``p`` to the boxes."""
    gap = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.sqrt(np.einsum("ij,ij->i", gap, gap)) * (1.0 - _SLACK)


def _box_sr(lo: np.ndarray, hi: np.ndarray, x: np.ndarray, u: np.ndarray
            ) -> tuple[np.ndarray, ...]:
    """Ranges ``[s_lo, s_hi]``, ``[r_lo, r_hi]`` of ``(s, r)`` over the boxes. With ``P``
    the projection across the chord, ``c`` a box's centre (from ``x``), ``h`` its half
    widths and ``w = P c / |P c|``: ``r(q) = |P(q - x)| >= w . (q - x) >= |P c| - sum_j
    h_j |w_j|`` and ``r(q)**2 <= |P c|**2 + 2 sum_j h_j |(P c)_j| + |P d|**2`` (``d`` the
    offset from the centre; both no looser than ``|P c| -+ |h|``, much tighter for a box
    long along the chord)."""
    c = 0.5 * (lo + hi) - x
    h = 0.5 * (hi - lo)
    sc = c @ u
    srad = h @ np.abs(u)
    perp = c - sc[:, None] * u
    rc = np.sqrt(np.einsum("ij,ij->i", perp, perp))
    hh = np.einsum("ij,ij->i", h, h)
    hp = np.einsum("ij,ij->i", h, np.abs(perp))  # sum_j h_j |(P c)_j|
    with np.errstate(invalid="ignore", divide="ignore"):
        r_lo = np.where(rc > 0.0, rc - hp / rc, 0.0)
    # |P d|**2 <= min(|h|**2, (sum_j h_j |P e_j|)**2), |P e_j| = sqrt(1 - u_j**2)
    hq = np.minimum(hh, (h @ np.sqrt(np.maximum(1.0 - u * u, 0.0))) ** 2)
    r_hi = np.sqrt(rc * rc + 2.0 * hp + hq)
    pad = _SLACK * (1.0 + np.abs(sc) + srad + rc + np.sqrt(hh))
    return (sc - srad - pad, sc + srad + pad, np.maximum(r_lo - pad, 0.0), r_hi + pad)


def _across(lo: np.ndarray, hi: np.ndarray, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``|e|`` per box: the unit vector from the chord's line to the box's centre (0 on
    the line)."""
    c = 0.5 * (lo + hi) - x
    perp = c - (c @ u)[:, None] * u
    norm = np.sqrt(np.einsum("ij,ij->i", perp, perp))[:, None]
    return np.abs(perp) / np.where(norm > 0.0, norm, np.inf)


def certify_conformal(metric: Metric | str, start: Any, goal: Any,
                      spec: ConformalSpec | None = None, *, path: Any = None,
                      part: tuple[Any, str, float, tuple[int, ...]] | None = None
                      ) -> ConformalCertifyResult:
    """Proven interval ``lower <= d(start, goal) <= upper`` on a conformal metric of any
    dimension (one providing the hook ``conformal_factor_sx``); see the module docstring
    for the method. ``path`` ``(n+1, dim)``: a curve from start to goal for the upper
    bound (default: `solvers.solve_geodesic` at ``spec.segments`` segments).
    Raises `InputError` for a metric without the hook, points outside the domain,
    start == goal, or a domain that is unbounded.

    ``part`` ``(factor, key, euclid, project)``, for `solvers.certificates.conformal.split`: bound
    the length ``int a(q) |q'|`` of the part ``a = factor(q) <= f`` (a callable ``SX ->
    SX``, cached under ``key``) over the paths whose full Euclidean length is at most
    ``euclid`` (those of ``F``-length at most ``upper``: the region is that ellipsoid);
    ``trivial`` is then ``min a |y - x|``; the coordinates ``project`` are bounded over
    their whole range (``a`` replaced by its minimum over them: fewer dimensions)."""
    t_start = time.perf_counter()
    m = as_metric(metric)
    spec = spec or ConformalSpec()
    if not isinstance(spec, ConformalSpec):
        raise InputError(f"spec must be a ConformalSpec, got {type(spec).__name__}")
    if not m.provides("conformal_factor_sx"):
        raise InputError(f"metric {m.name!r} is not conformal (it does not provide the hook "
                         "'conformal_factor_sx'): certify_conformal needs F(x, v) = f(x) |v|")
    x = m.domain.check(np.asarray(start, float), "start")[0]
    y = m.domain.check(np.asarray(goal, float), "goal")[0]
    dist = float(np.linalg.norm(y - x))
    if dist == 0.0:
        raise InputError("start equals goal: the distance is 0, nothing to certify")
    dom_lo, dom_hi = (np.asarray(b, float) for b in m.domain.bounds())
    if not (np.all(np.isfinite(dom_lo)) and np.all(np.isfinite(dom_hi))):
        raise InputError(f"certify_conformal needs a bounded domain; {m.name}'s is "
                         f"{m.domain.describe()}")

    # upper bound
    t0 = time.perf_counter()
    if path is None:
        from solvers.geodesic.solve import solve_geodesic

        n = spec.segments if spec.segments is not None else m.task.segments
        sol = solve_geodesic(m, x, y, n)
        pts = np.asarray(sol.points, float)
        solver_status = sol.status.label
    else:
        pts = np.array(as_real(path, "path", "a real numeric array of shape (n+1, dim)"))
        if pts.ndim != 2 or pts.shape[1] != m.dim or pts.shape[0] < 2:
            raise InputError(f"path must have shape (n+1, {m.dim}), got {pts.shape}")
        if not (np.allclose(pts[0], x, rtol=0, atol=1e-12)
                and np.allclose(pts[-1], y, rtol=0, atol=1e-12)):
            raise InputError("path must run from start to goal")
        m.domain.check(pts, "path")
        solver_status = "given"
    upper = float(m.path_length_bounds(pts).upper)
    t_solve = time.perf_counter() - t0

    # boxes: branch and bound on the reachable region
    t0 = time.perf_counter()
    factor, key, euclid, project = part if part is not None else (None, "", math.inf, ())
    fn, active = _factor_function(m, True, factor, key, project)
    if float(np.linalg.norm((y - x)[active])) <= 1e-9 * dist:  # only free coordinates move
        fn, active = _factor_function(m, False, factor, key)
        project = ()
    cons = domain_constraints(m, active)
    free_dist = float(np.linalg.norm((y - x)[~active]))
    full_dist, x_full, y_full = dist, x, y
    x, y = x[active], y[active]
    dist = float(np.linalg.norm(y - x))
    u = (y - x) / dist
    lo, hi = dom_lo[None, active].copy(), dom_hi[None, active].copy()
    proj = _Projected(fn, active, project, dom_lo, dom_hi)
    f_lo = proj.enclose(lo, hi)
    f_c = proj.value(0.5 * (lo + hi))
    f_c = np.where(np.isfinite(f_c), f_c, np.inf)
    work, rounds = 1, 0
    stopped_by = "max_rounds"
    grid: Grid | None = None
    g = np.zeros(0)
    m_low = 0.0
    radius = math.inf
    weight: np.ndarray | None = None
    lp_boxes, lp_solves = 0, 0

    def ellipse(m_low: float) -> float:
        """``U_A / m``: the largest Euclidean length, in the active coordinates, of a path
        shorter than ``U`` on which ``f >= m`` (Minkowski: ``U**2 >= L_A**2 + (m
        |free move|)**2``)."""
        cap = math.inf
        if math.isfinite(euclid):  # a part: the full path's Euclidean length is known
            cap = math.sqrt(max(euclid * euclid - (free_dist * (1.0 - _SLACK)) ** 2, 0.0))
            cap *= 1.0 + _SLACK
        if m_low <= 0:
            return cap
        ua = math.sqrt(max(upper * upper - (m_low * free_dist * (1.0 - _SLACK)) ** 2, 0.0))
        return min(ua / m_low * (1.0 + _SLACK), cap)

    while True:
        # the region: drop boxes outside the domain or the ellipse of the current m
        m_low = float(np.min(f_lo)) if f_lo.size else 0.0
        radius = ellipse(m_low)
        keep = ~outside_domain(cons, lo, hi)
        if math.isfinite(radius):
            keep &= (_box_point_distance(lo, hi, x) + _box_point_distance(lo, hi, y)
                     <= radius)
        lo, hi, f_lo, f_c = lo[keep], hi[keep], f_lo[keep], f_c[keep]
        if lo.shape[0] == 0:  # the path itself lies in the region: a sound run never empties it
            raise RuntimeError(f"{m.name}: no box of the region is left, which contradicts "
                               "the path's own length: the enclosures are wrong (a bug)")
        m_new = float(np.min(f_lo))
        if m_new > m_low:  # fewer boxes: a larger m, a smaller ellipse (next round)
            m_low = m_new
            radius = ellipse(m_low)
        if not math.isfinite(radius):
            radius = 2.0 * float(np.linalg.norm((dom_hi - dom_lo)[active])) + dist
        grid = Grid.make(dist, radius, spec.s_cells, spec.r_cells)
        rng = grid.ranges(*_box_sr(lo, hi, x, u))
        g = cell_bounds(grid, f_lo, rng)
        if rounds >= spec.max_rounds:
            break
        # the best value seen per cell (f at box centres), and the boxes holding cells down
        cs = _box_sr(0.5 * (lo + hi), 0.5 * (lo + hi), x, u)
        ci = grid.ranges(*cs)
        seen = np.full(g.size, np.inf)
        np.minimum.at(seen, ci[0] * grid.nr + ci[2], f_c)
        if weight is None or weight.size != g.size or lo.shape[0] > 1.3 * lp_boxes:
            # the bound's sensitivity to each cell's g (the cone program's duals)
            weight = potential(grid, reduced(g, m_low * free_dist / full_dist))[3]
            lp_boxes = lo.shape[0]
            lp_solves += 1
        box, cell = expand(*rng, grid.nr)
        # a box's priority: how far it holds a cell below the best value seen there,
        # weighted by what that cell is worth to the bound
        with np.errstate(invalid="ignore"):  # 0 x inf: a cell without a centre seen
            gain = weight[cell] * np.maximum((1.0 - spec.refine_tol) * seen[cell]
                                             - f_lo[box], 0.0)
        gain[~np.isfinite(gain)] = np.finfo(float).max  # a cell with no centre seen yet
        prio = np.zeros(lo.shape[0])
        np.maximum.at(prio, box, gain)
        # and the boxes holding the region's smallest bound m down (the ellipse, the
        # trivial bound), the lowest first
        low = np.flatnonzero(f_lo < (1.0 - spec.refine_tol) * float(np.min(f_c)))
        low = low[np.argsort(f_lo[low], kind="stable")[:MIN_SPLIT]]
        prio[low] = np.maximum(prio[low], np.finfo(float).tiny)
        split = np.flatnonzero(prio > 0)
        if split.size == 0:
            stopped_by = "no_refinement"
            break
        room = min(spec.max_boxes - work, spec.max_live - lo.shape[0]) // 2
        if room <= 0:
            stopped_by = "max_boxes" if spec.max_boxes - work < 2 else "max_live"
            break
        # the boxes carrying most of the priority (Doerfler marking), within the budgets
        order = split[np.argsort(-prio[split], kind="stable")]
        cum = np.cumsum(np.minimum(prio[order], 1e300))
        n_mark = int(np.searchsorted(cum, spec.mark_fraction * cum[-1]) + 1)
        split = np.union1d(order[:min(max(n_mark, MIN_SPLIT), room)], low[:room])[:room]
        rounds += 1
        # bisect the chosen boxes along their widest side, weighted by how much that side
        # widens the box's (s, r) ranges
        wid = hi[split] - lo[split]
        ax = np.argmax(wid * (1.0 + SPLIT_ALIGN * (np.abs(u) + _across(lo[split], hi[split],
                                                                       x, u))), axis=1)
        mid = lo[split, ax] + 0.5 * wid[np.arange(split.size), ax]
        lo_a, hi_a = lo[split].copy(), hi[split].copy()
        lo_b, hi_b = lo[split].copy(), hi[split].copy()
        hi_a[np.arange(split.size), ax] = mid
        lo_b[np.arange(split.size), ax] = mid
        new_lo, new_hi = np.concatenate([lo_a, lo_b]), np.concatenate([hi_a, hi_b])
        new_f = proj.enclose(new_lo, new_hi)
        new_c = proj.value(0.5 * (new_lo + new_hi))
        if CHECK_VALUES and np.any(new_f > new_c + 1e-9 * np.abs(new_c)):
            raise RuntimeError(f"{m.name}: an enclosure of the conformal factor lies above its "
                               "value at the box's centre: the enclosure is wrong (a bug)")
        work += new_lo.shape[0]
        rest = np.ones(lo.shape[0], bool)
        rest[split] = False
        lo = np.concatenate([lo[rest], new_lo])
        hi = np.concatenate([hi[rest], new_hi])
        f_lo = np.concatenate([f_lo[rest], new_f])
        f_c = np.concatenate([f_c[rest], np.where(np.isfinite(new_c), new_c, np.inf)])
    t_boxes = time.perf_counter() - t0

    # the verified potential on the (s, r) plane
    t0 = time.perf_counter()
    assert grid is not None
    pot, scale, lp_status, momentum, solves = best_potential(grid, g, m_low, free_dist)
    lp_solves += solves
    t_lp = time.perf_counter() - t0
    # the trivial bound, rounded down: m |y - x|
    x, y, dist = x_full, y_full, full_dist
    trivial = m_low * dist * (1.0 - _SLACK)
    lower = min(max(pot, trivial), upper)
    ratio = lower / upper
    status, message = CertifyStatus.BUDGET_REACHED, ""
    if not math.isfinite(scale):
        status = CertifyStatus.LP_FAILED
        stopped_by = "lp_failed"
        message = f"the potential's cone program failed ({lp_status}): lower is the trivial bound"
    elif 1.0 - ratio <= spec.target_gap:
        status = CertifyStatus.CERTIFIED
    total = time.perf_counter() - t_start
    return ConformalCertifyResult(
        metric=m.name, start=x, goal=y, lower=lower, upper=upper, ratio=ratio,
        gap=1.0 - ratio, trivial=trivial, potential_lower=pot, min_factor=m_low,
        min_factor_seen=float(np.min(f_c)),
        euclidean=dist, ellipse=radius, boxes=int(lo.shape[0]), enclosures=int(work),
        cells=int(np.sum(np.isfinite(g))), rounds=rounds, active_dims=int(active.sum()),
        momentum=momentum, cone_programs=lp_solves, scale=scale,
        lp_status=lp_status, solver_status=solver_status, stopped_by=stopped_by,
        status=status, message=message,
        method=(f"verified piecewise-linear potential on the (s, r) plane of the chord "
                f"({grid.ns} x {grid.nr} cells) plus momentum {momentum:.4g} along the "
                f"{m.dim - int(active.sum())} cyclic coordinates; cell bounds from affine "
                f"enclosures of the conformal factor over {int(lo.shape[0])} boxes "
                f"covering the reachable ellipsoid"),
        spec={k: getattr(spec, k) for k in spec.__dataclass_fields__},
        times={"solve": t_solve, "boxes": t_boxes, "lp": t_lp, "total": total},
        wall_time=total, path=pts)
