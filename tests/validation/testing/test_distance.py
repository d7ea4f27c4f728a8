"""Fast focused tests of validation/testing/distance.py (mutation testing
of the property suite). The distance properties run on oracles built here from the
closed-form Euclidean distance (exact, no solve), each wrong in one way, so every verdict,
counterexample and note is known; the two real oracles run on closed-form metrics (the
solver returns them in a fraction of a second) and are compared with the closed form."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from finsler import Box, Euclidean, InputError, Metric, Randers
from finsler.status import DistanceStatus, Status
from validation.testing import distance as VD
from validation.testing.engine import FAILED, INCONCLUSIVE, MAPPED, PASSED, SKIPPED

from tests.helpers.metrics.distance_suite import Flat, Ring

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


@dataclass
class Exact:
    """d = |x - y| (the Euclidean metric's distance), straight paths; ``wrong`` bends one
    part of the answer."""

    wrong: str = ""
    name: str = "exact oracle"
    calls: list = field(default_factory=list)

    def solve(self, metric, x, y):
        self.calls.append((tuple(x), tuple(y)))
        d = float(np.linalg.norm(y - x))
        if self.wrong == "zero" and np.array_equal(x, y):
            d = 1e-300
        if self.wrong == "negative" and np.array_equal(x, y):
            d = -1e-9
        if self.wrong == "nil" and not np.array_equal(x, y):
            d = 0.0
        if self.wrong == "squared":
            d = d * d
        if self.wrong == "long":
            d = 1.01 * d
        if self.wrong == "asymmetric":
            d = d + 1e-3 * float(x[0] > y[0])
        if self.wrong == "offset" and not np.array_equal(x, y):
            d = d + 1e-6
        mid = 0.5 * (x + y)
        if self.wrong == "midpoint":
            mid = x + 0.3 * (y - x)
        bend = 0.05 if self.wrong == "bent" else 0.0

        def curve(t):
            t = np.asarray(t, float).reshape(-1, 1)
            return x + t * (y - x) + bend * np.sin(np.pi * t)

        usable = not (self.wrong == "unconverged" and not np.array_equal(x, y))
        mapped = self.wrong == "mapped" and not np.array_equal(x, y)
        extra = {"segments": 8, "other": 1} if self.wrong == "unconverged" else {}
        return VD.Solved(d, 1e-12, "converged" if usable else "max_iterations", usable,
                         mapped, np.stack([x, mid, y]), mid, 1e-12, curve, 1e-9, extra)


def _suite(wrong="", metric=None, shrink=1.0, seed=0):
    return VD.DistanceSuite.make(metric or Euclidean(), Exact(wrong), seed=seed, shrink=shrink)


# ----------------------------------------------------------------------------------------
# small parts
# ----------------------------------------------------------------------------------------
def test_solved_and_cache():
    s = VD.Solved(1.0, 0.1, "ok", True)
    assert s.ok and s.midpoint_slack == math.inf and s.curve_slack == 1e-6 and s.extra == {}
    assert s.path is None and s.midpoint is None and s.curve is None and not s.mapped
    assert not VD.Solved(1.0, 0.1, "ok", True, mapped=True).ok
    assert not VD.Solved(1.0, 0.1, "ok", False).ok
    oracle = Exact()
    cache = VD.SolvedDistances(Euclidean(), oracle)
    x, y = np.array([0.1, 0.2]), np.array([0.3, -0.4])
    a = cache(x, y)
    assert cache(x.copy(), [0.3, -0.4]) is a and cache.solves == 1 and len(oracle.calls) == 1
    assert cache(y, x) is not a and cache.solves == 2
    assert a.value == np.linalg.norm(y - x)


def test_unusable_notes():
    m = VD._unusable("d(x, y)", VD.Solved(1.0, 0.1, "s", True, mapped=True))
    assert m == VD.Verdict(True, note="d(x, y): the solved curve crosses a region where "
                                      "F(x, .) is not convex", mapped=True)
    u = VD._unusable("d", VD.Solved(1.0, 0.1, "max_iterations", False,
                                     extra={"segments": 8, "degrees": 12, "x": 1}))
    assert u.inconclusive and u.ok and u.note == (
        "a solve did not converge (status max_iterations; segments 8, degrees 12)")
    assert VD._unusable("d", VD.Solved(1.0, 0.1, "stalled", False)).note == (
        "a solve did not converge (status stalled)")


def test_closed_form_of_and_suite_make():
    e = Euclidean()
    d, g = VD.closed_form_of(e)
    assert d is not None and g is not None
    assert d.__self__ is e and d.__name__ == "distance" and g.__name__ == "geodesic"
    assert VD.closed_form_of(Flat()) == (None, None)
    for bad in (0.0, 1.5, -1.0):
        with pytest.raises(InputError) as err:
            VD.DistanceSuite.make(e, shrink=bad)
        assert str(err.value) == f"the distance region (shrink) must be in (0, 1], got {bad!r}"
    s = VD.DistanceSuite.make(e, seed=np.int64(3), shrink=1, shrink_limit=4.0)
    assert isinstance(s.solved.oracle, VD.DiscreteDistance)
    assert (s.seed, s.shrink, s.shrink_limit) == (3, 1.0, 4)
    assert type(s.seed) is int and type(s.shrink) is float and type(s.shrink_limit) is int
    assert s.size() == 2.0
    assert VD.DistanceSuite.make(Euclidean(n=2), shrink=0.5).shrink == 0.5
    assert VD.DistanceSuite(e, VD.SolvedDistances(e, Exact())).shrink_limit == 6


def test_oracle_names_and_sizes():
    d = VD.DiscreteDistance()
    assert d.name == "discrete geodesic, tol 0.0001, 8 (64 if not smooth) to 64 (256) segments"
    assert VD.DiscreteDistance(1e-6, 4, 16).name == ("discrete geodesic, tol 1e-06, 4 to 16 "
                                                     "segments")
    assert d.sizes(Euclidean()) == (8, 64)

    class Rough(Flat):
        smooth = False

    assert d.sizes(Rough()) == (64, 256)
    assert VD.DiscreteDistance(segments=32, max_segments=16).sizes(Euclidean()) == (32, 32)
    assert VD.DiscreteDistance(segments=4).sizes(Rough()) == (4, 256)
    assert VD.DiscreteDistance(max_segments=100).sizes(Rough()) == (64, 100)
    assert (d.tol, d.error_floor) == (1e-4, 1e-8)
    assert VD.ContinuumDistance().name == "pseudospectral distance, rtol default"
    assert VD.ContinuumDistance(1e-6).name == "pseudospectral distance, rtol 1e-06"


def test_along():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]])
    cum = np.array([0.0, 1.0, 4.0])
    got = VD._along(path, cum, np.array([0.0, 0.125, 0.25, 0.5, 1.0]))
    np.testing.assert_allclose(got, [[0, 0], [0.5, 0], [1, 0], [1, 1], [1, 3]], atol=1e-15)
    flat = VD._along(path, np.zeros(3), [0.5, 1.0])  # no length: by vertex index
    np.testing.assert_allclose(flat, [[1.0, 0.0], [1.0, 3.0]], atol=1e-15)


# ----------------------------------------------------------------------------------------
# the real oracles on closed-form metrics
# ----------------------------------------------------------------------------------------
def test_discrete_oracle_on_euclidean():
    x, y = np.array([0.1, 0.2]), np.array([-0.5, 0.3])
    s = VD.DiscreteDistance().solve(Euclidean(), x, y)
    d = math.hypot(0.6, 0.1)
    assert s.usable and s.ok and s.status is Status.SUCCESS and not s.mapped
    assert abs(s.value - d) <= s.error and s.error >= 1e-8 * d
    assert math.isclose(s.error, 1e-8 * s.value, rel_tol=1e-12)  # the floor: exact solve
    assert s.extra["segments"] >= 8 and math.isclose(s.extra["polyline_length"], d,
                                                     rel_tol=1e-9)
    np.testing.assert_allclose(s.path[0], x, atol=1e-12)
    np.testing.assert_allclose(s.path[-1], y, atol=1e-12)
    np.testing.assert_allclose(s.midpoint, 0.5 * (x + y), atol=1e-9)
    assert s.midpoint_slack < 1e-6
    np.testing.assert_allclose(s.curve([0.0, 0.25, 1.0]), [x, 0.75 * x + 0.25 * y, y],
                               atol=1e-9)
    assert 1e-6 <= s.curve_slack < 2e-6
    floor = VD.DiscreteDistance(error_floor=1e-3).solve(Euclidean(), x, y)
    assert math.isclose(floor.error, 1e-3 * floor.value, rel_tol=1e-12)


def test_continuum_oracle_on_randers():
    x, y = np.array([0.1, 0.2]), np.array([-0.5, 0.3])
    m = Randers()
    s = VD.ContinuumDistance().solve(m, x, y)
    d = float(m.distance(x[None], y[None])[0])
    assert s.ok and s.status is DistanceStatus.CONVERGED and abs(s.value - d) <= s.error + 1e-12
    assert s.path.shape == (65, 2) and np.array_equal(s.midpoint, s.path[32])
    assert math.isclose(s.midpoint_slack, s.error + 1e-10 * s.value, rel_tol=1e-12)
    assert s.curve_slack == 1e-6 and "degrees" in s.extra
    np.testing.assert_allclose(s.curve(np.array([0.0, 1.0])), [x, y], atol=1e-9)


# ----------------------------------------------------------------------------------------
# the properties on exact and broken oracles
# ----------------------------------------------------------------------------------------
def test_distance_zero():
    ok = VD.check_distance_zero(_suite(), examples=5)
    assert ok.status is PASSED and ok.tried == ok.passed == 5
    bad = VD.check_distance_zero(_suite("zero"), examples=5)
    assert bad.status is FAILED and bad.lhs == ("d(x, x)", 1e-300) and bad.rhs == ("0", 0.0)
    assert set(bad.counterexample) == {"x"}
    assert bad.note == f"Distances by exact oracle. {VD.SOLVE_HINT}"


def test_distance_positive():
    ok = VD.check_distance_positive(_suite(), examples=6)
    assert ok.status is PASSED and ok.tried == ok.passed == 6
    nil = VD.check_distance_positive(_suite("nil"), examples=6)
    assert nil.status is FAILED and nil.relation == ">" and nil.lhs == ("d(x, y)", 0.0)
    assert nil.counterexample["x"] != nil.counterexample["y"]
    assert set(nil.counterexample) == {"x", "y"}
    assert nil.note.startswith("solved with status converged. Distances by exact oracle.")
    neg = VD.check_distance_positive(_suite("negative"), examples=3)
    assert neg.status is FAILED and neg.relation == ">=" and neg.lhs == ("d(x, y)", -1e-9)
    assert neg.counterexample["x"] == neg.counterexample["y"]


def test_triangle_inequality():
    ok = VD.check_triangle_inequality(_suite(), examples=8)
    assert ok.status is PASSED and ok.tried == ok.passed == 8
    sq = VD.check_triangle_inequality(_suite("squared"), examples=30)
    assert sq.status is FAILED and sq.relation == "<="
    x, y, z = (np.asarray(sq.counterexample[k]) for k in "xyz")
    dxz, dxy, dyz = (float(np.sum((b - a) ** 2)) for a, b in ((x, z), (x, y), (y, z)))
    assert sq.lhs == ("d(x, z)", pytest.approx(dxz, rel=1e-12))
    assert sq.rhs == ("d(x, y) + d(y, z)", pytest.approx(dxy + dyz, rel=1e-12))
    assert sq.note.startswith("stated errors 1e-12, 1e-12, 1e-12. Distances by")
    assert dxz > dxy + dyz


def test_segment_bound():
    ok = VD.check_segment_bound(_suite(), examples=6)
    assert ok.status is PASSED and ok.tried == ok.passed == 6
    long = VD.check_segment_bound(_suite("long"), examples=6)
    assert long.status is FAILED and long.rhs[0] == "straight segment's length"
    x, y = (np.asarray(long.counterexample[k]) for k in "xy")
    assert long.rhs[1] == pytest.approx(np.linalg.norm(y - x), rel=1e-9)
    assert long.lhs == ("d(x, y)", pytest.approx(1.01 * np.linalg.norm(y - x), rel=1e-12))
    assert long.note.startswith("stated error 1e-12. Distances by")


def test_segment_leaving_the_domain_is_not_judged():
    suite = VD.DistanceSuite.make(Ring(), Exact("long"))
    checker = {}

    def run(name, claim, check, examples, keys="xyz", strategy=None, hint=VD.SOLVE_HINT):
        checker["check"], checker["keys"] = check, keys
        return VD.PropertyResult(name, claim, PASSED)

    suite.run = run
    VD.check_segment_bound(suite, examples=1)
    assert checker["keys"] == "xy"
    x, y = np.array([-0.8, 0.0]), np.array([0.8, 0.0])
    assert checker["check"]((x, y, y)) == VD.Verdict(True, note="the segment leaves the domain")
    w = checker["check"]((np.array([0.6, 0.0]), np.array([0.8, 0.0]), y))
    assert not w.ok and w.relation == "<=" and w.rhs[1] == pytest.approx(0.2, rel=1e-9)
    # just inside the tolerance of contains: judged
    v = checker["check"]((np.array([0.6, 0.0]), np.array([0.5 - 5e-10, 0.0]), y))
    assert v.relation == "<="


def test_distance_symmetry():
    ok = VD.check_distance_symmetry(_suite(), examples=6)
    assert ok.status is PASSED and ok.tried == ok.passed == 6
    bad = VD.check_distance_symmetry(_suite("asymmetric"), examples=10)
    assert bad.status is FAILED and bad.relation == "=="
    assert abs(bad.lhs[1] - bad.rhs[1]) == pytest.approx(1e-3, rel=1e-6)
    assert bad.lhs[0] == "d(x, y)" and bad.rhs[0] == "d(y, x)"
    assert bad.note.startswith("stated errors 1e-12, 1e-12. Distances by")
    sk = VD.check_distance_symmetry(_suite(metric=Randers()), examples=3)
    assert sk.status is SKIPPED and sk.note == "randers is not declared reversible"
    un = VD.check_distance_symmetry(_suite("unconverged"), examples=4)
    assert un.status is INCONCLUSIVE


def test_closed_form():
    ok = VD.check_closed_form(_suite(), examples=5)
    assert ok.status is PASSED and ok.tried == ok.passed == 5
    off = VD.check_closed_form(_suite("offset"), examples=5)
    assert off.status is FAILED and off.lhs[0] == "d(x, y) solved"
    assert off.rhs[0] == "closed form" and off.lhs[1] - off.rhs[1] == pytest.approx(1e-6)
    assert off.note == ("stated error 1e-12 (exact oracle). Distances by exact oracle. "
                        + VD.CLOSED_FORM_HINT)
    bent = VD.check_closed_form(_suite("bent"), examples=5)
    assert bent.status is FAILED and bent.lhs[0] == "solved curve at t = 1/4, 1/2, 3/4"
    assert bent.rhs[0] == "closed-form geodesic" and len(bent.lhs[1]) == 6
    dev = max(abs(a - b) for a, b in zip(bent.lhs[1], bent.rhs[1], strict=True))
    assert dev == pytest.approx(0.05, rel=1e-9)
    tol = 2.0 * (1e-9 + math.sqrt(1e-12 / np.linalg.norm(
        np.subtract(bent.counterexample["y"], bent.counterexample["x"]))))
    assert bent.note.startswith(f"largest deviation {dev:.3g} (tolerance {tol:.3g})")
    # a distance given alone: the curve is not judged
    alone = VD.check_closed_form(_suite("bent"), examples=5,
                                 distance=Euclidean().distance)
    assert alone.status is PASSED
    given = VD.check_closed_form(_suite(metric=Flat()), examples=4,
                                 distance=lambda a, b: np.linalg.norm(b - a, axis=-1) + 1e-6)
    assert given.status is FAILED
    geo_only = VD.check_closed_form(_suite(metric=Flat()), examples=3,
                                    geodesic=Euclidean().geodesic)
    assert geo_only.status is SKIPPED
    sk = VD.check_closed_form(_suite(metric=Flat()), examples=3)
    assert sk.status is SKIPPED and sk.note == (
        "flat-test supplies no closed-form distance: give the metric a `distance(x, y)` "
        "method (finsler.ClosedFormMetric), or pass one to "
        "`validation.testing.check(metric, closed_form=...)`")
    un = VD.check_closed_form(_suite("unconverged"), examples=4)
    assert un.status is INCONCLUSIVE
    assert VD.check_closed_form(_suite("mapped"), examples=4).status is MAPPED


def test_closed_form_checks_both_directions_when_not_reversible():
    m = Randers()

    @dataclass
    class OneWay:
        name: str = "one-way"

        def solve(self, metric, x, y):
            d = float(m.distance(x[None], y[None])[0])
            if x[0] > y[0]:
                d = float(m.distance(y[None], x[None])[0])  # the reverse distance
            return VD.Solved(d, 1e-12, "converged", True)

    suite = VD.DistanceSuite.make(m, OneWay())
    r = VD.check_closed_form(suite, examples=10)
    assert r.status is FAILED and r.lhs[0] in ("d(x, y) solved", "d(y, x) solved")


class _FakeCert:
    def __init__(self, lower, upper, status="certified"):
        self.lower, self.upper = lower, upper
        self.gap = upper - lower
        self.status = SimpleNamespace(label=status)
        self.triangles, self.directions = 123, 16


def test_certificate_branches(monkeypatch):
    import solvers

    class Aniso5(Metric):  # F = sqrt(v0**2 + 2 v1**2 + ... + 5 v4**2): not conformal
        name = "aniso-5d"
        domain = property(lambda self: Box((-1.0,) * 5, (1.0,) * 5))

        def F_sx(self, x, v):
            return ca.sqrt(sum((i + 1.0) * v[i] ** 2 for i in range(5)))

    assert VD.check_certificate(_suite(metric=Aniso5()), 2).note == (
        "aniso-5d is 5-D and not conformal: certify proves intervals in 2-D and 3-D, and "
        "lower bounds beyond 3-D only for metrics providing conformal_factor_sx")

    class Bent3(Euclidean):
        convex_everywhere = False
        convexity_note = "bent somewhere"

    bent = VD.check_certificate(_suite(metric=Bent3(n=3)), 2)
    assert bent.status is SKIPPED and bent.note == (
        "euclidean does not declare F(x, .) convex on the whole domain (bent somewhere): "
        "the 3-D certificate needs it")

    class Rough(Flat):
        name = "rough-test"
        smooth = False

    sk = VD.check_certificate(_suite(metric=Rough()), 2)
    assert sk.status is SKIPPED and sk.note.startswith(
        "rough-test is declared not smooth: certify's bounds are proven where F is twice")
    seen = []

    def fake(kind):
        def certify(m, x, y, mesh, path=None):
            d = float(np.linalg.norm(y - x))
            seen.append((mesh, path is not None))
            return {"good": _FakeCert(d - 1e-3, d + 1e-3),
                    "high": _FakeCert(d + 1e-3, d + 2e-3),
                    "low": _FakeCert(d - 2e-3, d - 1e-3),
                    "budget": _FakeCert(0.0, math.inf, "lp_failed")}[kind]
        return certify

    monkeypatch.setattr(solvers, "certify", fake("good"))
    ok = VD.check_certificate(_suite(), 3)
    assert ok.status is PASSED and ok.tried == ok.passed == 3
    assert seen and all(s == ("coarse", True) for s in seen)
    monkeypatch.setattr(solvers, "certify", fake("high"))
    hi = VD.check_certificate(_suite(), 3)
    assert hi.status is FAILED and hi.lhs[0] == "certified lower bound"
    assert hi.rhs[0] == "d(x, y) + error" and hi.relation == "<="
    monkeypatch.setattr(solvers, "certify", fake("low"))
    lo = VD.check_certificate(_suite(), 3)
    assert lo.status is FAILED and lo.rhs[0] == "certified upper bound"
    assert lo.note.startswith("interval [")
    seen.clear()  # beyond the plane: at most CERTIFY_EXAMPLES_ND examples, same mesh
    monkeypatch.setattr(solvers, "certify", fake("good"))
    nd = VD.check_certificate(_suite(metric=Euclidean(n=3)), 10)
    assert nd.status is PASSED and nd.tried == VD.CERTIFY_EXAMPLES_ND == 3
    assert all(s == ("coarse", True) for s in seen)
    monkeypatch.setattr(solvers, "certify", fake("budget"))
    bud = VD.check_certificate(_suite(), 3)
    assert bud.status is INCONCLUSIVE
    assert ("certify ran out of its work budget (status lp_failed: mesh coarse, 123 "
            "triangles, 16 directions; interval [0, inf])") in bud.note
    given = VD.check_certificate(_suite(), 2, mesh=object())
    assert "mesh given" in given.note


def test_certificate_maps_a_pair_through_a_non_convex_region(monkeypatch):
    import solvers
    from finsler.metrics.paper import Matsumoto

    called = []
    monkeypatch.setattr(solvers, "certify", lambda *a, **k: called.append(1) or _FakeCert(
        0.0, math.inf))
    m = Matsumoto()
    suite = VD.DistanceSuite.make(m, Exact())
    r = VD.check_certificate(suite, 3)
    assert r.status is MAPPED and not called
    assert r.note.endswith("crossed a region where F(x, .) is not convex "
                           f"({m.convexity_note}): mapped")


def test_region_samples():
    m = Euclidean()
    path = np.array([[0.0, 0.0], [0.5, 0.5], [0.99, 0.99]])
    pts = VD._region_samples(m, path, path[0], path[-1])
    assert np.all(m.domain.contains(pts, tol=1e-9))
    np.testing.assert_array_equal(pts[:3], path)
    assert len(pts) > 3 + 200  # the projected neighbours stay
    assert np.max(np.min(np.linalg.norm(pts[3:, None] - path[None], axis=2), axis=1)) <= (
        0.05 * 2.0 * math.sqrt(2) + 1e-12)
    two = VD._region_samples(m, None, path[0], path[1])
    np.testing.assert_array_equal(two[:2], path[:2])


def test_midpoint_halves():
    ok = VD.check_midpoint_halves(_suite(), examples=4)
    assert ok.status is PASSED and ok.tried == ok.passed == 4
    bad = VD.check_midpoint_halves(_suite("midpoint"), examples=4)
    assert bad.status is FAILED and bad.lhs[0] == "d(x, m)" and bad.rhs[0] == "d(x, y) / 2"
    x, y = (np.asarray(bad.counterexample[k]) for k in "xy")
    d = float(np.linalg.norm(y - x))
    assert bad.lhs[1] == pytest.approx(0.3 * d, rel=1e-9)
    assert bad.rhs[1] == pytest.approx(0.5 * d, rel=1e-12)
    assert bad.note.startswith(f"difference {bad.lhs[1] - bad.rhs[1]:.3g}, allowed ")
    assert "(midpoint m = (" in bad.note
    assert VD.check_midpoint_halves(_suite("unconverged"), 4).status is INCONCLUSIVE


def test_run_notes():
    s = _suite("mapped", shrink=0.5)
    r = VD.check_distance_positive(s, examples=5)
    assert r.status is MAPPED
    assert r.note == (f"{r.mapped} of {r.tried} examples crossed a region where F(x, .) is "
                      f"not convex ({Euclidean().convexity_note}): mapped Points drawn from "
                      "the domain scaled by 0.5 about its centre.")
    u = VD.check_distance_positive(_suite("unconverged"), examples=5)
    assert u.status is INCONCLUSIVE and u.note.endswith(
        "Distances by exact oracle; `geodesics solve` on the pair shows the solver's statuses "
        "(more segments or seeds may converge).")
    assert "(status max_iterations; segments 8)" in u.note
    nohint = _suite("nil").run("p", "c", lambda t: VD.Verdict(False, note="n"), 3, hint="")
    assert nohint.note == "n. Distances by exact oracle."
    bare = _suite("nil").run("p", "c", lambda t: VD.Verdict(False), 3, hint="")
    assert bare.note == "Distances by exact oracle."
    assert set(bare.counterexample) == set("xyz")


def test_distance_properties_order_and_shared_solves():
    names = [n for n, _ in VD.distance_checks(_suite())]
    assert names == ["distance-zero", "distance-positive", "triangle-inequality",
                     "segment-bound", "distance-symmetry", "closed-form-distance",
                     "certificate", "midpoint-halves"]
    oracle = Exact()
    got = {}

    def spy(name):
        def f(suite, n, *a, **k):
            got[name] = n
            got["suite"] = (suite.seed, suite.shrink, suite.shrink_limit, suite.solved.oracle)
            return VD.PropertyResult(name, "c", PASSED)
        return f

    import unittest.mock as um
    with um.patch.multiple(VD, check_distance_zero=spy("z"), check_distance_positive=spy("p"),
                           check_triangle_inequality=spy("t"), check_segment_bound=spy("s"),
                           check_distance_symmetry=spy("y"), check_closed_form=spy("c"),
                           check_certificate=spy("cert"), check_midpoint_halves=spy("m")):
        out = VD.distance_properties(Euclidean(), examples=5, oracle=oracle)
        assert [r.name for r in out] == ["z", "p", "t", "s", "y", "c", "cert", "m"]
        assert got.pop("suite") == (0, 1.0, 6, oracle)
        assert got == {"z": 20, "p": 5, "t": 5, "s": 5, "y": 5, "c": 5, "cert": 4, "m": 4}
        VD.distance_properties(Euclidean(), examples=3, seed=4, oracle=oracle, shrink=0.5,
                               shrink_limit=2)
        assert got.pop("suite") == (4, 0.5, 2, oracle)
        VD.distance_properties(Euclidean(), examples=2, certify_examples=7, zero_examples=3)
        assert got["cert"] == 7 and got["z"] == 3 and got["m"] == 2
        VD.distance_properties(Euclidean(), examples=1)
        assert got["cert"] == 2 and got["m"] == 2


# ----------------------------------------------------------------------------------------
# second pass over the survivors of the first run (mutation-2026-11-28-19): names and
# claims, defaults, every tolerance at its edge (each check called on chosen points with
# an oracle whose values and errors are set), the unusable and degenerate branches
# ----------------------------------------------------------------------------------------
CLAIMS = {
    "distance-zero": "d(x, x) = 0",
    "distance-positive": "d(x, y) >= 0, and > 0 for x != y",
    "triangle-inequality": "d(x, z) <= d(x, y) + d(y, z) (within the stated errors)",
    "segment-bound": "d(x, y) <= the length of the straight segment x -> y",
    "distance-symmetry": "d(x, y) = d(y, x) for a reversible metric",
    "closed-form-distance": "the supplied closed-form distance equals the solved one",
    "certificate": "certify's interval [lower, upper] contains the solved distance",
    "midpoint-halves": "the midpoint m of a solved geodesic has d(x, m) = d(m, y) = d(x, y)/2",
}
_CHECKS = {"distance-zero": VD.check_distance_zero,
           "distance-positive": VD.check_distance_positive,
           "triangle-inequality": VD.check_triangle_inequality,
           "segment-bound": VD.check_segment_bound,
           "distance-symmetry": VD.check_distance_symmetry,
           "closed-form-distance": VD.check_closed_form,
           "certificate": VD.check_certificate,
           "midpoint-halves": VD.check_midpoint_halves}
DEFAULT_EXAMPLES = {"distance-zero": 20, "distance-positive": 3, "triangle-inequality": 3,
                    "segment-bound": 3, "distance-symmetry": 3, "closed-form-distance": 3,
                    "certificate": 2, "midpoint-halves": 2}


@pytest.fixture
def fake_certify(monkeypatch):
    import solvers

    seen = []

    def certify(m, x, y, mesh, path=None):
        d = float(np.linalg.norm(y - x))
        seen.append((m, np.array(x), np.array(y)))
        return _FakeCert(d - 1e-3, d + 1e-3)

    monkeypatch.setattr(solvers, "certify", certify)
    return seen


@pytest.mark.parametrize("name", list(CLAIMS))
def test_names_claims_and_default_examples(name, fake_certify):
    r = _CHECKS[name](_suite(), examples=3)
    assert (r.name, r.claim) == (name, CLAIMS[name])
    suite, got = _suite(), {}
    suite.run = lambda n, c, check, examples, **kw: got.update(n=n, c=c, e=examples) or \
        VD.PropertyResult(n, c, PASSED)
    _CHECKS[name](suite)
    assert (got["n"], got["c"], got["e"]) == (name, CLAIMS[name], DEFAULT_EXAMPLES[name])


def test_skipped_names_and_claims():
    class Rough(Flat):
        name = "rough-test"
        smooth = False

    class Bent3(Euclidean):
        convex_everywhere = False

    for r, name in ((VD.check_certificate(_suite(metric=Bent3(n=3)), 2), "certificate"),
                    (VD.check_certificate(_suite(metric=Rough()), 2), "certificate"),
                    (VD.check_closed_form(_suite(metric=Flat()), 2), "closed-form-distance"),
                    (VD.check_distance_symmetry(_suite(metric=Randers()), 2),
                     "distance-symmetry")):
        assert r.status is SKIPPED and (r.name, r.claim) == (name, CLAIMS[name])
    assert VD.check_certificate(_suite(metric=Rough()), 2).note == (
        "rough-test is declared not smooth: certify's bounds are proven where F is twice "
        "differentiable (Metric.path_length_bounds and the dual bound's corrections "
        "enclose second derivatives), so its interval would prove nothing here")


def test_defaults_of_distance_checks_and_properties():
    got = {}

    def spy(name):
        def f(suite, n, *a, **k):
            got[name] = (n, *a)
            got["suite"] = suite
            return VD.PropertyResult(name, "c", PASSED)
        return f

    import unittest.mock as um
    with um.patch.multiple(VD, check_distance_zero=spy("z"), check_distance_positive=spy("p"),
                           check_triangle_inequality=spy("t"), check_segment_bound=spy("s"),
                           check_distance_symmetry=spy("y"), check_closed_form=spy("c"),
                           check_certificate=spy("cert"), check_midpoint_halves=spy("m")):
        for _, fn in VD.distance_checks(_suite()):
            fn()
        assert {k: v[0] for k, v in got.items() if k != "suite"} == {
            "z": 20, "p": 3, "t": 3, "s": 3, "y": 3, "c": 3, "cert": 2, "m": 2}
        def dist(a, b):
            return np.linalg.norm(b - a, axis=-1)

        def geo(a, b, t):
            return a[:, None] + np.asarray(t)[None, :, None] * (b - a)[:, None]
        for _, fn in VD.distance_checks(_suite(), closed_form=dist, closed_form_geodesic=geo):
            fn()
        assert got["c"] == (3, dist, geo)
        e = Euclidean()
        VD.distance_properties(e, oracle=Exact(), closed_form=dist, closed_form_geodesic=geo)
        assert got["c"] == (3, dist, geo) and got["p"] == (3,)
        assert got["suite"].metric is e and got["suite"].solved.metric is e
    s = VD.DistanceSuite.make(e, Exact())
    assert (s.seed, s.shrink, s.shrink_limit) == (0, 1.0, 6) and s.solved.metric is e


@dataclass
class Table:
    """d(x, y) = |x - y| + extra(x, y), stated error err(x, y); midpoint, its slack and
    the curve settable."""

    extra: object = None
    err: object = None
    midpoint: object = None
    mid_slack: float = 0.0
    curve: object = None
    name: str = "table oracle"
    usable: object = None

    def solve(self, metric, x, y):
        d = float(np.linalg.norm(y - x)) + (self.extra(x, y) if self.extra else 0.0)
        e = self.err(x, y) if self.err else 0.0
        mid = self.midpoint(x, y) if self.midpoint else 0.5 * (x + y)
        ok = self.usable(x, y) if self.usable else True

        def straight(t):
            t = np.asarray(t, float).reshape(-1, 1)
            return x + t * (y - x)

        curve = (lambda t: self.curve(x, y, t)) if self.curve else straight
        return VD.Solved(d, e, "converged" if ok else "max_iterations", ok, False,
                         np.stack([x, 0.5 * (x + y), y]), mid, self.mid_slack, curve, 1e-9)


def _checker(fn, oracle, metric=None, **kw):
    """The check function of property ``fn`` on a suite of ``oracle`` (``suite.run`` spied)."""
    suite = VD.DistanceSuite.make(metric or Euclidean(), oracle)
    got = {}
    suite.run = lambda n, c, check, examples, **k: got.update(check=check, **k) or \
        VD.PropertyResult(n, c, PASSED)
    fn(suite, 1, **kw)
    return got["check"]


P0, P1, PM = np.array([0.0, 0.0]), np.array([1.0, 0.0]), np.array([0.5, 0.0])
FAR0, FAR1 = np.array([-1.0, -1.0]), np.array([1.0, 1.0])  # d = 2 sqrt 2


def _on(xs, ys):
    return lambda x, y: np.array_equal(x, xs) and np.array_equal(y, ys)


def test_triangle_slack_at_its_edges():
    xz = _on(P0, P1)
    # errors 1e-6 each: excess 2.5e-6 passes (3e-6), 3.5e-6 fails
    for v, ok in ((2.5e-6, True), (3.5e-6, False)):
        chk = _checker(VD.check_triangle_inequality, Table(
            extra=lambda x, y, v=v: v if xz(x, y) else 0.0, err=lambda x, y: 1e-6))
        assert chk((P0, PM, P1)).ok is ok
    # no stated errors: the slack 1e-12 (1 + d(x, z)) with d(x, z) = 2 sqrt 2
    far = _on(FAR0, FAR1)
    for v, ok in ((3.0e-12, True), (4.3e-12, False)):
        chk = _checker(VD.check_triangle_inequality, Table(
            extra=lambda x, y, v=v: v if far(x, y) else 0.0))
        assert chk((FAR0, np.zeros(2), FAR1)).ok is ok


def test_symmetry_slack_at_its_edges():
    fwd = _on(P0, PM)
    for v, ok in ((1.5e-6, True), (2.5e-6, False)):  # errors 1e-6 each
        chk = _checker(VD.check_distance_symmetry, Table(
            extra=lambda x, y, v=v: v if fwd(x, y) else 0.0, err=lambda x, y: 1e-6))
        assert chk((P0, PM, P1)).ok is ok
    far = _on(FAR0, FAR1)  # no errors: 1e-10 max(d, 1), d = 2 sqrt 2
    for v, ok in ((2.0e-10, True), (3.2e-10, False)):
        chk = _checker(VD.check_distance_symmetry, Table(
            extra=lambda x, y, v=v: v if far(x, y) else 0.0))
        assert chk((FAR0, FAR1, P1)).ok is ok
    for v, ok in ((0.9e-10, True), (1.5e-10, False)):  # d = 0.5: 1e-10
        chk = _checker(VD.check_distance_symmetry, Table(
            extra=lambda x, y, v=v: v if fwd(x, y) else 0.0))
        assert chk((P0, PM, P1)).ok is ok
    # y is the second point of the triple (an asymmetric pair x -> z is not looked at)
    chk = _checker(VD.check_distance_symmetry, Table(extra=lambda x, y: 1e-3 if _on(P0, P1)(
        x, y) else 0.0))
    assert chk((P0, PM, P1)).ok and not chk((P0, P1, PM)).ok


def test_midpoint_slack_at_its_edges():
    half = _on(FAR0, np.zeros(2))
    for v, ok in ((1.2e-6, True), (2.0e-6, False)):  # errors 1e-6: slack 1e-6 + 0.5e-6
        chk = _checker(VD.check_midpoint_halves, Table(
            extra=lambda x, y, v=v: v if half(x, y) else 0.0, err=lambda x, y: 1e-6))
        assert chk((FAR0, FAR1, P1)).ok is ok
    for v, ok in ((3.0e-12, True), (4.3e-12, False)):  # no errors: 1e-12 (1 + 2 sqrt 2)
        chk = _checker(VD.check_midpoint_halves, Table(
            extra=lambda x, y, v=v: v if half(x, y) else 0.0))
        assert chk((FAR0, FAR1, P1)).ok is ok
    # the oracle's own midpoint slack counts in full
    chk = _checker(VD.check_midpoint_halves, Table(
        extra=lambda x, y: 1e-4 if half(x, y) else 0.0, mid_slack=1.1e-4))
    assert chk((FAR0, FAR1, P1)).ok
    # d = 1 exactly is judged; a solve without a midpoint is not
    bad = _checker(VD.check_midpoint_halves, Table(midpoint=lambda x, y: x + 0.3 * (y - x)))
    assert not bad((P0, P1, P1)).ok
    none = _checker(VD.check_midpoint_halves, Table(midpoint=lambda x, y: None))
    assert none((P0, P1, P1)) == VD.Verdict(True)
    # the halves' solves unusable: inconclusive, not a failure
    sentinel = np.array([0.123, 0.456])
    un = _checker(VD.check_midpoint_halves, Table(
        midpoint=lambda x, y: sentinel,
        usable=lambda x, y: not (np.array_equal(x, sentinel) or np.array_equal(y, sentinel))))
    v = un((P0, P1, P1))
    assert v.inconclusive and v.ok


def test_segment_bound_and_closed_form_slack_at_their_edges():
    seg = _on(P0, PM)
    for v, ok in ((0.5e-6, True), (1.5e-6, False)):  # the solve's error 1e-6
        chk = _checker(VD.check_segment_bound, Table(
            extra=lambda x, y, v=v: v if seg(x, y) else 0.0, err=lambda x, y: 1e-6))
        assert chk((P0, PM, P1)).ok is ok
    far = _on(FAR0, FAR1)
    for fn in (VD.check_segment_bound, VD.check_closed_form):  # 1e-12 (1 + 2 sqrt 2)
        for v, ok in ((3.0e-12, True), (4.3e-12, False)):
            chk = _checker(fn, Table(extra=lambda x, y, v=v: v if far(x, y) else 0.0))
            assert chk((FAR0, FAR1, P1)).ok is ok, (fn.__name__, v)


def test_closed_form_directions_times_and_tolerance():
    back = _on(PM, P0)  # wrong only from y back to x
    wrong_back = Table(extra=lambda x, y: 1e-3 if back(x, y) else 0.0)
    assert _checker(VD.check_closed_form, wrong_back)((P0, PM, P1)).ok  # reversible: one way

    class Way(Flat):
        name = "flat-not-reversible-test"
        reversible = False

    e = Euclidean()
    chk = _checker(VD.check_closed_form, wrong_back, metric=Way(), distance=e.distance,
                   geodesic=e.geodesic)
    v = chk((P0, PM, P1))
    assert not v.ok and v.lhs[0] == "d(y, x) solved"
    # the curve is compared at t = 1/4, 1/2 and 3/4, each: a bump at one of them fails
    for t0 in (0.25, 0.5, 0.75):
        def bump(x, y, t, t0=t0):
            t = np.asarray(t, float).reshape(-1, 1)
            return x + t * (y - x) + np.array([0.0, 0.1]) * np.exp(-((t - t0) / 0.01) ** 2)

        v = _checker(VD.check_closed_form, Table(curve=bump))((P0, P1, P1))  # d = 1
        assert not v.ok and v.relation == "==", t0
    # tolerance 2 (1e-9 + sqrt(error / d)): d = 0.25, error 1e-6 -> about 4e-3
    q = np.array([0.25, 0.0])

    def off(x, y, t):
        t = np.asarray(t, float).reshape(-1, 1)
        return x + t * (y - x) + np.array([0.0, 3e-3])

    v = _checker(VD.check_closed_form, Table(curve=off, err=lambda x, y: 1e-6))((P0, q, q))
    assert v.ok


def test_relations_and_sides_of_failures(fake_certify):
    z = VD.check_distance_zero(_suite("zero"), examples=5)
    assert z.relation == "=="
    nil = VD.check_distance_positive(_suite("nil"), examples=6)
    assert nil.rhs == ("0", 0.0)
    off = VD.check_closed_form(_suite("offset"), examples=5)
    assert off.relation == "==" and set(off.counterexample) == {"x", "y"}
    bent = VD.check_closed_form(_suite("bent"), examples=5)
    assert bent.relation == "=="
    mid = VD.check_midpoint_halves(_suite("midpoint"), examples=4)
    assert mid.relation == "==" and set(mid.counterexample) == {"x", "y"}
    sym = VD.check_distance_symmetry(_suite("asymmetric"), examples=10)
    assert set(sym.counterexample) == {"x", "y"}
    pos = _checker(VD.check_distance_positive, Table())
    assert pos((P0, PM, P1)).ok  # d = 0.5 > 0


def test_certificate_edges_and_pairs(monkeypatch):
    import solvers

    def fake(lower, upper):
        def certify(m, x, y, mesh, path=None):
            d = float(np.linalg.norm(y - x))
            return _FakeCert(lower(d), upper(d))
        return certify

    chk = _checker(VD.check_certificate, Exact())
    pair = (P0, PM, P1)
    # the solve's error is 1e-12: lower = d + error and upper = d - error both hold
    monkeypatch.setattr(solvers, "certify", fake(lambda d: d + 1e-12, lambda d: d + 1.0))
    assert chk(pair).ok
    monkeypatch.setattr(solvers, "certify", fake(lambda d: d - 1.0, lambda d: d - 1e-12))
    assert chk(pair).ok
    monkeypatch.setattr(solvers, "certify", fake(lambda d: d, lambda d: d))
    assert chk(pair).ok
    monkeypatch.setattr(solvers, "certify", fake(lambda d: d - 1.0, lambda d: d - 1e-3))
    v = chk(pair)
    assert not v.ok and v.lhs == ("d(x, y) - error", 0.5 - 1e-12) and v.relation == "<="
    monkeypatch.setattr(solvers, "certify", fake(lambda d: d + 1e-3, lambda d: d + 1.0))
    v = chk(pair)
    assert not v.ok and v.rhs == ("d(x, y) + error", 0.5 + 1e-12)


def test_certificate_pairs_are_apart_in_the_region(fake_certify):
    r = VD.check_certificate(_suite(shrink=0.5), 4)
    assert r.status is PASSED and len(fake_certify) == r.tried  # no degenerate pair
    for m, x, y in fake_certify:
        assert isinstance(m, Euclidean)
        assert np.all(np.abs(x) <= 0.5 + 1e-12) and np.all(np.abs(y) <= 0.5 + 1e-12)
        assert not np.array_equal(x, y)


def test_certificate_unusable_and_convexity_threshold(fake_certify):
    u = VD.check_certificate(_suite("unconverged"), 3)
    assert u.status is INCONCLUSIVE

    class Half(Flat):  # F = |v| / 2: fundamental tensor I / 4, convex, eigenvalue 0.25
        name = "half-test"
        convex_everywhere = False

        def F_sx(self, x, v):
            return 0.5 * ca.sqrt(ca.dot(v, v))

    r = VD.check_certificate(VD.DistanceSuite.make(Half(), Exact()), 3)
    assert r.status is PASSED and len(fake_certify) == r.tried


class AllUnconverged(Exact):
    def solve(self, metric, x, y):
        s = super().solve(metric, x, y)
        s.usable = False
        s.status = "max_iterations"
        return s


@pytest.mark.parametrize("name", ["distance-zero", "distance-positive", "triangle-inequality",
                                  "segment-bound", "distance-symmetry",
                                  "closed-form-distance", "midpoint-halves"])
def test_unusable_solves_are_inconclusive(name):
    suite = VD.DistanceSuite.make(Euclidean(), AllUnconverged())
    r = _CHECKS[name](suite, examples=3)
    assert r.status is INCONCLUSIVE and "a solve did not converge (status max_iterations)" \
        in r.note


def test_run_passes_its_stream_and_shrink_limit(monkeypatch):
    seen, streams = [], []
    real_search, real_seeded = VD.search, VD.seeded
    monkeypatch.setattr(VD, "seeded", lambda seed, s: streams.append((seed, s)) or
                        real_seeded(seed, s))

    def search(*a, **kw):
        seen.append(kw)
        return real_search(*a, **kw)

    monkeypatch.setattr(VD, "search", search)
    suite = VD.DistanceSuite.make(Euclidean(), Exact(), seed=5, shrink_limit=2)
    VD.check_distance_positive(suite, 2)
    assert streams == [(5, "distances")] and seen[0]["shrink_limit"] == 2
    assert seen[0]["rng"] is not None


def test_triples_in_the_shrunk_region():
    pts = []
    suite = _suite(shrink=0.25)
    suite.run("p", "c", lambda t: pts.extend(t) or VD.Verdict(True), 20)
    assert pts and all(np.all(np.abs(p) <= 0.25 + 1e-12) for p in pts)


def test_cache_keys_and_what_the_oracle_gets():
    got = []

    class Rec(Exact):
        def solve(self, metric, x, y):
            got.append((metric, x.dtype, y.dtype))
            return super().solve(metric, x, y)

    e = Euclidean()
    cache = VD.SolvedDistances(e, Rec())
    a = cache(np.array([0, 1]), np.array([1, 0]))  # integers: the same pair as floats
    assert cache(np.array([0.0, 1.0]), np.array([1.0, 0.0])) is a and cache.solves == 1
    assert got == [(e, np.dtype(float), np.dtype(float))]


def test_sizes_of_an_unbounded_domain():
    class Strip(Flat):
        name = "strip-test"
        domain = property(lambda self: Box((-np.inf, -0.25), (np.inf, 0.25)))

    s = VD.DistanceSuite.make(Strip(), Exact())
    assert s.size() == 1.0  # 1 where unbounded (the finite side is 0.5)
    path = np.array([[0.0, 0.0], [5.0, 0.1]])
    pts = VD._region_samples(Strip(), path, path[0], path[-1])
    dev = np.min(np.abs(pts[2:, None, 0] - path[None, :, 0]), axis=1)
    assert 0.04 < dev.max() <= 0.05 + 1e-12  # 5% of the size 1 along the unbounded side


def test_region_samples_spread():
    m = Euclidean()
    path = np.array([[-0.9, -0.9], [0.0, 0.0], [0.9, 0.9]])
    pts = VD._region_samples(m, path, path[0], path[-1])
    again = VD._region_samples(m, path, path[0], path[-1])
    np.testing.assert_array_equal(pts, again)  # seeded
    near = pts[3:]
    d = np.linalg.norm(near[:, None] - path[None], axis=2)
    owner = np.argmin(d, axis=1)
    assert set(owner) == {0, 1, 2}  # around every vertex
    off = near - path[owner]
    assert np.abs(off).max() > 0.08  # up to 5% of the size 2 in each coordinate
    assert (off[:, 0] > 0).any() and (off[:, 0] < 0).any()
    assert np.std(off[:, 0] - off[:, 1]) > 0.01  # the coordinates drawn independently


def test_along_edges():
    path = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(VD._along(path, np.array([0.0, 0.0, 1.0]), [0.5]), [[0.5, 0.0]])
    short = np.array([[0.0, 0.0], [0.1, 0.0], [0.5, 0.0]])
    np.testing.assert_allclose(VD._along(short, np.array([0.0, 0.1, 0.5]), [0.5]),
                               [[0.25, 0.0]])
    assert VD._along(short, np.array([0.0, 0.1, 0.5]), 0.5).shape == (1, 2)


def test_discrete_oracle_sizes_and_mapping():
    x, y = np.array([0.1, 0.2]), np.array([-0.5, 0.3])
    capped = VD.DiscreteDistance(1e-12, 4, 8).solve(Randers(), x, y)
    assert capped.extra["segments"] == 8 and not capped.extra["tol_reached"]
    loose = VD.DiscreteDistance(1e-2, 4, 64).solve(Randers(), x, y)
    assert loose.extra["segments"] == 16 and loose.extra["tol_reached"]  # 4, 8, 16
    from finsler.metrics.paper import Matsumoto
    m = Matsumoto()  # convex near its centre only
    inside = VD.DiscreteDistance().solve(m, np.array([0.05, 0.0]), np.array([-0.05, 0.02]))
    assert inside.mapped is False and inside.ok
    out = VD.DiscreteDistance().solve(m, np.array([0.8, 0.0]), np.array([0.0, 0.8]))
    assert out.mapped and not out.ok


def test_continuum_oracle_path_runs_from_x_to_y():
    x, y = np.array([0.1, 0.2]), np.array([-0.5, 0.3])
    m = Randers()
    s = VD.ContinuumDistance().solve(m, x, y)
    np.testing.assert_allclose(s.path[0], x, atol=1e-9)
    np.testing.assert_allclose(s.path[-1], y, atol=1e-9)
    want = np.asarray(m.geodesic(x[None], y[None], np.array([0.5]))).reshape(2)
    np.testing.assert_allclose(s.midpoint, want, atol=1e-6)
    assert s.mapped is False


def test_midpoint_failure_labels_and_note():
    third = Table(midpoint=lambda x, y: x + (y - x) / 3.0)
    v = _checker(VD.check_midpoint_halves, third)((P0, P1, P1))
    assert not v.ok and v.lhs[0] == "d(x, m)"
    assert v.note.endswith("(midpoint m = (0.333333, 0.0))")  # 6 decimals
    late = Table(extra=lambda x, y: 1e-3 if _on(PM, P1)(x, y) else 0.0)  # only d(m, y) off
    w = _checker(VD.check_midpoint_halves, late)((P0, P1, P1))
    assert not w.ok and w.lhs == ("d(m, y)", pytest.approx(0.5 + 1e-3, rel=1e-12))


def test_certificate_counterexample_names_the_pair(monkeypatch):
    import solvers

    monkeypatch.setattr(solvers, "certify", lambda m, x, y, mesh, path=None: _FakeCert(
        float(np.linalg.norm(y - x)) + 1e-3, float(np.linalg.norm(y - x)) + 2e-3))
    r = VD.check_certificate(_suite(), 3)
    assert r.status is FAILED and set(r.counterexample) == {"x", "y"}


def test_closed_form_curve_tolerance_on_an_unbounded_strip():
    class Strip(Flat):
        name = "strip-cf-test"
        domain = property(lambda self: Box((-np.inf, -0.25), (np.inf, 0.25)))

    e = Euclidean()

    def off(x, y, t, dy=1.5e-3):
        t = np.asarray(t, float).reshape(-1, 1)
        return x + t * (y - x) + np.array([0.0, dy])

    # the size of an unbounded domain is 1: tolerance 1e-9 + sqrt(1e-6 / 1) = 1e-3
    chk = _checker(VD.check_closed_form, Table(curve=off, err=lambda x, y: 1e-6),
                   metric=Strip(), distance=e.distance, geodesic=e.geodesic)
    v = chk((P0, P1, P1))
    assert not v.ok and v.note.startswith("largest deviation 0.0015 (tolerance 0.001)")


def test_discrete_oracle_slacks_follow_the_stated_error():
    """With a floor of 1e-3 relative on an exact (straight) solve, the stated error is
    1e-3 d and the curve's slack 1e-6 + 1e-3 (relative to d), for short and long pairs."""
    for x, y in ((np.array([0.1, 0.2]), np.array([-0.3, 0.5])),
                 (np.array([-0.9, -0.9]), np.array([0.9, 0.95]))):
        s = VD.DiscreteDistance(error_floor=1e-3).solve(Euclidean(), x, y)
        d = float(np.linalg.norm(y - x))
        assert s.error == pytest.approx(1e-3 * d, rel=1e-9)
        assert s.curve_slack == pytest.approx(1e-6 + 1e-3, rel=1e-6)
        assert 1e-3 * d <= s.midpoint_slack <= 1e-3 * d + 1e-9
