"""Dense references of the block-tridiagonal solves."""

from __future__ import annotations

import numpy as np


def dense(a: np.ndarray, o: np.ndarray) -> np.ndarray:
    """The symmetric block-tridiagonal matrix of blocks ``a`` ``(M, d, d)`` and couplings
    ``o`` ``(M, d, d)`` (``o[j]`` couples unknowns ``j`` and ``j + 1``; ``o[M-1]`` unused)."""
    m, d, _ = a.shape
    h = np.zeros((m * d, m * d))
    for j in range(m):
        h[j * d:(j + 1) * d, j * d:(j + 1) * d] = a[j]
        if j < m - 1:
            h[j * d:(j + 1) * d, (j + 1) * d:(j + 2) * d] = o[j]
            h[(j + 1) * d:(j + 2) * d, j * d:(j + 1) * d] = o[j].T
    return h
