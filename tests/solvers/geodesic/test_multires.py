"""Exact solves at any resolution (issue 14) and seeding by capability (issue 10).

* the multiresolution ladder never ends above solving every seed at the full size, and
  its levels are what the plan says;
* ``SeedPlan.default`` follows what a metric can do (a renamed copy of a metric gets the
  same plan; a ``seed_plan`` hook wins);
* the chained min-max converges at a size where the single-epigraph form did not, and a
  size it cannot solve in its wall budget comes back with a status, in bounded time;
* ``tol``: Richardson extrapolation against synthetic sequences and the Poincare disk's
  closed-form distance (true error <= tol, the estimate >= a third of the true error);
  ``geodesics solve --tol``.
"""

from __future__ import annotations

import dataclasses
import json
import time

import numpy as np
import pytest

import finsler
import solvers
from finsler import InputError
from solvers import SeedPlan, Status
from solvers.geodesic.tolerance import richardson
from solvers.seeding.plans import perturbed_curves

from tests.helpers.metrics.multires import (
    HookedPoincare,
    NotUniquePoincare,
    RenamedMatsumoto,
    RenamedPoincare,
)


# ----------------------------------------------------------------------------------------
# multiresolution
# ----------------------------------------------------------------------------------------
def _work(r: solvers.GeodesicResult) -> int:
    """Segment-iterations of a solve: every level's iterations times its size."""
    return sum(lv["iterations"] * lv["segments"] for lv in r.levels)


@pytest.mark.parametrize("method", ["newton", "ipopt"])
def test_ladder_never_above_all_seeds_at_full_size(method) -> None:
    """Matsumoto at 256 segments, each method's default plan (IPOPT: 34 seeds at 64
    segments, 4 carried up 64 -> 256; Newton: 34 seeds at 16, the distinct optima within
    0.5 % carried up a x4 ladder, polished at 64): an energy no higher than the same
    seeds all solved at 256 (Newton: within 1e-4, the near-equal discrete minima of the
    non-convex metric), for less work (iterations x segments); every level reported."""
    m = finsler.get_metric("matsumoto")
    plan = SeedPlan.default(m, method)
    full = dataclasses.replace(plan, coarse=None)
    for s, g in finsler.sample_pairs(m, 2, seed=4321):
        multi = solvers.solve_geodesic(m, s, g, 256, method=method)
        ref = solvers.solve_geodesic(m, s, g, 256, seeds=full, method=method)
        assert multi.status is Status.SUCCESS and ref.status is Status.SUCCESS
        assert multi.method == ref.method == method
        rtol = 1e-9 if method == "ipopt" else 1e-4
        assert multi.energy <= ref.energy * (1 + rtol)
        sizes = [lv["segments"] for lv in multi.levels if not lv.get("polish")]
        assert sizes == plan.ladder(256)
        assert multi.levels[0]["solved"] == multi.seeds_tried == ref.seeds_tried
        ladder = [lv for lv in multi.levels if not lv.get("polish")]
        assert ladder[-1]["solved"] <= plan.refine_top
        assert _work(multi) < _work(ref)


def test_losing_starts_stop_at_the_coarse_level() -> None:
    """A drop tolerance of 1e-9 keeps only the coarse winner (and optima within 1e-9 of
    it); with a large one the refine_top best distinct optima go up."""
    m = finsler.get_metric("matsumoto")
    s, g = np.array([0.6, 0.05]), np.array([-0.6, 0.0])  # two routes round the hill
    base = SeedPlan(bulges=(0.3, 0.6), random=2, coarse=16, refine_top=3)
    tight = solvers.solve_geodesic(m, s, g, 64, seeds=dataclasses.replace(base,
                                                                          drop_rtol=1e-9))
    loose = solvers.solve_geodesic(m, s, g, 64, seeds=dataclasses.replace(base,
                                                                          drop_rtol=10.0))
    assert tight.levels[-1]["solved"] == 1 < loose.levels[-1]["solved"] <= 3
    assert loose.energy <= tight.energy * (1 + 1e-9)


def test_perturbed_curves_are_seeded_and_keep_the_ends() -> None:
    m = finsler.get_metric("matsumoto")
    path = np.linspace([0.5, 0.1], [-0.4, -0.3], 17)
    a = perturbed_curves(m, path, 3, 0.1, seed=5)
    b = perturbed_curves(m, path, 3, 0.1, seed=5)
    c = perturbed_curves(m, path, 3, 0.1, seed=6)
    assert len(a) == 3 and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c[0])
    for x in a:
        assert np.array_equal(x[0], path[0]) and np.array_equal(x[-1], path[-1])
        assert 0 < np.max(np.abs(x - path)) < 0.1 * 1.2 * 3  # amplitude ~ scale * |g - s|
        assert np.all(m.domain.contains(x))


def test_plan_validation() -> None:
    for bad in (dict(restarts=-1), dict(polish=1.5), dict(factor=1), dict(drop_rtol=0.0),
                dict(restart_scale=float("nan"))):
        with pytest.raises(InputError):
            SeedPlan(**bad)


def test_default_plan_follows_capabilities_not_names() -> None:
    mats, poin = finsler.get_metric("matsumoto"), finsler.get_metric("poincare")
    assert SeedPlan.default(RenamedMatsumoto()) == SeedPlan.default(mats)
    assert SeedPlan.default(RenamedPoincare()) == SeedPlan.default(poin)
    assert SeedPlan.default(mats) != SeedPlan.default(poin)
    assert SeedPlan.default(HookedPoincare()) == SeedPlan(bulges=(0.2,), random=7, coarse=8)
    car, panda = finsler.get_metric("carlike"), finsler.get_metric("panda-pole")
    assert not car.smooth and SeedPlan.default(car).field_routes == 6
    assert panda.dim > 3 and SeedPlan.default(panda).coarse == 32
    # one geodesic between any two points: the straight line alone; without that
    # declaration the same F gets the convex-smooth plan (a bulge each side)
    assert poin.unique_geodesics and SeedPlan.default(poin) == SeedPlan(
        bulges=(), random=0, graph=False)
    assert SeedPlan.default(NotUniquePoincare()).bulges == (0.3,)
    # the batched Newton method and IPOPT each have their plan for non-convex metrics
    assert SeedPlan.default(mats, "newton") != SeedPlan.default(mats, "ipopt")
    assert SeedPlan.default(mats) == SeedPlan.default(mats, "newton")  # auto: smooth F
    assert SeedPlan.default(car) == SeedPlan.default(car, "ipopt")
    import inspect

    import solvers.seeding.plans

    assert ".name" not in inspect.getsource(solvers.seeding.plans.SeedPlan.default)


# ----------------------------------------------------------------------------------------
# min-max at scale
# ----------------------------------------------------------------------------------------
def test_minmax_converges_at_1024_and_lowers_the_max() -> None:
    """The pair where the single-epigraph min-max went into restoration at 1024 segments
    (> 2 minutes, measured): the chained form converges and lowers the largest cost."""
    m = finsler.get_metric("matsumoto")
    s, g = finsler.sample_pairs(m, 2, seed=31)[1]
    r = solvers.solve_geodesic(m, s, g, 1024, minmax=True)
    assert r.status is Status.SUCCESS and r.minmax.status is Status.SUCCESS
    assert r.minmax.max_segment_cost <= r.max_segment_cost
    costs = r.minmax.segment_costs
    assert np.max(costs) / np.mean(costs) < 1 + 1e-6  # min-max: every segment at the max


def test_minmax_failure_is_a_status_in_bounded_time(monkeypatch) -> None:
    """With a wall budget of 1 ms per attempt IPOPT stops at once: the status says so,
    the time stays bounded, the energy solution is kept."""
    from solvers.transcription import MinMaxNLP

    m = finsler.get_metric("matsumoto")
    s, g = np.array([0.5, 0.1]), np.array([-0.5, -0.2])
    r = solvers.solve_geodesic(m, s, g, 64)
    monkeypatch.setattr(MinMaxNLP, "wall_budget", lambda self: 1e-3)
    nlp = MinMaxNLP(m, 64)
    t0 = time.perf_counter()
    pts, status, _, relaxed = nlp.solve(r.points, r.max_segment_cost)
    assert time.perf_counter() - t0 < 5.0
    assert status is Status.MAX_WALL_TIME and relaxed
    assert pts.shape == r.points.shape


# ----------------------------------------------------------------------------------------
# accuracy on request
# ----------------------------------------------------------------------------------------
def test_richardson_on_synthetic_sequences() -> None:
    sizes = [32, 64, 128]
    d, c = 2.5, 0.7
    exact2 = [d + c / n**2 for n in sizes]
    est = richardson(sizes, exact2, [0.0] * 3)
    assert est["order_seen"] and est["order"] == pytest.approx(2.0, abs=1e-9)
    assert est["length"] == pytest.approx(d, rel=1e-13)
    assert est["error_estimate"] == pytest.approx(c / 128**2, rel=1e-6)
    # first order (e.g. a kink): the order 2 is not claimed, the estimate is |L2 - L3|
    first = [d + c / n for n in sizes]
    est = richardson(sizes, first, [1e-12] * 3)
    assert not est["order_seen"] and est["order"] == pytest.approx(1.0, abs=1e-9)
    assert est["length"] == first[-1]
    assert est["error_estimate"] == pytest.approx(first[1] - first[2] + 2e-12, rel=1e-12)
    assert est["error_estimate"] >= abs(first[-1] - d)  # bounds the true error of L_k
    # oscillating: no order at all
    est = richardson(sizes, [d + 1e-3, d - 1e-4, d + 1e-5], [0.0] * 3)
    assert est["order"] is None and not est["order_seen"]
    assert richardson([32], [d], [0.0])["error_estimate"] == np.inf


def test_tol_on_fresh_poincare_pairs() -> None:
    """The bar: true relative error of the length <= 1e-7 and the estimate at least a
    third of the true error, on fresh pairs (closed-form distance)."""
    m = finsler.get_metric("poincare")
    pairs = finsler.sample_pairs(m, 4, seed=9090)
    exact = m.distance(pairs[:, 0], pairs[:, 1])
    for (s, g), d in zip(pairs, exact):
        r = solvers.solve_geodesic(m, s, g, tol=1e-7)
        err = abs(r.length_estimate - d)
        assert r.tol_reached and r.order_seen and len(r.tol_levels) >= 3
        assert err <= 1e-7 * d
        assert r.error_estimate >= err / 3
        assert r.error_estimate <= 1e-7 * r.length_estimate
        assert r.segments == r.tol_levels[-1]["segments"]


def test_tol_bad_input_and_strict() -> None:
    m = finsler.get_metric("poincare")
    s, g = np.array([0.1, 0.2]), np.array([-0.5, 0.3])
    for bad in (0.0, 1.5, float("nan"), True):
        with pytest.raises(InputError, match="tol"):
            solvers.solve_geodesic(m, s, g, tol=bad)
    with pytest.raises(InputError, match="max_segments"):
        solvers.solve_geodesic(m, s, g, 64, tol=1e-7, max_segments=32)
    with pytest.raises(solvers.SolverError, match="not reached"):
        solvers.solve_geodesic(m, s, g, 8, tol=1e-12, max_segments=32, strict=True)


def test_cli_solve_tol_json() -> None:
    from typer.testing import CliRunner

    from validation.cli import app

    m = finsler.get_metric("poincare")
    s, g = np.array([0.3, -0.4]), np.array([-0.6, 0.2])
    d = float(m.distance(s[None], g[None])[0])
    res = CliRunner().invoke(app, ["solve", "--metric", "poincare", "--start", "0.3,-0.4",
                                   "--goal", "-0.6,0.2", "--tol", "1e-7", "--json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.output)["results"][0]
    assert abs(row["length_estimate"] - d) <= 1e-7 * d
    assert row["error_estimate"] >= abs(row["length_estimate"] - d) / 3
    # "length" keeps one meaning: the sum of the costs C of the returned path
    pts = np.asarray(row["points"])
    assert row["length"] == pytest.approx(float(np.sum(m.path_costs(pts[None]))), rel=1e-12)
    assert row["segments"] >= 128 and row["order_seen"] is True
    assert row["minmax_status"] == "success" and row["status"] == "success"
    bad = CliRunner().invoke(app, ["solve", "--metric", "poincare", "--start", "0.3,-0.4",
                                   "--goal", "-0.6,0.2", "--tol", "2"])
    assert bad.exit_code != 0 and "--tol" in bad.output
