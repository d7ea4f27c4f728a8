"""Chebyshev-Gauss-Lobatto nodes, barycentric interpolation and differentiation matrices
(plain numpy; used by the pseudospectral transcription and by `DistanceResult`)."""

from __future__ import annotations

import numpy as np

__all__ = ["chebyshev_nodes", "differentiation_matrix", "interpolation_matrix"]


def chebyshev_nodes(n: int) -> np.ndarray:
    """Chebyshev-Gauss-Lobatto nodes ``-cos(pi j / n)``, ``j = 0..n`` (ascending) ``(n+1,)``."""
    return -np.cos(np.pi * np.arange(n + 1) / n)


def _bary_weights(n: int) -> np.ndarray:
    w = (-1.0) ** np.arange(n + 1)
    w[0] *= 0.5
    w[-1] *= 0.5
    return w


def interpolation_matrix(n: int, y: np.ndarray) -> np.ndarray:
    """Barycentric interpolation from the ``n + 1`` Chebyshev nodes to points ``y`` ``(T,)``
    in ``[-1, 1]`` -> ``(T, n+1)``."""
    x = chebyshev_nodes(n)
    w = _bary_weights(n)
    y = np.asarray(y, dtype=np.float64).reshape(-1)
    diff = y[:, None] - x[None, :]
    exact = diff == 0.0
    diff[exact] = 1.0
    a = w[None, :] / diff
    out = a / a.sum(axis=1, keepdims=True)
    rows = np.flatnonzero(exact.any(axis=1))
    out[rows] = exact[rows].astype(np.float64)
    return out


def differentiation_matrix(n: int) -> np.ndarray:
    """Derivative at the nodes of the interpolant of node values ``(n+1, n+1)``."""
    x = chebyshev_nodes(n)
    w = _bary_weights(n)
    dx = x[:, None] - x[None, :]
    np.fill_diagonal(dx, 1.0)
    d = (w[None, :] / w[:, None]) / dx
    np.fill_diagonal(d, 0.0)
    np.fill_diagonal(d, -d.sum(axis=1))
    return d
