"""Rows of a certify LP rebuilt densely and solved by scipy's HiGHS: the references of the
LP tests and of the repair tests."""

from __future__ import annotations

import numpy as np
from scipy.optimize import OptimizeResult, linprog

from solvers.certificates.plane.mesh import _Mesh

K = 32
ANG = 2 * np.pi * np.arange(K) / K
DIRS = np.stack([np.cos(ANG), np.sin(ANG)], 1)
S, G = np.array([0.1, 0.5]), np.array([0.9, 0.5])  # goal - start along DIRS[0]


def _mesh() -> _Mesh:
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 1.0, 5)
    x, y = np.meshgrid(t, t)
    grid = np.stack([x.ravel(), y.ravel()], 1) + rng.uniform(-0.03, 0.03, (25, 2))
    return _Mesh(np.concatenate([S[None], G[None], grid]))


MESH = _mesh()
NV = 3 * MESH.n_tri


def weights() -> np.ndarray:
    """Rows that differ from triangle to triangle (F = w(x) |v| piecewise)."""
    c = MESH.centroids
    w = 1.0 + c[:, 0] + 0.5 * c[:, 1]
    return np.broadcast_to(w[:, None, None], (MESH.n_tri, 3, K)).copy()


def full_rows() -> np.ndarray:
    """Dense matrix of every row ``grad phi(vertex) . v_k`` (vertex-major, then k), built
    from the P2 gradients the mesh gives, independently of the module's sparse assembly."""
    gc = MESH.grad.reshape(NV, 2, 6)
    dofs = np.repeat(MESH.dofs, 3, axis=0)
    a = np.zeros((NV * K, MESH.n_dofs))
    for v in range(NV):
        co = DIRS @ gc[v]  # (K, 6)
        for j in range(6):
            a[v * K:(v + 1) * K, dofs[v, j]] += co[:, j]
    return a


FULL = full_rows()


def highs_solve(b: np.ndarray) -> OptimizeResult:
    """The full LP (every row of ``FULL``, the start held at 0) by scipy's HiGHS."""
    c = np.zeros(MESH.n_dofs)
    c[1] = -1.0
    bounds = [(None, None)] * MESH.n_dofs
    bounds[0] = (0.0, 0.0)
    res = linprog(c, A_ub=FULL, b_ub=b.reshape(-1), bounds=bounds, method="highs")
    assert res.status == 0
    return res
