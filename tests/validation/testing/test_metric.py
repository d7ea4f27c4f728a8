"""Fast focused tests of validation/testing/metric.py (mutation testing of
the property suite). Each property runs on closed-form metrics (no solve, few examples)
and on metrics built here that are wrong in exactly one way; verdicts, counterexamples and
notes are checked against independent references (Matsumoto's analytic convex radius,
the broken metric's own definition)."""

from __future__ import annotations

import math
import re

import casadi as ca
import numpy as np
import pytest

from finsler import (
    Box,
    Disk,
    Domain,
    Euclidean,
    InputError,
    Matsumoto,
    Product,
    Randers,
)
from validation.testing import metric as VM
from validation.testing.engine import FAILED, MAPPED, PASSED, SKIPPED

from tests.helpers.metrics.property_suite import (
    Base,
    C1KinkV,
    ConvexClaimed,
    DiagonalKink,
    Drift,
    EuclidClaimedIrreversible,
    HalfZero,
    HiddenConvexity,
    InfOnAxis,
    Kinked,
    KinkedV,
    KinkOffCentre,
    LargeScaleOff,
    NanAndNegativeCones,
    NanBeyond095Off,
    NanOutside,
    NanOutsideOff,
    NegativeCone,
    OffAbs,
    OffHessian,
    OffHessianAbs,
    OffNumpy,
    OffNumpyShaped,
    Offset,
    OffTorch,
    RandersClaimedReversible,
    Root,
    RootX,
    ScaledEuclid,
    ShortBy,
    SlightlySquared,
    SmallScaleOff,
    Squared,
    SquaredX,
    TinyAsymmetric,
    TinyKinkV,
    Zero,
    ZeroCone,
    ZeroOnAxis,
)

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation

RC = 1.0 / (2.0 * math.sqrt(3.0))  # Matsumoto's convex radius at height 1 (its docs)


class _Square(Domain):
    """A domain kind without a centre and scale known to the suite (the unit square)."""

    dim = 2

    def contains(self, x, tol=1e-12):
        return np.all(np.abs(np.asarray(x, float)) <= 1.0 + tol, axis=-1)

    def sample(self, n, rng):
        return rng.uniform(-1.0, 1.0, size=(n, 2))

    def project(self, x):
        return np.clip(np.asarray(x, float), -1.0, 1.0)

    def bounds(self):
        return -np.ones(2), np.ones(2)

    def constraints_sx(self, x):
        return [(x[0], -1.0, 1.0), (x[1], -1.0, 1.0)]

    def describe(self):
        return "a square"


# ----------------------------------------------------------------------------------------
# domain scales, the convexity map, the convex region
# ----------------------------------------------------------------------------------------
def test_domain_scale_of():
    box = Box((-1.0, -2.0), (3.0, 2.0))
    got = VM.domain_scale_of(box, np.array([[1.0, 0.0], [3.0, 0.0], [1.0, -2.0],
                                             [2.0, 1.0], [0.0, 0.5]]))
    np.testing.assert_allclose(got, [0.0, 1.0, 1.0, 0.5, 0.5], rtol=0, atol=1e-15)
    disk = Disk(radius=2.0, center=(1.0, 0.0))
    np.testing.assert_allclose(VM.domain_scale_of(disk, [[2.0, 0.0], [1.0, -2.0]]),
                               [0.5, 1.0], rtol=0, atol=1e-15)
    prod = Product((Box((0.0,), (2.0,)), Disk(radius=2.0)))
    np.testing.assert_allclose(VM.domain_scale_of(prod, [[1.5, 1.0, 0.0], [2.0, 0.0, 0.0],
                                                         [1.0, 0.0, 1.0]]),
                               [0.5, 1.0, 0.5], rtol=0, atol=1e-15)
    other = _Square()
    assert VM.domain_scale_of(other, [[0.0, 0.0]]) is None
    assert VM.domain_scale_of(Product((Box((0.0,), (1.0,)), other)), [[0.0, 0.0, 0.0]]) is None
    assert VM.domain_scale_of(Product((other, Box((0.0,), (1.0,)))), [[0.0, 0.0, 0.0]]) is None


def test_convexity_map_describe():
    full = VM.ConvexityMap(100, 0.0, 0.5, None, None, 1.0)
    assert full.describe() == ("F(x, .) is strongly convex at all 100 sampled points of "
                               "the domain")
    part = VM.ConvexityMap(200, 0.125, -0.0123456, (0.1, 0.2), 0.3, 0.3, (0.5, 0.5))
    assert part.describe() == (
        "F(x, .) is not convex on 12.5% of 200 sampled points (smallest eigenvalue of the "
        "fundamental tensor -0.0123); the non-convex sample nearest the domain's centre is "
        "(0.1, 0.2), at 0.3000 of the domain's size")
    nowhere = VM.ConvexityMap(200, 0.125, -1.0, None, None, None)
    assert nowhere.describe().endswith("tensor -1)")
    assert full.worst is None


def test_convexity_map_against_matsumoto_radius():
    m = Matsumoto()
    cmap = VM.convexity_map(m, samples=2048, seed=3)
    assert cmap is VM.convexity_map(m, samples=2048, seed=3)  # cached
    assert cmap.samples == 2048
    assert abs(cmap.fraction - (1.0 - RC**2)) < 0.03
    assert RC <= cmap.nearest_scale < RC + 0.03
    assert cmap.core == cmap.nearest_scale
    assert math.isclose(float(np.linalg.norm(cmap.nearest)), cmap.nearest_scale, rel_tol=1e-12)
    assert cmap.min_eigenvalue < 0 and np.linalg.norm(cmap.worst) > RC
    lam = m.convexity(np.asarray(cmap.worst)[None], n_directions=32)[0]
    assert lam == cmap.min_eigenvalue
    other = VM.convexity_map(m, samples=2048, seed=4)
    assert other.nearest != cmap.nearest
    e = VM.convexity_map(Euclidean(), samples=256)
    assert (e.fraction, e.core, e.nearest, e.nearest_scale, e.worst) == (
        0.0, 1.0, None, None, None)
    assert e.min_eigenvalue > 0


def test_convex_region_and_solve_region():
    m = Matsumoto()
    assert VM.convex_region(m, 0.25) == (
        0.25, "the declared convex region (the domain scaled by 0.25)")
    assert VM.convex_region(m, 1) == (1.0, "the declared convex region (the domain scaled by 1)")
    for bad in (0.0, -0.1, 1.5):
        with pytest.raises(InputError, match=rf"convex_shrink must be in \(0, 1\], got "
                                             rf"{bad!r}"):
            VM.convex_region(m, bad)
    core = VM.convexity_map(m).core
    s, text = VM.convex_region(m, None)
    assert s == VM.CORE_MARGIN * core and 0.9 * RC < s < RC
    assert text == f"the convex core found by the map (the domain scaled by {s:.4g})"
    assert VM.solve_region(m) == s and VM.solve_region(m, 0.2) == 0.2
    assert VM.solve_region(Euclidean(), 0.2) == 1.0


# ----------------------------------------------------------------------------------------
# domain
# ----------------------------------------------------------------------------------------
def test_domain_passes_on_a_valid_metric():
    r = VM.check_domain(Euclidean(), examples=10)
    assert r.status is PASSED and r.tried == r.passed and r.tried > 10
    assert r.note.startswith("F finite and > 0 at all ") and not r.note.endswith(" ")
    assert "signed coordinate directions" in r.note


def test_domain_names_where_f_stops():
    r = VM.check_domain(NanOutside(), examples=10)
    assert r.status is FAILED and r.relation == ">" and r.rhs == ("0", 0.0)
    assert r.lhs[0] == "F(x, v)" and math.isnan(r.lhs[1])
    x = np.asarray(r.counterexample["x"])
    assert 0.9 < np.linalg.norm(x) <= 1.0 + 1e-12
    assert np.linalg.norm(r.counterexample["v"]) > 0
    assert r.passed < r.tried and r.note.endswith("Fix F there, or declare a smaller domain.")
    assert "the counterexample is the invalid sample nearest the domain's centre" in r.note
    # the nearest invalid sample: no valid-looking sample between the centre and it
    from validation.testing.regions import scan_domain
    scan = scan_domain(NanOutside(), 0)
    radii = np.linalg.norm(scan.points[scan.bad], axis=1)
    assert math.isclose(np.linalg.norm(x), radii.min(), rel_tol=1e-12)


class _OutsideBox(Box):
    def project(self, p):
        return np.asarray(p, float) + 5.0


class _HalvingBox(Box):
    def project(self, p):
        return 0.5 * np.clip(np.asarray(p, float), -1.0, 1.0)


class _ZeroBox(Box):
    def project(self, p):
        return np.zeros_like(np.asarray(p, float))


@pytest.mark.parametrize("box, note", [
    (_OutsideBox, "the projection lies outside the domain"),
    (_HalvingBox, "projection not idempotent"),
    (_ZeroBox, "a point of the domain is moved by the projection")])
def test_domain_projection_failures(box, note):
    class M(Base):
        name = "projection-test"
        domain = property(lambda self: box((-1.0, -1.0), (1.0, 1.0)))

    r = VM.check_domain(M(), examples=30)
    assert r.status is FAILED and r.note.endswith(f". {note}")
    p = np.asarray(r.counterexample["p"])
    assert np.all(np.abs(p) <= 1.2 + 1e-12)
    if box is _ZeroBox:  # shrunk towards a point of the domain that moves
        assert np.any(p != 0) and np.all(np.abs(p) <= 1.0)
        assert r.lhs == ("project(p)", [0.0, 0.0]) and r.relation == "=="
    if box is _OutsideBox:
        assert r.relation == "in" and r.lhs[0] == "project(p)"
        assert r.rhs == ("in the domain", M().domain.describe())


# ----------------------------------------------------------------------------------------
# finite-positive, homogeneity, subadditivity
# ----------------------------------------------------------------------------------------
def test_finite_positive():
    ok = VM.check_finite_positive(Euclidean(), examples=10)
    assert ok.status is PASSED and ok.tried == ok.passed == 10
    nan = VM.check_finite_positive(NanOutside(), examples=60)
    assert nan.status is FAILED and nan.lhs[0] == "F(x, v)" and math.isnan(nan.lhs[1])
    assert nan.note.startswith("F is not finite. F is not finite and > 0 for ")
    assert np.linalg.norm(nan.counterexample["x"]) > 0.9


def test_finite_positive_sweep_finds_a_thin_cone():
    r = VM.check_finite_positive(NegativeCone(), examples=5)
    assert r.status is FAILED and r.relation == ">" and r.rhs == ("0", 0.0)
    v = np.asarray(r.counterexample["v"])
    assert math.isclose(np.linalg.norm(v), 1.0, rel_tol=1e-12)
    assert v @ [math.cos(1.0), math.sin(1.0)] > 0.99
    assert math.isclose(r.lhs[1], -1.0, rel_tol=1e-12)  # the smallest value: -|v|
    x, dirs, f = VM.directions_scan(NegativeCone(), 0)
    bad = ~(f > 0)
    assert r.tried == 5 + bad.size and r.passed == 5 + int((~bad).sum())
    assert r.note.startswith(f"F is not finite and > 0 for {100 * float(bad.mean()):.1f}% of "
                             f"{bad.size} (point, direction) samples ({len(x)} uniform points "
                             f"x {len(dirs)} unit directions); the counterexample is the "
                             "smallest value")


def test_homogeneity():
    ok = VM.check_homogeneity(Randers(), examples=10)
    assert ok.status is PASSED and ok.tried == ok.passed == 10
    sq = VM.check_homogeneity(Squared(), examples=30)
    assert sq.status is FAILED and sq.lhs[0] == "F(x, lam v)" and sq.rhs[0] == "lam F(x, v)"
    lam, v = sq.counterexample["lam"], np.asarray(sq.counterexample["v"])
    assert math.isclose(sq.lhs[1], lam**2 * (v @ v), rel_tol=1e-12)
    assert math.isclose(sq.rhs[1], lam * (v @ v), rel_tol=1e-12)
    rel = abs(sq.lhs[1] - sq.rhs[1]) / abs(sq.rhs[1])
    assert sq.note == f"relative difference {rel:.3g} (tolerance 1e-12)"
    off = VM.check_homogeneity(Offset(), examples=10)
    assert off.status is FAILED and off.lhs == ("F(x, 0)", 1e-3) and off.rhs == ("0", 0.0)
    # a tolerance the defect fits in passes
    assert VM.check_homogeneity(Squared(), examples=5, rtol=1e9).status is PASSED


def test_subadditivity():
    assert VM.check_subadditivity(Randers(), examples=10).status is PASSED
    sq = VM.check_subadditivity(Squared(), examples=30, seed=1)
    assert sq.status is FAILED and sq.relation == "<="
    v, w = (np.asarray(sq.counterexample[k]) for k in "vw")
    assert math.isclose(sq.lhs[1], (v + w) @ (v + w), rel_tol=1e-12)
    assert math.isclose(sq.rhs[1], v @ v + w @ w, rel_tol=1e-12)
    assert sq.note == f"excess {sq.lhs[1] - sq.rhs[1]:.3g}"
    root = VM.check_subadditivity(Root(), examples=30, seed=1)
    assert root.status is FAILED and root.lhs[0] == "F(x, (v + w)/2)"
    v, w = (np.asarray(root.counterexample[k]) for k in "vw")
    fv, fw = (np.linalg.norm(a) ** 0.5 for a in (v, w))
    assert math.isclose(root.rhs[1], 0.5 * (fv + fw), rel_tol=1e-12)
    assert root.lhs[1] > root.rhs[1]


def test_subadditivity_mapped_and_declared_region():
    m = Matsumoto()
    r = VM.check_subadditivity(m, examples=15, seed=2)
    s, which = VM.convex_region(m, None, seed=2)
    assert which.endswith(f"(the domain scaled by {s:.4g})")
    assert r.status is MAPPED and r.mapped >= 1
    assert r.note.startswith(f"Holds on {which} (")
    assert ("On the whole domain it fails (the counterexample): mapped, not an error, since "
            f"{m.name} documents it ({m.convexity_note}). "
            f"{VM.convexity_map(m, seed=2).describe()}.") in r.note
    assert np.linalg.norm(r.counterexample["x"]) > RC
    bad = VM.check_subadditivity(m, examples=30, seed=2, convex_shrink=1.0)
    assert bad.status is FAILED
    assert bad.note.startswith("FAILS on the declared convex region (the domain scaled by 1), "
                               "where it must hold.")
    inside = VM.check_subadditivity(m, examples=15, seed=2, convex_shrink=0.2)
    assert inside.status is MAPPED
    assert re.match(r"Holds on the declared convex region \(the domain scaled by 0\.2\) "
                    r"\(1[0-5] examples\)\. On the whole domain it fails", inside.note)


# ----------------------------------------------------------------------------------------
# strong convexity
# ----------------------------------------------------------------------------------------
def test_strong_convexity():
    ok = VM.check_strong_convexity(Randers(), examples=10)
    assert ok.status is PASSED and ok.tried == ok.passed == 10 and ok.note == ""
    sk = VM.check_strong_convexity(NegativeCone(), examples=10)
    assert sk.status is SKIPPED and sk.note == (
        f"{NegativeCone.name} is declared not smooth ({NegativeCone.convexity_note}): its "
        "fundamental tensor is not defined everywhere; convexity is checked by subadditivity")
    mapped = VM.check_strong_convexity(Matsumoto(), examples=10)
    assert mapped.status is MAPPED and mapped.note.startswith("Holds on the convex core")


def test_strong_convexity_failure_says_where():
    m = ConvexClaimed()
    r = VM.check_strong_convexity(m, examples=10, directions=16)
    assert r.status is FAILED and r.relation == ">" and r.rhs == ("0", 0.0)
    assert r.lhs[0] == "smallest eigenvalue over 16 directions" and r.lhs[1] < 0
    x = np.asarray(r.counterexample["x"])
    assert np.linalg.norm(x) > RC
    v, w = np.asarray(r.counterexample["v"]), np.asarray(r.counterexample["w"])
    assert math.isclose(np.linalg.norm(v), 1.0, rel_tol=1e-9)
    cmap = VM.convexity_map(m)
    vv, lam, ww = VM.weakest_direction(m, x, 16)
    assert r.note.startswith(
        f"F(x, .) is not convex at x = {VM.fmt(list(x), 4)}: at the unit direction v = "
        f"{VM.fmt(list(vv), 4)} the fundamental tensor has eigenvalue {lam:.3g} along w = "
        f"{VM.fmt(list(ww), 4)} (the unit ball bends inwards there). F is not convex on "
        f"{100 * cmap.fraction:.1f}% of {cmap.samples} points sampled uniformly over the "
        f"domain; the non-convex sample nearest the domain's centre is "
        f"{VM.fmt(cmap.nearest, 4)}, at {cmap.nearest_scale:.3f} of the domain's size. Fix F")
    assert abs(cmap.fraction - (1 - RC**2)) < 0.03
    np.testing.assert_array_equal(v, vv)
    np.testing.assert_array_equal(w, ww)


def test_strong_convexity_map_finds_what_the_search_missed():
    m = HiddenConvexity()
    r = VM.check_strong_convexity(m, examples=5, directions=7)
    cmap = VM.convexity_map(m)
    assert r.status is FAILED
    assert r.counterexample["x"] == list(cmap.worst)
    assert r.tried == 5 + cmap.samples
    assert r.passed == 5 + round(cmap.samples * (1 - cmap.fraction))
    assert r.lhs[1] > 0  # what the 7-direction test says there


# ----------------------------------------------------------------------------------------
# reversibility, lowered forms, smoothness
# ----------------------------------------------------------------------------------------
def test_reversibility():
    ok = VM.check_reversibility(Euclidean(), examples=10)
    assert ok.status is PASSED and ok.tried == ok.passed == 10
    assert ok.claim == "F(x, -v) = F(x, v) (declared reversible)"
    bad = VM.check_reversibility(RandersClaimedReversible(), examples=20)
    assert bad.status is FAILED and bad.note == "the metric is declared reversible"
    x, v = (np.asarray(bad.counterexample[k]) for k in "xv")
    m = Randers()
    assert bad.lhs == ("F(x, -v)", float(m.F(x, -v))) and bad.rhs == ("F(x, v)",
                                                                      float(m.F(x, v)))
    sk = VM.check_reversibility(Randers(), examples=20)
    assert sk.status is SKIPPED
    assert sk.claim == "F(x, -v) != F(x, v) somewhere (declared not reversible)"
    assert sk.note.startswith("not applicable: randers is declared not reversible "
                              "(asymmetry confirmed at x=")
    assert ": F(x, -v) = " in sk.note and sk.note.endswith(")")
    sym = VM.check_reversibility(EuclidClaimedIrreversible(), examples=12)
    assert sym.status is FAILED and sym.passed == 0 and sym.tried == 12
    assert sym.note == ("F(x, -v) = F(x, v) within 0.001 relative on all 12 examples: the "
                        "metric looks reversible; declare reversible = True (symmetric "
                        "distances, checked by distance-symmetry)")


def test_reversibility_thresholds():
    class Slight(Base):  # asymmetric by 1e-4 relative: below ASYMMETRY_MIN, above rtol
        name = "slight-test"

        def F_sx(self, x, v):
            return ca.sqrt(ca.dot(v, v)) + 1e-4 * v[0]

    s = Slight()
    assert VM.check_reversibility(s, examples=20).status is FAILED
    type(s).reversible = False
    try:
        assert VM.check_reversibility(s, examples=20).status is FAILED  # looks reversible
    finally:
        type(s).reversible = True


def test_lowered_forms():
    ok = VM.check_lowered_forms(Randers(), examples=8)
    assert ok.status is PASSED and ok.tried == ok.passed == 8
    for cls, label in ((OffNumpy, "numpy"), (OffTorch, "torch")):
        r = VM.check_lowered_forms(cls(), examples=8)
        assert r.status is FAILED and r.lhs[0] == f"F lowered to {label}"
        assert r.rhs[0] == "F symbolic (CasADi)" and r.relation == "=="
        x, v = (np.asarray(r.counterexample[k]) for k in "xv")
        assert r.rhs[1] == float(Randers().F(x, v))
        assert r.note == f"difference {r.lhs[1] - r.rhs[1]:.3g} (tolerance 1e-12 max(1, |F|))"
    assert VM.check_lowered_forms(OffNumpy(), examples=5, rtol=1e-6).status is PASSED
    r2 = VM.check_lowered_forms(OffHessian(), examples=8)
    assert r2.status is FAILED
    assert r2.lhs[0] in ("fundamental tensor lowered [1,0]", "fundamental tensor lowered [0,1]")
    assert r2.rhs[0] == "symbolic (CasADi)" and abs(r2.lhs[1] - r2.rhs[1]) > 5e-7
    assert VM.check_lowered_forms(OffHessian(), examples=5,
                                  hessian_rtol=1e-4).status is PASSED


def test_smoothness():
    ok = VM.check_smoothness(Randers(), examples=6)
    assert ok.status is PASSED and ok.tried == ok.passed == 6 + VM.SMOOTH_SWEEP
    sk = VM.check_smoothness(NegativeCone(), examples=6)
    assert sk.status is SKIPPED and sk.note.endswith(
        "exp/log refuse it and the solver uses its smooth reformulation")
    k = VM.check_smoothness(Kinked(), examples=6)
    assert k.status is FAILED and k.relation == "=="
    assert k.rhs[0] == "u' Hess(F^2/2) u (symbolic)"
    assert k.note.startswith("error ") and "not converging" in k.note
    assert abs(k.counterexample["x"][0]) < 0.05  # the kink is at x0 = 0


def test_smoothness_sweep_finds_a_thin_kink(monkeypatch):
    m = Kinked()
    # the hypothesis search sees no kink: every search example passes
    monkeypatch.setattr(VM, "search", lambda *a, **kw: VM.PropertyResult(
        a[0], a[1], PASSED, tried=3, passed=3))
    r = VM.check_smoothness(m, examples=3)
    assert r.status is FAILED and r.tried == 3 + VM.SMOOTH_SWEEP
    n_bad = 3 + VM.SMOOTH_SWEEP - r.passed
    assert 0 < n_bad < VM.SMOOTH_SWEEP // 4
    assert r.lhs[0] == "second difference of F^2/2 (h = 0.005)"
    x = r.counterexample["x"]
    assert abs(x[0]) < 1e-2 and max(abs(a) for a in x) <= 0.9 + 1e-12
    assert math.isclose(np.linalg.norm(r.counterexample["v"]), 1.0, rel_tol=1e-12)
    assert math.isclose(np.linalg.norm(r.counterexample["u"]), 1.0, rel_tol=1e-12)
    assert (f"not converging, F^2 has a kink within 0.01 of x along u; {n_bad} of "
            f"{VM.SMOOTH_SWEEP} swept points fail. Declare smooth = False") in r.note
    assert VM._smoothness_sweep(Randers(), Randers().derived(
        "testing.joint_second_derivative", lambda: VM._build_second_derivative(Randers())),
        np.array([2.0, 2.0]), 0) is None


def test_centre_and_metric_properties():
    np.testing.assert_array_equal(VM._centre_of(Matsumoto()), [0.0, 0.0])

    class Off(Base):
        name = "off-test"
        domain = property(lambda self: Disk(radius=1.0, center=(2.0, -1.0)))

    np.testing.assert_array_equal(VM._centre_of(Off()), [2.0, -1.0])

    class Shifted(Base):
        name = "shifted-test"
        domain = property(lambda self: Box((0.0, 2.0), (2.0, 6.0)))

    np.testing.assert_array_equal(VM._centre_of(Shifted()), [1.0, 4.0])
    names = [r.name for r in VM.metric_properties(Euclidean(), examples=3)]
    assert names == ["domain", "finite-positive", "homogeneity", "subadditivity",
                     "strong-convexity", "reversibility", "lowered-forms", "smoothness"]


def test_vectors_strategy():
    from hypothesis import given, settings

    seen = []

    @settings(max_examples=30, database=None, derandomize=True)
    @given(VM.vectors(3, low=0.5, scale=2.0))
    def draw(v):
        seen.append(v)

    draw()
    assert all(v.shape == (3,) and v.dtype == float for v in seen)
    assert all(np.linalg.norm(v) >= 0.5 and np.all(np.abs(v) <= 2.0) for v in seen)
    assert any(np.abs(v).max() > 1.0 for v in seen)
    class Odd(Base):
        name = "odd-domain-test"
        domain = property(lambda self: _Square())

    with pytest.raises(InputError, match=re.escape(
            "a convex region (the domain scaled by 0.5) needs a box, disk or product domain; "
            "odd-domain-test has a square")):
        VM._points(Odd(), 0.5)
    VM._points(Odd(), 1.0)  # the whole domain needs no scale


def test_finite_positive_verdicts_in_full():
    r = VM.check_finite_positive(HalfZero(), examples=30)
    assert r.name == "finite-positive" and r.status is FAILED
    assert r.claim == "F(x, v) is finite and > 0 for v != 0 on the domain"
    assert r.lhs == ("F(x, v)", 0.0) and r.relation == ">" and r.rhs == ("0", 0.0)
    assert set(r.counterexample) == {"x", "v"} and r.counterexample["x"][0] < 0
    assert r.note.startswith("F is not finite and > 0 for ") and r.note.endswith(".")
    nan = VM.check_finite_positive(NanOutside(), examples=60)
    x, v = (np.asarray(nan.counterexample[k]) for k in "xv")
    assert np.linalg.norm(x) <= 1.0 + 1e-12 and np.linalg.norm(v) >= 1e-3
    assert nan.relation == ">" and nan.rhs == ("0", 0.0)
    assert isinstance(nan.seconds, float) and nan.seconds > 0


def test_finite_positive_sweep_zero_and_nan():
    z = VM.check_finite_positive(ZeroCone(), examples=5, seed=3)
    assert z.status is FAILED and z.lhs == ("F(x, v)", 0.0)
    assert z.name == "finite-positive" and z.claim.startswith("F(x, v) is finite")
    assert isinstance(z.seconds, float) and z.seconds > 0
    _, _, f = VM.directions_scan(ZeroCone(), 3)  # the seed's own sweep
    assert z.tried == 5 + f.size and z.passed == 5 + int((f > 0).sum())
    n = VM.check_finite_positive(NanAndNegativeCones(), examples=5)
    assert n.status is FAILED and math.isnan(n.lhs[1])


def test_searches_use_their_named_streams(monkeypatch):
    streams, rngs = [], []
    real_seeded, real_search = VM.seeded, VM.search

    def seeded(seed, stream):
        streams.append((seed, stream))
        rng = real_seeded(seed, stream)
        rngs.append(rng)
        return rng

    def search(*a, **kw):
        assert kw["rng"] is rngs[-1]
        return real_search(*a, **kw)

    monkeypatch.setattr(VM, "seeded", seeded)
    monkeypatch.setattr(VM, "search", search)
    m = Randers()
    for fn, stream in ((VM.check_finite_positive, "finite-positive"),
                       (VM.check_homogeneity, "homogeneity"),
                       (VM.check_domain, "domain"), (VM.check_subadditivity, "subadditivity"),
                       (VM.check_strong_convexity, "strong-convexity"),
                       (VM.check_reversibility, "reversibility"),
                       (VM.check_lowered_forms, "lowered-forms"),
                       (VM.check_smoothness, "smoothness")):
        streams.clear()
        fn(m, examples=2, seed=7)
        assert streams == [(7, stream)], fn.__name__


def test_seeds_reach_the_sweeps(monkeypatch):
    seen = []
    real = VM.directions_scan
    monkeypatch.setattr(VM, "directions_scan", lambda m, seed: seen.append(seed) or real(m, seed))
    VM.check_finite_positive(Euclidean(), examples=2, seed=5)
    assert seen == [5]
    maps = []
    real_map = VM.convexity_map
    monkeypatch.setattr(VM, "convexity_map", lambda m, samples=VM.MAP_SAMPLES, seed=0: (
        maps.append(seed) or real_map(m, samples, seed)))
    VM.check_strong_convexity(Euclidean(), examples=2, seed=6)
    assert maps == [6]
    maps.clear()
    VM.convex_region(Matsumoto(), None, seed=2)
    VM.solve_region(Matsumoto(), None, seed=4)
    assert maps == [2, 4]


def test_homogeneity_verdicts_in_full():
    off = VM.check_homogeneity(Offset(), examples=10)
    assert off.relation == "=="
    assert off.claim == "F(x, lam v) = lam F(x, v) for lam > 0, F(x, 0) = 0"
    sq = VM.check_homogeneity(Squared(), examples=30)
    assert sq.relation == "==" and sq.name == "homogeneity"
    assert VM.check_homogeneity(Zero(), examples=10).status is PASSED  # 0 = lam 0
    small = VM.check_homogeneity(SlightlySquared(), examples=30)
    assert small.status is FAILED
    a, b = small.lhs[1], small.rhs[1]
    assert abs(a - b) < 1e-3
    assert small.note == f"relative difference {abs(a - b) / abs(b):.3g} (tolerance 1e-12)"
    tiny = VM.check_homogeneity(SlightlySquared(), examples=30, seed=1)
    lam, v = tiny.counterexample["lam"], np.linalg.norm(tiny.counterexample["v"])
    f = v + 1e-6 * v * v
    assert tiny.rhs[1] == pytest.approx(lam * f, rel=1e-12)


def test_convex_region_without_a_core(monkeypatch):
    monkeypatch.setattr(VM, "convexity_map", lambda m, samples=0, seed=0: VM.ConvexityMap(
        8, 1.0, -1.0, None, None, None))
    assert VM.convex_region(Matsumoto(), None) == (
        None, "no convex core around the domain's centre")
    assert VM.solve_region(Matsumoto()) == 1.0
    r = VM.check_subadditivity(Matsumoto(), examples=30)
    assert r.status in (MAPPED, PASSED) and not r.note.startswith("Holds on")
    assert r.tried <= 30  # the whole domain only, no search of a convex part


def test_describe_rounds_the_nearest_point():
    part = VM.ConvexityMap(200, 0.125, -1.0, (0.123456, 0.2), 0.3, 0.3)
    assert "is (0.1235, 0.2), at 0.3000 of" in part.describe()


def test_strong_convexity_map_found_note_in_full():
    m = HiddenConvexity()
    r = VM.check_strong_convexity(m, examples=5, directions=7)
    cmap = VM.convexity_map(m)
    assert r.name == "strong-convexity" and r.relation == ">" and r.rhs == ("0", 0.0)
    assert r.claim == "the fundamental tensor Hess_v F^2/2 is positive definite"
    assert r.lhs[0] == "smallest eigenvalue over 7 directions"
    assert isinstance(r.seconds, float) and r.seconds > 0
    x = np.asarray(cmap.worst)
    vv, lam, ww = VM.weakest_direction(m, x, 7)
    assert r.counterexample == {"x": list(x), "v": list(vv), "w": list(ww)}
    assert r.note == (
        f"F(x, .) is not convex at x = {VM.fmt(list(x), 4)}: at the unit direction v = "
        f"{VM.fmt(list(vv), 4)} the fundamental tensor has eigenvalue {lam:.3g} along w = "
        f"{VM.fmt(list(ww), 4)} (the unit ball bends inwards there). F is not convex on "
        f"{100 * cmap.fraction:.1f}% of {cmap.samples} points sampled uniformly over the "
        f"domain; the non-convex sample nearest the domain's centre is "
        f"{VM.fmt(cmap.nearest, 4)}, at {cmap.nearest_scale:.3f} of the domain's size. Fix F "
        "there, or declare convex_everywhere = False with a convexity_note and the region is "
        "mapped instead.")
    assert len(VM.fmt(list(x), 4)) < len(VM.fmt(list(x), 6))


def test_strong_convexity_sizes_of_a_region_the_map_misses(monkeypatch):
    m = ConvexClaimed()
    real = VM.convexity_map
    monkeypatch.setattr(VM, "convexity_map", lambda mm, samples=VM.MAP_SAMPLES, seed=0: (
        VM.ConvexityMap(64, 0.0, 0.5, None, None, 1.0)))
    r = VM.check_strong_convexity(m, examples=10, directions=16)
    assert r.status is FAILED
    assert ("F is convex at all 64 points of the convexity map (the bad region is smaller "
            "than 1/64 of the domain). Fix F") in r.note
    assert real is not None


def test_strong_convexity_eigenvalue_zero_fails():
    class Degenerate(Base):  # F = |v0|-like along a direction: a zero eigenvalue
        name = "degenerate-test"

        def F_sx(self, x, v):
            return ca.sqrt(v[0] ** 2 + 1e-30 * v[1] ** 2 + 0.0 * ca.dot(x, x))

    r = VM.check_strong_convexity(Degenerate(), examples=5, directions=8)
    assert r.status is FAILED and r.lhs[1] <= 1e-20


def test_not_smooth_names_and_claims():
    sk = VM.check_strong_convexity(NegativeCone(), examples=3)
    assert sk.name == "strong-convexity"
    assert sk.claim == "the fundamental tensor Hess_v F^2/2 is positive definite"
    sm = VM.check_smoothness(NegativeCone(), examples=3)
    assert sm.name == "smoothness" and sm.claim.startswith("F^2 is C^2 in (x, v)")


def test_metric_properties_pass_their_options(monkeypatch):
    got = {}
    for name in ("check_domain", "check_finite_positive", "check_homogeneity",
                 "check_subadditivity", "check_strong_convexity", "check_reversibility",
                 "check_lowered_forms", "check_smoothness"):
        monkeypatch.setattr(VM, name, lambda m, _n=name, **kw: got.__setitem__(_n, kw))
    VM.metric_properties(Euclidean(), examples=4, seed=9, convex_shrink=0.5)
    base = {"examples": 4, "seed": 9}
    assert got == {"check_domain": base, "check_finite_positive": base,
                   "check_homogeneity": base,
                   "check_subadditivity": {**base, "convex_shrink": 0.5},
                   "check_strong_convexity": {**base, "convex_shrink": 0.5},
                   "check_reversibility": base, "check_lowered_forms": base,
                   "check_smoothness": base}


def test_reversibility_verdicts_in_full():
    r = VM.check_reversibility(Drift(), examples=30)
    assert r.status is FAILED and r.name == "reversibility" and r.relation == "=="
    x, v = (np.asarray(r.counterexample[k]) for k in "xv")
    f = Drift().F
    assert r.lhs == ("F(x, -v)", float(f(x, -v))) and r.rhs == ("F(x, v)", float(f(x, v)))
    assert isinstance(r.seconds, float) and r.seconds > 0
    assert VM.check_reversibility(Zero(), examples=5).status is PASSED  # 0 = 0
    assert VM.check_reversibility(TinyAsymmetric(), examples=10).status is FAILED
    sk = VM.check_reversibility(Randers(), examples=20)
    assert sk.name == "reversibility" and isinstance(sk.seconds, float) and sk.seconds > 0
    assert re.fullmatch(r"not applicable: randers is declared not reversible \(asymmetry "
                        r"confirmed at x=\(.*\) v=\(.*\): F\(x, -v\) = \S+   !=   F\(x, v\) "
                        r"= \S+\)", sk.note)
    sym = VM.check_reversibility(EuclidClaimedIrreversible(), examples=12)
    assert sym.name == "reversibility" and sym.claim.startswith("F(x, -v) != F(x, v)")
    assert isinstance(sym.seconds, float) and sym.seconds > 0


def test_reversible_search_uses_its_stream(monkeypatch):
    streams = []
    real = VM.seeded
    monkeypatch.setattr(VM, "seeded", lambda seed, s: streams.append((seed, s)) or real(seed, s))
    a = VM.check_reversibility(Drift(), examples=10, seed=3)
    assert streams == [(3, "reversibility")]
    b = VM.check_reversibility(Drift(), examples=10, seed=3)
    assert a.counterexample == b.counterexample


def test_smoothness_search_finds_the_kink_itself():
    k = VM.check_smoothness(KinkedV(), examples=20)
    assert k.status is FAILED and k.name == "smoothness"
    assert k.claim == "F^2 is C^2 in (x, v) for v != 0 (symbolic Hessian = second differences)"
    assert k.lhs[0] == "second difference of F^2/2 (h = 0.001)"  # the search's, not the sweep's
    assert re.fullmatch(r"error \S+ at h = 0\.002, \S+ at h/2: not converging, F\^2 has a "
                        r"kink here", k.note)
    x, v, u = (np.asarray(k.counterexample[a]) for a in "xvu")
    assert math.isclose(np.linalg.norm(u), 1.0, rel_tol=1e-12)
    assert np.all(np.abs(x) <= 0.9 + 1e-12) and np.linalg.norm(v) >= 0.1
    # a smooth metric passes with a tolerance far below the kink's error
    assert VM.check_smoothness(Randers(), examples=4, rtol=1e-9).status is PASSED


def test_domain_verdicts_in_full():
    m = NanOutsideOff()
    r = VM.check_domain(m, examples=5)
    assert r.name == "domain" and r.claim == (
        "F is finite and > 0 on the whole declared domain (boundary included); "
        "project(p) is in the domain, idempotent, the identity inside")
    x = np.asarray(r.counterexample["x"])
    from validation.testing.regions import describe_region, scan_domain
    scan = scan_domain(m, 0)
    radii = np.linalg.norm(scan.points[scan.bad] - [2.0, -1.0], axis=1)
    assert math.isclose(np.linalg.norm(x - [2.0, -1.0]), radii.min(), rel_tol=1e-12)
    assert r.tried == len(scan.points) and r.passed == int((~scan.bad).sum())
    j = int(np.flatnonzero(np.all(scan.points == x, axis=1))[0])
    i = int(np.flatnonzero(scan.bad_values[j])[0])
    assert r.counterexample["v"] == list(scan.directions[i])
    n = len(scan.points)
    assert r.note.startswith(describe_region(m, scan.points, scan.bad, scan.what()) + ". ")
    assert (f"Sampled {n} points ({scan.inside} uniform, {n - scan.inside} on the boundary, "
            "the centre) along the 4 signed coordinate directions;") in r.note
    assert isinstance(r.seconds, float) and 0 < r.seconds < 60
    ok = VM.check_domain(Euclidean(), examples=3)
    assert ok.name == "domain" and 0 < ok.seconds < 60


@pytest.mark.parametrize("box, note", [
    (_HalvingBox, "projection not idempotent"),
    (_ZeroBox, "a point of the domain is moved by the projection")])
def test_domain_projection_sides(box, note):
    class M(Base):
        name = "projection-sides-test"
        domain = property(lambda self: box((-1.0, -1.0), (1.0, 1.0)))

    r = VM.check_domain(M(), examples=30)
    assert r.relation == "=="
    p = np.asarray(r.counterexample["p"])
    q = M().domain.project(p[None])[0]
    if box is _HalvingBox:
        assert r.lhs == ("project(project(p))", list(M().domain.project(q[None])[0]))
        assert r.rhs == ("project(p)", list(q))
    else:
        assert r.lhs == ("project(p)", [0.0, 0.0]) and r.rhs == ("p", list(p))


class _ShiftedZeroBox(Box):
    """A box [2, 4] x [10, 11] whose projection sends every point to its centre."""

    def project(self, p):
        return np.broadcast_to(np.array([3.0, 10.5]), np.asarray(p, float).shape).copy()


def _domain_draws(metric, examples):
    """``check_domain(metric, examples=...)`` with every point its search judged recorded:
    ``(result, points (K, dim))``."""
    seen = []
    real = VM.search

    def spy(name, claim, strategy, check, describe, **kw):
        def judged(p):
            seen.append(np.array(p))
            return check(p)
        return real(name, claim, strategy, judged, describe, **kw)

    import unittest.mock as um
    with um.patch.object(VM, "search", spy):
        r = VM.check_domain(metric, examples=examples)
    return r, np.array(seen)


def test_domain_draws_around_a_shifted_box():

    class M(Base):
        name = "shifted-box-test"
        domain = property(lambda self: _ShiftedZeroBox((2.0, 10.0), (4.0, 11.0)))

    r, pts = _domain_draws(M(), 40)
    assert np.all(pts[:, 0] >= 2.0 - 0.4) and np.all(pts[:, 0] <= 4.0 + 0.4)
    assert np.all(pts[:, 1] >= 10.0 - 0.2) and np.all(pts[:, 1] <= 11.0 + 0.2)
    assert pts[:, 0].min() < 2.0 or pts[:, 0].max() > 4.0  # beyond the box too
    assert r.status is FAILED and r.note.endswith(
        ". a point of the domain is moved by the projection")


# ----------------------------------------------------------------------------------------
# second pass over the survivors (mutation-2026-11-28-15/-16): defaults, names and claims
# on every path, tolerances at their edges, counterexamples recomputed from their own
# definition
# ----------------------------------------------------------------------------------------
_CHECKS = [VM.check_domain, VM.check_finite_positive, VM.check_homogeneity,
           VM.check_subadditivity, VM.check_strong_convexity, VM.check_reversibility,
           VM.check_lowered_forms, VM.check_smoothness]


@pytest.mark.parametrize("fn", _CHECKS, ids=lambda f: f.__name__)
def test_defaults_are_100_examples_and_seed_0(fn, monkeypatch):
    examples, seeds = [], []
    real_search, real_seeded = VM.search, VM.seeded
    monkeypatch.setattr(VM, "seeded", lambda seed, s: seeds.append(seed) or real_seeded(seed, s))

    def search(*a, **kw):
        examples.append(kw["examples"])
        return real_search(*a, **{**kw, "examples": 2})

    monkeypatch.setattr(VM, "search", search)
    fn(Randers())
    assert examples == [100] and seeds == [0]


def test_metric_properties_defaults(monkeypatch):
    got = {}
    for fn in _CHECKS:
        monkeypatch.setattr(VM, fn.__name__, lambda m, _n=fn.__name__, **kw: got.__setitem__(
            _n, kw))
    VM.metric_properties(Euclidean())
    assert {k: (v["examples"], v["seed"]) for k, v in got.items()} == {
        f.__name__: (100, 0) for f in _CHECKS}


SUB_CLAIM = "F(x, v + w) <= F(x, v) + F(x, w) (the indicatrix is convex)"
SC_CLAIM = "the fundamental tensor Hess_v F^2/2 is positive definite"


def test_names_and_claims_on_every_path():
    e, mats = Euclidean(), Matsumoto()
    for r in (VM.check_subadditivity(e, examples=3), VM.check_subadditivity(mats, examples=3),
              VM.check_subadditivity(mats, examples=3, convex_shrink=0.5)):
        assert (r.name, r.claim) == ("subadditivity", SUB_CLAIM)
    for r in (VM.check_strong_convexity(e, examples=3),
              VM.check_strong_convexity(mats, examples=3)):
        assert (r.name, r.claim) == ("strong-convexity", SC_CLAIM)
    lf = VM.check_lowered_forms(e, examples=2)
    assert (lf.name, lf.claim) == ("lowered-forms",
                                   "numpy/torch F and its Hessian equal the symbolic CasADi F")
    d = VM.check_domain(e, examples=2)
    assert d.status is PASSED and d.claim == (
        "F is finite and > 0 on the whole declared domain (boundary included); "
        "project(p) is in the domain, idempotent, the identity inside")


def test_mapped_counts_the_whole_domains_counterexample_once():
    r = VM.check_subadditivity(Matsumoto(), examples=20)
    assert r.status is MAPPED and r.mapped == 1


def test_strong_convexity_declared_region_and_default_directions():
    r = VM.check_strong_convexity(Matsumoto(), examples=3, convex_shrink=0.5)
    assert "the declared convex region (the domain scaled by 0.5)" in r.note
    c = VM.check_strong_convexity(ConvexClaimed(), examples=10)
    assert c.status is FAILED and c.lhs[0] == "smallest eigenvalue over 64 directions"
    x = np.asarray(c.counterexample["x"])
    assert c.lhs[1] == float(ConvexClaimed().convexity(x[None], n_directions=64)[0]) < 0


def _fnp(m, x, v):
    return float(m.F(np.asarray(x, float), np.asarray(v, float)))


def test_counterexamples_recompute_their_sides():
    m = RootX()
    r = VM.check_subadditivity(m, examples=30)
    assert r.status is FAILED and r.relation == "<=" and r.lhs[0] == "F(x, (v + w)/2)"
    x, v, w = (np.asarray(r.counterexample[k]) for k in "xvw")
    assert r.lhs[1] == pytest.approx(_fnp(m, x, 0.5 * (v + w)), rel=1e-12)
    assert r.rhs[1] == pytest.approx(0.5 * (_fnp(m, x, v) + _fnp(m, x, w)), rel=1e-12)
    s = SquaredX()
    h = VM.check_homogeneity(s, examples=30)
    x, v, lam = np.asarray(h.counterexample["x"]), np.asarray(h.counterexample["v"]), \
        h.counterexample["lam"]
    assert h.status is FAILED
    assert h.lhs[1] == pytest.approx(_fnp(s, x, lam * v), rel=1e-12)
    o = VM.check_lowered_forms(OffNumpy(), examples=8)
    x, v = (np.asarray(o.counterexample[k]) for k in "xv")
    assert o.lhs[1] == pytest.approx(_fnp(OffNumpy(), x, v), rel=1e-15)
    hh = VM.check_lowered_forms(OffHessian(), examples=8)
    assert hh.relation == "==" and hh.lhs[0].startswith("fundamental tensor lowered [")


def _fixed_vectors(monkeypatch, v):
    from hypothesis import strategies as hst
    monkeypatch.setattr(VM, "vectors", lambda dim, low=1e-3, scale=3.0: hst.just(
        np.asarray(v, float)))


def test_subadditivity_tolerance_at_its_edges(monkeypatch):
    # v = w = (0.1, 0): the excess is delta, the tolerance 1e-12 (1 + F(v) + F(w)) = 1.2e-12
    _fixed_vectors(monkeypatch, [0.1, 0.0])
    assert VM.check_subadditivity(ShortBy(1.1e-12), examples=3).status is PASSED
    r = VM.check_subadditivity(ShortBy(1.3e-12), examples=3)
    assert r.status is FAILED and r.lhs[0] == "F(x, v + w)"


def test_homogeneity_scales_from_001_to_100(monkeypatch):
    _fixed_vectors(monkeypatch, [1.0, 0.0])
    small = VM.check_homogeneity(SmallScaleOff(), examples=30)
    assert small.status is FAILED and small.counterexample["lam"] < 0.5
    assert VM.check_homogeneity(LargeScaleOff(), examples=100).status is PASSED


def test_finite_positive_search_fails_on_inf_and_zero():
    # hypothesis draws v0 = 0 itself; the sweep's random unit directions never do
    r = VM.check_finite_positive(InfOnAxis(), examples=30)
    assert r.status is FAILED and r.lhs == ("F(x, v)", math.inf)
    assert r.note.startswith("F is not finite. ") and "not shrunk" not in r.note
    z = VM.check_finite_positive(ZeroOnAxis(), examples=30)
    assert z.status is FAILED and z.lhs == ("F(x, v)", 0.0) and "not shrunk" not in z.note


def test_lowered_forms_tolerance_is_rtol_max_1_abs_f():
    # |F| < 1: the tolerance is 1e-12 absolute
    assert VM.check_lowered_forms(OffAbs(0.1, 1.5e-12), examples=5).status is FAILED
    # |F| in [1, 430]: 1e-12 |F|, so a relative error of 0.5e-12 passes
    assert VM.check_lowered_forms(OffAbs(100.0, 0.5e-12, rel=True), examples=5
                                  ).status is PASSED
    # the tensor's tolerance is 1e-10 relative and absolute: 1e-9 on every entry fails
    r = VM.check_lowered_forms(OffHessianAbs(1.0), examples=3)
    assert r.status is FAILED and r.lhs[0].startswith("fundamental tensor lowered")


def _energy_kinked_v(z):
    v = z[2:]
    return 0.5 * (np.linalg.norm(v) + 0.2 * abs(v[0])) ** 2


def test_smoothness_counterexample_recomputes():
    """The search's two sides from the counterexample alone: u = (c_x * the domain's width
    2, c_v * |v|), the second difference of E = F^2/2 at h = 0.001, and at v0 = 0 (where
    CasADi's |v0| has zero derivatives) the symbolic u' Hess E u = |u_v|^2."""
    k = VM.check_smoothness(KinkedV(), examples=20)
    assert k.status is FAILED and k.relation == "=="
    assert k.rhs[0] == "u' Hess(F^2/2) u (symbolic)"
    x, v, c = (np.asarray(k.counterexample[a]) for a in "xvu")
    u = np.concatenate([c[:2] * 2.0, c[2:] * np.linalg.norm(v)])
    z, h = np.concatenate([x, v]), 1e-3
    d2 = (_energy_kinked_v(z + h * u) - 2 * _energy_kinked_v(z) + _energy_kinked_v(z - h * u)
          ) / h ** 2
    assert k.lhs[1] == pytest.approx(d2, rel=1e-6, abs=1e-6)
    assert v[0] == 0.0 and k.rhs[1] == pytest.approx(float(u[2:] @ u[2:]), rel=1e-9)


def test_smoothness_search_tolerances():
    for m in (TinyKinkV(), C1KinkV()):
        r = VM.check_smoothness(m, examples=30)
        assert r.status is FAILED and r.lhs[0] == "second difference of F^2/2 (h = 0.001)", \
            m.name
    # a smooth F with large values: rounding noise of E ~ 1e6 is judged relative to |E|
    big = VM.check_smoothness(ScaledEuclid(1000.0), examples=30)
    assert big.status is PASSED


def test_smoothness_sweep_counterexample_recomputes():
    m = KinkOffCentre()
    r = VM.check_smoothness(m, examples=10)
    assert r.status is FAILED and r.lhs[0] == "second difference of F^2/2 (h = 0.005)"
    assert (r.name, r.claim) == (
        "smoothness", "F^2 is C^2 in (x, v) for v != 0 (symbolic Hessian = second differences)")
    assert isinstance(r.seconds, float) and r.seconds > 0
    x, v, c = (np.asarray(r.counterexample[a]) for a in "xvu")
    u = np.concatenate([c[:2] * 2.0, c[2:]])  # the sweep's v is a unit vector

    def energy(z):
        return 0.5 * (np.linalg.norm(z[2:]) * (1.0 + 0.3 * abs(z[0] - 0.3127))) ** 2

    z, h = np.concatenate([x, v]), 5e-3
    d2 = (energy(z + h * u) - 2 * energy(z) + energy(z - h * u)) / h ** 2
    assert r.lhs[1] == pytest.approx(d2, rel=1e-6, abs=1e-6)
    # the symbolic side: E = |v|^2 g^2 / 2, g = 1 + 0.3 |x0 - a| (g'' = 0)
    g, gp = 1.0 + 0.3 * abs(x[0] - 0.3127), 0.3 * np.sign(x[0] - 0.3127)
    hess = np.zeros((4, 4))
    hess[0, 0] = v @ v * gp * gp
    hess[0, 2:] = hess[2:, 0] = 2.0 * g * gp * v
    hess[2:, 2:] = g * g * np.eye(2)
    assert r.rhs[1] == pytest.approx(float(u @ hess @ u), rel=1e-9)
    errs = [abs((energy(z + hh * u) - 2 * energy(z) + energy(z - hh * u)) / hh ** 2
                - float(u @ hess @ u)) for hh in (1e-2, 5e-3)]
    assert _numbers(r.note) == pytest.approx(errs, rel=6e-3)  # 3 digits
    again = VM.check_smoothness(m, examples=10)
    assert again.counterexample == r.counterexample  # seeded


def test_smoothness_stays_in_the_domain_scaled_by_09():
    assert VM.check_smoothness(NanBeyond095Off(), examples=10).status is PASSED


def test_domain_scan_uses_the_seed():
    from validation.testing.regions import scan_domain
    m = NanOutsideOff()
    r = VM.check_domain(m, examples=2, seed=5)
    scan = scan_domain(m, 5)
    radii = np.linalg.norm(scan.points[scan.bad] - [2.0, -1.0], axis=1)
    x = np.asarray(r.counterexample["x"])
    assert math.isclose(np.linalg.norm(x - [2.0, -1.0]), radii.min(), rel_tol=1e-12)
    assert r.tried == len(scan.points)


class _CreepBox(Box):
    """[2, 4] x [10, 11] whose projection adds ``creep`` to every coordinate."""

    creep = 0.0

    def project(self, p):
        lo, hi = self.bounds()
        return np.clip(np.asarray(p, float), lo, hi) + self.creep


class _LeakyBox(Box):
    """[-1, 1]^2 whose projection of an outside point lands ``leak`` beyond the face."""

    leak = 0.0

    def project(self, p):
        p = np.asarray(p, float)
        q = np.clip(p, -1.0, 1.0)
        return q + self.leak * np.sign(p - q)


@pytest.mark.parametrize("creep, ok", [(1e-12, True), (5e-12, False)])
def test_domain_projection_tolerance_is_relative_to_the_box(creep, ok):
    """1e-12 times the box's size (2 here): a creep of 1e-12 passes, 5e-12 fails."""
    box = type("B", (_CreepBox,), {"creep": creep})

    class M(Base):
        name = f"creep-{creep:g}-test"
        domain = property(lambda self: box((2.0, 10.0), (4.0, 11.0)))

    r = VM.check_domain(M(), examples=30)
    assert (r.status is PASSED) is ok
    if not ok:
        assert r.note.endswith(". projection not idempotent")


@pytest.mark.parametrize("leak, ok", [(1e-11, True), (1e-3, False)])
def test_domain_projection_containment_tolerance(leak, ok):
    """project(p) may lie 1e-9 outside the domain (rounding), not 1e-3."""
    box = type("B", (_LeakyBox,), {"leak": leak})

    class M(Base):
        name = f"leak-{leak:g}-test"
        domain = property(lambda self: box((-1.0, -1.0), (1.0, 1.0)))

    r = VM.check_domain(M(), examples=30)
    assert (r.status is PASSED) is ok
    if not ok:
        assert r.note.endswith(". the projection lies outside the domain")


def test_domain_draws_beyond_both_faces():

    class M(Base):
        name = "shifted-box-both-test"
        domain = property(lambda self: Box((2.0, 10.0), (4.0, 11.0)))

    _, pts = _domain_draws(M(), 60)
    assert pts[:, 0].min() < 1.9 and pts[:, 0].max() > 4.1  # 20% of the width 2


def test_domain_scale_of_three_factors():
    d = Product([Box((0.0,), (2.0,)), Box((0.0,), (4.0,)), Box((0.0,), (8.0,))])
    x = np.array([[1.0, 2.0, 8.0], [1.5, 2.0, 4.0]])
    # per factor |x - c| / r: (0, 0, 1) and (0.5, 0, 0)
    np.testing.assert_allclose(VM.domain_scale_of(d, x), [1.0, 0.5])


def test_convexity_map_is_seeded_and_has_no_core_without_a_centre():
    a, b = VM.convexity_map(Matsumoto()), VM.convexity_map(Matsumoto())
    assert a == b  # two instances, no shared cache

    class SquareMatsumoto(ConvexClaimed):
        name = "square-matsumoto-test"
        convex_everywhere = False
        domain = property(lambda self: _Square())

    c = VM.convexity_map(SquareMatsumoto())
    assert c.fraction > 0 and c.core is None and c.nearest is None


def test_vectors_default_scale_3():
    from hypothesis import given, settings

    seen = []

    @settings(max_examples=60, database=None, derandomize=True)
    @given(VM.vectors(2))
    def draw(v):
        seen.append(v)

    draw()
    top = max(float(np.abs(v).max()) for v in seen)
    assert 2.5 < top <= 3.0


def _numbers(note):
    return [float(a) for a in re.findall(r"error (\S+) at h = \S+, (\S+) at h/2", note)[0]]


def test_smoothness_notes_give_both_errors(monkeypatch):
    # the search's (KinkedV, v fixed at (0, 2)): errors at h = 0.002 and 0.001 recomputed
    _fixed_vectors(monkeypatch, [0.0, 2.0])
    k = VM.check_smoothness(KinkedV(), examples=20)
    assert k.status is FAILED and k.lhs[0] == "second difference of F^2/2 (h = 0.001)"
    x, v, c = (np.asarray(k.counterexample[a]) for a in "xvu")
    np.testing.assert_array_equal(v, [0.0, 2.0])
    u = np.concatenate([c[:2] * 2.0, c[2:] * 2.0])
    z = np.concatenate([x, v])
    sym = float(u[2:] @ u[2:])  # Hess E = I in v at v0 = 0 (module test above)
    errs = [abs((_energy_kinked_v(z + h * u) - 2 * _energy_kinked_v(z)
                 + _energy_kinked_v(z - h * u)) / h ** 2 - sym) for h in (2e-3, 1e-3)]
    assert k.rhs[1] == pytest.approx(sym, rel=1e-9)
    assert _numbers(k.note) == pytest.approx(errs, rel=6e-3)  # 3 digits


def test_smoothness_search_steps_x_by_the_domain_width(monkeypatch):
    from hypothesis import strategies as hst
    m = Kinked()  # |v| (1 + 0.3 |x0|), x drawn at x0 = 0: the search's own counterexample
    monkeypatch.setattr(VM, "_points", lambda mm, shrink=1.0: hst.just(np.array([0.0, 0.3])))
    k = VM.check_smoothness(m, examples=30)
    assert k.status is FAILED and k.lhs[0] == "second difference of F^2/2 (h = 0.001)"
    x, v, c = (np.asarray(k.counterexample[a]) for a in "xvu")
    u = np.concatenate([c[:2] * 2.0, c[2:] * np.linalg.norm(v)])

    def energy(z):
        return 0.5 * (np.linalg.norm(z[2:]) * (1.0 + 0.3 * abs(z[0]))) ** 2

    z, h = np.concatenate([x, v]), 1e-3
    d2 = (energy(z + h * u) - 2 * energy(z) + energy(z - h * u)) / h ** 2
    assert k.lhs[1] == pytest.approx(d2, rel=1e-6, abs=1e-6)


def test_labels_and_notes_of_failures(monkeypatch):
    r = VM.check_subadditivity(RootX(), examples=30)
    assert r.rhs[0] == "(F(x, v) + F(x, w))/2"
    f = VM.check_finite_positive(NegativeCone(), examples=5)
    assert f.status is FAILED and set(f.counterexample) == {"x", "v"}
    _fixed_vectors(monkeypatch, [1.0, 0.0])
    small = VM.check_homogeneity(SmallScaleOff(), examples=30)
    a, b = small.lhs[1], small.rhs[1]
    assert abs(b) < 1 and small.note == (
        f"relative difference {abs(a - b) / abs(b):.3g} (tolerance 1e-12)")
    _fixed_vectors(monkeypatch, [0.1, 0.0])
    s = VM.check_subadditivity(ShortBy(1.3e-12), examples=3)
    assert s.rhs[0] == "F(x, v) + F(x, w)"


def test_more_counterexamples_and_directions(monkeypatch):
    m = OffNumpyShaped()
    o = VM.check_lowered_forms(m, examples=8)
    x, v = (np.asarray(o.counterexample[k]) for k in "xv")
    assert o.status is FAILED and o.lhs[1] == pytest.approx(_fnp(m, x, v), rel=1e-15)
    f = VM.check_finite_positive(NegativeCone(), examples=5)
    assert f.note.endswith("; the counterexample is the smallest value (not shrunk: the "
                           "search drew no such direction).")
    from hypothesis import strategies as hst
    monkeypatch.setattr(VM, "_points", lambda mm, shrink=1.0: hst.just(np.array([0.2, 0.2])))
    k = VM.check_smoothness(DiagonalKink(), examples=30)  # directions of every sign
    assert k.status is FAILED and k.lhs[0] == "second difference of F^2/2 (h = 0.001)"
