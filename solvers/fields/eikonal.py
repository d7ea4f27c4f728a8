"""A semi-Lagrangian eikonal scheme for Finsler metrics on a regular grid.

The distance from a source, ``d(y) = d(source, y)``, is the viscosity solution of
``F*(y, grad d) = 1``; its discrete form on a grid of spacing ``h`` is the fixed point of

    d(y) = min over w on the faces of a stencil of [ interp(d, y - h w) + h F(y - h w / 2, w) ]

where the stencil is the boundary of a box of integer offsets around each node, split into
segments (2-D) or triangles (3-D), ``interp`` is the linear interpolation of ``d`` at the
vertices of a face, and ``F`` is evaluated at the midpoint of the step (second-order
quadrature of the step's length). The update is monotone (non-negative interpolation
weights) and consistent, so the fixed point converges to the viscosity solution as ``h``
goes to 0 (Barles-Souganidis); the error is of first order in ``h``. The update uses only
values of ``F``: any metric, smooth or not, isotropic or strongly anisotropic (a wider box
keeps the interpolation error small where the unit ball is thin). Where ``F(y, .)`` is not
convex, the minimum over interpolated face points is the distance of the convexified
metric (the convex hull of the unit ball), not the distance of ``F`` itself.

The minimum over each face is taken over a lattice of barycentric samples, refined by the
vertex of a parabola through the three samples around the best one (2-D) or of a quadratic
through seven (3-D): the sampling error falls from second to higher order in the sample
spacing.

The fixed point is found by an active-list Jacobi iteration (the fast iterative method):
only nodes whose stencil saw a value change are updated, all at once with numpy. Costs
``h F(., w)`` of every sample direction are computed once per node before the iteration,
and once per value of the coordinates ``F`` depends on when it does not depend on all of
them (car-like depends on the heading alone): the iteration then reads a small table.

Nodes within a few cells of the source start from the length of the straight segment from
the source (Gauss-Legendre quadrature of ``F``, an upper bound of the distance): this
removes the error of the source singularity that otherwise dominates a first-order scheme.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import Any

import casadi as ca
import numpy as np

from finsler.errors import InputError
from finsler.infra.limits import check_memory
from finsler.metrics.base import Metric

__all__ = ["Grid", "Stencil", "Sweep", "box_stencil", "depends_on", "make_grid", "solve_eikonal",
           "step_costs"]

#: Stand-in for an infinite value inside the iteration (``0 * inf`` would be NaN where a
#: barycentric weight is zero); values at or above `UNREACHED` mean no finite distance.
BIG = 1e30
UNREACHED = 1e29

#: In band order, every this many iterations updates every pending node (a Jacobi sweep):
#: values that keep falling by small amounts near the least pending key would otherwise
#: hold the band back indefinitely (seen on car-like at fine grids).
SWEEP_EVERY = 32

#: Largest grid (nodes of the padded grid) a field is computed on: the iteration holds a
#: few arrays of this size and, where ``F`` depends on every coordinate, a cost table of
#: this size times the number of sample directions.
MAX_NODES = 20_000_000


@dataclass(frozen=True)
class Grid:
    """A regular grid of spacing ``h`` ``(dim,)`` (per coordinate): node ``i`` (a
    multi-index) is at ``low + h i``; ``inside`` ``shape`` bool marks the nodes inside the
    domain."""

    low: np.ndarray
    h: np.ndarray
    shape: tuple[int, ...]
    inside: np.ndarray

    @property
    def dim(self) -> int:
        return len(self.shape)

    @property
    def high(self) -> np.ndarray:
        return self.low + self.h * (np.array(self.shape) - 1)

    def axes(self) -> list[np.ndarray]:
        """Node coordinates along each axis."""
        return [self.low[i] + self.h[i] * np.arange(n) for i, n in enumerate(self.shape)]

    def points(self) -> np.ndarray:
        """Every node ``(prod(shape), dim)`` in C order."""
        mesh = np.meshgrid(*self.axes(), indexing="ij")
        return np.stack([m.ravel() for m in mesh], -1)


def make_grid(domain: Any, resolution: int | tuple[int, ...],
              box: tuple[np.ndarray, np.ndarray] | None = None) -> Grid:
    """The grid over ``box`` (default: the domain's bounding box): ``resolution`` an
    integer, that many cells along the longest side and the same spacing in every
    coordinate (centred in the box); or one number of cells per coordinate."""
    low, high = (domain.bounds() if box is None else box)
    low = np.asarray(low, float)
    high = np.asarray(high, float)
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise InputError("a distance field needs a bounded domain (finite bounding box); "
                         f"got bounds {low.tolist()} .. {high.tolist()}")
    side = high - low
    if np.any(side <= 0):
        raise InputError(f"the grid box must have positive sides, got {side.tolist()}")
    if isinstance(resolution, tuple):
        n = np.array(resolution, int) + 1
        h = side / np.array(resolution, float)
    else:
        h = np.full(side.shape, float(side.max()) / resolution)
        n = np.floor(side / h + 1e-9).astype(int) + 1
    total = int(np.prod(n.astype(float)))
    if total > MAX_NODES:
        raise InputError(f"resolution {resolution} makes a grid of {total} nodes "
                         f"(shape {tuple(n.tolist())}), above the limit of {MAX_NODES}")
    low = low + 0.5 * (side - (n - 1) * h)
    grid = Grid(low=low, h=h, shape=tuple(int(k) for k in n),
                inside=np.zeros(tuple(n), bool))
    with np.errstate(all="ignore"):
        inside = domain.contains(grid.points(), tol=1e-12).reshape(grid.shape)
    return Grid(low=low, h=h, shape=grid.shape, inside=inside)


@dataclass(frozen=True)
class Stencil:
    """Vertices ``offsets`` ``(K, dim)`` (integers), faces ``faces`` ``(F, dim)`` (indices
    of vertices), and barycentric samples ``bary`` ``(P, dim)`` shared by every face: the
    sample ``p`` of face ``f`` is the direction ``bary[p] @ offsets[faces[f]]``."""

    offsets: np.ndarray
    faces: np.ndarray
    bary: np.ndarray
    order: int

    @property
    def radius(self) -> np.ndarray:
        """Largest offset per coordinate ``(dim,)``."""
        return np.abs(self.offsets).max(axis=0)

    def directions(self) -> np.ndarray:
        """Sample directions ``(F, P, dim)``."""
        return np.einsum("pj,fjd->fpd", self.bary, self.offsets[self.faces].astype(float))


def box_stencil(radius: tuple[int, ...], order: int) -> Stencil:
    """The stencil on the boundary of the box ``[-r_i, r_i]``: every integer point of the
    boundary a vertex, consecutive points faces (2-D), each unit square of the box's
    facets two triangles (3-D); ``order`` samples per unit of barycentric coordinate."""
    r = np.array(radius, int)
    dim = len(r)
    if dim not in (2, 3):
        raise InputError(f"distance fields are for dimension 2 or 3, got {dim}")
    pts = np.array([p for p in product(*[range(-k, k + 1) for k in r])
                    if np.any(np.abs(np.array(p)) == r)], int)
    index = {tuple(p): i for i, p in enumerate(pts)}
    if dim == 2:
        ang = np.arctan2(pts[:, 1], pts[:, 0])
        order_ = np.argsort(ang)
        pts = pts[order_]
        faces = np.stack([np.arange(len(pts)), np.roll(np.arange(len(pts)), -1)], -1)
        k = np.arange(order + 1) / order
        bary = np.stack([1 - k, k], -1)
        return Stencil(offsets=pts, faces=faces, bary=bary, order=order)
    faces = []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        for sign in (-1, 1):
            for i in range(-r[a], r[a]):
                for j in range(-r[b], r[b]):
                    corner = {}
                    for u, v in ((i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)):
                        p = [0, 0, 0]
                        p[axis], p[a], p[b] = sign * r[axis], u, v
                        corner[u - i, v - j] = index[tuple(p)]
                    c00, c10, c01, c11 = corner[0, 0], corner[1, 0], corner[0, 1], corner[1, 1]
                    # split along the diagonal that points away from the facet's centre,
                    # so the triangulation is symmetric under the box's reflections
                    if (i + 0.5) * (j + 0.5) >= 0:
                        faces += [(c00, c10, c11), (c00, c11, c01)]
                    else:
                        faces += [(c00, c10, c01), (c10, c11, c01)]
    bary = np.array([(i, j, order - i - j) for i in range(order + 1)
                     for j in range(order + 1 - i)], float) / order
    return Stencil(offsets=pts, faces=np.array(faces, int), bary=bary, order=order)


def depends_on(metric: Metric) -> np.ndarray:
    """Which coordinates of ``x`` the symbolic ``F(x, v)`` depends on ``(dim,)`` bool."""
    x = ca.SX.sym("x", metric.dim)
    v = ca.SX.sym("v", metric.dim)
    f = metric.F_sx(x, v)
    return np.array([bool(ca.depends_on(f, x[i])) for i in range(metric.dim)])


def _eval_F(metric: Metric, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``F`` on ``(N, dim)`` batches by the lowered program, in chunks (memory)."""
    out = np.empty(x.shape[0])
    step = 1 << 20
    for a in range(0, x.shape[0], step):
        (f,) = metric.lowered_F(x[a:a + step], v[a:a + step])
        out[a:a + step] = np.asarray(f, float).reshape(-1)
    return out


def step_costs(metric: Metric, grid: Grid, stencil: Stencil, dep: np.ndarray,
               domain: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Cost table ``(classes, F, P)`` of the steps ``F(y - h w / 2, h w)`` and the class of
    every node (``shape`` int): one class per value of the coordinates ``F`` depends on
    (``dep``), one per node where it depends on all."""
    w = stencil.directions()
    nf, npt, dim = w.shape
    dep_axes = [i for i in range(dim) if dep[i]]
    if len(dep_axes) == dim:
        cls = np.full(grid.shape, -1, np.int64)
        cls[grid.inside] = np.arange(int(grid.inside.sum()))
        reps = grid.points()[grid.inside.ravel()]
    else:
        sub = tuple(grid.shape[i] for i in dep_axes)
        idx = np.indices(grid.shape)
        cls = (np.ravel_multi_index(tuple(idx[i] for i in dep_axes), sub) if dep_axes
               else np.zeros(grid.shape, np.int64))
        # a representative per class: the class's coordinates, the others at the grid's centre
        n_cls = int(np.prod(sub)) if dep_axes else 1
        reps = np.tile(0.5 * (grid.low + grid.high), (n_cls, 1))
        if dep_axes:
            sub_idx = np.stack(np.unravel_index(np.arange(n_cls), sub), -1)
            for k, ax in enumerate(dep_axes):
                reps[:, ax] = grid.low[ax] + grid.h[ax] * sub_idx[:, k]
    n_cls = reps.shape[0]
    check_memory((n_cls, nf * npt, dim), "distance field step costs",
                 "lower the resolution or the stencil's order")
    # samples shared by neighbouring faces (their common vertices and edges) once
    flat_w, back = np.unique(np.round(w.reshape(-1, dim), 12), axis=0, return_inverse=True)
    nu = flat_w.shape[0]
    x = np.repeat(reps, nu, axis=0)
    v = np.tile(flat_w * grid.h, (n_cls, 1))   # the step in coordinates
    mid = x - 0.5 * v
    with np.errstate(all="ignore"):
        f = _eval_F(metric, mid, v)
        ok = np.isfinite(f) & (f > 0)
        if len(dep_axes) == dim and domain is not None:
            # the midpoint of a step near the boundary may leave the domain, where F may be
            # anything: F at the node there
            ok &= domain.contains(mid, tol=1e-12)
        if not ok.all():
            f[~ok] = _eval_F(metric, x[~ok], v[~ok])
    f = f.reshape(n_cls, nu)[:, back.reshape(-1)]
    cost = f.reshape(n_cls, nf, npt)
    bad = ~(np.isfinite(f) & (f > 0))
    if bad.any():
        c, k = np.argwhere(bad)[0]
        raise InputError(f"metric {metric.name!r}: F = {f[c, k]:.6g} at x = "
                         f"{reps[c].tolist()}, v = {w.reshape(-1, dim)[k].tolist()} (near a "
                         "grid node): F must be finite and > 0 for v != 0 on the domain")
    return cost, cls


@dataclass
class Sweep:
    """The outcome of `solve_eikonal`: values on the grid (``shape``, ``inf`` where
    unreached or outside the domain), iterations, node updates, and whether the iteration
    reached its fixed point."""

    values: np.ndarray
    iterations: int
    updates: int
    converged: bool


def _straight_lengths(metric: Metric, source: np.ndarray, pts: np.ndarray,
                      order: int = 4) -> np.ndarray:
    """Lengths of the straight segments from ``source`` to ``pts`` ``(N, dim)``
    (Gauss-Legendre quadrature of ``F``, an upper bound of the distance)."""
    t, wq = np.polynomial.legendre.leggauss(order)
    t = 0.5 * (t + 1)
    wq = 0.5 * wq
    d = pts - source
    x = source[None, None] + t[None, :, None] * d[:, None]
    v = np.repeat(d[:, None], order, axis=1)
    with np.errstate(all="ignore"):
        f = _eval_F(metric, x.reshape(-1, metric.dim), v.reshape(-1, metric.dim))
    out = (f.reshape(-1, order) * wq).sum(axis=1)
    out[np.all(d == 0, axis=1)] = 0.0
    return out


def _factor_table(metric: Metric, grid: Grid, stencil: Stencil, source: np.ndarray,
                  radius: int, pad: np.ndarray, strides: np.ndarray, size: int
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    """The factored correction near the source: for nodes within ``radius`` cells, per
    face sample, ``d0(y - h w) - interp(d0)`` with ``d0 = F(source, . - source)`` (the
    distance of the metric frozen at the source, a cone). Added to the update, it makes the
    interpolation exact for ``d0``, so only ``d - d0`` (smooth near the source) is
    interpolated: the singularity's error, which decays only like ``h / rho``, is removed.
    Returns the padded-grid map of nodes to rows (``-1`` elsewhere) and the rows
    ``(W, F, P)`` (None without a window)."""
    widx = np.full(size, -1, np.int64)
    if radius <= 0:
        return widx, None
    dim = grid.dim
    centre = np.rint((source - grid.low) / grid.h).astype(int)
    lo = np.maximum(centre - radius, 0)
    hi = np.minimum(centre + radius, np.array(grid.shape) - 1)
    nodes = np.stack(np.meshgrid(*[np.arange(a, b + 1) for a, b in zip(lo, hi)],
                                 indexing="ij"), -1).reshape(-1, dim)
    nodes = nodes[grid.inside[tuple(nodes.T)]]
    if nodes.size == 0:
        return widx, None
    check_memory((nodes.shape[0], stencil.faces.shape[0] * stencil.bary.shape[0]),
                 "distance field factored correction", "lower factor_radius")
    x = grid.low + grid.h * nodes                             # (W, dim)
    w = stencil.directions()                                  # (F, P, dim)
    verts = stencil.offsets.astype(float)                     # (K, dim)

    def cone(z: np.ndarray) -> np.ndarray:
        flat_z = z.reshape(-1, dim)
        with np.errstate(all="ignore"):
            f = _eval_F(metric, np.broadcast_to(source, flat_z.shape).copy(),
                        flat_z - source)
        return f.reshape(z.shape[:-1])

    at_samples = cone(x[:, None, None, :] - grid.h * w[None])       # (W, F, P)
    at_verts = cone(x[:, None, :] - grid.h * verts[None])           # (W, K)
    interp = np.einsum("wfj,pj->wfp", at_verts[:, stencil.faces], stencil.bary)
    corr = at_samples - interp
    corr[~np.isfinite(corr)] = 0.0
    widx[(nodes + pad) @ strides] = np.arange(nodes.shape[0])
    return widx, corr


def _prune_faces(cost: np.ndarray, stencil: Stencil, h: np.ndarray, prune: float | None
                 ) -> np.ndarray | None:
    """Per cost row, the faces ``(rows, M)`` whose cheapest sample costs at most ``prune``
    times the row's cheapest per unit of (Euclidean) step length; None without
    pruning. Strongly anisotropic metrics (car-like: sideways and backwards ten times
    dearer than forwards) never take their dear directions over a grid step, and leaving
    them out divides the work; a direction pruned where it would be the best makes the
    field an upper bound there instead. Rows with fewer faces repeat their best ones."""
    if prune is None:
        return None
    step = np.linalg.norm(stencil.directions() * h, axis=-1)          # (F, P)
    ratio = (cost / step[None]).min(axis=2)                            # (rows, F)
    keep = ratio <= prune * ratio.min(axis=1, keepdims=True)
    order = np.argsort(np.where(keep, ratio, np.inf), axis=1, kind="stable")
    m = int(keep.sum(axis=1).max())
    rows = order[:, :m]
    count = keep.sum(axis=1)
    # pad short rows with their cheapest face
    pad = np.arange(m)[None, :] >= count[:, None]
    rows = np.where(pad, rows[:, :1], rows)
    return rows


def _hex_neighbours(stencil: Stencil) -> tuple[np.ndarray, np.ndarray]:
    """For the triangular lattice of samples of a 3-D face (barycentric ``(i, j, k) /
    order``): per sample, the nearest interior sample (``i, j, k >= 1``) and that
    interior sample's six neighbours ``(i+1, j), (i-1, j), (i, j+1), (i, j-1), (i+1, j-1),
    (i-1, j+1)`` (indices into the samples); returns ``(centre (P,), neighbours (P, 6))``."""
    order = stencil.order
    ij = np.rint(stencil.bary[:, :2] * order).astype(int)
    index = {(int(i), int(j)): p for p, (i, j) in enumerate(ij)}
    interior = [p for p, (i, j) in enumerate(ij) if i >= 1 and j >= 1 and i + j <= order - 1]
    centre = np.empty(len(ij), int)
    nbrs = np.empty((len(ij), 6), int)
    for p, (i, j) in enumerate(ij):
        q = min(interior, key=lambda r: (ij[r, 0] - i) ** 2 + (ij[r, 1] - j) ** 2
                + (ij[r, 0] + ij[r, 1] - i - j) ** 2)
        centre[p] = q
        ci, cj = ij[q]
        nbrs[p] = [index[(ci + di, cj + dj)] for di, dj in
                   ((1, 0), (-1, 0), (0, 1), (0, -1), (1, -1), (-1, 1))]
    return centre, nbrs


def _quadratic_vertex(vals: np.ndarray, centre: np.ndarray, nbrs: np.ndarray) -> np.ndarray:
    """Per face ``(A, F)``: the minimum of the quadratic through the best sample's interior
    neighbourhood (seven samples of the triangular lattice), where the quadratic is convex
    and its minimiser lies within one lattice step (else ``BIG``): the 3-D counterpart of
    the 2-D parabola, it lets the update choose a direction between samples (a thin unit
    ball, car-like's, punishes the sampling's angular error quadratically)."""
    k = vals.argmin(axis=2)
    c_idx = centre[k]
    nb = nbrs[k]                                              # (A, F, 6)
    c = np.take_along_axis(vals, c_idx[..., None], 2)[..., 0]
    v = np.take_along_axis(vals, nb, 2)                       # (A, F, 6)
    a_ = 0.5 * (v[..., 0] - v[..., 1])
    b_ = 0.5 * (v[..., 2] - v[..., 3])
    haa = v[..., 0] + v[..., 1] - 2 * c
    hbb = v[..., 2] + v[..., 3] - 2 * c
    hab = 0.5 * (haa + hbb - (v[..., 4] + v[..., 5] - 2 * c))
    det = haa * hbb - hab * hab
    with np.errstate(all="ignore"):
        ds = -(hbb * a_ - hab * b_) / det
        dt = -(haa * b_ - hab * a_) / det
        q = c + 0.5 * (a_ * ds + b_ * dt)
    ok = ((det > 0) & (haa > 0) & (np.abs(ds) <= 1) & (np.abs(dt) <= 1)
          & (np.abs(ds + dt) <= 1) & (v.max(axis=2) < UNREACHED))
    return np.where(ok, q, BIG)


def solve_eikonal(metric: Metric, grid: Grid, stencil: Stencil, source: np.ndarray,
                  cost: np.ndarray, cls: np.ndarray, init_radius: int = 3,
                  factor_radius: int = 0, prune: float | None = None,
                  band: float | None = None, max_iterations: int | None = None) -> Sweep:
    """The fixed point of the semi-Lagrangian update (see the module's docstring) from
    ``source`` ``(dim,)``, with the step costs of `step_costs`."""
    dim = grid.dim
    pad = stencil.radius
    pshape = tuple(int(n + 2 * p) for n, p in zip(grid.shape, pad))
    strides = np.array([int(np.prod(pshape[i + 1:])) for i in range(dim)], np.int64)
    inside = np.zeros(pshape, bool)
    core = tuple(slice(p, p + n) for p, n in zip(pad, grid.shape))
    inside[core] = grid.inside
    inside = inside.ravel()
    pcls = np.zeros(pshape, np.int64)
    pcls[core] = np.where(cls >= 0, cls, 0)
    pcls = pcls.ravel()
    off = stencil.offsets.astype(np.int64) @ strides  # (K,)
    faces = stencil.faces
    bary = stencil.bary
    nf, npt = faces.shape[0], bary.shape[0]
    cost_t = cost.reshape(cost.shape[0], nf, npt)
    refine = dim == 2 and stencil.order >= 2
    # the 3-D quadratic refinement where F is smooth: at the kinks of a non-smooth F
    # (car-like's max) its undershoot below the samples makes the iteration creep by tiny
    # decreases
    hexes = (_hex_neighbours(stencil) if dim == 3 and stencil.order >= 3 and metric.smooth
             else None)

    d = np.full(int(np.prod(pshape)), BIG)
    # nodes near the source: the straight segment's length
    rel = (source - grid.low) / grid.h
    lo = np.maximum(np.floor(rel).astype(int) - init_radius + 1, 0)
    hi = np.minimum(np.floor(rel).astype(int) + init_radius, np.array(grid.shape) - 1)
    near = np.stack(np.meshgrid(*[np.arange(a, b + 1) for a, b in zip(lo, hi)],
                                indexing="ij"), -1).reshape(-1, dim)
    flat = (near + pad) @ strides
    keep = inside[flat]
    near, flat = near[keep], flat[keep]
    if flat.size == 0:
        raise InputError("the source has no grid node of the domain within "
                         f"{init_radius} cells: raise the resolution")
    d0 = _straight_lengths(metric, source, grid.low + grid.h * near)
    d0 = np.where(np.isfinite(d0), d0, BIG)
    d[flat] = d0
    active = np.unique((flat[:, None] + off[None, :]).ravel())
    active = np.union1d(active[inside[active]], flat)
    widx, corr = _factor_table(metric, grid, stencil, source, factor_radius, pad, strides,
                               int(np.prod(pshape)))
    if corr is not None:
        # one table: the class's costs, or (near the source) a node's own row with the
        # factored correction added
        win = widx >= 0
        rows = np.flatnonzero(win)
        # the correction is <= 0 (a cone is convex: its interpolation lies above it); where
        # the metric at a node differs much from the source's it could exceed the step's
        # cost and make cycles of decreasing values: it is kept to half the cost
        base = cost_t[pcls[rows]]
        table = np.concatenate([cost_t, base + np.maximum(corr[widx[rows]], -0.5 * base)])
        pcls = pcls.copy()
        pcls[rows] = cost_t.shape[0] + widx[rows]
        cost_t = table
    face_rows = _prune_faces(cost_t, stencil, grid.h, prune)
    limit = max_iterations if max_iterations is not None else 20 * int(sum(grid.shape)) + 100
    it = 0
    updates = 0
    chunk = max(1, int(4_000_000 // (nf * npt)))
    # Band ordering: of the pending nodes, those whose activating neighbour's value is
    # within ``width`` of the least are updated first (an untidy priority queue): nodes
    # far behind the front wait instead of being updated again and again.
    width = np.inf
    if band is not None:
        width = band * float(np.median(cost_t[: cost.shape[0]].min(axis=(1, 2))))
    key = np.full(d.size, np.inf)
    pending = np.zeros(d.size, bool)
    key[active] = 0.0
    pending[active] = True
    if np.isfinite(width):
        limit *= SWEEP_EVERY
    while it < limit:
        if np.isfinite(width) and it % SWEEP_EVERY:
            cand = np.flatnonzero(pending)
            if cand.size == 0:
                active = cand
                break
            kc = key[cand]
            active = cand[kc <= kc.min() + width]
        else:
            active = np.flatnonzero(pending)
            if active.size == 0:
                break
        pending[active] = False
        key[active] = np.inf
        it += 1
        new = np.empty(active.size)
        for a in range(0, active.size, chunk):
            nodes = active[a:a + chunk]
            vd = d[nodes[:, None] - off[None, :]]          # (A, K)
            rows = pcls[nodes]
            if face_rows is None:
                vf = vd[:, faces]                         # (A, F, dim)
                vals = cost_t[rows]                       # (A, F, P)
            else:
                fidx = face_rows[rows]                    # (A, M)
                vf = np.take_along_axis(vd, faces[fidx].reshape(len(nodes), -1),
                                        1).reshape(len(nodes), -1, dim)
                vals = cost_t[rows[:, None], fidx]
            for j in range(dim):
                vals = vals + vf[:, :, j, None] * bary[None, None, :, j]
            best = vals.min(axis=2)
            if refine:
                k = np.clip(vals.argmin(axis=2), 1, npt - 2)
                y0 = np.take_along_axis(vals, (k - 1)[..., None], 2)[..., 0]
                y1 = np.take_along_axis(vals, k[..., None], 2)[..., 0]
                y2 = np.take_along_axis(vals, (k + 1)[..., None], 2)[..., 0]
                den = y0 - 2 * y1 + y2
                with np.errstate(all="ignore"):
                    t = 0.5 * (y0 - y2) / den
                    par = y1 - 0.125 * (y0 - y2) ** 2 / den
                # the vertex of the parabola through the best sample and its neighbours,
                # where it lies between them (curvature > 0)
                ok = (den > 0) & (np.abs(t) <= 1) & (y0 < UNREACHED) & (y2 < UNREACHED)
                best = np.minimum(best, np.where(ok, par, BIG))
            if hexes is not None:
                best = np.minimum(best, _quadratic_vertex(vals, *hexes))
            new[a:a + chunk] = best.min(axis=1)
        old = d[active]
        better = new < old - 1e-12 * np.maximum(old, 1e-300)
        better &= new < UNREACHED
        changed = active[better]
        d[changed] = new[better]
        updates += int(active.size)
        if changed.size == 0:
            continue
        dep = (changed[:, None] + off[None, :]).ravel()
        src = np.repeat(d[changed], off.size)
        ok = inside[dep]
        dep, src = dep[ok], src[ok]
        np.minimum.at(key, dep, src)
        pending[dep] = True
    active = np.flatnonzero(pending)
    values = d.reshape(pshape)[core].copy()
    values[~grid.inside] = np.inf
    values[values >= UNREACHED] = np.inf
    return Sweep(values=values, iterations=it, updates=updates, converged=active.size == 0)
