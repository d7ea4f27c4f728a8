"""Quadrature rules of the length computations of `finsler.Metric`: Gauss-Legendre on
[0, 1] (eq. 58's straight-segment length) and adaptive Gauss-Kronrod 7-15 with an error
estimate."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

__all__: list[str] = []


#: Gauss-Kronrod 7-15 rule on [-1, 1] (QUADPACK's qk15): Kronrod nodes from the end to the
#: centre, their weights, and the Gauss weights of the odd-indexed nodes (1, 3, 5, 7).
_GK15_X = np.array([
    0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
    0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
    0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
    0.207784955007898467600689403773245, 0.0])
_GK15_WK = np.array([
    0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
    0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
    0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
    0.204432940075298892414161999234649, 0.209482141084727828012999174891714])
_G7_W = np.array([
    0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
    0.381830050505118944950369775488975, 0.417959183673469387755102040816327])


def _gk15_01() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The G7-K15 pair on ``[0, 1]``: nodes ``(15,)``, Kronrod weights ``(15,)`` and Gauss
    weights ``(15,)`` (zero at the Kronrod-only nodes)."""
    x = np.concatenate([-_GK15_X[:-1], _GK15_X[::-1]])
    wk = np.concatenate([_GK15_WK[:-1], _GK15_WK[::-1]])
    wg_half = np.zeros(8)
    wg_half[1::2] = _G7_W
    wg = np.concatenate([wg_half[:-1], wg_half[::-1]])
    return 0.5 * (x + 1.0), 0.5 * wk, 0.5 * wg


_GK_T, _GK_WK, _GK_WG = _gk15_01()


@functools.lru_cache(maxsize=16)
def _gauss_legendre01(order: int) -> tuple[np.ndarray, np.ndarray]:
    t, w = np.polynomial.legendre.leggauss(order)
    return 0.5 * (t + 1.0), 0.5 * w


def _adaptive_gk(f: Any, x: np.ndarray, d: np.ndarray, rtol: float, atol: float,
                 max_intervals: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Adaptive G7-K15 quadrature of ``t -> f(x + t d, d)`` over ``[0, 1]`` for every row of
    ``x``, ``d`` ``(N, dim)`` -> ``(value, error, intervals)`` each ``(N,)``.

    Subintervals are kept as flat arrays (owner row, left end, width). Each round evaluates
    every pending subinterval at once, accepts those whose ``|K15 - G7|`` is within
    ``tol * width`` (``tol`` from the row's current length), and bisects the others, until
    none is pending or a row reaches ``max_intervals`` (its pending subintervals are then
    accepted as they are, and the row is reported unconverged by its error)."""
    n, dim = x.shape
    value = np.zeros(n)
    error = np.zeros(n)
    count = np.ones(n, dtype=np.int64)
    owner = np.arange(n)
    left = np.zeros(n)
    width = np.ones(n)
    while owner.size:
        t = left[:, None] + width[:, None] * _GK_T[None, :]  # (M, 15)
        pts = x[owner][:, None, :] + t[:, :, None] * d[owner][:, None, :]
        dirs = np.broadcast_to(d[owner][:, None, :], pts.shape)
        fv = f(pts.reshape(-1, dim), dirs.reshape(-1, dim)).reshape(-1, 15)
        k = width * (fv @ _GK_WK)
        g = width * (fv @ _GK_WG)
        err = np.abs(k - g)
        # each row's current length (accepted parts plus pending estimates) sets its tolerance
        current = value + np.bincount(owner, weights=k, minlength=n)
        tol = np.maximum(atol, rtol * np.abs(current))
        ok = err <= tol[owner] * width
        full = count[owner] >= max_intervals  # rows at the cap accept what they have
        accept = ok | full
        np.add.at(value, owner[accept], k[accept])
        np.add.at(error, owner[accept], err[accept])
        split = ~accept
        # each bisection replaces one subinterval by two
        np.add.at(count, owner[split], 1)
        half = 0.5 * width[split]
        owner = np.repeat(owner[split], 2)
        left = np.stack([left[split], left[split] + half], 1).reshape(-1)
        width = np.repeat(half, 2)
    error = error + 1e2 * np.finfo(float).eps * np.abs(value)
    return value, error, count
