"""Affine rules of finsler.enclosures.affine for kinks and discrete values (abs, max, min, sign,
comparisons, if_else): enclosures hold sampled values of CasADi's own evaluation, keep
correlations through |.| (tighter than the natural interval extension on a correlated
expression), and make the car-like metric's F and its gradient affine-ready."""

from __future__ import annotations

import casadi as ca
import numpy as np

import finsler
from finsler.enclosures.affine import enclose_affine
from finsler.enclosures.intervals import Interval, enclose
from finsler.lowering import lower, max_through_abs


def _exprs() -> ca.Function:
    x = ca.SX.sym("x", 2)
    a, b = x[0], x[1]
    return ca.Function("kinks", [x], [ca.vertcat(
        ca.fabs(a) - 0.5 * a,
        ca.fmax(a, b) - b,
        ca.sign(a) * b,
        ca.if_else(a > 0.25, a * b, -b),
        ca.fmin(a * b, 0.2) + ca.fmax(0.0, a),
        (a < b) + ca.logic_and(a > 0, b > 0) + ca.logic_not(a < 0) + (a == b) + (a != b),
    )])


def _boxes(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    c = rng.uniform(-1.0, 1.0, (n, 2))
    r = rng.uniform(0.0, 0.8, (n, 2))
    r[: n // 10] = 0.0  # points
    return c - r, c + r


def test_kink_rules_hold_sampled_values() -> None:
    fn = _exprs()
    low = lower(fn)
    lo, hi = _boxes(300, 1)
    enc = enclose_affine(low, lo, hi)
    rng = np.random.default_rng(2)
    for k in range(lo.shape[0]):
        s = lo[k] + (hi[k] - lo[k]) * rng.uniform(0.0, 1.0, (400, 2))
        s = np.concatenate([s, lo[k][None], hi[k][None], np.array([[lo[k, 0], hi[k, 1]]])])
        ref = np.asarray(fn.map(s.shape[0])(s.T)).T  # CasADi's own evaluation
        for j, iv in enumerate(enc):
            assert iv.lo[k] <= ref[:, j].min() and ref[:, j].max() <= iv.hi[k], (k, j)


def test_abs_keeps_correlations() -> None:
    """``|x| - x / 2`` across 0: the Chebyshev line tracks x, the natural extension adds
    the ranges; ``max(a, b) - b`` likewise. Both stay within the interval's bound."""
    low = lower(_exprs())
    lo, hi = np.array([[-1.0, -0.5]]), np.array([[2.0, 1.5]])
    aff = enclose_affine(low, lo, hi)
    (nat,) = enclose(low, Interval(lo, hi))
    # exact ranges: |x| - x/2 on [-1, 2] is [0, 1.5]; max(a, b) - b is [0, 2.5]
    assert aff[0].lo[0] <= 0.0 and aff[0].hi[0] >= 1.5
    assert aff[0].hi[0] - aff[0].lo[0] < 0.75 * (nat[0].hi[0] - nat[0].lo[0])
    assert aff[1].lo[0] <= 0.0 and aff[1].hi[0] >= 2.5
    assert aff[1].hi[0] - aff[1].lo[0] <= nat[1].hi[0] - nat[1].lo[0]


def test_carlike_is_affine_ready_and_its_gradient_encloses_samples() -> None:
    """Car-like's F and grad_v F (max through abs) as affine forms over boxes across its
    kink hold sampled values and are finite."""
    from finsler.enclosures.affine import affine_forms
    from solvers.certificates.nd.p2 import affine_ready

    m = finsler.get_metric("carlike")
    assert affine_ready(m)
    u = ca.SX.sym("u", 6)
    f = max_through_abs(ca.Function("f", [u], [m.F_sx(u[:3], u[3:])]))(u)
    fn = lower(ca.Function("fg", [u], [ca.vertcat(f, ca.gradient(f, u[3:]))]))
    rng = np.random.default_rng(3)
    z0 = rng.uniform(-0.4, 0.4, (40, 3))
    w0 = np.column_stack([0.5 * np.cos(z0[:, 2]), 0.5 * np.sin(z0[:, 2]), np.ones(40)])
    r = np.concatenate([np.full((40, 3), 0.01), np.full((40, 3), 0.02)], axis=1)
    c = np.concatenate([z0, w0], axis=1)
    _, _, forms = affine_forms(fn, c - r, c + r)
    for k in range(40):
        s = c[k] + r[k] * rng.uniform(-1.0, 1.0, (500, 6))
        (ref,) = fn(s)
        for j, (_c, _a, _e, iv) in enumerate(forms):
            assert np.isfinite(iv.lo[k]) and np.isfinite(iv.hi[k])
            assert iv.lo[k] <= ref[:, j].min() and ref[:, j].max() <= iv.hi[k], (k, j)
