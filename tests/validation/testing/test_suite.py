"""Fast focused tests of validation/testing/suite.py (mutation testing of
the property suite). No search and no solve: every property :func:`check` runs is replaced
by a recorder whose status the test chooses, so the order of the properties, the
arguments each gets, which ones are ``not-run`` behind which root cause, the report's
fields, and the warnings and native stderr summarised on the results are all checked
against outcomes worked out by hand from :data:`suite.NEEDS`."""

from __future__ import annotations

import os
import tempfile
import warnings

import pytest

import finsler
from finsler import InputError
from validation.testing import PropertyResult
from validation.testing import suite as S
from validation.testing.engine import FAILED, INCONCLUSIVE, MAPPED, NOT_RUN, PASSED, SKIPPED

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation

F_PROPS = ["domain", "finite-positive", "homogeneity", "subadditivity", "strong-convexity",
           "reversibility", "lowered-forms", "smoothness"]
D_PROPS = ["distance-zero", "distance-positive", "triangle-inequality", "segment-bound",
           "distance-symmetry", "closed-form-distance", "certificate", "midpoint-halves"]
P_PROPS = ["policy-midpoint", "policy-symmetry", "policy-success", "policy-length-ratio"]
PREREQ = ("domain", "finite-positive", "homogeneity", "subadditivity", "strong-convexity",
          "lowered-forms", "smoothness")


def test_needs_and_prerequisites_written_out():
    assert S.PREREQUISITES == PREREQ
    want = {"domain": (), "finite-positive": ("domain",), "homogeneity": ("domain",),
            "subadditivity": ("finite-positive", "homogeneity"),
            "strong-convexity": ("finite-positive", "homogeneity"),
            "reversibility": ("finite-positive",), "lowered-forms": ("domain",),
            "smoothness": ("domain",),
            "distance-symmetry": (*PREREQ, "reversibility"),
            "policy-symmetry": (*PREREQ, "reversibility")}
    for n in ["distance-zero", "distance-positive", "triangle-inequality", "segment-bound",
              "closed-form-distance", "certificate", "midpoint-halves", "policy-midpoint",
              "policy-success", "policy-length-ratio"]:
        want[n] = PREREQ
    assert S.NEEDS == want
    assert S._NAMES == {"distance": tuple(D_PROPS), "policy": tuple(P_PROPS)}


@pytest.mark.parametrize(("examples", "solved"), [(1, 3), (89, 3), (90, 3), (119, 3),
                                                   (120, 4), (300, 10), (1000, 33)])
def test_solved_examples_for(examples, solved):
    assert S.solved_examples_for(examples) == solved


def test_params_of_dataclass_and_other_metrics():
    assert S._params(finsler.Euclidean(n=3)) == {"n": 3}
    assert S._params(finsler.Matsumoto()) == dict(finsler.MetricSpec.of(
        finsler.Matsumoto()).params)

    assert S._params(object()) == {}  # MetricSpec.of refuses it: no parameters


# ----------------------------------------------------------------------------------------
# check(): the properties replaced by recorders
# ----------------------------------------------------------------------------------------
class Env:
    def __init__(self):
        self.status: dict[str, str] = {}
        self.calls: list[tuple[str, tuple, dict]] = []
        self.made: list[tuple] = []
        self.regions: list[tuple] = []
        self.notes: dict[str, str] = {}

    def result(self, name):
        return PropertyResult(name, f"claim of {name}", self.status.get(name, PASSED),
                              note=self.notes.get(name, ""))

    def prop(self, name):
        def f(*args, **kw):
            self.calls.append((name, args, kw))
            return self.result(name)
        return f


class FakeSuite:
    def __init__(self, *args):
        self.args = args


@pytest.fixture()
def env(monkeypatch):
    e = Env()
    for name in F_PROPS:
        monkeypatch.setattr(S, "check_" + name.replace("-", "_"), e.prop(name))

    class DS:
        @staticmethod
        def make(*args):
            e.made.append(args)
            return FakeSuite(*args)

    def region(*args):
        e.regions.append(args)
        return 0.75

    def checks(suite, solved, cf, cg):
        e.calls.append(("distance_checks", (suite, solved, cf, cg), {}))
        return [(n, (lambda n=n: e.prop(n)(suite))) for n in D_PROPS]

    def success(*args, **kw):
        e.calls.append(("policy-success", args, kw))
        return [e.result("policy-success"), e.result("policy-length-ratio")]

    monkeypatch.setattr(S, "DistanceSuite", DS)
    monkeypatch.setattr(S, "solve_region", region)
    monkeypatch.setattr(S, "distance_checks", checks)
    monkeypatch.setattr(S, "check_policy_midpoint", e.prop("policy-midpoint"))
    monkeypatch.setattr(S, "check_policy_symmetry", e.prop("policy-symmetry"))
    monkeypatch.setattr(S, "check_policy_success", success)
    return e


class Pol:
    source = "runs/pol"


def test_check_rejects_bad_examples_and_seed(env):
    m = finsler.Euclidean()
    for bad in (True, 0, -3, 2.0, "5"):
        with pytest.raises(InputError) as err:
            S.check(m, examples=bad)
        assert str(err.value) == f"examples must be a positive integer, got {bad!r}"
    for bad in (False, -1, 1.0, "0"):
        with pytest.raises(InputError) as err:
            S.check(m, seed=bad)
        assert str(err.value) == f"seed must be a non-negative integer, got {bad!r}"
    assert env.calls == []
    S.check(m, examples=1, seed=0)  # the edges are accepted


def test_check_all_passing_runs_everything_in_order(env):
    m = finsler.Euclidean()
    seen = []

    def cf(x, y):
        return x

    def cg(x, y, t):
        return t

    oracle = object()
    rep = S.check(m, policy=Pol(), examples=150, seed=7, convex_shrink=0.6, oracle=oracle,
                  closed_form=cf, closed_form_geodesic=cg, midpoint_rtol=0.11,
                  symmetry_rtol=0.12, min_success=0.5, max_length_ratio=1.7,
                  progress=seen.append)
    names = [c[0] for c in env.calls]
    assert names == [*F_PROPS, "distance_checks", *D_PROPS, *P_PROPS[:3]]
    assert [r.name for r in rep.results] == [*F_PROPS, *D_PROPS, *P_PROPS]
    assert seen == rep.results
    assert all(r.status == PASSED for r in rep.results)
    kw = {"examples": 150, "seed": 7}
    calls = {c[0]: c for c in env.calls}
    for n in ("domain", "finite-positive", "homogeneity", "reversibility", "lowered-forms",
              "smoothness"):
        assert calls[n][1:] == ((m,), kw)
    for n in ("subadditivity", "strong-convexity"):
        assert calls[n][1:] == ((m,), {"convex_shrink": 0.6, **kw})
    assert env.regions == [(m, 0.6, 7)]
    assert env.made == [(m, oracle, 7, 0.75)]
    suite = calls["distance_checks"][1][0]
    assert calls["distance_checks"][1][1:] == (5, cf, cg)  # 150 // 30
    assert isinstance(suite, FakeSuite)
    pol = calls["policy-midpoint"][1][0]
    assert calls["policy-midpoint"][1:] == ((pol, m), {"examples": 5, "seed": 7,
                                                       "rtol": 0.11, "shrink": 0.75})
    assert calls["policy-symmetry"][1:] == ((pol, m), {"examples": 150, "seed": 7,
                                                       "rtol": 0.12})
    assert calls["policy-success"][1:] == ((pol, m), {"pairs": 15, "seed": 7,
                                                      "min_success": 0.5,
                                                      "max_length_ratio": 1.7})
    for r in rep.results:
        assert r.needs == S.NEEDS[r.name]
    assert (rep.metric, rep.params, rep.seed, rep.examples, rep.policy) == (
        "euclidean", {"n": 2}, 7, 150, "runs/pol")
    assert 0.0 < rep.seconds < 60.0 and rep.ok


def test_check_defaults_and_policy_name(env):
    m = finsler.Euclidean()

    class NoSource:
        pass

    class EmptySource:
        source = ""

    rep = S.check(m)
    assert [r.name for r in rep.results] == [*F_PROPS, *D_PROPS] and rep.policy is None
    calls = {c[0]: c for c in env.calls}
    assert calls["domain"][1:] == ((m,), {"examples": 100, "seed": 0})
    assert calls["subadditivity"][2] == {"convex_shrink": None, "examples": 100, "seed": 0}
    assert env.regions == [(m, None, 0)] and env.made == [(m, None, 0, 0.75)]
    assert calls["distance_checks"][1][1:] == (3, None, None)
    env.calls.clear()
    rep = S.check(m, policy=NoSource(), examples=20, solved_examples=6, policy_pairs=9)
    calls = {c[0]: c for c in env.calls}
    assert rep.policy == "NoSource"
    assert calls["distance_checks"][1][1] == 6
    assert calls["policy-midpoint"][2]["examples"] == 6
    assert calls["policy-success"][2]["pairs"] == 9
    env.calls.clear()
    rep = S.check(m, policy=EmptySource(), examples=20)
    calls = {c[0]: c for c in env.calls}
    assert rep.policy == "EmptySource"
    assert calls["policy-success"][2]["pairs"] == 4  # max(4, 20 // 10)
    env.calls.clear()
    S.check(m, policy=EmptySource(), examples=57)
    assert {c[0]: c for c in env.calls}["policy-success"][2]["pairs"] == 5


def _statuses(rep):
    return {r.name: r.status for r in rep.results}


def test_check_homogeneity_failure_blocks_what_needs_it(env):
    m = finsler.Euclidean()
    env.status["homogeneity"] = FAILED
    rep = S.check(m, policy=Pol())
    st = _statuses(rep)
    assert st["homogeneity"] == FAILED
    assert st["subadditivity"] == st["strong-convexity"] == NOT_RUN
    for n in ("domain", "finite-positive", "reversibility", "lowered-forms", "smoothness"):
        assert st[n] == PASSED
    for n in D_PROPS + P_PROPS:
        assert st[n] == NOT_RUN
    ran = [c[0] for c in env.calls]
    assert ran == ["domain", "finite-positive", "homogeneity", "reversibility",
                   "lowered-forms", "smoothness", "distance_checks"]
    assert env.regions == [] and env.made[0][3] == 1.0  # blocked: the whole domain
    notes = {r.name: r.note for r in rep.results}
    one = ("needs homogeneity, which fails on euclidean: its verdict would mean nothing "
           "until that is fixed")
    assert notes["subadditivity"] == one and notes["distance-zero"] == one
    assert notes["policy-success"] == notes["policy-length-ratio"] == one
    by = {r.name: r for r in rep.results}
    assert by["subadditivity"].claim == "" and by["subadditivity"].needs == S.NEEDS[
        "subadditivity"]
    assert rep.failed == [by["homogeneity"]]


def test_check_domain_failure_is_the_root_of_everything(env):
    env.status["domain"] = FAILED
    rep = S.check(finsler.Euclidean(), policy=Pol())
    st = _statuses(rep)
    assert st["domain"] == FAILED and all(st[n] == NOT_RUN for n in st if n != "domain")
    one = ("needs domain, which fails on euclidean: its verdict would mean nothing until "
           "that is fixed")
    assert all(r.note == one for r in rep.results if r.name != "domain")
    assert [c[0] for c in env.calls] == ["domain", "distance_checks"]


def test_check_two_roots_deduplicated_and_plural(env):
    env.status["finite-positive"] = FAILED
    env.status["homogeneity"] = FAILED
    env.status["smoothness"] = FAILED
    rep = S.check(finsler.Euclidean())
    notes = {r.name: r.note for r in rep.results}
    assert notes["subadditivity"] == ("needs finite-positive, homogeneity, which fail on "
                                      "euclidean: its verdict would mean nothing until that "
                                      "is fixed")
    assert notes["reversibility"].startswith("needs finite-positive, which fails on")
    assert notes["distance-zero"].startswith("needs finite-positive, homogeneity, "
                                             "smoothness, which fail on euclidean")
    assert notes["distance-symmetry"] == notes["distance-zero"]
    assert _statuses(rep)["lowered-forms"] == PASSED


def test_check_only_reversibility_fails(env):
    env.status["reversibility"] = FAILED
    rep = S.check(finsler.Euclidean(), policy=Pol())
    st = _statuses(rep)
    assert st["distance-symmetry"] == st["policy-symmetry"] == NOT_RUN
    for n in ["distance-zero", "certificate", "midpoint-halves", "policy-midpoint",
              "policy-success", "policy-length-ratio"]:
        assert st[n] == PASSED
    # the other distance properties run on the convex region (found by this test: any
    # blocked distance property used to put them all on the whole domain)
    assert env.regions == [(finsler.Euclidean(), None, 0)] and env.made[0][3] == 0.75
    assert {r.name: r.note for r in rep.results}["distance-symmetry"].startswith(
        "needs reversibility, which fails")


def test_check_mapped_skipped_inconclusive_do_not_block(env):
    env.status.update({"domain": MAPPED, "homogeneity": SKIPPED,
                       "finite-positive": INCONCLUSIVE, "reversibility": NOT_RUN})
    rep = S.check(finsler.Euclidean())
    st = _statuses(rep)
    assert all(st[n] == PASSED for n in st if n not in env.status)
    assert st["reversibility"] == NOT_RUN


def test_check_a_distance_failure_blocks_nothing_after_it(env):
    env.status["distance-zero"] = FAILED
    env.status["certificate"] = FAILED
    rep = S.check(finsler.Euclidean(), policy=Pol())
    st = _statuses(rep)
    assert [n for n in st if st[n] != PASSED] == ["distance-zero", "certificate"]


# ----------------------------------------------------------------------------------------
# _quietly and _native_stderr
# ----------------------------------------------------------------------------------------
def test_quietly_summarises_warnings_on_every_result():
    long = "x" * 200

    def fn():
        for _ in range(3):
            warnings.warn("invalid   value\nencountered", RuntimeWarning, stacklevel=1)
        warnings.warn(long, UserWarning, stacklevel=1)
        return [PropertyResult("a", "c", PASSED), PropertyResult("b", "c", PASSED)]

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # none escapes
        out = S._quietly(fn)
    want = ["RuntimeWarning: invalid value encountered (3x)", "UserWarning: " + "x" * 120]
    assert [r.warnings for r in out] == [want, want]
    one = S._quietly(lambda: PropertyResult("a", "c", PASSED))
    assert one.warnings == [] and one.name == "a"


def test_quietly_collects_native_stderr(monkeypatch):
    with tempfile.TemporaryFile("w+") as err:
        monkeypatch.setattr("sys.stderr", err)
        fd = err.fileno()

        def fn():
            line = ('CasADi - 2026-11-28 02:19:37 WARNING("solver:nlp_g failed: NaN detected '
                    'for output g, at (row 66, col 0).")\n')
            os.write(fd, line.encode())
            os.write(fd, line.replace("66", "3").encode())
            os.write(fd, b"   \nplain   text\n")
            return PropertyResult("a", "c", PASSED)

        r = S._quietly(fn)
        os.write(fd, b"after\n")
        err.seek(0)
        left = err.read()
    assert r.warnings == [
        'stderr: CasADi WARNING("solver:nlp_g failed: NaN detected for output g, at (row ., '
        'col .).") (2x)', "stderr: plain text"]
    assert left == "after\n"  # restored, and nothing captured leaks


def test_native_stderr_without_a_descriptor(monkeypatch):
    class NoFd:
        def fileno(self):
            raise OSError("none")

    monkeypatch.setattr("sys.stderr", NoFd())
    with S._native_stderr() as lines:
        pass
    assert lines == []


def test_native_stderr_long_lines_cut_at_120():
    with tempfile.TemporaryFile("w+") as err:
        import sys

        saved = sys.stderr
        sys.stderr = err
        try:
            r = S._quietly(lambda: (os.write(err.fileno(), b"y" * 300 + b"\n"),
                                    PropertyResult("a", "c", PASSED))[1])
        finally:
            sys.stderr = saved
    assert r.warnings == ["stderr: " + "y" * 120]


def test_a_result_of_an_unlisted_name_needs_nothing(env, monkeypatch):
    def domain(*args, **kw):
        return [PropertyResult("domain", "c", PASSED), PropertyResult("extra", "c", PASSED)]

    monkeypatch.setattr(S, "check_domain", domain)
    rep = S.check(finsler.Euclidean())
    extra = next(r for r in rep.results if r.name == "extra")
    assert extra.needs == () and rep.results[0].needs == ()
