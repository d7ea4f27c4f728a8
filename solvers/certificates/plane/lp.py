"""The linear programs of the 2-D certificate
(`solvers.certificates.plane.certificate.certify_plane`): the best P2 potential on a mesh.

Given the rows ``grad phi_T(z_m) . v_k <= b[T, m, k]`` that module proves (values of F minus the
second-order corrections), `_solve_lp` maximises ``phi(goal) - phi(start)`` with
cvxpy (Clarabel) in rounds: vertices away from the path are kept inside inner polygons of
their rows' sets (`_Rays`, never violated), vertices near it get the sampled rows
themselves, grown by the violated directions; every round's potential is checked against
ALL rows and scaled down by its largest row ratio, so the bound it gives is valid whatever
the LP solver's tolerance. `_initial_modes` chooses the first exact vertices and
directions of a mesh (near the path, or inherited from the previous mesh's LP).

A failed LP raises `LPFailure`, which the certificate turns into
`solvers.CertifyStatus.LP_FAILED`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from finsler.errors import short
from solvers.certificates.plane.mesh import _distance_to_path, _Mesh
from solvers.certificates.plane.repair import repair

_LOG = logging.getLogger(__name__)

#: cvxpy solver of the LPs (Clarabel: an interior-point method, far faster here than HiGHS).
LP_SOLVER = "CLARABEL"
#: Clarabel settings of the LPs. Every potential is checked against ALL rows and scaled
#: (its bound never depends on the LP's accuracy), so 1e-5 instead of Clarabel's 1e-8 is
#: enough; with `TIGHT_DUAL` at 1e-4 the rounds are unchanged (with 1e-7 a loose
#: solve promotes many more vertices).
#: Iterative refinement of Clarabel's linear solves off: it doubled the time of each
#: iteration on the fine mesh's LPs (140k rows: 6.1 s against 3.1 s) for the same iterations
#: and objective to 1e-7.
LP_OPTIONS: dict[str, Any] = {"tol_gap_abs": 1e-5, "tol_gap_rel": 1e-5, "tol_feas": 1e-5,
                              "tol_ktratio": 1e-3, "iterative_refinement_enable": False}
#: Rows whose dual exceeds this fraction of the largest dual count as tight (refined).
#: 1e-4: the duals of an interior-point solve to `LP_OPTIONS`' tolerance.
TIGHT_DUAL = 1e-4
#: Evenly spaced rays of the inner polygons that keep the vertices away from the path safe.
INITIAL_DIRECTIONS = 8
#: Directions an exact vertex starts with around the path's (or a tight edge's) direction:
#: this fraction of the K sampled directions on each side (violated ones are added later).
WINDOW_FRACTION = 1 / 64
#: ``settle``: the rounds stop once the LP's value rises by less than this fraction of
#: ``target * upper`` while still short of the target.
SETTLE = 0.1
#: Rows added after a round at an exact vertex: every direction whose row the potential
#: fills to more than ``1 - near`` (``near = min(NEAR_TIGHT, NEAR_PER_TARGET * target)``),
#: not only the violated ones, and ``WORST_WINDOW`` directions each side of its worst row;
#: a promoted vertex also gets its near-tight directions. The gradient's next position is
#: near those rows: on Matsumoto tuning pairs a mesh's rounds fall from ~6 to 2-3.
NEAR_TIGHT = 0.06
#: ``settle``: a mesh short of the target stops after this many rounds in any case (its
#: duals already say where to refine).
SETTLE_ROUNDS = 3
NEAR_PER_TARGET = 6.0
#: A refined mesh inherits of its host's rows only the 16 evenly spaced directions and
#: those (with one neighbour each side) the host's best potential filled to more than
#: ``1 - near``, not every row the host's rounds ever added.
INHERIT_NEAR_ONLY = True
#: Mend a round's potential that would reach the target but for a few broken rows
#: (`solvers.certificates.plane.repair`) instead of solving another round.
REPAIR = True
#: Evenly spaced directions an exact vertex always has (first mesh, promotion, inheritance).
COARSE_DIRECTIONS = 16
#: A promoted vertex gets this many windows (`_window`) of directions each side of
#: its tight facet's normal (3: its gradient moves out along that normal, and some meshes
#: need one LP round fewer than with 1).
PROMOTE_WINDOW = 3
WORST_WINDOW = 2


class LPFailure(RuntimeError):
    """The LP solver failed on one round (turned into `CertifyStatus.LP_FAILED`)."""


def _window(k: int) -> int:
    return max(1, int(k * WINDOW_FRACTION))


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
    away from the path; see `_solve_lp`).
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
              max_iter: int = 30, settle: bool = False,
              tighten: Callable[[np.ndarray, np.ndarray], None] | None = None
              ) -> dict[str, Any]:
    """Maximise ``phi[g] - phi[s]`` under the rows ``(T, 3, K)`` (``g . v_k <= b``) at every
    triangle vertex, in rounds.

    A vertex is either SAFE: its gradient is kept in the inner polygon of 8 rays
    (`_Rays`), inside the rows' set, so it can never violate a row; or EXACT: it
    has sampled rows ``g . v_k <= b_k`` directly, a set of directions grown in rounds by the
    near-tight ones (ratio above ``1 - near``, `NEAR_TIGHT`) and ``WORST_WINDOW``
    each side of a violated vertex's worst row. A safe vertex whose polygon edge is tight
    (positive dual) becomes exact, with the directions near that edge's normal, 16 evenly
    spaced ones and its near-tight ones. Each round's
    potential, divided by its largest row ratio over ALL rows, is a valid potential; the
    best one is returned. Stops when no vertex changes mode and no row is violated beyond
    ``0.1 target``, when a potential certifies ``target``, or after ``max_iter`` rounds.
    ``start``: ``exact`` ``(T*3,)`` bool and ``active`` ``(T*3, K)`` bool, the first
    exact vertices and their directions. ``settle``: also stop (``"settled": True``) once
    the LP's value (before scaling) rose by less than ``SETTLE`` times ``target * upper``
    in a round yet stays below ``(1 - target) upper``: this mesh cannot reach the target,
    and the rounds that would remove the last violations only serve a bound the refined
    mesh will beat (the duals already say where to refine).
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
    coarse[:: max(1, k // COARSE_DIRECTIONS)] = True
    near = min(NEAR_TIGHT, NEAR_PER_TARGET * target)
    best: dict[str, Any] = {"lower": -np.inf}
    n_iter = 0
    value_before = -np.inf
    settled = False
    lp_seconds = 0.0
    while n_iter < max_iter:
        n_iter += 1
        safe_rows = ~exact[rays.vid]
        s_vid = rays.vid[safe_rows]
        s_normal, s_rhs = safe_normal[safe_rows], safe_rhs[safe_rows]
        e_vid, e_k = np.nonzero(active & exact[:, None])
        if tighten is not None:  # the exact rows' bounds, direction by direction
            tighten(e_vid // 3, e_k)
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
                prob.solve(solver=LP_SOLVER, **LP_OPTIONS)
        except cp.error.SolverError as err:
            raise LPFailure(f"the LP solver failed: {short(str(err))}") from err
        lp_seconds += time.perf_counter() - t0
        status = str(prob.status)
        if x.value is None:
            raise LPFailure(f"the LP ended with status {status}")
        phi = np.asarray(x.value, float)
        duals = np.maximum(np.asarray(cons[0].dual_value, float), 0.0)
        slope = np.einsum("vi,ki->vk", np.einsum("vid,vd->vi", gradc, phi[dofs]), dirs)
        ratio = slope / b_flat
        if tighten is not None:  # the rows the potential (nearly) fills, direction by direction
            t_vid, t_k = np.nonzero(ratio > 1.0 - near)
            tighten(t_vid // 3, t_k)
            ratio = slope / b_flat
        ratio_max = float(np.max(ratio))
        scale = max(ratio_max, 1.0) * (1.0 + 1e-12)
        lower = float(phi[g_idx] - phi[s_idx]) / scale
        _LOG.debug("LP rows %d (%d exact vertices) %.2f s: value %.8f, max row ratio %.6f "
                   "-> bound %.8f", rhs.size, int(exact.sum()), time.perf_counter() - t0,
                   phi[g_idx] - phi[s_idx], ratio_max, lower)
        kept = (phi, ratio_max, scale)  # the potential the bound is of (maybe repaired)
        if REPAIR and upper - lower > target * upper and (
                phi[g_idx] - phi[s_idx] >= (1.0 - target) * upper):
            # the value would reach the target but for a few broken rows: mend them locally
            t1 = time.perf_counter()
            fixed = repair(mesh, b_flat, dirs, phi, ratio, (s_idx, g_idx))
            if fixed is not None:
                r_max = float(np.max(np.einsum("vi,ki->vk", np.einsum(
                    "vid,vd->vi", gradc, fixed[dofs]), dirs) / b_flat))
                sc = max(r_max, 1.0) * (1.0 + 1e-12)
                low = float(fixed[g_idx] - fixed[s_idx]) / sc
                _LOG.debug("repaired in %.2f s: max row ratio %.6f -> bound %.8f",
                           time.perf_counter() - t1, r_max, low)
                if low > lower:
                    kept, lower = (fixed, r_max, sc), low
        if lower > best["lower"]:
            ang = np.arctan2(normal[:, 1], normal[:, 0])
            kk = np.mod(np.rint(ang / (2 * np.pi / k)).astype(np.int64), k)
            best = {"phi": (kept[0] - kept[0][s_idx]) / kept[2], "lower": lower,
                    "status": status, "rows": np.stack([vid // 3, vid % 3, kk], 1),
                    "duals": duals, "n_rows": int(rhs.size), "ratio": kept[1],
                    "near": ratio > 1.0 - near}
        if upper - lower <= target * upper:
            break
        value = float(phi[g_idx] - phi[s_idx])
        if settle and value < (1.0 - target) * upper and (
                value - value_before < SETTLE * target * upper or n_iter >= SETTLE_ROUNDS):
            settled = True
            break
        value_before = value
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
            for off in range(-PROMOTE_WINDOW * _window(k), PROMOTE_WINDOW * _window(k) + 1):
                active[pv, (kc + off) % k] = True
            active[promote] |= coarse | (ratio[promote] > 1.0 - near)
            exact |= promote
        viol = exact[:, None] & (ratio > 1.0 - near) & ~active
        worst = np.argmax(np.where(exact[:, None], ratio, -np.inf), axis=1)
        bad = exact & (ratio[np.arange(nv), worst] > 1.0 + 0.1 * target)
        for off in range(-WORST_WINDOW, WORST_WINDOW + 1):
            active[np.flatnonzero(bad), (worst[bad] + off) % k] = True
        active |= viol
        if not promote.any() and not bad.any():
            break
    best.update({"iterations": n_iter, "lp_seconds": lp_seconds, "solver": LP_SOLVER,
                 "exact": exact, "active": active, "settled": settled})
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
        act[:, :: max(1, k // COARSE_DIRECTIONS)] = True
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
        keep = lp["active"] & lp["exact"][:, None]
        if INHERIT_NEAR_ONLY and "near" in lp:
            near = lp["near"]
            coarse = np.zeros(k, bool)
            coarse[:: max(1, k // COARSE_DIRECTIONS)] = True
            keep &= near | np.roll(near, 1, axis=1) | np.roll(near, -1, axis=1) | coarse
        old_active = keep.reshape(-1, 3, k).any(axis=1)
        new_exact = np.zeros(mesh.n_tri, bool)
        new_exact[ok] = old_exact[host[ok]]
        exact = np.repeat(new_exact, 3)
        act = np.zeros((mesh.n_tri, k), bool)
        act[ok] = old_active[host[ok]]
        active = np.repeat(act, 3, axis=0)
    return {"exact": exact, "active": active}
