"""Fast focused tests of validation/testing/cases.py (mutation testing of
the property suite). No search and no solve: every property function the classes call is
replaced by a recorder that returns a result chosen by the test, so each test method is
checked to call the right function with the right arguments, and to pass, skip or fail
exactly as the result says."""

from __future__ import annotations

import sys
import types

import pytest

import finsler
from validation.testing import PropertyFailure, PropertyResult
from validation.testing import cases as C
from validation.testing import distance as D
from validation.testing import metric as M
from validation.testing import policy as P
from validation.testing.engine import FAILED, INCONCLUSIVE, MAPPED, NOT_RUN, PASSED, SKIPPED

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


class Recorder:
    """Stands for a property function: records its arguments, returns ``result``."""

    def __init__(self, result=None):
        self.calls = []
        self.result = result if result is not None else PropertyResult("p", "c", PASSED)

    def __call__(self, *args, **kw):
        self.calls.append((args, kw))
        return self.result


@pytest.fixture()
def metric():
    return finsler.Euclidean()


# ----------------------------------------------------------------------------------------
# _outcome, _Case
# ----------------------------------------------------------------------------------------
def test_outcome_skips_fails_and_passes():
    for status in (SKIPPED, INCONCLUSIVE):
        with pytest.raises(pytest.skip.Exception) as err:
            C._outcome(PropertyResult("prop", "claim", status, note="why not"))
        assert err.value.msg == f"prop {status}: why not"
    for status in (PASSED, MAPPED, NOT_RUN):
        assert C._outcome(PropertyResult("prop", "claim", status)) is None
    with pytest.raises(PropertyFailure):
        C._outcome(PropertyResult("prop", "claim", FAILED))


def test_case_defaults_and_metric(metric):
    assert (C._Case.metric, C._Case.examples, C._Case.seed, C._Case.convex_shrink) == (
        None, 100, 0, None)
    case = C._Case()
    with pytest.raises(TypeError) as err:
        case.get_metric()
    assert str(err.value) == ("_Case must set `metric` (a finsler.Metric or a registered "
                              "name)")
    case.metric = metric
    assert case.get_metric() is metric
    case.metric = "euclidean"
    got = case.get_metric()
    assert isinstance(got, finsler.Euclidean) and got == finsler.get_metric("euclidean")


def test_case_option_instance_over_class_and_functions_unbound():
    def f(x):
        return 2 * x

    class K(C._Case):
        fn = f
        n = 3

    k = K()
    assert k.option("fn") is f and k.option("n") == 3
    k.__dict__["n"] = 5
    assert k.option("n") == 5
    k.__dict__["fn"] = None
    assert k.option("fn") is None


# ----------------------------------------------------------------------------------------
# MetricTests
# ----------------------------------------------------------------------------------------
METRIC_METHODS = [
    ("test_domain", "check_domain", False),
    ("test_finite_and_positive", "check_finite_positive", False),
    ("test_homogeneity", "check_homogeneity", False),
    ("test_subadditivity", "check_subadditivity", True),
    ("test_strong_convexity", "check_strong_convexity", True),
    ("test_reversibility", "check_reversibility", False),
    ("test_lowered_forms", "check_lowered_forms", False),
    ("test_smoothness", "check_smoothness", False),
]


@pytest.mark.parametrize(("method", "fn", "shrink"), METRIC_METHODS)
def test_metric_tests_call_their_property(monkeypatch, metric, method, fn, shrink):
    for _, other, _ in METRIC_METHODS:
        monkeypatch.setattr(M, other, Recorder(PropertyResult(other, "c", FAILED)))
    rec = Recorder()
    monkeypatch.setattr(M, fn, rec)

    class T(C.MetricTests):
        examples = 7
        seed = 3
        convex_shrink = 0.4

    T.metric = metric
    getattr(T(), method)()
    want = {"examples": 7, "seed": 3, **({"convex_shrink": 0.4} if shrink else {})}
    assert rec.calls == [((metric,), want)]
    rec.result = PropertyResult(fn, "c", FAILED)
    with pytest.raises(PropertyFailure):
        getattr(T(), method)()
    rec.result = PropertyResult(fn, "c", SKIPPED, note="n/a")
    with pytest.raises(pytest.skip.Exception):
        getattr(T(), method)()


# ----------------------------------------------------------------------------------------
# _shared
# ----------------------------------------------------------------------------------------
def test_shared_builds_once_per_entry(metric):
    built = []

    def build(tag):
        def b():
            built.append(tag)
            return [tag]
        return b

    obj, other = object(), object()
    a = C._shared(metric, "k", ("Q", obj, 1, 0.5, None), build("a"))
    assert C._shared(metric, "k", ("Q", obj, 1, 0.5, None), build("x")) is a
    assert built == ["a"]
    # objects by identity, numbers by value and type, strings by value, length matters
    for entry in [("Q", other, 1, 0.5, None), ("Q", obj, 2, 0.5, None),
                  ("Q", obj, 1.0, 0.5, None), ("Q", obj, True, 0.5, None),
                  ("R", obj, 1, 0.5, None), ("Q", obj, 1, 0.5, 0.0), ("Q", obj, 1, 0.5),
                  ("Q", obj, 1, 0.5, None, None)]:
        b = C._shared(metric, "k", entry, build(entry))
        assert b is not a and built[-1] == entry
        assert C._shared(metric, "k", entry, build("y")) is b
    assert "y" not in built and "x" not in built
    # equal lists are not the same object: built again
    lst = [1]
    c = C._shared(metric, "k", (lst,), build("l1"))
    assert C._shared(metric, "k", (lst,), build("l2")) is c
    assert C._shared(metric, "k", ([1],), build("l3")) is not c
    # equal numbers and strings that are not the same object: found by value
    v1, v2 = float("0.25"), float("0.25")
    w1, w2 = "".join(["na", "me"]), "".join(["na", "me"])
    assert v1 is not v2 and w1 is not w2
    d = C._shared(metric, "k", (v1, w1), build("v1"))
    assert C._shared(metric, "k", (v2, w2), build("v2")) is d and "v2" not in built
    # another key, another table
    assert C._shared(metric, "k2", ("Q", obj, 1, 0.5, None), build("z")) == ["z"]
    assert C._shared(finsler.Euclidean(), "k", ("Q", obj, 1, 0.5, None), build("w")) == ["w"]


# ----------------------------------------------------------------------------------------
# DistanceTests
# ----------------------------------------------------------------------------------------
class FakeSuite:
    pass


@pytest.fixture()
def distance_env(monkeypatch):
    made, regions = [], []
    oracle = object()

    def make(m, o, seed, shrink):
        made.append((m, o, seed, shrink))
        return FakeSuite()

    def region(m, convex_shrink, seed):
        regions.append((m, convex_shrink, seed))
        return 0.625

    monkeypatch.setattr(D.DistanceSuite, "make", staticmethod(make))
    monkeypatch.setattr(D, "DiscreteDistance", lambda: oracle)
    monkeypatch.setattr(M, "solve_region", region)
    return made, regions, oracle


def test_distance_tests_defaults():
    t = C.DistanceTests
    assert (t.solved_examples, t.distance_oracle, t.distance_shrink, t.closed_form_distance,
            t.closed_form_geodesic, t.certify_examples) == (3, None, None, None, None, 2)


def test_distance_suite_default_oracle_region_and_cache(distance_env):
    made, regions, oracle = distance_env
    m = finsler.Euclidean()

    class T(C.DistanceTests):
        seed = 4
        convex_shrink = 0.3

    T.metric = m
    s = T().suite()
    assert isinstance(s, FakeSuite) and made == [(m, oracle, 4, 0.625)]
    assert regions == [(m, 0.3, 4)]
    assert T().suite() is s and len(made) == 1  # shared by the methods' instances
    # kept on the metric under the module's key (Metric.derived)
    (entry,) = m.derived("validation.testing.distance_suites", list)
    assert entry[0][1:] == (oracle, 4, 0.625) and entry[1] is s
    # a set shrink: no convexity map, its own suite
    T.distance_shrink = 0.5
    s2 = T().suite()
    assert s2 is not s and made[-1] == (m, oracle, 4, 0.5) and len(regions) == 2
    # the class's own oracle, and another class: another suite
    own = object()
    T.distance_oracle = own
    assert T().suite() is not s2 and made[-1] == (m, own, 4, 0.5)

    class U(C.DistanceTests):
        seed = 4
        distance_shrink = 0.5

    U.metric = m
    assert U().suite() is not s2 and made[-1] == (m, oracle, 4, 0.5)


DISTANCE_METHODS = {
    "test_distance_zero": "check_distance_zero",
    "test_distance_positive": "check_distance_positive",
    "test_triangle_inequality": "check_triangle_inequality",
    "test_segment_bound": "check_segment_bound",
    "test_distance_symmetry": "check_distance_symmetry",
    "test_closed_form_distance": "check_closed_form",
    "test_certificate": "check_certificate",
    "test_midpoint_halves": "check_midpoint_halves",
}


@pytest.mark.parametrize(("solved", "want"), [
    (3, {"test_distance_zero": (20,), "test_distance_positive": (3,),
         "test_triangle_inequality": (3,), "test_segment_bound": (3,),
         "test_distance_symmetry": (3,), "test_certificate": (5,),
         "test_midpoint_halves": (2,)}),
    (25, {"test_distance_zero": (25,), "test_distance_positive": (25,),
          "test_triangle_inequality": (25,), "test_segment_bound": (25,),
          "test_distance_symmetry": (25,), "test_certificate": (5,),
          "test_midpoint_halves": (24,)}),
    (1, {"test_midpoint_halves": (2,), "test_distance_zero": (20,)}),
])
def test_distance_methods_call_their_property(monkeypatch, distance_env, solved, want):
    recs = {fn: Recorder() for fn in DISTANCE_METHODS.values()}
    for fn, rec in recs.items():
        monkeypatch.setattr(D, fn, rec)

    def dist(x, y):
        return x

    def geo(x, y, t):
        return t

    class T(C.DistanceTests):
        solved_examples = solved
        certify_examples = 5
        closed_form_distance = dist
        closed_form_geodesic = geo

    T.metric = finsler.Euclidean()
    for method, args in want.items():
        getattr(T(), method)()
        (got,) = recs[DISTANCE_METHODS[method]].calls
        assert isinstance(got[0][0], FakeSuite)
        assert got[0][1:] == args and got[1] == {}
    T().test_closed_form_distance()
    (got,) = recs["check_closed_form"].calls
    assert isinstance(got[0][0], FakeSuite) and got[0][1:] == (solved, dist, geo)
    for rec in recs.values():
        rec.result = PropertyResult("p", "c", FAILED)
    for method in DISTANCE_METHODS:
        with pytest.raises(PropertyFailure):
            getattr(T(), method)()
    for rec in recs.values():
        rec.result = PropertyResult("p", "c", INCONCLUSIVE, note="no convergence")
    for method in DISTANCE_METHODS:
        with pytest.raises(pytest.skip.Exception):
            getattr(T(), method)()


# ----------------------------------------------------------------------------------------
# PolicyTests
# ----------------------------------------------------------------------------------------
class FakePolicy:
    def __init__(self, metric):
        self.metric = metric


def test_policy_tests_defaults():
    t = C.PolicyTests
    assert (t.policy, t.solved_examples, t.pairs, t.policy_shrink) == (None, 3, 10, None)
    assert (t.midpoint_rtol, t.symmetry_rtol, t.min_success, t.max_length_ratio) == (
        P.MIDPOINT_RTOL, P.SYMMETRY_RTOL, P.MIN_SUCCESS, P.MAX_LENGTH_RATIO)


def test_policy_get_policy_and_metric(monkeypatch):
    # a stand-in for the package (importing learn loads torch: seconds)
    learn = types.ModuleType("learn")
    monkeypatch.setitem(sys.modules, "learn", learn)
    m = finsler.Euclidean()
    loads = []

    def load(src):
        loads.append(src)
        return FakePolicy(m)

    learn.load_any_policy = load
    monkeypatch.setattr(C.PolicyTests, "_loaded", {})

    class T(C.PolicyTests):
        pass

    with pytest.raises(TypeError) as err:
        T().get_policy()
    assert str(err.value) == "T must set `policy`"
    T.policy = "runs/some-run"
    p = T().get_policy()
    assert isinstance(p, FakePolicy) and loads == ["runs/some-run"]
    assert T().get_policy() is p and loads == ["runs/some-run"]  # loaded once
    assert T().get_metric() is m  # the policy's metric
    other = finsler.Euclidean(n=3)
    T.metric = other
    assert T().get_metric() is other
    given = FakePolicy(m)
    T.policy = given
    assert T().get_policy() is given and loads == ["runs/some-run"]


def test_policy_methods_call_their_properties(monkeypatch, distance_env):
    _, regions, _ = distance_env
    m = finsler.Euclidean()
    pol = FakePolicy(m)
    mid, sym = Recorder(), Recorder()
    succ = Recorder([PropertyResult("policy-success", "c", PASSED),
                     PropertyResult("policy-length-ratio", "c", FAILED)])
    monkeypatch.setattr(P, "check_policy_midpoint", mid)
    monkeypatch.setattr(P, "check_policy_symmetry", sym)
    monkeypatch.setattr(P, "check_policy_success", succ)

    class T(C.PolicyTests):
        examples = 11
        seed = 2
        solved_examples = 4
        pairs = 6
        midpoint_rtol = 0.1
        symmetry_rtol = 0.2
        min_success = 0.7
        max_length_ratio = 1.5
        convex_shrink = 0.9

    T.policy = pol
    T().test_policy_midpoint()
    assert mid.calls == [((pol, m), {"examples": 4, "seed": 2, "rtol": 0.1, "shrink": 0.625})]
    assert regions == [(m, 0.9, 2)]
    T.policy_shrink = 0.55
    T().test_policy_midpoint()
    assert mid.calls[-1][1]["shrink"] == 0.55 and len(regions) == 1
    T().test_policy_symmetry()
    assert sym.calls == [((pol, m), {"examples": 11, "seed": 2, "rtol": 0.2})]
    T().test_policy_success()
    with pytest.raises(PropertyFailure):
        T().test_policy_length_ratio()
    assert succ.calls == [((pol, m), {"pairs": 6, "seed": 2, "min_success": 0.7,
                                      "max_length_ratio": 1.5})]  # shared by the two
    (run,) = m.derived("validation.testing.policy_runs", list)
    assert run[1] is succ.result
    succ.result = [PropertyResult("policy-success", "c", FAILED),
                   PropertyResult("policy-length-ratio", "c", PASSED)]
    T.pairs = 8
    with pytest.raises(PropertyFailure):
        T().test_policy_success()
    T().test_policy_length_ratio()
    assert len(succ.calls) == 2 and succ.calls[-1][1]["pairs"] == 8
    for rec in (mid, sym):
        rec.result = PropertyResult("p", "c", FAILED)
    with pytest.raises(PropertyFailure):
        T().test_policy_midpoint()
    with pytest.raises(PropertyFailure):
        T().test_policy_symmetry()
    # a changed seed, rate or ratio limit: fresh results again
    for attr, value in (("seed", 5), ("min_success", 0.6), ("max_length_ratio", 1.4)):
        setattr(T, attr, value)
        T().test_policy_length_ratio()
        assert succ.calls[-1][1][attr] == value
    assert len(succ.calls) == 5
