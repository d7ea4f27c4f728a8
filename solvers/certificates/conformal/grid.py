"""The plane step of `solvers.certificates.conformal.certificate`: a verified piecewise-linear
potential on a grid of ``(s, r)`` cells (``s`` along the chord, ``r`` the distance from its line).

Given a lower bound ``g`` of the conformal factor per cell, `potential` maximises
``Phi(goal) - Phi(start)`` subject to ``|grad Phi| <= g`` on every triangle (a second-order
cone program through cvxpy), checks every gradient of the float64 solution exactly and
divides ``Phi`` by the largest ratio, so the bound never rests on the solver's tolerance;
`best_potential` adds the free (cyclic) coordinates' momentum (Clairaut). See
`solvers.certificates.conformal.certificate` for why ``Phi(goal) - Phi(start)`` bounds the distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CONE_SOLVERS", "MOMENTA", "SLACK", "Grid", "best_potential", "cell_bounds", "expand",
           "potential", "reduced", "triangles"]

#: Relative widening of float64 geometry (s, r, distances) against rounding.
SLACK = 1e-9
#: cvxpy solvers of the potential's cone program, tried in turn.
CONE_SOLVERS = ("CLARABEL", "SCS")
#: Momenta tried for the free coordinates, as fractions of the smallest factor ``m``.
MOMENTA = (0.0, 0.3, 0.5, 0.65, 0.8, 0.9, 0.97)
_U = 2.0**-53


@dataclass
class Grid:
    """``(s, r)`` cells: s nodes ``s0 + i hs`` (0 and ``dist`` are nodes), r nodes
    ``j hr``."""

    s0: float
    hs: float
    ns: int
    hr: float
    nr: int
    i_start: int
    i_goal: int

    @classmethod
    def make(cls, dist: float, radius: float, s_cells: int, r_cells: int) -> Grid:
        hs = dist / s_cells
        half_minor = 0.5 * math.sqrt(max(radius * radius - dist * dist, 0.0))
        extra = max(0.5 * (radius - dist), 0.0) * (1.0 + SLACK)
        k = math.ceil(extra / hs) + 1
        # (a thin ellipse keeps cells no flatter than 1 : 4, for the cone program's scaling)
        hr = max(half_minor * (1.0 + SLACK) / r_cells, 0.25 * hs)
        return cls(s0=-k * hs, hs=hs, ns=s_cells + 2 * k, hr=hr, nr=r_cells,
                   i_start=k, i_goal=k + s_cells)

    def ranges(self, s_lo: np.ndarray, s_hi: np.ndarray, r_lo: np.ndarray,
               r_hi: np.ndarray) -> tuple[np.ndarray, ...]:
        """Index ranges (inclusive, clipped to the grid) of the cells the rectangles
        meet."""
        def idx(v: np.ndarray, origin: float, h: float, n: int) -> np.ndarray:
            with np.errstate(invalid="ignore", over="ignore"):
                k = np.floor((v - origin) / h)
            return np.clip(np.nan_to_num(k, nan=0.0), 0, n - 1).astype(np.int64)
        return (idx(s_lo, self.s0, self.hs, self.ns), idx(s_hi, self.s0, self.hs, self.ns),
                idx(r_lo, 0.0, self.hr, self.nr), idx(r_hi, 0.0, self.hr, self.nr))


def expand(i0: np.ndarray, i1: np.ndarray, j0: np.ndarray, j1: np.ndarray, nr: int
            ) -> tuple[np.ndarray, np.ndarray]:
    """(box, flat cell) pairs of every cell of every box's index range."""
    ni, nj = i1 - i0 + 1, j1 - j0 + 1
    count = ni * nj
    box = np.repeat(np.arange(i0.size), count)
    start = np.repeat(np.cumsum(count) - count, count)
    k = np.arange(box.size) - start
    nj_b = nj[box]
    cell = (i0[box] + k // nj_b) * nr + (j0[box] + k % nj_b)
    return box, cell


def cell_bounds(grid: Grid, f_lo: np.ndarray, rng: tuple[np.ndarray, ...]) -> np.ndarray:
    """``g`` per cell ``(ns * nr,)``: the smallest box enclosure meeting it (inf: none)."""
    box, cell = expand(*rng, grid.nr)
    g = np.full(grid.ns * grid.nr, np.inf)
    np.minimum.at(g, cell, f_lo[box])
    return g


def triangles(grid: Grid, g: np.ndarray) -> tuple[np.ndarray, ...]:
    """For every triangle of a bounded cell: node indices ``(a, b, c)`` with gradient
    ``((phi_b - phi_a) / hs, (phi_c - phi_a) / hr)`` (up to sign), and its bound ``g``."""
    cells = np.flatnonzero(np.isfinite(g))
    i, j = cells // grid.nr, cells % grid.nr
    nrn = grid.nr + 1
    n00, n10, n01, n11 = i * nrn + j, (i + 1) * nrn + j, i * nrn + j + 1, (i + 1) * nrn + j + 1
    # lower-left (n00, n10, n01): d/ds = n10 - n00, d/dr = n01 - n00
    # upper-right (n11, n01, n10): d/ds = n11 - n01, d/dr = n11 - n10
    sa = np.concatenate([n00, n01])
    sb = np.concatenate([n10, n11])
    ra = np.concatenate([n00, n10])
    rb = np.concatenate([n01, n11])
    return sa, sb, ra, rb, np.concatenate([g[cells], g[cells]])


def potential(grid: Grid, g: np.ndarray) -> tuple[float, float, str, np.ndarray]:
    """Maximise ``Phi(goal) - Phi(start)`` s.t. ``|grad Phi| <= g`` per triangle (cvxpy
    SOCP), check every gradient exactly and rescale -> (bound, scale, solver status, the
    dual weight of every cell: the bound's sensitivity to its ``g``)."""
    import cvxpy as cp
    import scipy.sparse as sp

    sa, sb, ra, rb, gt = triangles(grid, g)
    n_nodes = (grid.ns + 1) * (grid.nr + 1)
    t = gt.size
    rows = np.arange(t)
    ds = sp.csr_matrix((np.concatenate([np.full(t, 1.0 / grid.hs), np.full(t, -1.0 / grid.hs)]),
                        (np.concatenate([rows, rows]), np.concatenate([sb, sa]))),
                       shape=(t, n_nodes))
    dr = sp.csr_matrix((np.concatenate([np.full(t, 1.0 / grid.hr), np.full(t, -1.0 / grid.hr)]),
                        (np.concatenate([rows, rows]), np.concatenate([rb, ra]))),
                       shape=(t, n_nodes))
    start = grid.i_start * (grid.nr + 1)
    goal = grid.i_goal * (grid.nr + 1)
    phi = cp.Variable(n_nodes)
    gn = float(np.max(gt)) if gt.size else 0.0
    weight = np.zeros(g.size)
    if not gn > 0.0:
        return 0.0, 1.0, "no_bound", weight  # f is not bounded away from 0: Phi = 0
    cone = cp.SOC(gt / gn, cp.vstack([ds @ phi, dr @ phi]) / gn, axis=0)
    prob = cp.Problem(cp.Maximize((phi[goal] - phi[start]) / gn), [cone, phi[start] == 0.0])
    for solver in CONE_SOLVERS:  # the next one where a solver fails
        try:
            prob.solve(solver=solver)
            break
        except (cp.error.SolverError, ValueError) as err:
            failure = f"solver_error ({solver}): {err}"
    else:
        return 0.0, float("nan"), failure, weight
    if phi.value is None or not np.all(np.isfinite(phi.value)):
        return 0.0, float("nan"), str(prob.status), weight
    dual = cone.dual_value[0] if isinstance(cone.dual_value, list) else None
    if dual is not None:
        cells = np.flatnonzero(np.isfinite(g))
        np.add.at(weight, np.concatenate([cells, cells]), np.maximum(np.asarray(dual), 0.0))
    val = np.asarray(phi.value, float)
    zero = gt <= 0.0
    if np.any(zero):  # f not bounded away from 0 there: Phi exactly constant on such cells
        from scipy.sparse.csgraph import connected_components

        ends = np.concatenate([np.stack([sa[zero], sb[zero]], 1),
                               np.stack([ra[zero], rb[zero]], 1)])
        graph = sp.coo_matrix((np.ones(len(ends)), (ends[:, 0], ends[:, 1])),
                              shape=(n_nodes, n_nodes))
        _, label = connected_components(graph, directed=False)
        touched = np.unique(ends)
        low = np.full(n_nodes, np.inf)
        np.minimum.at(low, label[touched], val[touched])
        val[touched] = low[label[touched]]
    # the exact check: gradients of the float64 potential against the cell bounds
    gs = (val[sb] - val[sa]) / grid.hs
    gr = (val[rb] - val[ra]) / grid.hr
    norm = np.hypot(gs, gr)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = float(np.max(np.where(zero, np.where(norm > 0.0, np.inf, 0.0), norm / gt)))
    scale = max(1.0, ratio) * (1.0 + SLACK)
    bound = (val[goal] - val[start]) / scale
    return max(bound * (1.0 - SLACK), 0.0), scale, str(prob.status), weight


def reduced(g: np.ndarray, p: float) -> np.ndarray:
    """``sqrt(g**2 - p**2)`` rounded down (0 where ``g <= p``): the bound left for the
    active coordinates when the free ones carry the momentum ``p``."""
    if p <= 0.0:
        return g
    with np.errstate(invalid="ignore", over="ignore"):
        g2 = g * g * (1.0 - 4 * _U) - p * p * (1.0 + 4 * _U)
        out = np.sqrt(np.maximum(g2, 0.0) * (1.0 - 4 * _U)) * (1.0 - 4 * _U)
    return np.where(np.isinf(g), np.inf, out)


def best_potential(grid: Grid, g: np.ndarray, m_low: float, free_dist: float
                    ) -> tuple[float, float, str, float, int]:
    """The best bound ``p |free move| + Psi(goal) - Psi(start)`` over momenta ``p`` in
    ``[0, m]`` (``phi = p e_F . q_F + Psi(s, r)``: ``|grad phi|**2 = p**2 + |grad
    Psi|**2 <= f**2`` where ``|grad Psi| <= sqrt(g**2 - p**2)``; the coordinates ``f``
    does not depend on are cyclic, Clairaut's integral) -> (bound, scale, status, p,
    cone programs solved)."""
    def run(p: float) -> tuple[float, float, str]:
        bound, scale, status, _ = potential(grid, reduced(g, p))
        return bound + p * free_dist * (1.0 - SLACK), scale, status

    if free_dist <= 0.0 or m_low <= 0.0:
        bound, scale, status = run(0.0)
        return bound, scale, status, 0.0, 1
    tried = {p: run(p) for p in m_low * np.array(MOMENTA)}
    fine = [p for p in tried if math.isfinite(tried[p][1])]
    if fine:  # one golden-section refinement round around the best
        best = max(fine, key=lambda p: tried[p][0])
        grid_p = sorted(tried)
        k = grid_p.index(best)
        for q in (0.5 * (grid_p[max(k - 1, 0)] + best),
                  0.5 * (best + grid_p[min(k + 1, len(grid_p) - 1)])):
            if q not in tried:
                tried[q] = run(q)
    fine = [p for p in tried if math.isfinite(tried[p][1])]
    if not fine:
        p = min(tried)
        return 0.0, float("nan"), tried[p][2], p, len(tried)
    best = max(fine, key=lambda p: tried[p][0])
    return (*tried[best], best, len(tried))
