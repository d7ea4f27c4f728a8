"""Fast tests of solvers/newton/driver.py (the `batched` group of
benchmarks/mutation.py): the row bookkeeping on crafted batches whose answers are counted
by hand, and whole batched solves checked against closed-form distances (euclidean,
poincare), seed counts from the plan's own numbers, and status propagation of rows that
cannot converge."""

from __future__ import annotations

import time

import numpy as np
import pytest

from finsler import CarLike, Euclidean, Poincare
from solvers import SeedPlan
from solvers.newton.driver import (
    AGREE_RTOL,
    BatchOptions,
    BatchSolution,
    Rows,
    _agreeing,
    _best,
    _best_of,
    _carried,
    _level,
    covers,
    covers_opt_in,
    residuals,
    solve_pairs_batched,
)
from solvers.newton.energy import NewtonOptions
from solvers.status import NewtonStatus

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation

C, MI, ST = int(NewtonStatus.CONVERGED), int(NewtonStatus.MAX_ITERATIONS), int(
    NewtonStatus.STALLED)


def _rows(pair, energy, status, points=None, iterations=None):
    pair = np.asarray(pair, dtype=np.int64)
    r = len(pair)
    pts = np.zeros((r, 3, 2)) if points is None else np.asarray(points, float)
    it = np.arange(1, r + 1) if iterations is None else np.asarray(iterations)
    return Rows(pair, [f"r{i}" for i in range(r)], pts, np.asarray(energy, float),
                np.asarray(status, dtype=np.int64), it.astype(np.int64),
                np.full(r, 1e-12))


# ---------------------------------------------------------------- bookkeeping of rows
def test_rows_ok_take_cat():
    r = _rows([0, 0, 1, 1], [1.0, np.nan, 2.0, 3.0], [C, C, MI, C])
    assert r.ok.tolist() == [True, False, False, True]
    t = r.take([3, 0])
    assert t.names == ["r3", "r0"] and t.pair.tolist() == [1, 0]
    assert t.energy.tolist() == [3.0, 1.0] and t.status.tolist() == [C, C]
    assert t.iterations.tolist() == [4, 1] and t.residual.shape == (2,)
    unsolved = Rows(np.array([0, 1]), ["a", "b"], np.ones((2, 3, 2)))
    assert len(unsolved.take([1]).energy) == 0 and unsolved.take([1]).names == ["b"]
    c = Rows.cat([r, Rows(np.zeros(0, dtype=np.int64), [], np.zeros((0, 3, 2))), t])
    assert len(c) == 6 and c.names == r.names + t.names
    assert c.energy.tolist()[4:] == [3.0, 1.0] and c.iterations.tolist()[:4] == [1, 2, 3, 4]
    assert c.status.tolist()[4:] == [C, C] and c.residual.shape == (6,)
    assert c.pair.tolist() == [0, 0, 1, 1, 1, 0]
    mixed = Rows.cat([r, unsolved])   # one part unsolved: the result is unsolved
    assert len(mixed) == 6 and len(mixed.energy) == 0
    empty = Rows.cat([])
    assert len(empty) == 0 and empty.points.shape == (0, 0, 0) and empty.pair.dtype == np.int64


def test_best_prefers_converged_then_lowest_finite():
    # pair 0: converged 3.0 beats unconverged 1.0; pair 1: none converged, lowest finite
    # 5.0 (NaN ignored); pair 2: only NaN -> -1; pair 3: no rows -> -1
    r = _rows([0, 0, 0, 1, 1, 1, 2], [1.0, 3.0, 4.0, np.nan, 6.0, 5.0, np.nan],
              [MI, C, C, C, ST, MI, C])
    assert _best(r, 4).tolist() == [1, 5, -1, -1]


def test_best_of_subsets():
    r = _rows([0, 0, 1, 1], [1.0, 2.0, 3.0, 0.5], [C, C, C, C])
    assert _best_of(r, 2, np.ones(4, bool)).tolist() == [0, 3]
    assert _best_of(r, 2, np.zeros(4, bool)).tolist() == [-1, -1]
    assert _best_of(r, 3, np.array([False, True, True, False])).tolist() == [1, 2, -1]
    assert _best_of(r, 2, np.array([False, False, True, False])).tolist() == [-1, 2]
    assert _best_of(r, 2, np.array([True, False, False, False])).tolist() == [0, -1]


def test_agreeing_counts_by_hand():
    e = [1.0, 1.0 + 0.5e-6, 1.0 + 2e-6, 1.0, 0.9, 2.0, 2.0 * (1 + 0.9 * AGREE_RTOL), 0.0, 0.0,
         0.0 + 1e-12]
    s = [C, C, C, MI, ST, C, C, C, C, C]
    r = _rows([0, 0, 0, 0, 0, 1, 1, 2, 2, 2], e, s)
    # pair 0: 1.0 and 1.0+5e-7 (the unconverged 1.0 and 0.9 count for nothing, nor set
    # the best); pair 1: both; pair 2: the two exact zeros (1e-12 > 1e-6 * 1e-300)
    assert _agreeing(r, 4).tolist() == [2, 2, 2, 0]


def _line(a, b, n=3):
    t = np.linspace(0, 1, n)[:, None]
    return (1 - t) * np.asarray(a, float) + t * np.asarray(b, float)


def test_carried_keeps_distinct_optima_in_band():
    base = _line([0, 0], [1, 0])
    up = base + np.array([0, 0.1])       # another optimum (0.1 away)
    up2 = base + np.array([0, 0.2])
    near = base + 1e-6                   # the best again, within tol
    pts = [base, near, up, up2, base + np.array([0, -0.1]), base, up]
    e = [1.0, 1.0, 1.01, 1.02, 1.2, 0.5, 0.7]
    s = [C, C, C, C, C, MI, MI]
    r = _rows([0, 0, 0, 0, 0, 1, 1], e, s, points=pts)
    # pair 0: best (0), `near` is the same optimum, `up` and `up2` in the 5 % band, row 4
    # is 20 % above; keep 3 -> 0, 2, 3; keep 2 -> 0, 2. Pair 1 has no converged row:
    # its `keep` lowest finite rows
    assert _carried(r, 2, 3, 0.05, 1e-4).tolist() == [0, 2, 3, 5, 6]
    assert _carried(r, 2, 2, 0.05, 1e-4).tolist() == [0, 2, 5, 6]
    assert _carried(r, 2, 1, 0.05, 1e-4).tolist() == [0, 5]
    assert _carried(r, 2, 3, 0.015, 1e-4).tolist() == [0, 2, 5, 6]
    assert _carried(r, 2, 3, 0.5, 1e-4).tolist() == [0, 2, 3, 5, 6]   # keep caps it
    assert _carried(r, 2, 4, 0.5, 1e-4).tolist() == [0, 2, 3, 4, 5, 6]
    # a tolerance wider than the optima's distance merges them
    assert _carried(r, 2, 3, 0.05, 0.15).tolist() == [0, 3, 5, 6]
    assert _carried(r, 2, 3, 0.05, 0.25).tolist() == [0, 5, 6]


def test_carried_no_converged_orders_by_energy():
    pts = [_line([0, 0], [1, j]) for j in range(4)]
    r = _rows([0, 0, 0, 0], [3.0, 1.0, np.nan, 2.0], [MI, MI, MI, ST], points=pts)
    assert _carried(r, 1, 2, 0.05, 1e-4).tolist() == [1, 3]
    assert _carried(r, 1, 3, 0.05, 1e-4).tolist() == [0, 1, 3]


def test_level_and_solution_views():
    r = _rows([1, 0, 1, 1], [1, 1, 1, 1], [C] * 4, iterations=[2, 3, 5, 7])
    lv = _level(r, 3, 16)
    assert lv["segments"] == 16 and "polish" not in lv
    assert lv["solved"].tolist() == [1, 3, 0] and lv["iterations"].tolist() == [3, 14, 0]
    assert lv["iterations"].dtype == np.int64
    assert _level(r, 2, 8, polish=True)["polish"] is True
    sol = BatchSolution(r, np.array([1, 0, -1]), np.zeros(3), np.zeros(3), np.zeros(3),
                        [lv, _level(r, 3, 32, polish=True)], {})
    assert sol.levels_of(1) == [{"segments": 16, "solved": 3, "iterations": 14},
                                {"segments": 32, "solved": 3, "iterations": 14,
                                 "polish": True}]
    assert [x.tolist() for x in sol.rows_of()] == [[1], [0, 2, 3], []]


def test_covers():
    assert covers(Euclidean(2)) and covers_opt_in(Euclidean(2))
    car = CarLike()
    assert not covers(car)
    assert covers_opt_in(car) == car.provides("smooth_square_sx")


# ---------------------------------------------------------------- whole batched solves
PAIRS = np.array([[[-0.5, -0.2], [0.5, 0.3]], [[0.1, 0.6], [-0.4, -0.5]]])


def _energy_line(m, pairs, n):
    return m.distance(pairs[:, 0], pairs[:, 1]) ** 2 / n


def test_euclidean_ladder_restarts_polish():
    m, n = Euclidean(2), 8
    plan = SeedPlan(bulges=(0.3,), random=1, graph=False, coarse=4, factor=2, refine_top=2,
                    restarts=2, polish=2, seed=3)
    t0 = time.perf_counter()
    s = solve_pairs_batched(m, PAIRS, n, plan)
    elapsed = time.perf_counter() - t0
    assert sum(d["wall_time"] for d in s.stats["levels"]) <= elapsed
    assert s.stats["value_evaluations"] >= 0     # reported (its count is newton.py's)
    S = 1 + 2 * len(plan.bulges) + plan.random          # straight, two bulges, random
    assert s.seeds_tried.tolist() == [S, S]
    # every seed and restart reaches the one straight line: all agree
    assert s.seeds_agreeing.tolist() == [S + plan.restarts] * 2
    assert len(s.first) == 2 * (S + plan.restarts)
    assert s.first.names[:S] == ["straight", "bulge+0.3", "bulge-0.3", "random0"] or \
        len(set(s.first.names[:S])) == S
    assert sum("~" in nm for nm in s.first.names) == 2 * plan.restarts
    assert [lv["segments"] for lv in s.levels] == [4, 8, 8]
    assert [lv.get("polish", False) for lv in s.levels] == [False, False, True]
    assert s.levels[0]["solved"].tolist() == [S + plan.restarts] * 2
    assert s.levels[1]["solved"].tolist() == [1, 1]     # one optimum carried
    assert s.levels[2]["solved"].tolist() == [plan.polish] * 2
    assert [d["rows"] for d in s.stats["levels"]] == [2 * (S + plan.restarts), 2, 4]
    assert [d["segments"] for d in s.stats["levels"]] == [4, 8, 8]
    assert s.stats["levels"][2]["polish"] is True and s.stats["evaluations"] > 0
    assert all(d["wall_time"] >= 0 for d in s.stats["levels"])
    assert s.iterations.tolist() == sum(lv["iterations"] for lv in s.levels).tolist()
    assert s.final.names == ["straight@4", "straight@4", "straight@4~p0", "straight@4~p1",
                             "straight@4~p0", "straight@4~p1"]
    assert s.final.pair.tolist() == [0, 1, 0, 0, 1, 1]
    assert (s.final.status == C).all()
    np.testing.assert_allclose(s.final.energy[s.best], _energy_line(m, PAIRS, n), rtol=1e-9)
    # the best path is the closed-form geodesic at equal spacing
    geo = m.geodesic(PAIRS[:, 0], PAIRS[:, 1], np.linspace(0, 1, n + 1))
    np.testing.assert_allclose(s.final.points[s.best], geo, atol=1e-8)
    assert (s.final.residual <= NewtonOptions().gtol).all()
    np.testing.assert_allclose(residuals(m, s.final.points), s.final.residual, atol=1e-11)


def test_restart_and_polish_curves_are_perturbed_from_the_best():
    m, n = Euclidean(2), 8
    plan = SeedPlan(bulges=(), graph=False, coarse=None, restarts=3, polish=2,
                    restart_scale=0.1, polish_scale=0.05, seed=11)
    s = solve_pairs_batched(m, PAIRS, n, plan)
    assert s.seeds_tried.tolist() == [1, 1]
    assert s.first.names == ["straight", "straight", "straight~0", "straight~1", "straight~2",
                             "straight~0", "straight~1", "straight~2"]
    assert s.first.pair.tolist() == [0, 1, 0, 0, 0, 1, 1, 1]
    assert s.seeds_agreeing.tolist() == [4, 4]
    assert s.final.names[len(s.first):] == ["straight~p0", "straight~p1"] * 2
    assert s.final.pair[len(s.first):].tolist() == [0, 0, 1, 1]
    assert [lv["segments"] for lv in s.levels] == [n, n]
    # restarts converge to the line: restart rows took iterations (they were perturbed)
    assert (s.first.iterations[2:] > 0).all() and (s.final.iterations[len(s.first):] > 0).all()
    np.testing.assert_allclose(s.final.energy, np.repeat(_energy_line(m, PAIRS, n), [1, 1])
                               [s.final.pair], rtol=1e-9)


def _near_geodesic(m, paths, d):
    """The paths' lengths by the closed-form distance of consecutive points: at least
    ``d`` (triangle inequality) and within 0.1 % of it."""
    for p, dk in zip(paths, d):
        length = m.distance(p[:-1], p[1:]).sum()
        assert dk * (1 - 1e-12) <= length <= dk * (1 + 1e-3)


def test_poincare_distance_and_given_rows():
    m, n = Poincare(), 16
    pairs = np.array([[[-0.6, 0.1], [0.5, 0.2]], [[0.0, -0.6], [0.2, 0.6]]])
    ts = np.linspace(0, 1, n + 1)[:, None]
    bent = [(1 - ts) * p[0] + ts * p[1] + 0.2 * np.sin(np.pi * ts) for p in pairs]
    wave = 0.05 * np.sin(2 * np.pi * ts)
    given = [[("mine", bent[0]), ("mine2", bent[0] + wave)], [("yours", bent[1])]]
    plan = SeedPlan(bulges=(0.3,), graph=False, coarse=4, factor=2, refine_top=3)
    s = solve_pairs_batched(m, pairs, n, plan, given=given)
    d = m.distance(pairs[:, 0], pairs[:, 1])
    _near_geodesic(m, s.final.points[s.best], d)
    assert {"mine", "mine2", "yours"} <= set(s.final.names)
    assert s.final.pair[s.final.names.index("yours")] == 1
    assert s.levels[-1]["segments"] == n
    assert [lv["segments"] for lv in s.levels] == [4, 8, 16]
    # carried rows name the size they were seeded at once (not "@4@8"); given rows
    # join at the final size only, once each
    carried = [nm for nm in s.final.names if "@" in nm]
    assert carried and all(nm.count("@") == 1 and nm.endswith("@4") for nm in carried)
    assert sorted(nm for nm in s.final.names if "@" not in nm) == ["mine", "mine2", "yours"]
    assert len(s.final) == s.levels[-1]["solved"].sum() == s.stats["levels"][-1]["rows"]
    assert s.levels[1]["solved"].sum() == s.stats["levels"][1]["rows"] == len(carried)
    # the given rows are solved at the last level only (3 of pair 0's are given + carried)
    assert s.levels[-1]["solved"][0] >= 2 and s.levels[-1]["solved"][1] >= 1
    # given paths alone (no seeds): tried = given count, one level, agreement counted
    a = solve_pairs_batched(m, pairs, n, plan, given=given, global_seeds=False)
    assert a.seeds_tried.tolist() == [2, 1] and len(a.levels) == 1
    assert a.final.names == ["mine", "mine2", "yours"] and a.first is a.final
    assert a.seeds_agreeing.tolist() == [2, 1]
    _near_geodesic(m, a.final.points[a.best], d)
    np.testing.assert_allclose(a.final.energy[a.best], s.final.energy[s.best], rtol=1e-9)


def test_given_row_at_single_size_and_not_polished():
    m, n = Euclidean(2), 8
    off = [[("w", _line(*PAIRS[0], n + 1) + 0.05 * np.sin(np.pi * np.linspace(0, 1, n + 1))
             [:, None])], []]
    plan = SeedPlan(bulges=(), graph=False, coarse=None, polish=1, seed=2)
    s = solve_pairs_batched(m, PAIRS, n, plan, given=off)
    assert s.seeds_tried.tolist() == [1, 1]
    assert "w" in s.first.names and s.final.names[-2:] == ["straight~p0", "straight~p0"]
    assert s.seeds_agreeing.tolist() == [2, 1]


def test_unconverged_rows_report_their_status():
    m, n = Poincare(), 16
    pairs = np.array([[[-0.6, 0.1], [0.5, 0.2]]])
    plan = SeedPlan(bulges=(0.4,), graph=False, coarse=None)
    s = solve_pairs_batched(m, pairs, n, plan, BatchOptions(newton=NewtonOptions(max_iter=1)))
    assert (s.final.status == MI).all() and not s.final.ok.any()
    assert s.seeds_agreeing.tolist() == [0] and s.best[0] == int(np.argmin(s.final.energy))
    assert s.iterations.tolist() == [3]


def test_drop_losers_stop_bad_rows():
    m, n = Poincare(), 16
    pairs = np.array([[[-0.6, 0.1], [0.5, 0.2]], [[0.0, -0.6], [0.2, 0.6]]])
    plan = SeedPlan(bulges=(0.8,), graph=False, coarse=None, drop_after=1, drop_factor=1.01)
    s = solve_pairs_batched(m, pairs, n, plan)
    full = solve_pairs_batched(m, pairs, n, SeedPlan(bulges=(0.8,), graph=False, coarse=None))
    assert (full.final.status == C).all()
    # the far bulges lose at once and stop, unconverged; the straight lines converge
    st = s.final.status.reshape(2, 3)
    assert (st[:, 0] == C).all() and (st == int(NewtonStatus.DROPPED)).sum() >= 2
    assert set(st.ravel().tolist()) <= {C, int(NewtonStatus.DROPPED)}
    assert s.iterations.sum() < full.iterations.sum()
    np.testing.assert_allclose(s.final.energy[s.best], full.final.energy[full.best], rtol=1e-9)


def test_graph_seeds_are_counted():
    m, n = Euclidean(2), 8
    plan = SeedPlan(bulges=(), graph=True, routes=2, coarse=None)
    s = solve_pairs_batched(m, PAIRS, n, plan)
    graph = [sum(nm.startswith("graph") for nm, p in zip(s.first.names, s.first.pair)
                 if p == k) for k in range(2)]
    assert min(graph) >= 1
    assert s.seeds_tried.tolist() == [1 + g for g in graph]
    # every row (graph ones included) runs from the pair's start to its goal
    np.testing.assert_array_equal(s.final.points[:, 0], PAIRS[s.final.pair, 0])
    np.testing.assert_array_equal(s.final.points[:, -1], PAIRS[s.final.pair, 1])
    np.testing.assert_allclose(s.final.energy, _energy_line(m, PAIRS, n)[s.final.pair],
                               rtol=1e-9)


@pytest.mark.parametrize("k", [0, 1])
def test_pairs_independent(k):
    m, n = Euclidean(2), 8
    plan = SeedPlan(bulges=(0.3,), graph=False, coarse=4, factor=2)
    both = solve_pairs_batched(m, PAIRS, n, plan)
    one = solve_pairs_batched(m, PAIRS[k:k + 1], n, plan)
    np.testing.assert_allclose(both.final.energy[both.best[k]], one.final.energy[one.best[0]],
                               rtol=1e-12)


# ---------------------------------------------------------------- second iteration
def test_exact_ties_and_empty_takes():
    # 1e-6 * 1e6 == 1.0 exactly: a row exactly AGREE_RTOL above the best agrees
    r = _rows([0, 0], [1e6, 1e6 + 1.0], [C, C])
    assert AGREE_RTOL * 1e6 == 1.0 and _agreeing(r, 1).tolist() == [2]
    assert len(r.take([])) == 0 and len(r.take([]).energy) == 0
    empty = Rows.cat([])
    assert empty.pair.shape == (0,)


def test_carried_pairs_do_not_share_their_kept_lists():
    base = _line([0, 0], [1, 0])
    off = [base + np.array([0, 0.1 * j]) for j in range(4)]
    # pair 0: best, alt 0.1, a copy of the alt (within tol of it, not of the best), alt
    # 0.3; pair 1: best, alt 0.2; row 6 at exactly the band's edge (1 * 1.5), row 7
    # exactly tol (0.5 in y) from pair 1's best
    pts = [off[0], off[1], off[1] + 1e-6, off[3], off[0], off[2], off[3] + 2.0, off[0] + 0.5]
    e = [1.0, 1.1, 1.1 + 1e-9, 1.2, 1.0, 1.1, 1.5, 1.2]
    r = _rows([0, 0, 0, 0, 1, 1, 1, 1], e, [C] * 8, points=pts)
    assert _carried(r, 2, 3, 0.5, 0.05).tolist() == [0, 1, 3, 4, 5, 7]
    assert _carried(r, 2, 5, 0.5, 0.05).tolist() == [0, 1, 3, 4, 5, 6, 7]
    assert _carried(r, 2, 2, 0.5, 0.05).tolist() == [0, 1, 4, 5]
    # tol 0.5: everything within 0.5 of a kept path (row 7 exactly) is the same optimum
    assert _carried(r, 2, 5, 0.5, 0.5).tolist() == [0, 4, 6]


class _FakeState:
    def __init__(self, status, energy, active):
        self.status = np.asarray(status, dtype=np.int64)
        self.energy = np.asarray(energy, float)
        self.active = np.asarray(active, dtype=np.int64)
        self.dropped: list[int] = []

    def drop(self, idx):
        self.dropped.extend(int(i) for i in idx)


def test_drop_losers_rule_by_hand():
    from solvers.newton.driver import _Runner
    R = int(NewtonStatus.RUNNING)
    # pair 0 best converged 1.0: running 2.0 (= 2 x best: kept), 2.5 (dropped); pair 1
    # has none converged: its running rows stay; a running row's low energy sets no best
    st = _FakeState([C, R, R, R, R, C], [1.0, 2.0, 2.5, 9.0, 0.1, 3.0], [1, 2, 3, 4])
    _Runner._drop_losers(st, np.array([0, 0, 0, 1, 1, 2]), 2.0)
    assert st.dropped == [2]
    one = _FakeState([C, R], [1.0, 3.0], [1])
    _Runner._drop_losers(one, np.array([0, 0]), 2.0)
    assert one.dropped == [1]
    none = _FakeState([R, R], [1.0, 3.0], [0, 1])
    _Runner._drop_losers(none, np.array([0, 0]), 2.0)
    assert none.dropped == []


def test_nonsmooth_rows_go_to_the_interior_point():
    from solvers.inputs import domain_scale
    from solvers.newton.interior import InteriorOptions, interior_energy
    from solvers.seeding.plans import seed_batch

    car, n = CarLike(), 8
    pairs = np.array([[[-0.4, -0.3, 0.0], [0.4, 0.2, 0.3]],
                      [[0.2, -0.5, 0.5], [-0.3, 0.4, -0.2]]])
    plan = SeedPlan(bulges=(0.3,), random=0, graph=False, coarse=None, own=False)
    iopt = InteriorOptions(max_iter=4)
    s = solve_pairs_batched(car, pairs, n, plan, BatchOptions(interior=iopt))
    names, curves = seed_batch(car, pairs[:, 0], pairs[:, 1], n, plan)
    ref = interior_energy(car, curves.reshape(-1, n + 1, 3), iopt, scale=domain_scale(car))
    assert s.final.names == names * 2 and s.final.pair.tolist() == [0] * 3 + [1] * 3
    np.testing.assert_array_equal(s.final.points, ref.points)
    np.testing.assert_array_equal(s.final.energy, ref.energy)
    np.testing.assert_array_equal(s.final.status, ref.status)
    np.testing.assert_array_equal(s.final.iterations, ref.iterations)
    assert s.final.residual.shape == (6,) and np.isnan(s.final.residual).all()  # for the KKT
    assert s.iterations.dtype == np.int64
    assert s.iterations.tolist() == [int(ref.iterations[:3].sum()), int(ref.iterations[3:].sum())]
    assert s.stats["evaluations"] == ref.evaluations > 0
    assert s.stats["value_evaluations"] == ref.value_evaluations


def test_unconverged_pairs_get_no_restarts_nor_polish():
    m, n = Poincare(), 16
    pairs = np.array([[[-0.6, 0.1], [0.5, 0.2]]])
    plan = SeedPlan(bulges=(0.4,), graph=False, coarse=None, restarts=2, polish=1)
    s = solve_pairs_batched(m, pairs, n, plan, BatchOptions(newton=NewtonOptions(max_iter=1)))
    assert not any("~" in nm for nm in s.final.names) and len(s.final) == len(s.first) == 3
    assert s.levels[-1]["polish"] and s.levels[-1]["solved"].tolist() == [0]
    assert s.stats["levels"][-1]["rows"] == 0 and s.stats["levels"][-1]["segments"] == n


def test_given_only_with_a_pair_without_rows():
    m, n = Euclidean(2), 8
    given = [[("g", _line(*PAIRS[0], n + 1))], []]
    a = solve_pairs_batched(m, PAIRS, n, SeedPlan(), given=given, global_seeds=False)
    assert a.seeds_tried.tolist() == [1, 0] and a.best.tolist() == [0, -1]
    assert a.levels[0]["segments"] == n and a.levels[0]["solved"].tolist() == [1, 0]
    assert a.seeds_agreeing.tolist() == [1, 0]
