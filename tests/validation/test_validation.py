"""validation: property tests on solver distances (eq. 7, quasi-metric axioms, midpoint
property), the learned-vs-exact comparison API, and the report (its numbers agree with
``geodesics evaluate`` and ``geodesics solve`` run separately).

References are independent of the code under test: closed-form distances, straight lines
that are geodesics for constant norms, and the other CLI commands.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from typer.testing import CliRunner

import finsler
import solvers
from finsler import InputError
from validation import (
    ExactPolicy,
    StraightLine,
    build_report,
    compare,
    exact_reference,
    midpoint_error,
)
from validation import strategies as vs
from validation.cli import app
from validation.testing import ContinuumDistance, DistanceTests

SETTINGS = settings(
    max_examples=8,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
CLOSED = ("poincare", "sphere", "randers", "minkowski")


def _d(m: finsler.Metric, x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Solver distance and its error estimate (asserting convergence: a status, not a
    silent number)."""
    r = solvers.distance(m, x, y)
    assert r.converged, (m.name, x, y, r.status)
    return float(r.distance), float(r.error_estimate)


# ----------------------------------------------------------------------------------------
# properties of solver distances
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", CLOSED)
class TestSolverDistances(DistanceTests):
    """Quasi-metric axioms of the continuum solver distances (d(x, x) = 0, d > 0, the
    triangle inequality within the error estimates, symmetry exactly for the reversible
    metrics), the closed forms (both directions for the others: the asymmetry is the true
    one) to the solver's 1e-8, the certified interval and the midpoint halves: the suite
    users subclass (:class:`validation.testing.DistanceTests`)."""

    solved_examples = 4
    distance_oracle = ContinuumDistance()  # solvers.distance, rtol 1e-8
    distance_shrink = 0.95

    @pytest.fixture(autouse=True)
    def _metric(self, name: str) -> None:
        self.metric = finsler.get_metric(name)


@pytest.mark.parametrize("name", ["poincare", "randers", "sphere"])
@pytest.mark.parametrize("gap", [1e-162, 1e-12])
@pytest.mark.parametrize("x", [(0.0, 0.0), (0.1, -0.2)])
def test_solver_distance_of_nearly_coincident_points(name: str, gap: float, x) -> None:
    """d(x, x + gap e1) for tiny gaps (the case hypothesis found: x = 0, gap 1.7e-162):
    converged and equal to gap * F(x, e1) = C(x, y), which is d up to a relative O(gap)
    (Proposition 1). The reference uses homogeneity: the closed forms lose all digits at
    such gaps and F(x, v) itself underflows for |v| ~ 1e-162."""
    m = finsler.get_metric(name)
    x = np.array(x)
    e1 = np.array([1.0, 0.0])
    y = x + gap * e1
    ref = gap * float(m.F(x, e1))
    r = solvers.distance(m, x, y)
    assert r.converged, (name, gap, r.status, r.distance, ref)
    assert r.distance == pytest.approx(ref, rel=1e-6)


@pytest.mark.parametrize("name", ["carlike", "panda-pole"])
class TestDiscreteDistances(DistanceTests):
    """The paper's car and arm through the suite with the oracle ``geodesics check`` uses
    by default (discrete geodesics refined to 1e-4 from 8 to 64 segments)."""

    @pytest.fixture(autouse=True)
    def _metric(self, name: str) -> None:
        self.metric = finsler.get_metric(name)

    @pytest.mark.slow
    def test_certificate(self) -> None:
        """Slow (60-140 s: two 7-D Panda certificates; car-like is skipped, not smooth).
        The default run proves Panda's certificate sound in
        tests/solvers/certificates/conformal/test_certify_panda_split.py
        (lower bound below the solver's path on fresh pairs, parts and grouped)."""
        super().test_certificate()


class TestMatsumotoDistancesWhereFinsler(DistanceTests):
    """The same suite on Matsumoto's convex disk (well inside it: short pairs whose
    geodesics stay where F is convex), including the straight segment's length as an upper
    bound of d."""

    metric = finsler.get_metric("matsumoto")
    solved_examples = 6
    certify_examples = 2
    distance_oracle = ContinuumDistance()
    distance_shrink = 0.6 * finsler.MATSUMOTO_CONVEX_RADIUS


@SETTINGS
@given(vs.metric_and_triple(("poincare", "sphere", "randers"), shrink=0.95))
def test_eq7_on_solver_distances(mt) -> None:
    m, x, y, z = mt
    dxy, exy = _d(m, x, y)
    dxz, exz = _d(m, x, z)
    dzy, ezy = _d(m, z, y)
    slack = 2 * (dxz * exz + dzy * ezy) + dxy * exy + 1e-12
    assert dxz**2 + dzy**2 >= 0.5 * dxy**2 - slack
    if dxy < 1e-6:
        return
    # equality at the solver's midpoint, up to its O(1/n**2) discretisation error
    mid = solvers.midpoint(m, x, y, 64).point
    dxm, _ = _d(m, x, mid)
    dmy, _ = _d(m, mid, y)
    assert (dxm**2 + dmy**2) / (0.5 * dxy**2) - 1 <= 4e-4


@SETTINGS
@given(vs.metric_and_pair(("poincare", "sphere", "randers", "euclidean"), shrink=0.95))
def test_solver_midpoint_property_first_order_in_segments(mp) -> None:
    """d(x, m) = d(m, y) = d(x, y)/2 up to the discrete midpoint's O(1/n) error, which
    halves when n doubles (exact for constant norms)."""
    m, x, y = mp
    dxy = float(m.distance(x[None], y[None])[0])
    if dxy < 1e-3:
        return
    errs = []
    for n in (32, 64):
        p = solvers.midpoint(m, x, y, n).point
        d = m.distance(np.stack([x, p]), np.stack([p, y]))
        errs.append(float(np.max(np.abs(d - 0.5 * dxy))) / dxy)
        assert errs[-1] <= 1.0 / n, (n, errs)
    if errs[0] > 1e-7:
        assert 0.4 < errs[1] / errs[0] < 0.6, errs  # first order
    else:
        assert errs[1] < 1e-7


def test_solver_midpoint_property_on_matsumoto_inside_convex_radius() -> None:
    m = finsler.get_metric("matsumoto")
    x, y = np.array([0.12, -0.05]), np.array([-0.1, 0.1])
    dxy, e = _d(m, x, y)
    p = solvers.midpoint(m, x, y, 128).point
    dxm, _ = _d(m, x, p)
    dmy, _ = _d(m, p, y)
    assert abs(dxm - 0.5 * dxy) / dxy < 1.0 / 128
    assert abs(dmy - 0.5 * dxy) / dxy < 1.0 / 128
    assert dxm + dmy >= dxy - 3 * e  # triangle inequality


def test_prop1_reference_distance_agrees_with_the_solver_on_matsumoto() -> None:
    """The polygon reference of validation.propositions (used for Proposition 1 where no
    closed form exists) against solvers.distance, inside the convex radius; and the rate
    of C/d -> 1 measured with the solver's distances."""
    from validation import propositions as P

    m = finsler.get_metric("matsumoto")
    x, u = np.array([0.1, 0.05]), np.array([0.6, 0.8])
    ts = 0.1 * 2.0 ** -np.arange(4)
    for t in ts:
        y = x + t * u
        d, e = _d(m, x, y)
        poly = P.polygon_distance(m, x, y)
        assert d - e <= poly * (1 + 1e-12)  # the polygon is an upper bound
        assert poly == pytest.approx(d, rel=2e-6)
    r = P.proposition1_rate(m, x, u, ts, distance=lambda a, b: _d(m, a, b)[0])
    assert r.err[-1] < r.err[0] / 6
    assert 0.8 < r.rate < 1.2


# ----------------------------------------------------------------------------------------
# the comparison API
# ----------------------------------------------------------------------------------------
class DetourPolicy:
    """A deliberately bad policy: midpoints pushed sideways by half the pair's length."""

    def __init__(self, metric: finsler.Metric) -> None:
        self.metric = metric
        self.depth = metric.task.depth
        self.eps = metric.task.eps
        self.source = "detour"

    def midpoint(self, s: np.ndarray, g: np.ndarray) -> np.ndarray:
        s, g = np.atleast_2d(s), np.atleast_2d(g)
        d = g - s
        perp = np.stack([-d[:, 1], d[:, 0]], 1)
        return self.metric.domain.project(0.5 * (s + g) + 0.5 * perp)

    def generate(self, s: np.ndarray, g: np.ndarray, depth: int | None = None) -> np.ndarray:
        pts = [np.asarray(s, float), np.asarray(g, float)]
        for _ in range(self.depth if depth is None else depth):
            new = [pts[0]]
            for a, b in itertools.pairwise(pts):
                new += [self.midpoint(a, b), b]
            pts = new
        return np.stack(pts, 1)


@pytest.fixture(scope="module")
def randers_cmp():
    m = finsler.get_metric("randers")
    pairs = finsler.default_pairs(m)[:10]
    return m, pairs, compare(StraightLine(m), m, pairs, workers=1, progress=False)


def test_compare_straight_lines_are_exact_for_constant_norms(randers_cmp) -> None:
    m, pairs, c = randers_cmp
    np.testing.assert_array_equal(c.learned.paths, c.straight.paths)
    d = m.distance(pairs[:, 0], pairs[:, 1])
    np.testing.assert_allclose(c.exact.length, d, rtol=1e-8)  # exact = straight, C = d
    np.testing.assert_allclose(c.ratios("learned"), 1.0, atol=1e-8)
    np.testing.assert_allclose(c.ratios("learned", "length_quadrature"), 1.0, atol=1e-8)
    assert c.midpoint is not None and np.all(c.midpoint.ok)
    assert c.midpoint.err_max.max() < 1e-7  # coordinate midpoints are midpoints here
    assert c.learned.success_rate == c.straight.success_rate == c.exact.ceiling_rate
    assert c.timing["speedup_batched"] > 1


def test_comparison_has_success_rates_and_a_short_repr(randers_cmp) -> None:
    _, pairs, c = randers_cmp
    assert c.success_rate == c.to_dict()["success_rate"]
    assert c.success_rate["learned"] == c.learned.success_rate
    text = repr(c)
    assert len(text) < 300 and text.startswith("Comparison(metric='randers'")
    assert f"pairs={len(pairs)}" in text and "exact ceiling" in text


def test_compare_exposes_detours_on_a_curved_metric() -> None:
    m = finsler.get_metric("poincare")
    pairs = finsler.default_pairs(m)[:8]
    exact = exact_reference(m, pairs, workers=1, progress=False)
    d = m.distance(pairs[:, 0], pairs[:, 1])
    assert np.all(exact.converged)
    assert np.all(exact.length_quadrature >= d * (1 - 1e-9))  # an upper bound of d
    np.testing.assert_allclose(exact.length, d, rtol=0.02)  # discrete length near d
    straight = compare(StraightLine(m), m, pairs, exact=exact, midpoint=False, progress=False)
    # the straight segment is never shorter than d; against the exact discrete geodesic
    # (energy minimiser at n segments) only up to that path's O(1/n) discretisation error
    assert np.all(straight.learned.length_quadrature >= d * (1 - 1e-9))
    assert np.nanmin(straight.ratios("learned")) > 1 - 1.0 / m.task.segments
    assert np.nanmin(straight.ratios("learned", "length_quadrature")) > 1 - 1.0 / m.task.segments
    bad = compare(DetourPolicy(m), m, pairs, exact=exact, workers=1, progress=False)
    r = bad.ratios("learned")
    assert np.nanmax(r) > 1.5 and np.nanmedian(r) > 1.2
    assert bad.to_dict()["length_ratio"]["learned"]["length"]["max"] == pytest.approx(
        np.nanmax(r))
    assert bad.midpoint is not None and np.median(bad.midpoint.err_max) > 0.05
    # the exact midpoint p_{n/2} has only the O(1/n) discretisation error
    floor = midpoint_error(ExactPolicy(m), m, pairs[:4], exact=None, workers=1,
                           progress=False)
    assert floor.err_max.max() < 1.0 / m.task.segments


def test_compare_rejects_bad_input() -> None:
    m = finsler.get_metric("euclidean")
    pol = StraightLine(m)
    with pytest.raises(InputError, match="pairs"):
        compare(pol, m, np.zeros((3, 2)), progress=False)
    with pytest.raises(InputError, match="outside"):
        compare(pol, m, np.full((2, 2, 2), 3.0), progress=False)
    with pytest.raises(InputError, match="eps"):
        compare(pol, m, finsler.default_pairs(m)[:2], eps=-1.0, progress=False)

    class Broken(StraightLine):
        def generate(self, s, g, depth=None):  # wrong number of points
            return super().generate(s, g, depth)[:, :-1]

    with pytest.raises(InputError, match="shape"):
        compare(Broken(m), m, finsler.default_pairs(m)[:2], progress=False)


# ----------------------------------------------------------------------------------------
# the report, and agreement with `geodesics evaluate` / `geodesics solve`
# ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def matsumoto_policy(tmp_path_factory) -> list[str]:
    """CLI arguments selecting the shipped Matsumoto policy, or (before one is shipped) a
    tiny run trained here."""
    import learn

    if "matsumoto" in learn.shipped_policies():
        return ["--env", "matsumoto"]
    run = tmp_path_factory.mktemp("run")
    cfg = learn.default_config("matsumoto", timesteps=200_000, minutes=0.2, eval_every=2)
    learn.train_run(cfg, run, progress=False)
    return ["--run", str(run)]


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory, matsumoto_policy):
    tmp = tmp_path_factory.mktemp("report")
    pairs = finsler.default_pairs(finsler.get_metric("matsumoto"))[:8]
    np.save(tmp / "pairs.npy", pairs)
    res = CliRunner().invoke(app, ["report", *matsumoto_policy, "--pairs",
                                   str(tmp / "pairs.npy"), "--out", str(tmp / "out"),
                                   "--quick", "--workers", "1", "--no-progress"])
    assert res.exit_code == 0, res.output
    return tmp


def test_report_writes_markdown_json_and_figures(report_dir: Path) -> None:
    out = report_dir / "out"
    doc = json.loads((out / "report.json").read_text())  # strict JSON: no NaN
    md = (out / "report.md").read_text()
    assert doc["pairs"] == 8 and doc["segments"] == 64
    for f in ("paths.png", "length_ratio.png", "midpoint_error.png", "learning_curve.png"):
        assert f in doc["figures"]
        assert _png_has_content(out / f), f
        assert f"]({f})" in md
    assert f"{100 * doc['success_rate']['straight']:.0f}%" in md
    lr = doc["length_ratio"]["learned"]["length"]
    ratios = [p["learned_length"] / p["exact_length"] for p in doc["per_pair"]]
    assert lr["max"] == pytest.approx(max(ratios), rel=1e-12)
    assert lr["median"] == pytest.approx(float(np.median(ratios)), rel=1e-12)


def test_report_states_its_threads_and_times_warm(report_dir: Path, matsumoto_policy) -> None:
    """The report's learned time per path: one torch thread (said in report.md), batches
    1, 100 and 10,000, and at 10,000 within 2x of a warm one-thread measurement made here."""
    import time

    import torch

    import learn

    out = report_dir / "out"
    doc = json.loads((out / "report.json").read_text())
    t = doc["timing"]
    md = (out / "report.md").read_text()
    assert t["threads"] == 1 and "torch limited to 1 thread(s)" in md
    assert set(t["learned_seconds_per_path"]) == {"1", "100", "10000"}
    for row in ("| 1 |", "| 100 |", "| 10,000 |"):
        assert row in md
    assert "Speed-up of the learned policy on matsumoto" in md
    src = matsumoto_policy[1]
    policy = learn.load_policy(src) if matsumoto_policy[0] == "--env" else \
        learn.load_any_policy(src)
    pairs = finsler.default_pairs(finsler.get_metric("matsumoto"))[:8]
    idx = np.arange(10_000) % len(pairs)
    s, g = pairs[idx, 0], pairs[idx, 1]
    old = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        policy.generate(s, g)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            policy.generate(s, g)
            times.append((time.perf_counter() - t0) / len(idx))
    finally:
        torch.set_num_threads(old)
    ours, theirs = float(np.median(times)), t["learned_seconds_per_path"]["10000"]
    assert 0.5 < theirs / ours < 2.0, (theirs, ours)


def test_report_gives_the_route_search_beside_the_policy(report_dir: Path) -> None:
    """The report's fourth path set: the policy with the route search, never failing where
    the policy succeeds (its largest segment within max(eps, the policy's)), shorter on
    average, its ratios computed from its per-pair lengths, its cost in evaluations of C
    stated."""
    out = report_dir / "out"
    doc = json.loads((out / "report.json").read_text())
    md = (out / "report.md").read_text()
    assert doc["search"]["evaluations_of_C_per_path"] > 0
    assert doc["search"]["uses_derivative_of_C"] is False
    rows = doc["per_pair"]
    eps = doc["eps"]
    assert all(r["searched_max_segment_cost"]
               <= max(eps, r["learned_max_segment_cost"]) * (1 + 1e-12) for r in rows)
    assert all(r["searched_success"] for r in rows if r["learned_success"])
    assert np.mean([r["searched_length"] for r in rows]) < np.mean(
        [r["learned_length"] for r in rows])
    ratios = [r["searched_length"] / r["exact_length"] for r in rows]
    assert doc["length_ratio"]["searched"]["length"]["mean"] == pytest.approx(
        float(np.mean(ratios)), rel=1e-12)
    assert "learned policy + route search" in md and "evaluates C" in md


def test_report_certifies_a_few_pairs(report_dir: Path) -> None:
    """Quick reports on 2-D metrics certify 2 pairs: every curve from s to g (the exact
    path, the learned one) is at least as long as the certified lower bound, the upper bound
    is the exact path's proven length, and the excess bounds follow from the learned
    paths' proven lengths (recomputed here)."""
    import learn

    doc = json.loads((report_dir / "out" / "report.json").read_text())
    md = (report_dir / "out" / "report.md").read_text()
    cert = doc["certified"]
    assert cert["mesh"] == "coarse" and len(cert["pairs"]) == 2
    m = finsler.get_metric("matsumoto")
    pairs = np.load(report_dir / "pairs.npy")
    pol = learn.load_policy("matsumoto")
    paths = pol.generate(pairs[:, 0], pairs[:, 1])  # the batch the report generated
    for r in cert["pairs"]:
        row = doc["per_pair"][r["pair"]]
        assert 0 < r["lower"] <= r["upper"]
        assert r["lower"] <= row["exact_length_quadrature"] * (1 + 1e-9)
        assert r["lower"] <= row["learned_length_quadrature"] * (1 + 1e-9)
        assert r["upper"] == pytest.approx(r["exact_length_proven_upper"], rel=1e-12)
        up = m.path_length_bounds(paths[r["pair"]]).upper
        assert r["learned_excess_bound"] == pytest.approx(up / r["lower"] - 1, rel=1e-9)
        assert r["searched_excess_bound"] <= r["learned_excess_bound"] + 1e-9
    assert "## Certified distances" in md


def test_report_names_its_checkpoint_and_running_mean_times(report_dir: Path) -> None:
    doc = json.loads((report_dir / "out" / "report.json").read_text())
    assert "policy.pt" in doc["policy_note"] or "checkpoint_best.pt" in doc["policy_note"]
    assert set(doc["time_to_success"]) == {"0.9", "0.95", "0.99"}


def test_the_learning_curve_names_the_pairs_it_was_evaluated_on(report_dir: Path,
                                                                 tmp_path: Path,
                                                                 monkeypatch) -> None:
    """A policy trained before the validation set existed (the replaced Matsumoto and
    Panda policies) has its curve on the default set; the shipped Matsumoto and Panda
    policies (issue 25) and a run trained now are on the validation set, and the report
    says which."""
    import learn
    from validation.report import curve_set

    doc = json.loads((report_dir / "out" / "report.json").read_text())
    md = (report_dir / "out" / "report.md").read_text()
    if "matsumoto" in learn.shipped_policies():
        assert doc["learning_curve_pairs"] == "validation"
        assert "the validation pairs (finsler.validation_pairs)" in md
        assert "DEFAULT evaluation pairs" not in md
    run = tmp_path / "run"
    learn.train_run(learn.default_config("euclidean", timesteps=5000, eval_every=1), run,
                    progress=False)
    assert curve_set(run) == "validation"
    assert curve_set(Path(learn.load_policy("matsumoto").source)) == "validation"
    old = Path(__file__).resolve().parents[2] / "benchmarks" / "previous_policies"
    assert curve_set(old / "matsumoto") == "default"
    assert curve_set(old / "panda-pole") == "default"
    assert curve_set(Path(learn.load_policy("panda-pole").source)) == "validation"
    # the sentence naming a shipped policy says the same (it said "default" for all)
    from validation.report import load_report_policy

    _, _, note = load_report_policy("matsumoto", None, False, tmp_path)
    assert "selected on the validation set" in note and "default evaluation" not in note
    _, _, note = load_report_policy("panda-pole", None, False, tmp_path)
    assert "selected on the validation set" in note and "default evaluation" not in note
    # a shipped policy chosen on the default set (the replaced Panda one) is named so
    monkeypatch.setattr(learn.runs, "shipped_dir", lambda name: old / name)
    _, _, note = load_report_policy("panda-pole", None, False, tmp_path)
    assert "selected on the default evaluation set" in note


def test_time_to_success_needs_a_running_mean_of_five() -> None:
    from validation.report import time_to_success

    succ = [0.5, 1.0, 0.9, 0.9, 0.9, 0.9, 0.96, 0.97, 1.0, 1.0]
    rows = [{"timesteps": 100 * i, "wall_seconds": float(i), "success_rate": s}
            for i, s in enumerate(succ)]
    got = time_to_success(rows, thresholds=(0.9, 0.95, 0.99))
    # means of 5: rows 0-4 0.84, 1-5 0.92 (>= 0.9 at row 5), ..., 5-9 0.966 (>= 0.95 at 9)
    assert got["0.9"] == {"timesteps": 500.0, "wall_seconds": 5.0}
    assert got["0.95"] == {"timesteps": 900.0, "wall_seconds": 9.0}
    assert got["0.99"] is None  # one evaluation of 1.0 is not a running mean


def _png_has_content(path: Path) -> bool:
    """The PNG decodes and is not blank: over 2% of its pixels differ from the background."""
    import matplotlib.image as mpimg

    img = mpimg.imread(path)[..., :3]
    background = img[0, 0]
    return img.shape[0] > 200 and img.shape[1] > 200 and \
        float(np.mean(np.any(np.abs(img - background) > 0.05, axis=-1))) > 0.02


def test_report_success_equals_an_independent_evaluation(report_dir: Path) -> None:
    """The report's per-pair success and max segment cost, recomputed here from the
    policy's paths with CasADi's own evaluation of C (not the lowered numpy program the
    report and `evaluate` share)."""
    import learn

    doc = json.loads((report_dir / "out" / "report.json").read_text())
    pol = learn.load_policy("matsumoto")
    pairs = np.load(report_dir / "pairs.npy")
    paths = pol.generate(pairs[:, 0], pairs[:, 1])
    cost = pol.metric.casadi_cost
    for path, row in zip(paths, doc["per_pair"]):
        c = np.array([float(cost(path[i], path[i + 1])) for i in range(len(path) - 1)])
        assert row["learned_max_segment_cost"] == pytest.approx(c.max(), rel=1e-10)
        assert row["learned_length"] == pytest.approx(c.sum(), rel=1e-10)
        assert row["learned_success"] == bool(c.max() <= doc["eps"])


def test_report_agrees_with_geodesics_evaluate(report_dir: Path, matsumoto_policy) -> None:
    doc = json.loads((report_dir / "out" / "report.json").read_text())
    res = CliRunner().invoke(app, ["evaluate", *matsumoto_policy, "--pairs",
                                   str(report_dir / "pairs.npy"), "--json"])
    assert res.exit_code == 0, res.output
    ev = json.loads(res.output)
    assert ev["success_rate"] == doc["success_rate"]["learned"]
    assert ev["eps"] == doc["eps"] and ev["depth"] == doc["depth"]
    for a, b in zip(ev["per_pair"], doc["per_pair"]):
        assert a["success"] == b["learned_success"]
        assert a["length"] == pytest.approx(b["learned_length"], rel=1e-12)
        assert a["max_segment_cost"] == pytest.approx(b["learned_max_segment_cost"], rel=1e-12)


def test_report_agrees_with_geodesics_solve(report_dir: Path) -> None:
    doc = json.loads((report_dir / "out" / "report.json").read_text())
    res = CliRunner().invoke(app, ["solve", "--metric", "matsumoto", "--pairs",
                                   str(report_dir / "pairs.npy"), "--json", "--workers", "1",
                                   "--no-progress"])
    assert res.exit_code == 0, res.output
    sv = json.loads(res.output)
    assert sv["success_rate"] == doc["success_rate"]["exact_ceiling"]
    for a, b in zip(sv["results"], doc["per_pair"]):
        assert a["status"] == b["exact_status"]
        assert a["length"] == pytest.approx(b["exact_length"], rel=1e-9)
        assert a["length_quadrature"] == pytest.approx(b["exact_length_quadrature"], rel=1e-9)
        assert a["minmax_max_segment_cost"] == pytest.approx(
            b["exact_minmax_max_segment_cost"], rel=1e-9)


# car-like costs ~80 s (its exact solve at 256 segments): slow; the same figure is drawn for
# a user's pose metric in tests/learn/test_metric_params.py (test_report_picks_figures_...)
@pytest.mark.parametrize("env", [pytest.param("carlike", marks=pytest.mark.slow), "panda-pole"])
def test_report_figures_for_car_and_arm(tmp_path: Path, env: str) -> None:
    m = finsler.get_metric(env)
    doc = build_report(env, tmp_path, pairs=finsler.default_pairs(m)[:1],
                       policy=StraightLine(m), workers=1, progress=False, continuum=False,
                       certify=0)  # beyond 2-D: tests/validation/test_report_certify.py
    name = "carlike_headings.png" if env == "carlike" else "panda_motion.png"
    assert name in doc["figures"] and _png_has_content(tmp_path / name)
    assert math.isfinite(doc["success_rate"]["straight"])


def test_report_cli_errors_are_named(tmp_path: Path) -> None:
    r = CliRunner()
    res = r.invoke(app, ["report", "--env", "nosuch", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "unknown" in res.output
    res = r.invoke(app, ["report", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "--env" in res.output
    res = r.invoke(app, ["report", "--env", "euclidean", "--run", str(tmp_path / "none"),
                         "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "does not exist" in res.output
    m = finsler.get_metric("euclidean")
    bad = tmp_path / "bad.npy"
    bad.write_bytes(b"not numpy")
    with pytest.raises(InputError, match="readable"):
        build_report("euclidean", tmp_path / "o", pairs=bad, policy=StraightLine(m))
    np.save(tmp_path / "wrong.npy", np.zeros((3, 2)))
    with pytest.raises(InputError, match="shape"):
        build_report("euclidean", tmp_path / "o", pairs=tmp_path / "wrong.npy",
                     policy=StraightLine(m))
