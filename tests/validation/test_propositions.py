"""The paper's theory checked numerically: eq. (7), Proposition 1 (and where it fails),
Proposition 2 by exact dynamic programming of eqs. (9)-(11) on grids, Lemma 1 items 3-4
at every iteration, Remark 3's counterexample (eq. 13 with C = f o d).

Closed-form distances are the references; every check compares against an independent
quantity and can fail (negative controls included). Larger grids are marked ``slow``.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import finsler
from finsler import InputError
from validation import propositions as P
from validation import strategies as vs

SETTINGS = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
CURVED = ("poincare", "sphere")
CONSTANT = ("euclidean", "minkowski", "randers")


# ----------------------------------------------------------------------------------------
# strategies
# ----------------------------------------------------------------------------------------
@SETTINGS
@given(st.data())
def test_strategies_draw_points_inside_every_domain(data: st.DataObject) -> None:
    m = data.draw(vs.metrics())
    x = data.draw(vs.points(m))
    assert x.shape == (m.dim,) and x.dtype == np.float64
    assert m.domain.contains(x[None]).all()
    x, y = data.draw(vs.close_pairs(m, 0.05))
    assert 0 < np.linalg.norm(y - x) <= 0.05 + 1e-12
    assert m.domain.contains(np.stack([x, y])).all()


# ----------------------------------------------------------------------------------------
# eq. (7) on closed-form distances
# ----------------------------------------------------------------------------------------
@SETTINGS
@given(vs.metric_and_triple(vs.CLOSED_FORM))
def test_eq7_lower_bound_and_equality_at_midpoints(mt) -> None:
    m, x, y, z = mt
    d = lambda a, b: float(m.distance(a[None], b[None])[0])  # noqa: E731
    dxy = d(x, y)
    assert d(x, z) ** 2 + d(z, y) ** 2 >= 0.5 * dxy**2 * (1 - 1e-12) - 1e-15
    mid = m.geodesic(x[None], y[None], [0.5])[0, 0]
    assert d(x, mid) ** 2 + d(mid, y) ** 2 == pytest.approx(0.5 * dxy**2, rel=1e-9, abs=1e-14)
    assert d(x, mid) == pytest.approx(0.5 * dxy, rel=1e-8, abs=1e-12)


# ----------------------------------------------------------------------------------------
# Proposition 1
# ----------------------------------------------------------------------------------------
TS = 0.1 * 2.0 ** -np.arange(7)


@SETTINGS
@given(st.data())
def test_prop1_ratio_tends_to_one_at_first_order_on_curved_metrics(data: st.DataObject) -> None:
    m = finsler.get_metric(data.draw(st.sampled_from(CURVED)))
    x = data.draw(vs.points(m, shrink=0.8))
    ang = data.draw(st.floats(0, 2 * np.pi))
    u = np.array([np.cos(ang), np.sin(ang)])
    if not m.domain.contains(x + TS[0] * u).all():
        u = -u
    r = P.proposition1_rate(m, x, u, TS)
    # first-order prediction: d(x, x + t u) = t F(x, u) + t^2/2 <grad_x F(x, u), u> + O(t^3),
    # so |C/d - 1| = t |k| + O(t^2) with k = <grad_x F, u> / (2 F) (finite differences)
    h = 1e-6
    f = float(m.F(x, u))
    k = abs(float(m.F(x + h * u, u) - m.F(x - h * u, u)) / (2 * h) / (2 * f))
    assert r.err[-1] / TS[-1] == pytest.approx(k, abs=0.02 + 0.05 * k)  # C/d -> 1
    if k > 0.2:  # clearly first order: the fitted rate is 1
        assert 0.85 < r.rate < 1.2, r.rate
    elif k < 1e-3:  # grad_x F vanishes along u (e.g. at the centre): higher order
        assert r.rate > 1.6, r.rate


@SETTINGS
@given(vs.metrics(CONSTANT).flatmap(lambda m: vs.close_pairs(m, 0.5).map(lambda p: (m, p))))
def test_prop1_cost_is_the_distance_for_constant_norms(mp) -> None:
    m, (x, y) = mp
    assert float(m.cost(x, y)) == pytest.approx(float(m.distance(x[None], y[None])[0]), rel=1e-12)


@pytest.mark.parametrize("name", CONSTANT)
def test_for_constant_norms_no_curve_beats_the_straight_segment(name: str) -> None:
    """The closed-form ``distance`` of a constant norm is F(y - x), the same formula as C, so
    comparing the two proves nothing about the geometry. The independent check: the exact
    solver, free to bend the curve, finds no curve shorter than C(x, y)."""
    import solvers

    m = finsler.get_metric(name)
    pairs = finsler.sample_pairs(m, 5, seed=31)
    for x, y in pairs:
        d = solvers.distance(m, x, y, rtol=1e-10)
        assert d.converged, d.status
        assert float(m.cost(x, y)) == pytest.approx(d.distance, rel=1e-8)


def test_polygon_reference_distance_matches_closed_form() -> None:
    m = finsler.get_metric("poincare")
    x, y = np.array([-0.5, 0.3]), np.array([0.4, 0.5])
    exact = float(m.distance(x[None], y[None])[0])
    approx = P.polygon_distance(m, x, y, segments=16)
    assert approx >= exact * (1 - 1e-9)  # an upper bound
    assert approx == pytest.approx(exact, rel=2e-3)


def test_prop1_on_matsumoto_inside_its_convex_radius() -> None:
    m = finsler.get_metric("matsumoto")
    x = np.array([0.1, 0.05])
    assert np.linalg.norm(x) + 0.1 < m.convex_radius
    assert m.convexity(np.array([x]))[0] > 0
    ts = 0.1 * 2.0 ** -np.arange(5)
    r = P.proposition1_rate(m, x, np.array([0.6, 0.8]), ts)
    assert r.err[-1] < r.err[0] / 8
    assert 0.8 < r.rate < 1.25, r.rate


def test_convexification_is_F_where_F_is_convex() -> None:
    a = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    v = np.stack([np.cos(a), np.sin(a)], 1)
    for name, x in [("randers", [0.1, 0.2]), ("matsumoto", [0.1, -0.1])]:
        m = finsler.get_metric(name)
        f = m.F(np.broadcast_to(np.array(x), v.shape), v)
        fcc = P.convexified_F(m, np.array(x), v)
        np.testing.assert_allclose(fcc, f, rtol=1e-5)


def test_prop1_fails_where_matsumoto_is_not_convex() -> None:
    """At |p| = 0.6 > 0.29, C/d does not tend to 1 but to F/F** > 1: the two-segment
    zig-zag (an upper bound of d) is shorter than C by that factor."""
    m = finsler.get_metric("matsumoto")
    p = np.array([0.6, 0.0])
    assert m.convexity(p[None])[0] < 0
    ts = 0.05 * 2.0 ** -np.arange(6)
    r = P.proposition1_nonconvex(m, p, ts)
    assert r.limit > 1.3  # predicted F/F** from the convex hull of the indicatrix
    assert np.all(r.ratio > 1.3)  # C/d >= C/d_upper stays far above 1
    assert abs(r.ratio[-1] - r.limit) < 0.01 * r.limit  # and tends to F/F**
    assert abs(r.ratio[-1] - r.limit) < abs(r.ratio[0] - r.limit) / 8
    # control: inside the convex radius no direction has F > F**
    _, lim_inside = P.nonconvex_direction(m, np.array([0.2, 0.0]))
    assert lim_inside == pytest.approx(1.0, abs=1e-5)


# ----------------------------------------------------------------------------------------
# Proposition 2: exact DP of eqs. (9)-(11) on grids
# ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tables() -> dict[str, list[dict]]:
    return {
        name: P.proposition2_table(finsler.get_metric(name), (11, 15, 21), 4) for name in CURVED
    }


def _by_n(rows: list[dict]) -> dict[int, list[dict]]:
    out: dict[int, list[dict]] = {}
    for r in rows:
        out.setdefault(r["n"], []).append(r)
    return out


@pytest.mark.parametrize("name", CURVED)
def test_prop2_values_approach_d_as_the_grid_is_refined(tables, name: str) -> None:
    by_n = _by_n(tables[name])
    ns = sorted(by_n)
    best = [min(r["V_err_mean"] for r in by_n[n]) for n in ns]
    assert all(b1 < b0 for b0, b1 in itertools.pairwise(best)), best
    v0 = by_n[ns[-1]][0]["V_err_mean"]
    assert best[-1] < 0.25 * v0, (best[-1], v0)  # the DP improves much on V_0 = C
    # at a fixed iteration the error shrinks with the grid spacing
    i3 = [by_n[n][3]["V_err_mean"] for n in ns]
    assert all(b < a for a, b in itertools.pairwise(i3)), i3


@pytest.mark.parametrize("name", CURVED)
def test_prop2_policies_approach_midpoints_as_the_grid_is_refined(tables, name: str) -> None:
    by_n = _by_n(tables[name])
    ns = sorted(by_n)
    best = [min(r["mid_err_mean"] for r in by_n[n] if "mid_err_mean" in r) for n in ns]
    assert all(b1 < b0 for b0, b1 in itertools.pairwise(best)), best
    floors = [by_n[n][0]["mid_floor_max"] for n in ns]
    assert all(b < a for a, b in itertools.pairwise(floors)), floors
    # the first policy (from C) is worse than the best later one
    assert best[-1] < 0.6 * by_n[ns[-1]][0]["mid_err_mean"]


@pytest.mark.parametrize("name", CONSTANT)
def test_prop2_on_constant_norms_exact_midpoints_and_values_bound_d(name: str) -> None:
    m = finsler.get_metric(name)
    n = 9
    dp = P.run_grid_dp(m, n, 3)
    d = P.grid_distance(m, dp.points)
    np.testing.assert_allclose(dp.V[0], d, rtol=1e-12, atol=1e-15)  # C = d here
    for v in dp.V:  # V_i is the length of a grid path: never below d
        assert np.all(v >= d * (1 - 1e-12) - 1e-15)
    # pairs whose lattice midpoint exists get it as pi_0 (the unique minimiser of eq. 7)
    idx = {tuple(np.round(p, 9)): k for k, p in enumerate(dp.points)}
    checked = 0
    for a in range(len(dp.points)):
        for b in range(len(dp.points)):
            if a == b:
                continue
            mid = tuple(np.round(0.5 * (dp.points[a] + dp.points[b]), 9))
            if mid in idx:
                assert dp.pi[0][a, b] == idx[mid]
                checked += 1
    assert checked > 500


def test_lemma1_items_3_and_4_hold_at_every_iteration() -> None:
    for name in ("poincare", "sphere", "randers", "minkowski"):
        m = finsler.get_metric(name)
        dp = P.run_grid_dp(m, 11, 5)
        d = P.grid_distance(m, dp.points)
        deltas = [float(q) for q in np.quantile(d[d > 0], [0.05, 0.2, 0.5, 1.0])]
        rep = P.check_lemma1(dp, d, deltas)
        assert len(rep.item3) == 6 and len(rep.item4) == 5
        assert rep.holds, (name, rep.item3, rep.item4)


def test_lemma1_check_detects_a_broken_recursion() -> None:
    """Negative control: shrinking V at each step (not eq. 11) violates item 3."""
    m = finsler.get_metric("sphere")
    dp = P.run_grid_dp(m, 9, 3)
    d = P.grid_distance(m, dp.points)
    broken = P.GridDP(dp.points, [dp.V[0]] + [0.8 * v for v in dp.V[1:]], dp.pi, "squared",
                      dp.spacing)
    assert not P.check_lemma1(broken, d, [float(d.max()) + 1]).holds


@pytest.mark.parametrize("name", ("poincare", "minkowski"))
def test_remark3_sum_rule_stays_at_C(name: str) -> None:
    r = P.remark3(finsler.get_metric(name), n=11, iterations=4)
    assert r.stays  # V_i = C and pi_i(x, y) = x for every pair and iteration
    assert r.x_in_argmin_gap <= 1e-12  # x attains the minimum of eq. (13)
    assert r.gap_to_d > 0.2  # but C = f o d != d
    # the squared rule (eq. 10) from the same V_0 moves towards d
    assert r.squared_rule_err[2] < 0.6 * r.squared_rule_err[0]


def test_remark3_f_is_subadditive_with_unit_slope() -> None:
    h = np.linspace(0, 5, 101)
    hh = h[:, None] + h[None, :]
    assert np.all(P.remark3_f(hh) <= P.remark3_f(h)[:, None] + P.remark3_f(h)[None, :] + 1e-12)
    assert P.remark3_f(np.array(1e-8)) / 1e-8 == pytest.approx(1.0, rel=1e-6)


def test_bad_input_is_named() -> None:
    with pytest.raises(InputError, match="2-D"):
        P.grid_points(finsler.get_metric("carlike"), 5)
    with pytest.raises(InputError, match="rule"):
        P.run_grid_dp(finsler.get_metric("euclidean"), 5, 1, rule="max")
    with pytest.raises(InputError, match="closed-form"):
        P.grid_distance(finsler.get_metric("matsumoto"), np.zeros((3, 2)))
    with pytest.raises(InputError, match="V_0"):
        P.run_grid_dp(None, points=np.zeros((2, 2)), cost=np.full((2, 2), np.nan))


@pytest.mark.slow
@pytest.mark.parametrize("name", CURVED)
def test_prop2_larger_grids(name: str) -> None:
    rows = P.proposition2_table(finsler.get_metric(name), (17, 25, 33), 5)
    by_n = _by_n(rows)
    ns = sorted(by_n)
    best = [min(r["V_err_mean"] for r in by_n[n]) for n in ns]
    assert all(b1 < b0 for b0, b1 in itertools.pairwise(best)), best
    assert best[-1] < 0.035
    mids = [min(r["mid_err_mean"] for r in by_n[n] if "mid_err_mean" in r) for n in ns]
    assert all(b1 < b0 for b0, b1 in itertools.pairwise(mids)), mids
    dp = P.run_grid_dp(finsler.get_metric(name), 25, 5)
    d = P.grid_distance(finsler.get_metric(name), dp.points)
    assert P.check_lemma1(dp, d, [0.3, 1.0, float(d.max()) + 1]).holds
