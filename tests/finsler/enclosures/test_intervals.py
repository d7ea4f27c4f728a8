"""Interval enclosures of lowered CasADi programs (``finsler.enclosures.intervals``): every value
the function takes on a box lies in the enclosure (sampled points of the box, elementary
functions with known ranges), undefined operations give the whole line, and the
Hessians the certification bounds with are enclosed for every 2-D metric."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import finsler
from finsler.enclosures.intervals import Interval, enclose
from finsler.lowering import lower

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation

UNARY = {
    "exp": ca.exp, "log": ca.log, "sqrt": ca.sqrt, "sin": ca.sin, "cos": ca.cos,
    "tanh": ca.tanh, "atan": ca.atan, "fabs": ca.fabs, "sinh": ca.sinh, "cosh": ca.cosh,
    "sq": lambda x: x * x, "cube": lambda x: x**3, "inv": lambda x: 1.0 / x,
    "pow_half": lambda x: x**0.5, "pow_neg2": lambda x: x**-2,
}
POSITIVE_ONLY = {"log", "sqrt", "pow_half"}


def _lowered(expr_fn, n: int = 1):
    x = ca.SX.sym("x", n)
    return lower(ca.Function("f", [x], [expr_fn(x)]))


def _check_contains(fn, lo: np.ndarray, hi: np.ndarray, samples: int = 64, seed: int = 0):
    rng = np.random.default_rng(seed)
    (out,) = enclose(fn, Interval(lo, hi))
    pts = lo[None] + rng.uniform(0, 1, (samples, *lo.shape)) * (hi - lo)[None]
    pts = np.concatenate([pts, lo[None], hi[None]])
    for p in pts:
        # A reference value may be infinite (x**-2 where x*x underflows to 0): the
        # enclosure must still contain it, so numpy's divide/overflow warnings are noise.
        with np.errstate(divide="ignore", over="ignore"):
            (val,) = fn(p)
        for j, iv in enumerate(out):
            v = np.asarray(val)[..., j]
            ok = np.isnan(v) | ((iv.lo <= v) & (v <= iv.hi))
            assert np.all(ok), (v[~ok], iv.lo[~ok], iv.hi[~ok])
    return out


@pytest.mark.parametrize("name", sorted(UNARY))
@settings(max_examples=25, deadline=None)
@given(a=st.floats(-6, 6), w=st.floats(0, 8))
def test_unary_enclosures_contain_every_value(name: str, a: float, w: float) -> None:
    if name in POSITIVE_ONLY:
        a = abs(a) + 1e-3
    lo, hi = np.array([[a]]), np.array([[a + w]])
    if name in ("inv", "pow_neg2") and lo[0, 0] <= 0 <= hi[0, 0]:
        (out,) = enclose(_lowered(UNARY[name]), Interval(lo, hi))
        assert out[0].lo[0] == -np.inf or name == "pow_neg2"
        assert out[0].hi[0] == np.inf
        return
    _check_contains(_lowered(UNARY[name]), lo, hi)


def test_trigonometric_extrema_and_known_ranges() -> None:
    sin = _lowered(ca.sin)
    cos = _lowered(ca.cos)
    (s,) = enclose(sin, Interval(np.array([[0.0]]), np.array([[math.pi]])))
    assert s[0].hi[0] == 1.0 and -1e-15 < s[0].lo[0] <= 0.0
    (c,) = enclose(cos, Interval(np.array([[3.0]]), np.array([[3.3]])))
    assert c[0].lo[0] == -1.0 and c[0].hi[0] < -0.98
    (c,) = enclose(cos, Interval(np.array([[0.1]]), np.array([[0.2]])))
    assert math.cos(0.2) - 1e-14 < c[0].lo[0] < math.cos(0.2)
    assert math.cos(0.1) < c[0].hi[0] < math.cos(0.1) + 1e-14
    # a full period: the whole range
    (s,) = enclose(sin, Interval(np.array([[-10.0]]), np.array([[0.0]])))
    assert s[0].lo[0] == -1.0 and s[0].hi[0] == 1.0


def test_undefined_operations_give_the_whole_line() -> None:
    div = _lowered(lambda x: x[0] / x[1], 2)
    (q,) = enclose(div, Interval(np.array([[1.0, -1.0]]), np.array([[2.0, 1.0]])))
    assert q[0].lo[0] == -np.inf and q[0].hi[0] == np.inf
    log = _lowered(ca.log)
    (lg,) = enclose(log, Interval(np.array([[-1.0]]), np.array([[1.0]])))
    assert lg[0].lo[0] == -np.inf and lg[0].hi[0] > 0
    # 0 x inf is not a number: the whole line, never NaN
    prod = Interval(np.array([0.0]), np.array([1.0])) * Interval(np.array([1.0]),
                                                                 np.array([np.inf]))
    assert prod.lo[0] <= 0.0 and prod.hi[0] == np.inf
    assert not np.any(np.isnan(prod.lo)) and not np.any(np.isnan(prod.hi))


def test_square_of_one_interval_is_not_a_product_of_two() -> None:
    # x*x over [-1, 2] is [0, 4]; the product of two independent intervals is [-2, 4]
    sq = _lowered(lambda x: x * x)
    (out,) = enclose(sq, Interval(np.array([[-1.0]]), np.array([[2.0]])))
    assert out[0].lo[0] == 0.0 and 4.0 <= out[0].hi[0] < 4.0 + 1e-14


def test_outward_rounding_encloses_exact_arithmetic() -> None:
    # 0.1 + 0.2 is not 0.3 in float64; the enclosure of the exact sum contains both
    add = _lowered(lambda x: x[0] + x[1], 2)
    (out,) = enclose(add, Interval(np.array([[0.1, 0.2]])))
    assert out[0].lo[0] < 0.1 + 0.2 < out[0].hi[0]
    assert out[0].lo[0] < 0.3 < out[0].hi[0]
    assert out[0].hi[0] - out[0].lo[0] < 1e-15


@pytest.mark.parametrize("name", ["matsumoto", "poincare", "randers", "minkowski", "sphere"])
def test_metric_hessians_enclosed_on_boxes(name: str) -> None:
    # the functions the certification bounds: Hess_x F, its x-gradient, d' Hess_v F d
    m = finsler.get_metric(name)
    x, v, d = ca.SX.sym("x", 2), ca.SX.sym("v", 2), ca.SX.sym("d", 2)
    f = m.F_sx(x, v)
    hx, _ = ca.hessian(f, x)
    hv, _ = ca.hessian(f, v)
    fn = lower(ca.Function("h", [ca.vertcat(x, v, d)],
                           [ca.vertcat(ca.reshape(hx, 4, 1), ca.mtimes([d.T, hv, d]))]))
    rng = np.random.default_rng(7)
    n = 200
    r = 0.6 * np.sqrt(rng.uniform(0, 1, n))
    a = rng.uniform(0, 2 * np.pi, n)
    c = np.stack([r * np.cos(a), r * np.sin(a)], 1)
    h = rng.uniform(0.005, 0.05, (n, 1))
    ang = rng.uniform(0, 2 * np.pi, n)
    vv = np.stack([np.cos(ang), np.sin(ang)], 1)
    dd = rng.normal(size=(n, 2))
    lo = np.concatenate([c - h, vv - 0.01, dd], 1)
    hi = np.concatenate([c + h, vv + 0.01, dd], 1)
    out = _check_contains(fn, lo, hi, samples=32)
    assert all(np.all(np.isfinite(iv.lo)) and np.all(np.isfinite(iv.hi)) for iv in out)


def test_bad_boxes_are_refused() -> None:
    fn = _lowered(ca.sin)
    with pytest.raises(ValueError, match="lo > hi"):
        enclose(fn, Interval(np.array([[1.0]]), np.array([[0.0]])))
    with pytest.raises(ValueError, match="last dimension"):
        enclose(fn, Interval(np.zeros((3, 2))))
    with pytest.raises(TypeError, match="expected 1 inputs"):
        enclose(fn, Interval(np.zeros((3, 1))), Interval(np.zeros((3, 1))))


def test_box_shapes_checked_on_both_bounds_and_one_box_accepted() -> None:
    """The last dimension of hi is checked as well as lo's (a wider hi is not silently
    cut), a wrong number of per-coordinate intervals is named, and a single box given as
    1-D arrays (broadcast along N) encloses like the same box in a batch of one."""
    fn = _lowered(lambda x: ca.sin(x[0]) * x[1], 2)
    with pytest.raises(ValueError, match="last dimension 2"):
        enclose(fn, Interval(np.zeros((3, 2)), np.ones((3, 3))))
    with pytest.raises(ValueError, match="input 0 needs 2 intervals, got 1"):
        enclose(fn, [Interval(0.0, 1.0)])
    lo, hi = np.array([0.2, 1.0]), np.array([0.7, 2.0])
    (one,) = enclose(fn, Interval(lo, hi))
    (batch,) = enclose(fn, Interval(lo[None], hi[None]))
    assert np.allclose(one[0].lo, batch[0].lo) and np.allclose(one[0].hi, batch[0].hi)
    assert one[0].lo <= np.sin(0.2) * 1.0 and one[0].hi >= np.sin(0.7) * 2.0
    assert one[0].hi <= np.sin(0.7) * 2.0 + 1e-12 and one[0].lo >= np.sin(0.2) - 1e-12


def test_logical_operations_are_certain_only_where_the_truth_is() -> None:
    from finsler.enclosures.intervals import _IntervalBackend as B

    t, f, u = Interval(np.array([1.0]), np.array([2.0])), Interval(np.zeros(1), np.zeros(1)), \
        Interval(np.array([-1.0]), np.array([1.0]))
    a = Interval(np.array([2.0]), np.array([3.0]))
    for got, lo, hi in [(B.logical_and(t, t), 1, 1), (B.logical_and(f, u), 0, 0),
                        (B.logical_and(u, t), 0, 1), (B.logical_or(f, f), 0, 0),
                        (B.logical_or(u, t), 1, 1), (B.logical_or(u, f), 0, 1),
                        (B.if_else_zero(t, a), 2, 3), (B.if_else_zero(f, a), 0, 0),
                        (B.if_else_zero(u, a), 0, 3)]:
        assert (got.lo[0], got.hi[0]) == (lo, hi)


def test_reciprocal_of_subnormals_keeps_the_true_value() -> None:
    """1 / x on tiny intervals overflows float64: the bound towards 0 is the largest float,
    not inf (found by hypothesis: [0, 2.2e-313] raised an overflow warning)."""
    pos = Interval(np.array([1e-320]), np.array([2.2250738585e-313])).reciprocal()
    assert np.isfinite(pos.lo[0]) and pos.lo[0] >= 1e308 and pos.hi[0] == np.inf
    neg = Interval(np.array([-2.2250738585e-313]), np.array([-1e-320])).reciprocal()
    assert neg.lo[0] == -np.inf and np.isfinite(neg.hi[0]) and neg.hi[0] <= -1e308
    zero = Interval(np.array([0.0]), np.array([2.2250738585e-313])).reciprocal()
    assert (zero.lo[0], zero.hi[0]) == (-np.inf, np.inf)
