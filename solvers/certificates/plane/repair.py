"""Local repair of an LP round's potential (`solvers.certificates.plane.lp._solve_lp`).

A round's LP sees only some of the sampled rows ``grad phi_T(z_m) . v_k <= b[T, m, k]``; its
potential may break a few unsampled ones, at a few triangle vertices, and the round's bound
is then the LP's value divided by the largest row ratio: one vertex at ratio 1.03 costs 3 %
of the bound and another LP round (on Matsumoto pairs the last rounds of a mesh fix 1-20
such vertices while the value no longer moves). `repair` instead moves only the
unknowns of the triangles that break a row (start and goal held, so the value is kept) to
minimise the largest ratio ``tau`` over EVERY row of the triangles those unknowns touch
(all K directions at their three vertices), a small LP (HiGHS through scipy). The other
rows do not involve the moved unknowns and keep their ratios. The caller checks the
repaired potential against ALL rows again and scales it by its largest ratio, as any
round's potential: the bound is valid whatever this LP returns.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Repair only when at most this many triangles break a row (larger LPs: not worth it).
REPAIR_MAX_TRIANGLES = 40
#: Where moving the broken triangles' own unknowns leaves a ratio above 1, also move those
#: of the triangles around them, this many rings.
REPAIR_RINGS = 1
#: Passes of the repair (each moves every unknown by at most the room its dropped rows
#: leave, so a large break may take more than one).
REPAIR_PASSES = 3
#: The repair LP keeps the rows the potential fills beyond this fraction (the others are
#: far from binding for a small move; a move that breaks one only weakens the bound,
#: which the caller's check of all rows catches).
REPAIR_KEEP = 0.2


def repair(mesh: Any, b_flat: np.ndarray, dirs: np.ndarray, phi: np.ndarray,
           ratio: np.ndarray, fixed: tuple[int, ...]) -> np.ndarray | None:
    """A potential equal to ``phi`` except on the unknowns of the triangles whose rows
    ``ratio`` ``(3 T, K)`` exceed 1 (not the unknowns ``fixed``), chosen to minimise the
    largest row ratio of the triangles they touch, in up to `REPAIR_PASSES` passes
    (each from the last one's potential and its broken rows); None if nothing breaks a
    row, too many triangles do (`REPAIR_MAX_TRIANGLES`) or the first LP fails."""
    out = None
    worst = float(ratio.max())
    for _ in range(REPAIR_PASSES):
        bad_tri = np.unique(np.flatnonzero(ratio.max(axis=1) > 1.0) // 3)
        if bad_tri.size == 0 or bad_tri.size > REPAIR_MAX_TRIANGLES:
            break
        cur = phi if out is None else out
        for ring in range(REPAIR_RINGS + 1):
            if ring:  # one ring more: every triangle sharing an unknown with those
                bad_tri = np.flatnonzero(np.isin(mesh.dofs, mesh.dofs[bad_tri]).any(axis=1))
            got = _mend(mesh, b_flat, dirs, cur, bad_tri, fixed)
            if got is None:
                break
            cur, tau = got
            if tau <= 1.0:
                break
        grads = np.einsum("vid,vd->vi", mesh.grad.reshape(-1, 2, 6),
                          cur[np.repeat(mesh.dofs, 3, axis=0)])
        ratio = (grads @ dirs.T) / b_flat
        if float(ratio.max()) >= worst:
            break
        out, worst = cur, float(ratio.max())
        if worst <= 1.0:
            break
    return out


def _mend(mesh: Any, b_flat: np.ndarray, dirs: np.ndarray, phi: np.ndarray,
          bad_tri: np.ndarray, fixed: tuple[int, ...]) -> tuple[np.ndarray, float] | None:
    """`repair` moving the unknowns of the triangles ``bad_tri`` -> (the potential,
    its largest ratio on the rows touched), None if there is nothing to move or the LP
    fails."""
    from scipy.optimize import linprog
    from scipy.sparse import csr_matrix

    free = np.setdiff1d(np.unique(mesh.dofs[bad_tri]), np.asarray(fixed, np.int64))
    if free.size == 0:
        return None
    col = np.full(mesh.n_dofs, -1, np.int64)
    col[free] = np.arange(free.size)
    touched = np.flatnonzero((col[mesh.dofs] >= 0).any(axis=1))  # triangles (A,)
    vid = (3 * touched[:, None] + np.arange(3)).reshape(-1)  # their vertices (3 A,)
    tdofs = np.repeat(mesh.dofs[touched], 3, axis=0)  # (3 A, 6)
    grad = mesh.grad.reshape(-1, 2, 6)[vid]  # (3 A, 2, 6)
    coef = np.einsum("ki,vij->vkj", dirs, grad)  # row (v, k) on local unknown j
    c_free = col[tdofs]  # (3 A, 6), -1 where held
    held = np.where(c_free < 0, phi[tdofs], 0.0)
    const = np.einsum("vkj,vj->vk", coef, held)  # (3 A, K)
    b = b_flat[vid]  # (3 A, K), > 0
    # only the rows the potential fills beyond REPAIR_KEEP (the caller checks all rows)
    now = np.einsum("vkj,vj->vk", coef, phi[tdofs]) / b
    rv, rk = np.nonzero(now > REPAIR_KEEP)
    n_rows = rv.size
    coef_r = coef[rv, rk]  # (R, 6)
    cf = c_free[rv]  # (R, 6)
    rr, jj = np.nonzero(cf >= 0)
    # coef . x - tau b <= -const
    a_ub = csr_matrix((np.concatenate([coef_r[rr, jj], -b[rv, rk]]),
                       (np.concatenate([rr, np.arange(n_rows)]),
                        np.concatenate([cf[rr, jj], np.full(n_rows, free.size)]))),
                      shape=(n_rows, free.size + 1))
    # moves |dx_j| <= delta_j keep every dropped row below 1: a dropped row r with room
    # (1 - now_r) b_r and sum_j |coef_rj| = reach_r over its free unknowns changes by at
    # most sum_j |coef_rj| delta_j <= room_r if every delta_j <= room_r / reach_r
    moving = (c_free >= 0).astype(float)
    reach = np.einsum("vkj,vj->vk", np.abs(coef), moving)
    with np.errstate(divide="ignore"):
        room = np.where((now <= REPAIR_KEEP) & (reach > 0), (1.0 - now) * b / reach, np.inf)
    per_vertex = room.min(axis=1)  # (3 A,): the tightest dropped row at each vertex
    delta = np.full(free.size, np.inf)
    has = c_free >= 0
    np.minimum.at(delta, c_free[has], np.broadcast_to(per_vertex[:, None], has.shape)[has])
    delta = 0.5 * delta  # margin for the rounding of the rows' float64 evaluation
    cost = np.zeros(free.size + 1)
    cost[-1] = 1.0
    bounds = np.stack([np.append(phi[free] - delta, -np.inf),
                       np.append(phi[free] + delta, np.inf)], 1)
    res = linprog(cost, A_ub=a_ub, b_ub=-const[rv, rk], bounds=bounds, method="highs")
    if res.status != 0 or res.x is None:
        return None
    out = phi.copy()
    out[free] = res.x[:-1]
    return out, float(res.x[-1])
