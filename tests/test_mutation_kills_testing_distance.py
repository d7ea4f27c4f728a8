"""Fast focused tests of validation/testing/distance.py (issue 48 item 6: mutation testing
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

from finsler import Box, Metric, Task
from finsler.errors import InputError
from finsler.metrics import Euclidean, Randers
from finsler.status import DistanceStatus, Status
from validation.testing import distance as VD
from validation.testing.engine import FAILED, INCONCLUSIVE, MAPPED, PASSED, SKIPPED


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


class Flat(Metric):
    """F = |v| without a closed form."""

    name = "flat-test"
    task = Task(depth=3, eps=0.5)
    reversible = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v))


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


class _Annulus(Box):
    """The square without the disk |x| < 0.5: a segment through the hole leaves it."""

    def contains(self, x, tol=1e-12):
        x = np.asarray(x, float)
        return super().contains(x, tol) & (np.linalg.norm(x, axis=-1) >= 0.5 - tol)


class Ring(Flat):
    name = "ring-test"
    domain = property(lambda self: _Annulus((-1.0, -1.0), (1.0, 1.0)))


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

    assert VD.check_certificate(_suite(metric=Euclidean(n=3)), 2).note == (
        "certified intervals are for 2-D metrics; euclidean is 3-D")

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
    monkeypatch.setattr(solvers, "certify", fake("budget"))
    bud = VD.check_certificate(_suite(), 3)
    assert bud.status is INCONCLUSIVE
    assert ("certify ran out of its work budget (status lp_failed: mesh coarse, 123 "
            "triangles, 16 directions; interval [0, inf])") in bud.note
    given = VD.check_certificate(_suite(), 2, mesh=object())
    assert "mesh given" in given.note


def test_certificate_maps_a_pair_through_a_non_convex_region(monkeypatch):
    import solvers
    from finsler.metrics import Matsumoto

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
