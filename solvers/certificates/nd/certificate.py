"""Certified intervals ``lower <= d(start, goal) <= upper`` in 3 and more dimensions.

Lower bound: a verified potential. If ``phi`` is Lipschitz and ``grad phi(z) . v <=
R F(z, v)`` for every ``v`` and almost every ``z`` a path shorter than ``upper`` can reach,
then ``d(start, goal) >= min((phi(goal) - phi(start)) / R, upper)`` (integrate along any
curve; a curve that leaves the region is longer than ``upper``). Here ``phi`` is
piecewise linear on the Delaunay cells of a point cloud graded around the solver's path
(one gradient ``g_T`` per cell), covering the domain's bounding box:

1. the region: a cell is left out when ``m (|start - Z_T| + |Z_T - goal|) > upper``, ``Z_T``
   its box and ``m`` a proven lower bound of ``F(z, v) / |v|`` over the domain
   (`scale_lower_bound`);
2. the LP (cvxpy, Clarabel) maximises ``phi(goal) - phi(start)`` under rows ``g_T . w <=
   Flo(Z_T, w)`` at directions ``w`` of a grid on the cube's surface, ``Flo`` a proven
   lower bound of F over the cell's box (interval enclosure of the metric's own F), rows
   added in rounds where violated (row generation);
3. the verification (`verify`) proves, cell by cell with
   interval arithmetic, the ``R`` for EVERY direction and every point of the cell (branch
   and bound over the cube's surface with a mean-value form in ``v``, enclosures of F and
   of its gradient in ``v``); the boxes it could not close become new rows (cuts) and the
   LP is solved again;
4. cells are refined (edge midpoints added, Delaunay again) where the LP's duals weigh the
   loss ``F(centroid, w) - Flo(Z_T, w)`` most.

The rows only steer the LP; the proof is step 3, whatever the LP solver's tolerance. The
gradient of each cell is computed in float64 with an a-posteriori bound of its error
(residual of the cell's linear system), added to ``g . w`` in step 3. F(z, .) must be
convex (the metrics' ``convex_everywhere``): step 3 needs no convexity, but without it the
bound is that of the convexified metric and the rows' directions would not suffice.

Upper bound: the length of the solver's path with its proven error
(`finsler.Metric.path_length_bounds`), as in `solvers.certify`.

Results are decided by work budgets (cells, rounds, LP rounds, verification depth), never
by the clock: the same input gives the same interval on any machine.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from finsler.domains import as_real
from finsler.errors import InputError
from finsler.metrics.base import Metric
from finsler.status import CertifyStop, LPStatus, Status
from solvers.certificates.domain import domain_constraints, outside_domain
from solvers.certificates.nd.parts import (
    LP_SOLVER,
    Cells,
    LPFailure,
    add_points,
    box_distance,
    build_cells,
    cube_directions,
    edge_midpoints,
    f_lower,
    lowered_f_grad,
    point_cloud,
    reached,
    round_record,
    scale_lower_bound,
    solve_lp,
    verify,
)
from solvers.inputs import SHORT_PAIR, as_metric, is_short_pair
from solvers.result import MeshCertificate
from solvers.status import CertifyStatus

__all__ = ["NDResult", "NDSpec", "certify_nd"]


@dataclass(frozen=True)
class NDSpec:
    """Settings of `certify_nd` (lengths in coordinates). Every budget is a count."""

    h_path: float = 0.08
    """Spacing of the finest lattice, around the solver's path."""
    corridor: float = 0.12
    """Half-width of the band kept at ``h_path`` (doubling per coarser level)."""
    h_far: float = 0.5
    """Spacing of the coarsest lattice (the whole bounding box)."""
    faces: int = 8
    """Grid of the sampled row directions: ``faces`` per side of each cube face."""
    target_gap: float = 1e-2
    """Stop once ``(upper - lower) / upper`` is at most this."""
    max_cells: int = 60000
    """Do not refine beyond this many cells."""
    max_rounds: int = 4
    """Meshes (refinement rounds)."""
    lp_rounds: int = 16
    """LP solves per mesh (row generation and verification cuts)."""
    verify_tol: float = 2e-3
    """The verification tries to prove ``R = (1 + verify_tol) x`` the LP's largest ratio."""
    verify_depth: int = 9
    """Branch-and-bound levels of the verification."""
    mark_fraction: float = 0.7
    """Refine the cells carrying this fraction of the dual-weighted loss."""
    segments: int | None = None
    """Segments of the solver's path (default: 4 x the task's)."""
    seed: int = 0
    """Seed of the jitter of the point cloud (reproducible)."""
    element: str = "P1"
    """The potential: ``"P1"`` (piecewise linear), ``"P2"`` (piecewise quadratic: loses
    second order in the cell's width instead of first; F must have affine rules, see
    `solvers.certificates.nd.p2`) or ``"auto"`` (P2 where F allows it)."""

    def __post_init__(self) -> None:
        for name in ("h_path", "corridor", "h_far", "target_gap", "verify_tol",
                     "mark_fraction"):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not (
                    math.isfinite(val) and val > 0):
                raise InputError(f"NDSpec.{name} must be positive and finite, got {val!r}")
        if self.element not in ("P1", "P2", "auto"):
            raise InputError(f"NDSpec.element must be 'P1', 'P2' or 'auto', got "
                             f"{self.element!r}")
        if self.h_path > self.h_far:
            raise InputError(f"NDSpec.h_path ({self.h_path}) must be <= h_far ({self.h_far})")
        for name, low in (("faces", 2), ("max_cells", 10), ("max_rounds", 1),
                          ("lp_rounds", 1), ("verify_depth", 1)):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < low:
                raise InputError(f"NDSpec.{name} must be an integer >= {low}, got {val!r}")

    @classmethod
    def preset(cls, name: str) -> NDSpec:
        """``"coarse"`` (fast, gap ~ a few 1e-2), ``"default"``, ``"fine"`` or ``"p2"`` (the
        coarse mesh with the P2 element: gap 1e-2 in minutes where F allows it)."""
        presets = {
            "coarse": cls(h_path=0.15, h_far=0.6, faces=6, target_gap=5e-2, max_rounds=2),
            "default": cls(),
            "fine": cls(h_path=0.05, faces=10, target_gap=5e-3, max_rounds=6,
                        max_cells=150000),
            "p2": cls(h_path=0.15, h_far=0.6, faces=6, target_gap=1e-2, max_rounds=2,
                      lp_rounds=40, verify_depth=40, element="P2"),
        }
        if name not in presets:
            raise InputError(f"unknown mesh preset {name!r}; choose one of "
                             f"{', '.join(presets)}")
        return presets[name]


@dataclass
class NDResult(MeshCertificate):
    """A certified interval from `certify_nd`. ``gap = (upper - lower) / upper``.
    ``rigour`` says what each part rests on; ``rounds`` lists per mesh the cells, LP rows,
    the LP's value, the verified ``R`` and the bound; ``status`` is in the toolkit's family
    ([`solvers.CertifyStatus`][solvers.CertifyStatus]): ``certified`` (target gap reached),
    ``budget_reached`` (a work budget ended it), ``lp_failed``."""

    metric: str
    start: np.ndarray
    goal: np.ndarray
    lower: float
    upper: float
    length: float
    length_error: float
    gap: float
    cells: int
    relevant_cells: int
    vertices: int
    directions: int
    lp_rows: int
    lp_status: LPStatus
    lp_solver: str
    verified_ratio: float
    scale_bound: float
    solver_status: Status
    rigour: dict[str, str]
    mesh: dict[str, Any]
    times: dict[str, float]
    rounds: list[dict[str, Any]] = field(default_factory=list)
    path: np.ndarray | None = None
    stopped_by: CertifyStop = CertifyStop.TARGET_GAP
    status: CertifyStatus = CertifyStatus.CERTIFIED
    message: str = ""


RIGOUR = {
    "upper": "proven: path length with interval bound of the quadrature error "
             "(Metric.path_length_bounds)",
    "lower": "proven: piecewise-linear potential verified on every cell of the region by "
             "interval arithmetic (enclosures of F and grad_v F, outward rounding, branch "
             "and bound over all directions), gradients with a-posteriori error bounds",
    "region": "proven: cells left out only where m (|start - Z| + |Z - goal|) > upper, m an "
              "interval lower bound of F(z, v)/|v| on the domain's bounding box",
}


def _check(m: Metric, start: Any, goal: Any) -> tuple[np.ndarray, np.ndarray]:
    if not m.convex_everywhere:
        raise InputError(f"certify in {m.dim}-D needs F(x, .) convex on the whole domain; "
                         f"{m.name} is not ({m.convexity_note})")
    lo, hi = m.domain.bounds()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise InputError(f"certify needs a bounded domain; {m.name} has {m.domain.describe()}")
    s = m.domain.check(np.asarray(start, float), "start")[0]
    g = m.domain.check(np.asarray(goal, float), "goal")[0]
    if np.array_equal(s, g):
        raise InputError("start equals goal: the distance is 0, nothing to certify")
    if is_short_pair(m, s, g):
        raise InputError(f"start and goal are {float(np.max(np.abs(g - s))):.3g} apart, below "
                         f"{SHORT_PAIR:g} x the domain's size: too close to certify")
    return s, g


def certify_nd(metric: Metric | str, start: Any, goal: Any, mesh: NDSpec | str | None = None,
               *, path: Any = None) -> NDResult:
    """Certified interval ``lower <= d(start, goal) <= upper`` on a metric of any dimension
    whose ``F(x, .)`` is convex (see the module docstring). ``mesh``: an `NDSpec` or
    a preset name. ``path`` ``(m+1, dim)``: a curve from start to goal for the upper bound
    (default: `solvers.solve_geodesic`). Raises `InputError` for bad input."""
    t_start = time.perf_counter()
    m = as_metric(metric)
    spec = NDSpec.preset(mesh) if isinstance(mesh, str) else (mesh or NDSpec())
    if not isinstance(spec, NDSpec):
        raise InputError(f"mesh must be an NDSpec or a preset name, got {type(mesh).__name__}")
    s, g = _check(m, start, goal)
    element = spec.element
    if element != "P1":
        from solvers.certificates.nd.p2 import affine_missing

        missing = affine_missing(m)
        if element == "P2" and missing is not None:
            raise InputError(f"the P2 element needs affine rules for every operation of "
                             f"{m.name}'s F ({missing}); use element='P1'")
        element = "P2" if missing is None else "P1"
    n = m.dim
    blo, bhi = (np.asarray(b, float) for b in m.domain.bounds())

    t0 = time.perf_counter()
    if path is None:
        from solvers.geodesic.solve import solve_geodesic

        segs = spec.segments if spec.segments is not None else 4 * m.task.segments
        sol = solve_geodesic(m, s, g, segs)
        pts = np.asarray(sol.points, float)
        solver_status = sol.status.label
    else:
        pts = np.array(as_real(path, "path", "a real numeric array of shape (n+1, dim)"))
        if pts.ndim != 2 or pts.shape[1] != n or pts.shape[0] < 2:
            raise InputError(f"path must have shape (m+1, {n}), got {pts.shape}")
        if not (np.allclose(pts[0], s, rtol=0, atol=1e-12)
                and np.allclose(pts[-1], g, rtol=0, atol=1e-12)):
            raise InputError("path must run from start to goal")
        m.domain.check(pts, "path")
        solver_status = "given"
    est = m.path_length_error(pts)
    upper = float(m.path_length_bounds(pts).upper)
    t_solve = time.perf_counter() - t0
    # the LP's box on potential values (any finite size keeps the bound sound: the
    # verification, not the box, proves it); the quadrature estimate where the length has
    # no finite proven bound (an infinite box made the LP fail: lower stayed 0)
    cap = upper if math.isfinite(upper) else float(est.value) + abs(float(est.error))

    f_fn, fg_fn = lowered_f_grad(m)
    cons = domain_constraints(m)  # cells that miss the domain hold no path
    t0 = time.perf_counter()
    scale = scale_lower_bound(f_fn, blo, bhi)
    rng = np.random.default_rng(spec.seed)
    points = point_cloud(blo, bhi, pts, spec.h_path, spec.corridor, spec.h_far, rng)
    points = np.concatenate([points, s[None], g[None]])
    dirs = cube_directions(n, spec.faces)
    t_mesh = time.perf_counter() - t0
    times = {"solve": t_solve, "mesh": t_mesh, "bounds": 0.0, "lp": 0.0, "verify": 0.0}
    rounds: list[dict[str, Any]] = []
    best: dict[str, Any] = {"lower": 0.0, "R": float("nan"), "lp_status": "not_solved",
                            "rows": 0, "cells": 0, "rel": 0, "vertices": 0}
    stopped_by, status, message = "max_rounds", CertifyStatus.BUDGET_REACHED, ""
    for _ in range(spec.max_rounds if element == "P1" else 0):
        t0 = time.perf_counter()
        cells = build_cells(points, blo, bhi, rng, spec.h_path)
        points = cells.points
        dist = box_distance(s, cells.zlo, cells.zhi) + box_distance(g, cells.zlo, cells.zhi)
        rel = np.flatnonzero(cells.inside & ~cells.flat & ~(scale * dist > upper * (1 + 1e-9))
                             & ~outside_domain(cons, cells.zlo, cells.zhi))
        zlo, zhi = cells.zlo[rel], cells.zhi[rel]
        times["mesh"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        nr, nd = rel.size, dirs.shape[0]
        b = f_lower(f_fn, np.repeat(zlo, nd, 0), np.repeat(zhi, nd, 0),
                    np.tile(dirs, (nr, 1)), np.tile(dirs, (nr, 1))).reshape(nr, nd)
        b_lp = np.maximum(b, 1e-9 * float(np.max(b[np.isfinite(b)], initial=1.0)))
        times["bounds"] += time.perf_counter() - t0
        s_w, g_w = cells.weights(s), cells.weights(g)
        active = np.zeros((nr, nd), bool)
        active[:, np.flatnonzero(np.sum(np.abs(dirs), axis=1) == 1.0)] = True  # face centres
        active[:, np.flatnonzero(np.all(np.abs(dirs) == 1.0, axis=1))] = True  # corners
        extra_c, extra_w, extra_b = (np.zeros(0, np.int64), np.zeros((0, n)), np.zeros(0))
        result: dict[str, Any] | None = None
        failure = None
        for _lp in range(spec.lp_rounds):
            rc, rd = np.nonzero(active)
            rows_c = np.concatenate([rc, extra_c])
            rows_w = np.concatenate([dirs[rd], extra_w])
            rows_b = np.concatenate([b_lp[rc, rd], extra_b])
            t0 = time.perf_counter()
            try:
                phi, duals, lp_status = solve_lp(cells, rel, rows_c, rows_w, rows_b, s_w, g_w,
                                                 10.0 * cap)
            except LPFailure as err:
                failure = str(err)
                break
            times["lp"] += time.perf_counter() - t0
            grad, gerr = cells.gradients(phi)
            gr = grad[rel]
            ratio = (gr @ dirs.T) / b_lp
            viol = ratio > 1.0 + 1e-7
            viol &= ~active
            if np.any(viol):  # row generation: the 8 worst sampled directions of each cell
                order = np.argsort(-np.where(viol, ratio, -np.inf), axis=1)[:, :8]
                take = np.take_along_axis(viol, order, 1)
                rr = np.repeat(np.arange(nr), order.shape[1])[take.ravel()]
                active[rr, order.ravel()[take.ravel()]] = True
                continue
            r_lp = max(float(np.max(ratio)), 1e-300)
            if extra_c.size:
                r_lp = max(r_lp, float(np.max(np.einsum("ij,ij->i", gr[extra_c], extra_w)
                                              / extra_b)))
            t0 = time.perf_counter()
            ver = verify(fg_fn, zlo, zhi, gr, gerr[rel], r_lp, spec.verify_tol,
                         max_depth=spec.verify_depth)
            times["verify"] += time.perf_counter() - t0
            dphi = float(g_w[1] @ phi[g_w[0]] - s_w[1] @ phi[s_w[0]])
            lower = min(dphi / ver["R"] * (1 - 1e-12), upper) if ver["R"] > 0 else 0.0
            result = {"lower": max(lower, 0.0), "R": ver["R"], "lp_status": lp_status,
                      "rows": int(rows_b.size), "cells": cells.n_cells, "rel": int(nr),
                      "vertices": int(cells.points.shape[0]), "dphi": dphi, "ver": ver,
                      "duals": duals, "rows_c": rows_c, "rows_w": rows_w, "rows_b": rows_b}
            if lower > best["lower"]:
                best = result
            cc, cw, _ = ver["cuts"]
            if (reached(upper, best["lower"], spec.target_gap) or not cc.size
                    or ver["R"] <= r_lp * (1 + 2 * spec.verify_tol)):
                break
            # cuts: the directions the verification could not close become rows
            fb = f_lower(f_fn, zlo[cc], zhi[cc], cw, cw)
            ok = fb > 0
            extra_c = np.concatenate([extra_c, cc[ok]])
            extra_w = np.concatenate([extra_w, cw[ok]])
            extra_b = np.concatenate([extra_b, fb[ok]])
        if failure is not None:
            stopped_by, status, message = "lp_failed", CertifyStatus.LP_FAILED, failure
            break
        if result is None:
            stopped_by = "lp_rounds"
            continue
        rounds.append(round_record(result, upper, t_start))
        if reached(upper, best["lower"], spec.target_gap):
            stopped_by, status = "target_gap", CertifyStatus.CERTIFIED
            break
        marked = _mark(cells, rel, result, f_fn, spec.mark_fraction)
        new = edge_midpoints(cells, marked, rng)
        if cells.n_cells + 6 * new.shape[0] > spec.max_cells:
            stopped_by = "max_cells"
            break
        points = add_points(cells.points, new)
    if element == "P2":
        from solvers.certificates.nd.p2 import run_p2

        run = run_p2(m, f_fn, s, g, upper, cap, spec, blo, bhi, scale, rng, points, dirs,
                     times, t_start)
        best, rounds = run["best"], run["rounds"]
        stopped_by, status, message = run["stopped_by"], run["status"], run["message"]
    lower = float(best["lower"])
    if not math.isfinite(upper):
        message = ("the path's length has no finite proven bound (path_length_bounds: its "
                   "second derivative along the path is not enclosed, e.g. at kinks of a "
                   "non-smooth F); length +- length_error is the quadrature estimate")
    times["total"] = time.perf_counter() - t_start
    return NDResult(
        metric=m.name, start=s, goal=g, lower=lower, upper=upper, length=float(est.value),
        length_error=float(est.error), gap=(upper - lower) / upper, cells=int(best["cells"]),
        relevant_cells=int(best["rel"]), vertices=int(best["vertices"]),
        directions=int(dirs.shape[0]), lp_rows=int(best["rows"]), lp_status=best["lp_status"],
        lp_solver=LP_SOLVER, verified_ratio=float(best["R"]), scale_bound=float(scale),
        solver_status=solver_status, rigour=dict(RIGOUR),
        mesh={**asdict(spec), "element": f"{element} (Delaunay)"}, times=times, rounds=rounds,
        path=pts, stopped_by=stopped_by, status=status, message=message)


def _mark(cells: Cells, rel: np.ndarray, result: dict[str, Any], f_fn: Any,
          fraction: float) -> np.ndarray:
    """Cells (indices into ``cells``) carrying ``fraction`` of the dual-weighted loss
    ``y_r (F(centroid, w) - b_r)``."""
    y = result["duals"]
    keep = y > 1e-9 * max(float(y.max(initial=0.0)), 1e-300)
    rc, rw, rb = result["rows_c"][keep], result["rows_w"][keep], result["rows_b"][keep]
    (fc,) = f_fn(cells.centroid[rel[rc]], rw)
    loss = y[keep] * np.maximum(np.asarray(fc, float).reshape(-1) - rb, 0.0)
    weight = np.bincount(rc, weights=loss, minlength=rel.size)
    order = np.argsort(-weight)
    cum = np.cumsum(weight[order])
    if cum.size == 0 or cum[-1] <= 0:
        return rel[order[: max(1, rel.size // 10)]]
    k = int(np.searchsorted(cum, fraction * cum[-1]) + 1)
    return rel[order[:k]]
