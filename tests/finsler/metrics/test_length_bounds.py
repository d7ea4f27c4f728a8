"""``Metric.path_length_bounds`` (issue 22, mutation testing): the proven interval contains
the closed-form or adaptive-quadrature length, is as narrow as ``rtol`` says, halves only
where needed, falls back to the zeroth-order enclosure ``tau [F(box, d)]`` where the second
derivative is unbounded (a kink), and is infinite (never wrong) where F itself is. Fast:
every test is well under a second, so that mutation runs can afford them."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import quad

import finsler
from finsler import InputError
from finsler.metrics.base import MAX_LENGTH_HALVINGS

from tests.helpers.metrics.singular import Cone

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


def _quad_length(m: finsler.Metric, pts: np.ndarray) -> float:
    """Adaptive quadrature of ``int F(x(t), x'(t)) dt`` segment by segment."""
    total = 0.0
    for a, b in itertools.pairwise(pts):
        d = b - a
        val, err = quad(lambda t, a=a, d=d: float(np.asarray(
            m.F((a + t * d)[None], d[None], check=False)).reshape(-1)[0]), 0.0, 1.0,
            epsabs=0.0, epsrel=1e-13, limit=200)
        assert err < 1e-11 * max(val, 1.0)
        total += val
    return total


def test_euclidean_bounds_are_the_polyline_length_to_a_few_ulp() -> None:
    m = finsler.get_metric("euclidean")
    pts = np.array([[0.0, 0.0], [0.3, 0.4], [0.3, -0.2], [-0.5, -0.2]])
    exact = 0.5 + 0.6 + 0.8
    bd = m.path_length_bounds(pts)
    assert bd.lower <= exact <= bd.upper
    assert bd.upper - bd.lower < 1e-14
    assert bd.lower > exact - 1e-14
    # F is linear along segments (Hess_x F = 0): one piece each, converged
    assert bd.pieces == 3 and isinstance(bd.pieces, int)
    assert bd.converged is True


def test_poincare_radial_segment_against_the_closed_form() -> None:
    """From the origin to ``(r, 0)``: ``int_0^r 2 / (1 - t**2) dt = 2 artanh r``."""
    m = finsler.get_metric("poincare")
    for r in (0.1, 0.5, 0.75):
        exact = 2.0 * math.atanh(r)
        pts = np.array([[0.0, 0.0], [r, 0.0]])
        bd = m.path_length_bounds(pts, rtol=1e-9)
        assert bd.lower <= exact <= bd.upper, r
        assert bd.upper - bd.lower <= 1e-9 * exact, r
        assert bd.upper - bd.lower >= 1e-13 * exact, r  # honest: the midpoint rule's error
        assert bd.converged
        assert bd.pieces > 1
        # reversed: the same length (F is reversible)
        back = m.path_length_bounds(pts[::-1], rtol=1e-9)
        assert back.lower <= exact <= back.upper


@pytest.mark.parametrize("name", ["poincare", "randers", "matsumoto"])
def test_bounds_contain_the_quadrature_length_of_a_polyline(name: str) -> None:
    m = finsler.get_metric(name)
    rng = np.random.default_rng(7)
    c = np.asarray(m.domain.project(rng.uniform(-0.4, 0.4, (4, 2))), float)
    ref = _quad_length(m, c)
    for rtol in (1e-3, 1e-9):
        bd = m.path_length_bounds(c, rtol=rtol)
        assert bd.lower <= ref <= bd.upper, (name, rtol, bd, ref)
        assert bd.upper - bd.lower <= rtol * ref * (1 + 1e-9) + 1e-14, (name, rtol)
        assert bd.converged
    # narrower tolerance, more pieces, nested intervals
    wide = m.path_length_bounds(c, rtol=1e-3)
    narrow = m.path_length_bounds(c, rtol=1e-9)
    assert narrow.pieces >= wide.pieces >= 3
    if name != "randers":  # (Randers: F affine in x, the midpoint rule is exact)
        assert narrow.pieces > wide.pieces
    assert wide.lower <= narrow.lower and narrow.upper <= wide.upper


def test_pieces_are_halved_only_where_needed() -> None:
    """A tiny segment near the centre is accurate at once; a long one reaching towards the
    rim is halved (and each half is halved independently)."""
    m = finsler.get_metric("poincare")
    pts = np.array([[0.0, 0.0], [1e-3, 0.0], [0.7, 0.0]])
    bd = m.path_length_bounds(pts, rtol=1e-6)
    exact = 2.0 * math.atanh(0.7)
    assert bd.lower <= exact <= bd.upper and bd.upper - bd.lower <= 1e-6 * exact
    one = m.path_length_bounds(pts[:2], rtol=1e-6)
    assert one.pieces == 1
    long = m.path_length_bounds(pts[1:], rtol=1e-6)
    assert bd.pieces == 1 + long.pieces and long.pieces > 8
    # where a piece hits the halving limit: the bound is still proven, not converged
    tight = m.path_length_bounds(pts[1:], rtol=1e-15)
    assert not tight.converged
    assert tight.pieces <= 2**MAX_LENGTH_HALVINGS
    assert tight.lower <= exact - 2.0 * math.atanh(1e-3) <= tight.upper
    # a pieces' count of an accurate run is below the limit and within the rule's factor
    assert long.pieces < 2**MAX_LENGTH_HALVINGS


def test_bounds_of_a_segment_split_by_hand_agree() -> None:
    """Splitting a segment at its midpoint by hand gives the same pieces as the halving."""
    m = finsler.get_metric("poincare")
    whole = m.path_length_bounds(np.array([[-0.6, 0.1], [0.6, 0.3]]), rtol=1e-8)
    split = m.path_length_bounds(np.array([[-0.6, 0.1], [0.0, 0.2], [0.6, 0.3]]), rtol=1e-8)
    ref = _quad_length(m, np.array([[-0.6, 0.1], [0.6, 0.3]]))
    for bd in (whole, split):
        assert bd.lower <= ref <= bd.upper
        assert bd.upper - bd.lower <= 1e-8 * ref
    assert abs(whole.lower - split.lower) < 1e-8 * ref


def test_unbounded_second_derivative_falls_back_to_the_enclosure_of_f() -> None:
    """Through the cone's apex f'' is unbounded: the pieces there take ``tau [F(box, d)]``
    (issue 46: a finite bound at kinks), so the bound is finite and contains the closed form
    ``int_{-0.5}^{0.5} (1 + |t|) dt = 1.25``; rtol 1e-9 is out of reach of the zeroth-order
    pieces within the halvings, so it is not converged."""
    m = Cone()
    pts = np.array([[-0.5, 0.0], [0.5, 0.0]])  # through the origin
    bd = m.path_length_bounds(pts)
    assert bd.lower <= 1.25 <= bd.upper and bd.upper - bd.lower <= 2e-8
    assert not bd.converged
    coarse = m.path_length_bounds(pts, rtol=0.9)  # one piece: tau [F(box)] = [1, 1.5]
    assert coarse.pieces == 1 and coarse.lower <= 1.0 + 1e-12 and coarse.upper >= 1.5 - 1e-12
    # away from the origin it is finite: int_{-0.5}^{0.5} (1 + sqrt(t**2 + 0.01)) dt
    off = m.path_length_bounds(np.array([[-0.5, 0.1], [0.5, 0.1]]), rtol=1e-8)
    ref = 1.0 + 2 * quad(lambda t: math.sqrt(t * t + 0.01), 0.0, 0.5, epsrel=1e-13)[0]
    assert off.lower <= ref <= off.upper and off.upper - off.lower <= 1e-8 * ref
    assert off.converged


def test_lower_bound_never_negative() -> None:
    m = finsler.get_metric("euclidean")
    bd = m.path_length_bounds(np.array([[0.1, 0.1], [0.1, 0.1]]))
    assert bd.lower == 0.0 and 0.0 <= bd.upper < 1e-100


def test_bad_input_is_an_input_error() -> None:
    m = finsler.get_metric("poincare")
    pts = np.array([[0.0, 0.0], [0.3, 0.0]])
    for bad in (pts[:1], pts[:, :1], pts[None], np.zeros(2)):
        shape = str(bad.shape).replace("(", r"\(").replace(")", r"\)")
        with pytest.raises(InputError, match=rf"^points must have shape \(n\+1, 2\) with n >= 1, "
                                             rf"got {shape}$"):
            m.path_length_bounds(bad)
    for rtol in (0.0, 1.0, -1e-3, 2.0, True, "1e-3", None):
        with pytest.raises(InputError, match="rtol must be in"):
            m.path_length_bounds(pts, rtol=rtol)
    assert m.path_length_bounds(pts, rtol=0.5).converged
    with pytest.raises(InputError, match=r"^points row 1 = \(0.9, 0.0\) lies outside"):
        m.path_length_bounds(np.array([[0.0, 0.0], [0.9, 0.0]]))  # outside the disk


def test_any_real_input_is_taken_as_float64() -> None:
    """float32 or integer points: the bounds of the same points in float64 (the
    arithmetic is float64 whatever the input's type)."""
    m = finsler.get_metric("poincare")
    p32 = np.array([[0.1, -0.2], [0.3, 0.5], [-0.6, 0.1]], dtype=np.float32)
    assert m.path_length_bounds(p32) == m.path_length_bounds(p32.astype(np.float64))
    e = finsler.get_metric("euclidean")
    ints = [[0, 0], [1, 0], [1, 1], [-1, 1]]
    bd = e.path_length_bounds(ints)
    assert bd == e.path_length_bounds(np.array(ints, float))
    assert bd.lower <= 4.0 <= bd.upper


def test_non_finite_enclosures_of_either_sign_give_zero_and_inf(monkeypatch) -> None:
    """Whatever the enclosures hold (+inf, -inf, both, on different pieces), the bounds
    are the trivially valid ``[0, inf]``, never an exception or a NaN. The enclosures are
    faked by position along the x axis: F in [+inf, +inf] left, a second derivative in
    [-inf, inf] in the middle, F in [-inf, -inf] right."""
    import finsler.enclosures.intervals as fi

    def fake(fn, x, v):
        n = x[0].lo.shape[0]
        mid = x[0].lo
        f = np.where(mid < -0.3, np.inf, np.where(mid > 0.3, -np.inf, 1.0))
        q_lo = np.where(np.abs(mid) <= 0.3, -np.inf, 0.0)
        q_hi = np.where(np.abs(mid) <= 0.3, np.inf, 0.0)
        return [fi.Interval(f + np.zeros(n))], [fi.Interval(q_lo + np.zeros(n), q_hi)]

    monkeypatch.setattr(fi, "enclose", fake)
    m = finsler.get_metric("euclidean")
    pts = np.array([[-0.9, 0.0], [-0.5, 0.0], [-0.1, 0.0], [0.1, 0.0], [0.5, 0.0],
                    [0.9, 0.0]])
    bd = m.path_length_bounds(pts)
    assert bd.lower == 0.0 and bd.upper == math.inf and not bd.converged


def test_carlike_segment_across_its_kink_has_a_finite_bound_holding_the_length() -> None:
    """Car-like's ``max(r_min |v_th| - u, 0)`` switches along this segment (at
    ``cos(theta) = 0.6``), where the enclosure of f'' is infinite on every box around the
    switch (checked here, so the fallback is what is tested); the bound is finite, narrow
    and contains the adaptive quadrature of the integrand."""
    from finsler.enclosures.intervals import Interval, enclose

    m = finsler.get_metric("carlike")
    a, b = np.array([0.0, 0.0, 0.6]), np.array([0.5, 0.0, 1.2])
    d = b - a
    t_kink = (math.acos(0.6) - 0.6) / 0.6
    lo, hi = a + (t_kink - 1e-6) * d, a + (t_kink + 1e-6) * d
    box = [Interval(np.array([min(u, w)]), np.array([max(u, w)])) for u, w in zip(lo, hi)]
    _, q = enclose(m._length_enclosure, box, [Interval(np.array([x])) for x in d])
    assert not np.isfinite(q[0].hi[0])
    bd = m.path_length_bounds(np.stack([a, b]))
    ref = _quad_length(m, np.stack([a, b]))
    assert bd.lower <= ref <= bd.upper and bd.upper - bd.lower <= 1e-8 * ref
