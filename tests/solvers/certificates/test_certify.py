"""Certified intervals (issue 10 part 1): lower <= exact distance <= upper on closed-form
references, the rigour test (sampled constraints overshoot, rigorous ones do not), input
errors and the CLI."""

from __future__ import annotations

import gc
import importlib
import json
import weakref

import casadi as ca
import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
from finsler import InputError
from solvers import CertifyResult, CertifyStatus, MeshSpec, Status, certify
from validation.cli import app

from tests.helpers.metrics.certify import Bowl

runner = CliRunner()
# the module (``solvers.certify`` the attribute is the function of the same name)
certify_mod = importlib.import_module("solvers.certificates.plane.certificate")
bounds_mod = importlib.import_module("solvers.certificates.plane.bounds")
mesh_mod = importlib.import_module("solvers.certificates.plane.mesh")
bounds_mod = importlib.import_module("solvers.certificates.plane.bounds")

#: the metrics that provide a closed-form distance (asked, not listed)
CLOSED_FORM = finsler.list_metrics(provides="distance", dim=2)
#: a quick mesh for the default test run
QUICK = MeshSpec(h_path=0.15, h_far=0.4, corridor=0.1, directions=32, target_gap=5e-2,
                 max_rounds=2, max_triangles=2000)


def _exact_path(m: finsler.ClosedFormMetric, s: np.ndarray, g: np.ndarray,
                n: int = 64) -> np.ndarray:
    pts = m.geodesic(s[None], g[None], np.linspace(0.0, 1.0, n + 1))[0]
    pts[0], pts[-1] = s, g
    return np.asarray(m.domain.project(pts), float)


def _check_interval(name: str, k: int, seed: int, spec: MeshSpec) -> list[CertifyResult]:
    m = finsler.get_metric(name)
    out = []
    for s, g in finsler.sample_pairs(m, k, seed):
        exact = float(m.distance(s, g)[0])
        r = certify(m, s, g, spec, path=_exact_path(m, s, g))
        # the lower bound is never above the exact distance (the point of the method)
        assert r.lower <= exact * (1 + 1e-12), (name, s, g, r.lower, exact)
        # a curve's length plus its quadrature error is never below it
        assert r.upper >= exact * (1 - 1e-12), (name, s, g, r.upper, exact)
        assert r.gap < 0.2
        out.append(r)
    return out


@pytest.mark.parametrize("name", CLOSED_FORM)
def test_interval_contains_exact_distance(name: str) -> None:
    _check_interval(name, 2, 4242, QUICK)


@pytest.mark.slow
@pytest.mark.parametrize("name", CLOSED_FORM)
def test_interval_contains_exact_distance_50_pairs(name: str) -> None:
    # the bar: 50 random pairs per closed-form metric
    _check_interval(name, 50, 777, MeshSpec.preset("coarse"))


def test_solver_path_upper_bound_and_default_gap_poincare() -> None:
    m = finsler.get_metric("poincare")
    s, g = np.array([0.5, -0.4]), np.array([-0.3, 0.6])
    exact = float(m.distance(s, g)[0])
    r = certify(m, s, g, MeshSpec(h_path=0.1, directions=64, target_gap=1e-2))
    assert r.lower <= exact <= r.upper
    assert r.gap <= 1e-2
    assert r.solver_status is Status.SUCCESS and r.to_dict()["solver_status"] == "success"
    assert r.status is CertifyStatus.CERTIFIED and r.converged
    assert r.convexity == "convex"
    assert r.upper - exact < 1e-4 * exact  # the solver's path is near the geodesic
    d = r.to_dict()
    assert {"lower", "upper", "gap", "triangles", "directions", "times", "mesh"} <= set(d)
    assert d["status"] == "certified" and d["stopped_by"] == "target_gap"
    assert "path" not in d and len(r.to_dict(with_path=True)["path"]) == r.path.shape[0]
    json.dumps(d)


def test_refinement_tightens_the_bound() -> None:
    # a finer target makes the dual-driven refinement add rounds and raise the lower bound
    m = finsler.get_metric("poincare")
    s, g = np.array([-0.6, -0.2]), np.array([0.55, 0.3])
    path = _exact_path(m, s, g)
    coarse = certify(m, s, g, MeshSpec(h_path=0.2, directions=64, target_gap=0.5,
                                       max_rounds=1), path=path)
    fine = certify(m, s, g, MeshSpec(h_path=0.2, directions=64, target_gap=2e-3,
                                     max_rounds=3), path=path)
    assert len(fine.rounds) > 1
    assert fine.triangles > coarse.triangles
    assert fine.lower > coarse.lower
    assert fine.lower <= float(m.distance(s, g)[0])


def _weights_lp(w: list[float]) -> tuple[dict, np.ndarray]:
    """An LP result whose triangle ``t`` carries dual-weighted correction ``w[t]`` (one row
    per triangle, correction 1)."""
    n = len(w)
    rows = np.stack([np.arange(n), np.zeros(n, int), np.zeros(n, int)], 1)
    return {"rows": rows, "duals": np.asarray(w, float)}, np.ones((n, 1))


@pytest.mark.parametrize(("scale", "goal", "expected"), [
    # W = 1e-3 (the target): cutting 0.45 W brings it to 0.7 x target -> the top triangle
    (1e-4, True, [0]),
    # W = 1e-2, far above the target: Doerfler's 0.99 of the weight, every triangle here
    (1e-3, True, [0, 1, 2, 3, 4]),
    # without the goal, Doerfler's fraction at any W
    (1e-4, False, [0, 1, 2, 3, 4]),
    # W below 0.7 x target: the floor (0.3 of the weight) still refines the top triangle
    (0.6e-4, True, [0])])
def test_marking_refines_what_the_target_needs(monkeypatch: pytest.MonkeyPatch, scale: float,
                                               goal: bool, expected: list[int]) -> None:
    monkeypatch.setattr(certify_mod, "GOAL_MARKING", goal)
    lp, corr = _weights_lp([5 * scale, 3 * scale, scale, 0.5 * scale, 0.5 * scale])
    spec = MeshSpec(target_gap=1e-3, mark_fraction=0.99)
    marked = certify_mod._marked(lp, corr, 5, spec, 1.0)
    assert sorted(marked.tolist()) == expected
    # ten times the upper bound is ten times the absolute target: less weight to cut
    if goal and scale == 1e-3:
        assert len(certify_mod._marked(lp, corr, 5, spec, 10.0)) < 5


def _no_corrections(monkeypatch: pytest.MonkeyPatch) -> None:
    """Drop the second-order corrections: constraints at sampled points and directions
    only (not a bound)."""
    def zero(hz: np.ndarray, ht: np.ndarray, r2: np.ndarray) -> np.ndarray:
        return np.zeros_like(hz)

    monkeypatch.setattr(bounds_mod, "_corrections", zero)
    # and no region (certify_reach): its bound min(rise, upper) would hide the overshoot
    monkeypatch.setattr(certify_mod, "speed_floor", lambda metric, poly: 0.0)


def test_sampled_directions_overshoot_rigorous_does_not(monkeypatch) -> None:
    # Euclidean, 8 directions: a pair between two sampled directions. Rows g . v_k <= 1 at
    # the samples only allow |g| up to 1/cos(pi/8) there: the "bound" exceeds the exact
    # distance by ~8%; the chord correction keeps the rigorous one below it.
    m = finsler.get_metric("euclidean")
    a = np.pi / 8
    s = np.array([-0.5 * np.cos(a), -0.5 * np.sin(a)])
    g = -s
    exact = 1.0
    spec = MeshSpec(h_path=0.2, h_far=0.4, directions=8, target_gap=1e-3, max_rounds=1)
    rigorous = certify(m, s, g, spec, path=np.stack([s, g]))
    assert rigorous.lower <= exact
    _no_corrections(monkeypatch)
    sampled = certify(m, s, g, spec, path=np.stack([s, g]))
    assert sampled.lower > exact * 1.05


def test_sampled_points_overshoot_rigorous_does_not(monkeypatch) -> None:
    # Poincare (F convex in z: the linear interpolant of vertex values lies above F inside a
    # triangle) on a coarse mesh with many directions: rows at the vertices only let the
    # bound exceed the exact distance; with the curvature correction it stays below.
    m = finsler.get_metric("poincare")
    s, g = np.array([-0.7, 0.1]), np.array([0.7, 0.1])
    exact = float(m.distance(s, g)[0])
    spec = MeshSpec(h_path=0.3, h_far=0.4, corridor=0.3, directions=256, target_gap=1e-3,
                    max_rounds=1)
    path = _exact_path(m, s, g)
    rigorous = certify(m, s, g, spec, path=path)
    assert rigorous.lower <= exact
    _no_corrections(monkeypatch)
    sampled = certify(m, s, g, spec, path=path)
    assert sampled.lower > exact


def test_matsumoto_convexified_and_below_a_fine_path() -> None:
    m = finsler.get_metric("matsumoto")
    s, g = np.array([-0.6, 0.1]), np.array([0.5, 0.3])  # across the non-convex region
    r = certify(m, s, g, MeshSpec(h_path=0.12, directions=128, target_gap=3e-2, max_rounds=2))
    assert r.convexity == "convexified" and "convexification" in r.convexity_note
    # an independent upper value: a 512-segment solve, its length by quadrature
    from solvers import solve_geodesic

    fine = solve_geodesic(m, s, g, 512)
    assert r.lower <= m.path_length_error(fine.points).value
    assert r.lower <= r.upper and r.gap <= 0.1


def test_same_input_same_result() -> None:
    m = finsler.get_metric("randers")
    s, g = np.array([0.3, -0.2]), np.array([-0.6, 0.5])
    a = certify(m, s, g, QUICK, path=np.stack([s, g]))
    b = certify(m, s, g, QUICK, path=np.stack([s, g]))
    assert a.lower == b.lower and a.upper == b.upper and a.triangles == b.triangles


@pytest.mark.parametrize(
    ("args", "kwargs", "message"),
    [
        # 7-D is accepted (conformal lower bounds): its input is checked the same way
        (("panda-pole", np.zeros(7), np.ones(7) * 0.1), {}, "outside the domain"),
        (("panda-pole", [0.0, 0.0, 0.0, -1.5, 0.0, 1.8, 0.0],
          [0.0, 0.0, 0.0, -1.5, 0.0, 1.8, 0.0]), {}, "start equals goal"),
        (("matsumoto", [1.2, 0.0], [0.0, 0.0]), {}, "outside the domain"),
        (("matsumoto", [0.1, 0.0], [0.1, 0.0]), {}, "start equals goal"),
        (("matsumoto", [0.1, 0.0], [0.0, 0.0]), {"settings": "huge"}, "unknown mesh preset"),
        (("matsumoto", [0.1, 0.0], [0.0, 0.0]), {"settings": 3}, "MeshSpec"),
        (("matsumoto", [0.1, 0.0], [0.0, 0.0]), {"time_limit": -1.0}, "time_limit"),
        (("matsumoto", [0.1, 0.0], [0.0, 0.0]), {"path": [[0.1, 0.0], [0.0, 0.5]]},
         "from start to goal"),
        (("matsumoto", [0.1, 0.0], [0.0, 0.0]), {"path": [[0.1, 0.0], [2.0, 0.0], [0.0, 0.0]]},
         "outside the domain"),
    ],
)
def test_bad_input(args: tuple, kwargs: dict, message: str) -> None:
    with pytest.raises(InputError, match=message):
        certify(*args, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"directions": 4}, "directions"), ({"h_path": 0.0}, "h_path"),
     ({"h_path": 0.5, "h_far": 0.1}, "h_far"), ({"target_gap": float("nan")}, "target_gap"),
     ({"segments": 1}, "segments"), ({"mark_fraction": 2.0}, "mark_fraction")],
)
def test_bad_mesh_spec(kwargs: dict, message: str) -> None:
    with pytest.raises(InputError, match=message):
        MeshSpec(**kwargs)


def test_cli_certify_json() -> None:
    res = runner.invoke(app, ["certify", "--metric", "euclidean", "--start", "-0.5,-0.2",
                              "--goal", "0.4,0.6", "--mesh", "coarse", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    exact = float(np.hypot(0.9, 0.8))
    assert out["lower"] <= exact <= out["upper"]
    assert out["gap"] == pytest.approx((out["upper"] - out["lower"]) / out["upper"])
    assert out["triangles"] > 0 and out["times"]["total"] > 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--metric", "panda-pole", "--start", "0,0,0,-1,0,1,0", "--goal", "0,0,0,-1,0,1,0"],
         "start equals goal"),  # 7-D conformal: solvers.certificates.conformal
        (["--metric", "matsumoto", "--start", "1.2,0", "--goal", "0,0"], "outside the domain"),
        (["--metric", "matsumoto", "--start", "0.1,0", "--goal", "0,0", "--mesh", "huge"],
         "unknown mesh preset"),
        (["--metric", "matsumoto", "--start", "0.1,0", "--goal", "0,0", "--directions", "3"],
         "directions"),
        (["--metric", "matsumoto", "--start", "0.1,0", "--goal", "0,0", "--target-gap", "2"],
         "--target-gap"),
        (["--metric", "matsumoto", "--start", "0.1,0", "--goal", "0.1,0"], "start equals goal"),
    ],
)
def test_cli_certify_bad_input(args: list[str], message: str) -> None:
    res = runner.invoke(app, ["certify", *args])
    assert res.exit_code == 2
    assert message in res.output


def test_derived_geometry_lives_in_the_metric() -> None:
    # issue 23: the values of F are the metric's own lowered_F and the Hessian programs are
    # built once in Metric.derived, not in module caches keyed by metric (which would keep
    # the metric alive after its last use)
    m = type(finsler.get_metric("randers"))()  # its own instance (the registry shares its own)
    lo, v = np.array([[0.1, 0.1], [-0.2, 0.3]]), np.array([[1.0, 0.0], [0.6, 0.8]])
    w = np.array([[np.cos(0.1), np.sin(0.1)], [0.0, 1.0]])
    bounds_mod._bounds_on_boxes(m, lo, lo + 0.02, v, w)
    progs = bounds_mod._second_derivatives(m)
    assert m.derived("certify.second_derivatives", lambda: pytest.fail("rebuilt")) is progs
    f = bounds_mod._eval_values(m, lo, v)
    exact = m.F(lo, v)
    assert np.all(f < exact) and np.allclose(f, exact, rtol=1e-14, atol=0)
    assert not hasattr(certify_mod, "_values")
    ref = weakref.ref(m)
    del m
    gc.collect()
    assert ref() is None


@pytest.mark.parametrize("name", ["matsumoto", "poincare", "randers"])
def test_second_order_bounds_hold_at_every_sampled_point(name: str) -> None:
    # the corrections' Hz and Ht (interval enclosures, mean-value form) are above the
    # largest eigenvalue of Hess_z F and the chord curvature at random points of the box /
    # chord, including the steep Matsumoto rim
    m = finsler.get_metric(name)
    rng = np.random.default_rng(3)
    n, k = 300, 64
    r = (0.85 if name == "matsumoto" else 0.6) * np.sqrt(rng.uniform(0, 1, n))
    a = rng.uniform(0, 2 * np.pi, n)
    c = np.stack([r * np.cos(a), r * np.sin(a)], 1)
    h = rng.uniform(0.005, 0.04, (n, 1))
    ang = 2 * np.pi * np.arange(k) / k
    dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
    kidx = rng.integers(0, k, n)
    v, w = dirs[kidx], dirs[(kidx + 1) % k]
    hz, ht = bounds_mod._bounds_on_boxes(m, c - h, c + h, v, w)
    # an infinite enclosure is allowed (certify then splits the box), a wrong one is not
    assert np.mean(np.isfinite(hz) & np.isfinite(ht)) > 0.9
    x, vv = ca.SX.sym("x", 2), ca.SX.sym("v", 2)
    f = m.F_sx(x, vv)
    hess_x = ca.Function("hx", [x, vv], [ca.hessian(f, x)[0]])
    hess_v = ca.Function("hv", [x, vv], [ca.hessian(f, vv)[0]])
    seen_z, seen_t = np.zeros(n), np.zeros(n)
    for _ in range(30):
        z = c + rng.uniform(-1, 1, (n, 2)) * h
        t = rng.uniform(0, 1, n)
        u = (1 - t)[:, None] * v + t[:, None] * w
        for i in range(n):
            lam = np.linalg.eigvalsh(np.array(hess_x(z[i], v[i])))[-1]
            d = w[i] - v[i]
            q = float(d @ np.array(hess_v(z[i], u[i])) @ d)
            assert lam <= hz[i] * (1 + 1e-12) + 1e-12, (i, lam, hz[i])
            assert q <= ht[i] * (1 + 1e-12) + 1e-12, (i, q, ht[i])
            seen_z[i], seen_t[i] = max(seen_z[i], lam), max(seen_t[i], q)
    # and the bounds are not vacuous: typically within a factor 5 of the sampled maximum
    for seen, bound in ((seen_z, hz), (seen_t, ht)):
        ok = np.isfinite(bound) & (bound > 1e-9)
        if np.any(ok):
            assert np.median(seen[ok] / bound[ok]) > 0.2


def test_row_bounds_hold_inside_every_triangle_where_the_hessian_term_is_tight() -> None:
    """The rows at a triangle's vertices are ``grad phi_T(z_m) . v_k <= b_m,k``; grad phi_T
    is affine, so inside the triangle ``grad phi_T(z) . v_k`` is at most the barycentric
    mix of the ``b``: that mix must stay below ``F(z, v_k)`` at EVERY point z (else the
    potential may violate the dual condition there and the lower bound is not proven).
    On the bowl metric the Hessian term is tight at the centres of equilateral triangles:
    a correction any smaller (e.g. ``0.25 * hz * r2`` instead of ``0.5``) fails here."""
    m = Bowl()
    pts = mesh_mod._hex_lattice(np.array([-0.6, -0.6]), np.array([0.6, 0.6]), 0.2)
    pts = pts[np.linalg.norm(pts, axis=1) <= 0.75]
    msh = certify_mod._Mesh(pts)
    data = certify_mod._PointData(m, 64)
    b, corr = bounds_mod._row_bounds(msh, data)
    z = pts[msh.tri]  # (T, 3, 2)
    side = np.linalg.norm(z[:, 1] - z[:, 0], axis=1)
    eq = np.abs(side - 0.2) < 1e-9  # the lattice's equilateral triangles
    assert eq.sum() > 20
    rng = np.random.default_rng(0)
    lam = np.vstack([np.full((1, 3), 1 / 3), rng.dirichlet(np.ones(3), 30)])  # centre first
    worst_centre = np.inf
    for j, w in enumerate(lam):
        zz = np.einsum("i,tid->td", w, z[eq])
        fz = 1 + m.c * np.sum(zz**2, axis=1)  # F(z, v_k) for unit v_k
        mix = np.einsum("i,tik->tk", w, b[eq])
        slack = fz[:, None] - mix
        assert np.all(slack >= 0), (j, slack.min())
        if j == 0:
            worst_centre = float((slack / corr[eq]).min())
    # at the centre almost all of the correction is used: it is tight, not loose
    assert worst_centre < 0.05


# ---- failures of the refinement are statuses with a proven interval, not exceptions ----
def _failing_lp(monkeypatch: pytest.MonkeyPatch, fail_from_call: int) -> list[int]:
    """Make the LP solver fail from its ``fail_from_call``-th call (1-based) on."""
    real, calls = certify_mod._solve_lp, [0]

    def solve_lp(*args: object, **kwargs: object) -> dict:
        calls[0] += 1
        if calls[0] >= fail_from_call:
            raise certify_mod.LPFailure("the LP ended with status infeasible (simulated)")
        return real(*args, **kwargs)

    monkeypatch.setattr(certify_mod, "_solve_lp", solve_lp)
    return calls


POINCARE_PAIR = (np.array([0.5, -0.4]), np.array([-0.3, 0.6]))


def test_lp_failure_in_first_round_is_a_status_with_trivial_lower_bound(
        monkeypatch: pytest.MonkeyPatch) -> None:
    _failing_lp(monkeypatch, 1)
    m = finsler.get_metric("poincare")
    s, g = POINCARE_PAIR
    r = certify(m, s, g, "coarse")
    exact = float(m.distance(s, g)[0])
    assert r.status is CertifyStatus.LP_FAILED and not r.converged
    assert r.stopped_by == "lp_failed" and "simulated" in r.message
    assert r.lower == 0.0 and r.upper >= exact and r.certified and r.rounds == []
    assert r.to_dict()["status"] == "lp_failed"


def test_lp_failure_in_a_later_round_keeps_the_best_proven_lower_bound(
        monkeypatch: pytest.MonkeyPatch) -> None:
    _failing_lp(monkeypatch, 2)
    m = finsler.get_metric("poincare")
    s, g = POINCARE_PAIR
    r = certify(m, s, g, MeshSpec(h_path=0.2, directions=16, target_gap=1e-6))
    exact = float(m.distance(s, g)[0])
    assert r.status is CertifyStatus.LP_FAILED and len(r.rounds) == 1
    assert r.lower == r.rounds[0]["lower"] and 0.0 < r.lower <= exact <= r.upper


def test_corrections_that_do_not_shrink_are_a_status(monkeypatch: pytest.MonkeyPatch) -> None:
    def huge(hz: np.ndarray, ht: np.ndarray, r2: np.ndarray) -> np.ndarray:
        return np.full_like(hz, 1e6)

    monkeypatch.setattr(bounds_mod, "_corrections", huge)
    m = finsler.get_metric("poincare")
    s, g = POINCARE_PAIR
    r = certify(m, s, g, "coarse")
    assert r.status is CertifyStatus.CORRECTIONS_TOO_LARGE and r.lower == 0.0
    assert "max_triangles" in r.message or "refinements" in r.message


def test_budget_ends_with_budget_reached_status() -> None:
    m = finsler.get_metric("poincare")
    s, g = POINCARE_PAIR
    r = certify(m, s, g, MeshSpec(h_path=0.2, directions=16, target_gap=1e-9, max_rounds=1))
    exact = float(m.distance(s, g)[0])
    assert r.status is CertifyStatus.BUDGET_REACHED and r.stopped_by == "max_rounds"
    assert r.lower <= exact <= r.upper and r.gap > 1e-9 and not r.converged


def test_cli_certify_failure_prints_the_result_then_exits_1(
        monkeypatch: pytest.MonkeyPatch) -> None:
    _failing_lp(monkeypatch, 1)
    res = runner.invoke(app, ["certify", "--metric", "poincare", "--start", "0.5,-0.4",
                              "--goal", "-0.3,0.6", "--mesh", "coarse", "--json"])
    assert res.exit_code == 1
    doc = json.loads(res.stdout)
    assert doc["status"] == "lp_failed" and doc["lower"] == 0.0
    assert "certify lp_failed" in res.stderr and len(res.stderr.strip().splitlines()) == 1

