"""solvers.certificates.plane.lp against independent references, FAST (the mutation-testing
selection of
the module, see docs/guides/mutation-testing.md): the rays' exit points by brute force, the
LP's optimum in closed form (a uniform Euclidean row set: the best potential rises by
exactly |goal - start|) and by scipy's HiGHS (``linprog``) on the full row set, strong
duality and dual feasibility of the returned duals, every row checked on the returned
potential, the round logic's stopping rules counted by hand, and the first exact vertices
recomputed from their definition."""

from __future__ import annotations

import math

import numpy as np
import pytest

import solvers.certificates.plane.lp as lp_mod
from solvers.certificates.plane.lp import (
    INITIAL_DIRECTIONS,
    LP_SOLVER,
    NEAR_PER_TARGET,
    NEAR_TIGHT,
    SETTLE,
    SETTLE_ROUNDS,
    TIGHT_DUAL,
    WINDOW_FRACTION,
    WORST_WINDOW,
    LPFailure,
    _initial_modes,
    _Rays,
    _solve_lp,
    _window,
)
from solvers.certificates.plane.mesh import _Mesh

from tests.helpers.lp_rows import DIRS, FULL, MESH, NV, K, S, highs_solve, weights
from tests.helpers.tick_clock import TickClock

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


def _none() -> dict[str, np.ndarray]:
    return {"exact": np.zeros(NV, bool), "active": np.zeros((NV, K), bool)}


def _highs_optimum(b: np.ndarray) -> float:
    return float(-highs_solve(b).fun)


def _max_ratio(phi: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(FULL @ phi / b.reshape(-1)))


# ---- constants and the window ----------------------------------------------------------
def test_constants_and_the_direction_window() -> None:
    assert LP_SOLVER == "CLARABEL" and INITIAL_DIRECTIONS == 8 and WINDOW_FRACTION == 1 / 64
    assert TIGHT_DUAL == 1e-4 and SETTLE == 0.1
    assert NEAR_TIGHT == 0.06 and NEAR_PER_TARGET == 6.0 and WORST_WINDOW == 2
    assert SETTLE_ROUNDS == 3 and lp_mod.PROMOTE_WINDOW == 3
    assert lp_mod.LP_OPTIONS == {"tol_gap_abs": 1e-5, "tol_gap_rel": 1e-5, "tol_feas": 1e-5,
                                 "tol_ktratio": 1e-3, "iterative_refinement_enable": False}
    assert [_window(k) for k in (8, 16, 64, 127, 128, 200, 640)] == [1, 1, 1, 1, 2, 3, 10]


# ---- the inner polygons ----------------------------------------------------------------
def test_rays_are_evenly_spaced_off_the_sampled_angles_and_chained_per_vertex() -> None:
    r = _Rays(3)
    assert r.vid.tolist() == [v for v in range(3) for _ in range(8)]
    np.testing.assert_allclose(r.ang, np.tile(2 * np.pi * np.arange(8) / 8 + 1e-3, 3),
                               rtol=0, atol=1e-15)
    assert r.next.dtype == np.int64
    assert r.next.tolist() == [v * 8 + (i + 1) % 8 for v in range(3) for i in range(8)]
    r5 = _Rays(2, rays=5)
    assert r5.vid.tolist() == [0] * 5 + [1] * 5
    assert r5.next.tolist() == [1, 2, 3, 4, 0, 6, 7, 8, 9, 5]


def _brute_facets(rays: _Rays, b_flat: np.ndarray, dirs: np.ndarray) -> tuple:
    pts = []
    for v, a in zip(rays.vid, rays.ang):
        u = np.array([math.cos(a), math.sin(a)])
        r = min(b_flat[v, k] / (u @ dirs[k]) for k in range(dirs.shape[0])
                if u @ dirs[k] > 1e-12)
        pts.append(r * u)
    return np.array(pts)


@pytest.mark.parametrize("n, k", [(4, 32), (2, 5)])
def test_facets_pass_through_the_exit_points_by_brute_force(n: int, k: int) -> None:
    rng = np.random.default_rng(k)
    a = 2 * np.pi * np.arange(k) / k
    dirs = np.stack([np.cos(a), np.sin(a)], 1)
    b_flat = rng.uniform(0.5, 2.0, (n, k))
    rays = _Rays(n)
    normal, rhs = rays.facets(b_flat, dirs)
    pts = _brute_facets(rays, b_flat, dirs)
    assert normal.shape == (8 * n, 2) and rhs.shape == (8 * n,)
    # the edge from each exit point to the next one's: through both, origin inside
    np.testing.assert_allclose(np.einsum("ri,ri->r", normal, pts), rhs, rtol=1e-12)
    np.testing.assert_allclose(np.einsum("ri,ri->r", normal, pts[rays.next]), rhs,
                               rtol=1e-11, atol=1e-12)
    e = pts[rays.next] - pts
    np.testing.assert_allclose(normal, np.stack([e[:, 1], -e[:, 0]], 1), rtol=1e-12,
                               atol=1e-14)
    assert np.all(rhs > 0)
    # every exit point satisfies every row of its vertex, one of them with equality
    ratio = np.einsum("ri,ki->rk", pts, dirs) / b_flat[rays.vid]
    assert np.all(ratio <= 1 + 1e-12)
    np.testing.assert_allclose(ratio.max(axis=1), 1.0, rtol=1e-12)


def test_facets_of_more_rays_than_one_chunk() -> None:
    n = 2600  # 20800 rays: two chunks of 20000
    a = 2 * np.pi * np.arange(6) / 6
    dirs = np.stack([np.cos(a), np.sin(a)], 1)
    b_flat = np.linspace(1.0, 3.0, n)[:, None] * np.ones((1, 6))
    rays = _Rays(n)
    normal, rhs = rays.facets(b_flat, dirs)
    # a regular hexagon of inradius b: the exit radius at angle t is b / cos(t - nearest)
    u = np.stack([np.cos(rays.ang), np.sin(rays.ang)], 1)
    dev = (rays.ang + np.pi / 6) % (np.pi / 3) - np.pi / 6
    pts = (b_flat[rays.vid, 0] / np.cos(dev))[:, None] * u
    np.testing.assert_allclose(np.einsum("ri,ri->r", normal, pts), rhs, rtol=1e-12)
    np.testing.assert_allclose(np.einsum("ri,ri->r", normal, pts[rays.next]), rhs,
                               rtol=1e-11)


# ---- the LP ----------------------------------------------------------------------------
def test_uniform_euclidean_rows_give_exactly_the_straight_distance() -> None:
    """b = 1 for every direction: the rows hold at every point of each triangle (a P2
    gradient is linear there), so phi(goal) - phi(start) <= |goal - start| along the
    segment (goal - start lies along a sampled direction), and phi = x0 attains it."""
    b = np.ones((MESH.n_tri, 3, K))
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none())
    assert r["lower"] == pytest.approx(0.8, rel=1e-7) and r["lower"] <= 0.8 * (1 + 1e-9)
    assert r["phi"][0] == 0.0 and r["phi"][1] == pytest.approx(r["lower"], rel=1e-14)
    assert _max_ratio(r["phi"], b) <= 1.0
    assert r["status"] == "optimal" and r["solver"] == "CLARABEL"
    assert r.get("settled", False) is False
    assert r["lp_seconds"] > 0 and r["ratio"] == pytest.approx(1.0, abs=1e-5)
    assert 1 <= r["iterations"] <= 30 and r["exact"].shape == (NV,)
    assert r["active"].shape == (NV, K) and r["n_rows"] == r["duals"].size


def test_rows_that_vary_reach_the_highs_optimum_of_all_rows() -> None:
    b = weights()
    best = _highs_optimum(b)
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none())
    assert best * (1 - 1e-6) <= r["lower"] <= best * (1 + 1e-9)
    assert _max_ratio(r["phi"], b) <= 1.0
    assert r["iterations"] >= 2 and r["exact"].any()  # safe vertices were promoted
    # promoted vertices carry the 16 coarse directions
    assert np.all(r["active"][r["exact"]][:, :: K // 16])
    assert not r["active"][r["exact"]].all()  # only the coarse, window and violated ones
    assert not r["active"][~r["exact"]].any()


def test_rows_tightened_on_demand_reach_the_optimum_of_the_tight_rows() -> None:
    """Rows that start loose (90 % of their proven value, as a group of directions' bound
    would) and a ``tighten`` callback that sets the asked (triangle, direction) rows of all
    three vertices to their tight value: the LP asks for every row it holds and every row
    its potential nearly fills, and so reaches the HiGHS optimum of the TIGHT rows (the
    loose rows alone give about 10 % less); the bound holds for the rows it ended with."""
    tight = weights()
    b = 0.9 * tight
    asked: set[tuple[int, int]] = set()

    def tighten(tri: np.ndarray, kk: np.ndarray) -> None:
        for t, k in zip(tri.tolist(), kk.tolist(), strict=True):
            asked.add((t, k))
            b[t, :, k] = tight[t, :, k]

    best = _highs_optimum(tight)
    loose = _solve_lp(MESH, 0.9 * tight, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none())
    assert loose["lower"] < 0.91 * best
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none(),
                  tighten=tighten)
    assert best * (1 - 1e-6) <= r["lower"] <= best * (1 + 1e-9)
    assert _max_ratio(r["phi"], b) <= 1.0
    # every row of an exact vertex the LP held, and every row filled beyond 1 - near
    vid, kk = np.nonzero(r["active"] & r["exact"][:, None])
    assert {(v // 3, k) for v, k in zip(vid.tolist(), kk.tolist(), strict=True)} <= asked
    near = min(NEAR_TIGHT, NEAR_PER_TARGET * 1e-6)
    fill = (FULL @ r["phi"]).reshape(NV, K) / tight.reshape(NV, K)
    vid, kk = np.nonzero(fill > 1.0 - near)
    assert vid.size and {(v // 3, k) for v, k in zip(vid.tolist(), kk.tolist(),
                                                     strict=True)} <= asked
    assert len(asked) < 0.5 * MESH.n_tri * K  # on demand, not everything


def test_one_round_tightens_the_rows_its_potential_fills_before_scaling() -> None:
    """One round, every vertex exact with 5 directions: the potential breaks unsampled rows.
    Those it fills beyond ``1 - near`` (and only rows of the triangles asked) are tightened
    BEFORE the scale, so the bound is the value over the largest ratio against the TIGHT
    rows there (a loose row would scale it down by about 10 %)."""
    tight = weights()
    b = 0.9 * tight
    asked: list[tuple[int, int]] = []

    def tighten(tri: np.ndarray, kk: np.ndarray) -> None:
        for t, k in zip(tri.tolist(), kk.tolist(), strict=True):
            asked.append((t, k))
            b[t, :, k] = tight[t, :, k]

    active = np.zeros((NV, K), bool)
    active[:, [0, 7, 13, 20, 26]] = True
    start = {"exact": np.ones(NV, bool), "active": active}
    target = 1e-3
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=target, start=start, max_iter=1,
                  tighten=tighten)
    value = r["lower"] * r["ratio"] * (1 + 1e-12)
    slope = (FULL @ (r["phi"] * r["ratio"] * (1 + 1e-12))).reshape(NV, K)
    near = min(NEAR_TIGHT, NEAR_PER_TARGET * target)
    # the rows the unscaled potential fills beyond 1 - near against the rows it was given
    # (the sampled ones tight, the others loose) were all asked for, by triangle
    given = np.where(active, tight.reshape(NV, K), 0.9 * tight.reshape(NV, K))
    vid, kk = np.nonzero(slope / given > 1.0 - near)
    assert vid.size and {(v // 3, k) for v, k in zip(vid.tolist(), kk.tolist(),
                                                     strict=True)} <= set(asked)
    assert {t for t, _ in asked} <= set(range(MESH.n_tri))
    # the scale is the largest ratio against the rows as tightened, equal to the tight one
    assert r["ratio"] == pytest.approx(float(np.max(slope / tight.reshape(NV, K))), rel=1e-9)
    assert r["ratio"] > 1.01 and value > _highs_optimum(tight)


def test_one_round_of_few_rows_is_scaled_into_a_valid_bound() -> None:
    """All vertices exact with 5 directions each (not enough: the potential violates
    other rows): the bound is the LP value over its largest row ratio; the duals satisfy
    strong duality (value = duals . rhs) and dual feasibility (A^T y = e_goal off the start)
    against the rows rebuilt here."""
    b = weights()
    active = np.zeros((NV, K), bool)
    active[:, [0, 7, 13, 20, 26]] = True
    start = {"exact": np.ones(NV, bool), "active": active}
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=start, max_iter=1)
    assert r["iterations"] == 1
    ratio = _max_ratio(r["phi"], b)
    assert ratio <= 1.0 and ratio == pytest.approx(1.0, abs=1e-12)
    assert r["ratio"] > 1.01  # the unscaled potential broke some unsampled row
    value = r["lower"] * r["ratio"] * (1 + 1e-12)
    assert value > _highs_optimum(b)  # fewer rows: a larger LP optimum
    vid, kk = np.nonzero(active)
    rows = FULL[vid * K + kk]
    rhs = b.reshape(NV, K)[vid, kk]
    assert r["n_rows"] == vid.size
    np.testing.assert_array_equal(r["rows"], np.stack([vid // 3, vid % 3, kk], 1))
    assert r["rows"].dtype == np.int64
    y = r["duals"]  # strong duality to Clarabel's tol_gap_rel 1e-5 (LP_OPTIONS)
    assert np.all(y >= 0) and y @ rhs == pytest.approx(value, rel=2e-5)
    aty = rows.T @ y
    target = np.zeros(MESH.n_dofs)
    target[1] = 1.0
    np.testing.assert_allclose(np.delete(aty - target, 0), 0.0, atol=1e-6)
    # the rows it had hold for the unscaled potential (LP tolerance)
    assert np.max(rows @ r["phi"] * r["ratio"] / rhs) <= 1 + 1e-6


def test_rows_of_safe_vertices_point_along_their_facet_normals() -> None:
    b = np.ones((MESH.n_tri, 3, K))
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none(), max_iter=1)
    rays = _Rays(NV)
    assert r["n_rows"] == 8 * NV
    np.testing.assert_array_equal(r["rows"][:, 0], rays.vid // 3)
    np.testing.assert_array_equal(r["rows"][:, 1], rays.vid % 3)
    # the facet between rays at 2 pi i / 8 and 2 pi (i+1) / 8 faces 2 pi (i + 1/2) / 8,
    # the sampled direction k = 4 i + 2 of 32 (the 1e-3 offset moves it by far less)
    i = np.tile(np.arange(8), NV)
    np.testing.assert_array_equal(r["rows"][:, 2], (4 * i + 2) % K)


def test_the_rounds_stop_when_the_bound_reaches_the_target() -> None:
    b = weights()
    best = _highs_optimum(b)
    far = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none())
    near = _solve_lp(MESH, b, DIRS, 0, 1, upper=best * 1.02, target=0.1, start=_none())
    assert near["iterations"] == 1 < far["iterations"]
    assert best * 1.02 - near["lower"] <= 0.1 * best * 1.02
    # a target just out of the first round's reach needs a second round
    first = near["lower"]
    gap = (best - first) / best
    assert gap > 1e-4
    nxt = _solve_lp(MESH, b, DIRS, 0, 1, upper=best, target=0.5 * gap, start=_none())
    assert nxt["iterations"] >= 2 and nxt["lower"] >= best * (1 - 0.5 * gap)


def test_settle_stops_a_mesh_that_cannot_reach_the_target() -> None:
    b = weights()
    best = _highs_optimum(b)
    # rounds 1 -> 2 gain far less than SETTLE * target * upper: settled after round 2
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=2 * best, target=0.1, start=_none(),
                  settle=True)
    assert r["settled"] and r["iterations"] == 2
    full = _solve_lp(MESH, b, DIRS, 0, 1, upper=2 * best, target=0.1, start=_none())
    assert not full["settled"] and full["iterations"] > 2
    # a gain larger than SETTLE * target * upper: not settled after two rounds
    one = _solve_lp(MESH, b, DIRS, 0, 1, upper=2 * best, target=0.1, start=_none(),
                    max_iter=1)
    two = _solve_lp(MESH, b, DIRS, 0, 1, upper=2 * best, target=0.1, start=_none(),
                    max_iter=2)
    assert two["iterations"] == 2 and one["iterations"] == 1
    gain = two["lower"] * two["ratio"] - one["lower"] * one["ratio"]
    assert gain > 0
    tiny = 0.5 * gain / (SETTLE * 2 * best)  # SETTLE * tiny * upper = gain / 2
    r2 = _solve_lp(MESH, b, DIRS, 0, 1, upper=2 * best, target=tiny, start=_none(),
                   settle=True, max_iter=3)
    assert not r2["settled"] or r2["iterations"] == 3
    # values that keep rising by more than SETTLE * target * upper, short of the target:
    # settled after SETTLE_ROUNDS rounds all the same (unsettled, the rounds go on; this
    # small mesh needs 3 rounds, so the cap is lowered to 2 to bite)
    full3 = _solve_lp(MESH, b, DIRS, 0, 1, upper=best * 1.0005, target=1e-4, start=_none())
    assert full3["iterations"] == 3 and not full3["settled"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(lp_mod, "SETTLE_ROUNDS", 2)
        r3 = _solve_lp(MESH, b, DIRS, 0, 1, upper=best * 1.0005, target=1e-4,
                       start=_none(), settle=True)
    assert r3["settled"] and r3["iterations"] == 2


def test_lp_seconds_add_up_the_rounds(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(lp_mod, "time", TickClock())
    r = _solve_lp(MESH, weights(), DIRS, 0, 1, upper=100.0, target=1e-6, start=_none(),
                  max_iter=3)
    # each round reads the clock before the solve, after it (+1 s), and for the log
    assert r["iterations"] == 3 and r["lp_seconds"] == 3.0


def test_vertices_exact_with_no_rows_leave_the_goal_free() -> None:
    """Every vertex exact but only triangle 0's with directions: the goal's unknown is in
    no row, the LP is unbounded, and that is an LPFailure naming the status."""
    active = np.zeros((NV, K), bool)
    t = int(np.flatnonzero((MESH.dofs != 1).all(axis=1))[0])
    active[3 * t: 3 * t + 3, ::4] = True
    start = {"exact": np.ones(NV, bool), "active": active}
    with pytest.raises(LPFailure, match=r"^the LP ended with status unbounded"):
        _solve_lp(MESH, np.ones((MESH.n_tri, 3, K)), DIRS, 0, 1, upper=100.0, target=1e-6,
                  start=start)


def test_each_round_logs_its_rows_value_ratio_and_bound(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    import logging
    import re

    monkeypatch.setattr(lp_mod, "time", TickClock())
    caplog.set_level(logging.DEBUG, logger="solvers.certificates.plane.lp")
    r = _solve_lp(MESH, weights(), DIRS, 0, 1, upper=100.0, target=1e-6, start=_none(),
                  max_iter=1)
    msgs = [rec.getMessage() for rec in caplog.records
            if rec.name == "solvers.certificates.plane.lp"]
    assert len(msgs) == 1
    got = re.fullmatch(r"LP rows (\d+) \((\d+) exact vertices\) (\S+) s: value (\S+), "
                       r"max row ratio (\S+) -> bound (\S+)", msgs[0])
    assert got is not None, msgs[0]
    assert int(got[1]) == 8 * NV and int(got[2]) == 0 and got[3] == "2.00"
    value = r["lower"] * max(r["ratio"], 1.0) * (1 + 1e-12)
    assert float(got[4]) == pytest.approx(value, abs=2e-8)
    assert float(got[5]) == pytest.approx(r["ratio"], abs=2e-6)
    assert float(got[6]) == pytest.approx(r["lower"], abs=2e-8)
    assert len(got[4].split(".")[1]) == 8 and len(got[5].split(".")[1]) == 6


def test_the_target_is_relative_to_the_upper_bound() -> None:
    """Rows scaled by 0.1 (optimum ~0.14) and an upper bound 0.5 with target 0.5: the gap
    0.36 is above 0.5 * 0.5, so the rounds go on (a gap tested against target / upper,
    1.0, would stop at once)."""
    b = 0.1 * weights()
    best = _highs_optimum(b)
    assert best < 0.2
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=0.5, target=0.5, start=_none())
    assert r["iterations"] > 1


def test_a_value_above_the_target_line_never_settles() -> None:
    """Few rows at first (unscaled values above the optimum, falling round by round) and
    (1 - target) upper just below the optimum: every value stays above that line, so the
    rounds never settle; they end on the target once the bound gets there."""
    b = weights()
    best = _highs_optimum(b)
    active = np.zeros((NV, K), bool)
    active[:, [0, 7, 13, 20, 26]] = True
    start = {"exact": np.ones(NV, bool), "active": active}
    target = 0.01
    upper = 0.999 * best / (1 - target)
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=upper, target=target, start=start, settle=True)
    assert not r["settled"] and upper - r["lower"] <= target * upper
    assert r["iterations"] >= 2


def test_promoted_vertices_get_every_direction_when_k_is_16() -> None:
    """K = 16 directions: the coarse set (every K // 16 = 1st) is all of them."""
    a = 2 * np.pi * np.arange(16) / 16
    dirs = np.stack([np.cos(a), np.sin(a)], 1)
    b = weights()[:, :, :16]
    start = {"exact": np.zeros(NV, bool), "active": np.zeros((NV, 16), bool)}
    r = _solve_lp(MESH, b, dirs, 0, 1, upper=100.0, target=1e-6, start=start, max_iter=1)
    assert r["exact"].any()
    assert r["active"][r["exact"]].all()


def test_one_rounds_refinement_recomputed_from_its_duals_and_rows() -> None:
    """After one round from every other triangle's vertices exact (5 directions each) and
    the rest safe: the safe vertices with a tight facet (dual above TIGHT_DUAL times the
    largest) become exact with the window around that facet's direction, the coarse
    directions and the rows the unscaled potential fills beyond ``1 - near``; then every
    such near-tight row of an exact vertex, and WORST_WINDOW neighbours each side of the
    worst row of a vertex that breaks one by more than 0.1 target, are added. Recomputed
    here from the returned potential, duals and rows."""
    b, target = weights(), 0.1
    ex0 = np.repeat(np.arange(MESH.n_tri) % 2 == 0, 3)
    act0 = np.zeros((NV, K), bool)
    act0[np.ix_(ex0, [0, 7, 13, 20, 26])] = True
    r = _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=target,
                  start={"exact": ex0.copy(), "active": act0.copy()}, max_iter=1)
    phi = r["phi"] * max(r["ratio"], 1.0) * (1 + 1e-12)
    ratio = (FULL @ phi).reshape(NV, K) / b.reshape(NV, K)
    assert ratio.max() == pytest.approx(r["ratio"], rel=1e-9)
    n_safe = 8 * int((~ex0).sum())
    y, rows = r["duals"], r["rows"]
    tight = np.zeros(y.size, bool)
    tight[:n_safe] = y[:n_safe] > TIGHT_DUAL * y.max()
    pv, kc = 3 * rows[tight, 0] + rows[tight, 1], rows[tight, 2]
    assert not ex0[pv].any()
    want = act0.copy()
    for off in range(-3, 4):  # window of 32 directions: 1, times PROMOTE_WINDOW = 3
        want[pv, (kc + off) % K] = True
    ex = ex0.copy()
    ex[pv] = True
    want[np.ix_(~ex0 & ex, np.arange(0, K, 2))] = True
    near = min(0.06, 6 * target)
    over = ex[:, None] & (ratio > 1 - near)
    worst = np.argmax(np.where(ex[:, None], ratio, -np.inf), axis=1)
    bad = ex & (ratio[np.arange(NV), worst] > 1 + 0.1 * target)
    for off in (-2, -1, 0, 1, 2):
        want[np.flatnonzero(bad), (worst[bad] + off) % K] = True
    want |= over
    # the near-tight rows reach beyond the violated ones and the worst one's neighbours
    assert (over & ~(ratio > 1 + 0.1 * target)).any()
    assert (ex & ~ex0).any() and bad.any()
    np.testing.assert_array_equal(r["exact"], ex)
    np.testing.assert_array_equal(r["active"], want)


def test_a_failing_lp_solver_raises_lp_failure(monkeypatch: pytest.MonkeyPatch) -> None:
    b = np.ones((MESH.n_tri, 3, K))
    monkeypatch.setattr(lp_mod, "LP_SOLVER", "NO_SUCH_SOLVER")
    with pytest.raises(LPFailure, match=r"^the LP solver failed: .*NO_SUCH_SOLVER"):
        _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none())
    monkeypatch.undo()
    import cvxpy as cp

    monkeypatch.setattr(cp.Problem, "solve", lambda self, **kw: None)
    with pytest.raises(LPFailure, match=r"^the LP ended with status None$"):
        _solve_lp(MESH, b, DIRS, 0, 1, upper=100.0, target=1e-6, start=_none())


# ---- the first exact vertices ----------------------------------------------------------
def _seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    t = min(1.0, max(0.0, float((p - a) @ d / (d @ d))))
    return float(np.linalg.norm(p - (a + t * d)))


@pytest.mark.parametrize("k", [128, 16])  # windows of 2 and 1 directions each side
def test_first_mesh_marks_the_triangles_near_the_path_with_its_direction(k: int) -> None:
    path = np.array([[0.1, 0.5], [0.5, 0.62], [0.9, 0.8]])
    width = 0.15
    out = _initial_modes(MESH, k, None, path, width)
    assert out["exact"].shape == (NV,) and out["active"].shape == (NV, k)
    assert out["exact"].dtype == bool and out["active"].dtype == bool
    for t in range(MESH.n_tri):
        c = MESH.centroids[t]
        dist = [_seg_dist(c, path[i], path[i + 1]) for i in range(2)]
        near = min(dist) <= width
        assert out["exact"][3 * t: 3 * t + 3].tolist() == [near] * 3
        if not near:
            assert not out["active"][3 * t: 3 * t + 3].any()
            continue
        mids = 0.5 * (path[1:] + path[:-1])
        seg = int(np.argmin(np.linalg.norm(mids - c, axis=1)))
        d = path[seg + 1] - path[seg]
        kc = round(math.atan2(d[1], d[0]) / (2 * math.pi / k))
        want = np.zeros(k, bool)
        want[:: k // 16] = True
        w = max(1, k // 64)
        want[[(kc + o) % k for o in range(-w, w + 1)]] = True
        for m in range(3):
            np.testing.assert_array_equal(out["active"][3 * t + m], want)
    assert out["exact"].any() and not out["exact"].all()


def test_a_refined_mesh_inherits_exact_triangles_and_their_directions() -> None:
    k = 16
    exact = np.zeros(NV, bool)
    active = np.zeros((NV, k), bool)
    hot = [0, 5]  # old triangles with one exact vertex each
    exact[3 * 0 + 1] = True
    active[3 * 0 + 1, [2, 3]] = True
    active[3 * 0 + 2, 9] = True  # not exact: its directions are not inherited
    exact[3 * 5 + 0] = True
    active[3 * 5 + 0, [7]] = True
    marked = np.zeros(MESH.n_tri, bool)
    marked[hot] = True
    new = _Mesh(MESH.refine(marked))
    out = _initial_modes(new, k, (MESH, {"exact": exact, "active": active}), S[None], 0.1)
    host = MESH.delaunay.find_simplex(new.centroids)
    for t in range(new.n_tri):
        h = MESH.simplex_row[host[t]] if host[t] >= 0 else -1
        want = np.zeros(k, bool)
        if h == 0:
            want[[2, 3]] = True
        elif h == 5:
            want[7] = True
        assert out["exact"][3 * t: 3 * t + 3].tolist() == [h in hot] * 3
        for m in range(3):
            np.testing.assert_array_equal(out["active"][3 * t + m], want)
    assert out["exact"].sum() >= 3 * 4
    assert out["exact"].dtype == bool and out["active"].dtype == bool


def test_a_refined_mesh_inherits_only_the_near_tight_and_coarse_directions() -> None:
    """With the host's near-tight rows (``near``) given: of the host's exact rows only
    the evenly spaced (every K // 16 = 2nd of 32) and those within one direction of a
    near-tight one are inherited."""
    assert lp_mod.INHERIT_NEAR_ONLY and lp_mod.COARSE_DIRECTIONS == 16
    exact = np.zeros(NV, bool)
    active = np.zeros((NV, K), bool)
    near = np.zeros((NV, K), bool)
    exact[0] = True
    active[0, [1, 3, 4, 9, 11, 20, 22]] = True
    near[0, 10] = True  # keeps 9 and 11 (neighbours); 4, 20, 22 are coarse; 1, 3 go
    marked = np.zeros(MESH.n_tri, bool)
    marked[0] = True
    new = _Mesh(MESH.refine(marked))
    out = _initial_modes(new, K, (MESH, {"exact": exact, "active": active, "near": near}),
                         S[None], 0.1)
    host = MESH.delaunay.find_simplex(new.centroids)
    inside = np.flatnonzero(MESH.simplex_row[host] == 0)
    assert inside.size >= 4
    want = np.zeros(K, bool)
    want[[4, 9, 11, 20, 22]] = True
    for t in inside:
        for m in range(3):
            np.testing.assert_array_equal(out["active"][3 * t + m], want)


def test_the_path_width_is_inclusive() -> None:
    path = np.array([[0.1, 0.5], [0.9, 0.5]])
    dist = np.abs(MESH.centroids[:, 1] - 0.5)  # all centroids project inside the segment
    inside = (MESH.centroids[:, 0] >= 0.1) & (MESH.centroids[:, 0] <= 0.9)
    t = int(np.flatnonzero(inside)[np.argsort(dist[inside])[3]])
    from solvers.certificates.plane.mesh import _distance_to_path

    width = float(_distance_to_path(MESH.centroids[t:t + 1], path)[0])
    out = _initial_modes(MESH, K, None, path, width)
    assert out["exact"][3 * t: 3 * t + 3].all()


def test_triangles_of_a_new_mesh_outside_the_old_region_inherit_nothing() -> None:
    """The old mesh drops the triangles right of x = 0.6 (a region), its last kept triangle
    is exact; the new mesh keeps them all: those whose centroid lies in a dropped old
    triangle (located as -1) are not exact."""
    def region(z: np.ndarray) -> np.ndarray:
        return z.mean(axis=1)[:, 0] < 0.6

    old = _Mesh(MESH.points, region)
    nv_old = 3 * old.n_tri
    exact = np.zeros(nv_old, bool)
    active = np.zeros((nv_old, K), bool)
    exact[-3:] = True
    active[-3:, 4] = True
    new = _Mesh(MESH.points)
    out = _initial_modes(new, K, (old, {"exact": exact, "active": active}), S[None], 0.1)
    host = old.locate(new.centroids)
    assert (host < 0).any()
    want = np.repeat(host == old.n_tri - 1, 3)
    np.testing.assert_array_equal(out["exact"], want)
    np.testing.assert_array_equal(out["active"][:, 4], want)
