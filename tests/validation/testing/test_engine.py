"""Fast focused tests of validation/testing/engine.py (mutation testing of
the property suite). No metric, no solve: the search runs on integer and float strategies
whose failing examples are known exactly, and the result classes are compared with texts
written out by hand."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from hypothesis import strategies as st

from finsler import InputError
from validation.testing import CheckReport, PropertyFailure, PropertyResult, Verdict, search
from validation.testing import engine as E
from validation.testing.engine import (
    FAILED,
    INCONCLUSIVE,
    MAPPED,
    NOT_RUN,
    PASSED,
    SKIPPED,
    combine,
    fmt,
    jsonable,
    seeded,
)

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


def _search(check, strategy=None, examples=30, seed=1, **kw):
    strategy = st.integers(0, 1000) if strategy is None else strategy
    return search("p", "claim", strategy, check, lambda x: {"x": x}, examples=examples,
                  rng=seeded(seed, "t"), **kw)


# ----------------------------------------------------------------------------------------
# Verdict
# ----------------------------------------------------------------------------------------
def test_verdict_constructors():
    v = Verdict.unjudged("no convergence")
    assert (v.ok, v.inconclusive, v.mapped, v.note) == (True, True, False, "no convergence")
    assert v.lhs is None and v.rhs is None and v.relation == ""
    c = Verdict.compare(("a", 1.0), "<=", ("b", 2.0), np.bool_(False), note="n")
    assert c.ok is False and type(c.ok) is bool
    assert (c.lhs, c.relation, c.rhs, c.note) == (("a", 1.0), "<=", ("b", 2.0), "n")
    assert (c.mapped, c.inconclusive) == (False, False)
    d = Verdict.compare(("a", 1), "==", ("b", 1), 1)
    assert d.ok is True and d.note == ""
    plain = Verdict(True)
    assert (plain.mapped, plain.inconclusive, plain.note, plain.relation) == (
        False, False, "", "")


# ----------------------------------------------------------------------------------------
# PropertyResult
# ----------------------------------------------------------------------------------------
def test_property_result_status_words_and_defaults():
    r = PropertyResult("n", "c", "passed")
    assert r.status is PASSED
    assert (r.tried, r.passed, r.mapped, r.inconclusive, r.shrink_evaluations) == (0,) * 5
    assert r.counterexample is None and r.lhs is None and r.rhs is None
    assert (r.relation, r.note, r.shrink_limited, r.seconds, r.needs, r.warnings) == (
        "", "", False, 0.0, (), [])
    assert PropertyResult("n", "c", "not-run").status is NOT_RUN
    with pytest.raises(InputError) as err:
        PropertyResult("n", "c", "fine")
    assert str(err.value) == ("unknown property status 'fine'; choose one of passed, failed, "
                              "inconclusive, mapped, skipped, not-run")


def test_property_result_ok_and_converged():
    for status in (PASSED, INCONCLUSIVE, MAPPED, SKIPPED, NOT_RUN):
        r = PropertyResult("n", "c", status)
        assert r.ok
        r.assert_ok()
    bad = PropertyResult("n", "c", FAILED, seconds=2.5)
    assert not bad.ok and bad.wall_time == 2.5 and type(bad.wall_time) is float
    with pytest.raises(PropertyFailure) as err:
        bad.assert_ok()
    assert err.value.result is bad and str(err.value) == bad.describe()
    assert isinstance(err.value, AssertionError)
    assert PropertyResult("n", "c", MAPPED).converged
    assert not PropertyResult("n", "c", INCONCLUSIVE).converged


def test_sides_and_short_example():
    r = PropertyResult("n", "c", FAILED)
    assert r.sides() == "" and r.short_example() == "-"
    r.lhs = ("F(x, v)", 1.5)
    assert r.sides() == ""
    r.rhs = ("2", 2.0)
    assert r.sides() == "F(x, v) = 1.5   vs   2"
    r.relation = "<="
    r.rhs = ("F(x, w)", 0.123456789)
    assert r.sides() == "F(x, v) = 1.5   <=   F(x, w) = 0.123457"
    r.lhs = ("1.5", 1.5)  # a label that is its own value is printed once
    assert r.sides() == "1.5   <=   F(x, w) = 0.123457"
    r.lhs, r.rhs = None, ("a", 1)
    assert r.sides() == ""
    r.counterexample = {"x": [1.0, 2.0], "t": 0.5}
    assert r.short_example() == "x=(1, 2) t=0.5"
    r.counterexample = {"x": list(range(30))}
    text = " ".join(["x=(" + ", ".join(str(i) for i in range(30)) + ")"])
    assert r.short_example() == text[:57] + "..."
    assert len(r.short_example(20)) == 20 and r.short_example(20).endswith("...")
    exact = "x=" + "(0, 1, 2)"
    r.counterexample = {"x": [0, 1, 2]}
    assert r.short_example(len(exact)) == exact
    r.counterexample = {}
    assert r.short_example() == "-"


def test_describe_lines():
    r = PropertyResult("homogeneity", "F(x, t v) = t F(x, v)", FAILED, tried=7, passed=6)
    assert r.describe() == ("FAILED homogeneity: F(x, t v) = t F(x, v)\n"
                            "  examples tried 7, passed 6")
    r.mapped, r.inconclusive = 2, 3
    r.counterexample = {"t": 0.1234567890123456}
    r.lhs, r.rhs, r.relation = ("a", 1.0), ("b", 2.0), "=="
    r.note = "the note"
    r.warnings = ["w1 (2x)", "w2"]
    assert r.describe() == (
        "FAILED homogeneity: F(x, t v) = t F(x, v)\n"
        "  examples tried 7, passed 6, in the mapped region 2, not judged (inconclusive) 3\n"
        "  counterexample (not shrunk):\n"
        "    t = 0.123456789012\n"
        "  a = 1   ==   b = 2\n"
        "  the note\n"
        "  warnings while checking: w1 (2x); w2")
    r.shrink_evaluations = 5
    assert "  counterexample (shrunk in 5 evaluations):" in r.describe()
    r.shrink_limited = True
    assert ("  counterexample (shrunk in 5 evaluations, shrink budget reached):"
            in r.describe())
    assert PropertyResult("p", "c", "passed").describe().startswith("PASSED p: c")


def test_property_result_to_dict():
    r = PropertyResult("p", "c", MAPPED, tried=3, passed=1, mapped=2, inconclusive=0,
                       counterexample={"x": np.array([1.0, math.inf])},
                       lhs=("l", np.float64(1.0)), rhs=("r", math.nan), relation="<=",
                       note="n", shrink_evaluations=4, shrink_limited=True,
                       seconds=1.23456, needs=("domain",), warnings=["w"])
    d = r.to_dict()
    assert d == {"name": "p", "claim": "c", "status": "mapped", "tried": 3, "passed": 1,
                 "mapped": 2, "counterexample": {"x": [1.0, "inf"]},
                 "lhs": {"label": "l", "value": 1.0}, "relation": "<=",
                 "rhs": {"label": "r", "value": "nan"}, "note": "n", "inconclusive": 0,
                 "needs": ["domain"], "warnings": ["w"], "shrink_evaluations": 4,
                 "shrink_limited": True, "seconds": 1.235, "converged": True}
    assert type(d["needs"]) is list and type(d["warnings"]) is list
    assert PropertyResult("p", "c", FAILED).to_dict()["lhs"] is None
    assert PropertyResult("p", "c", FAILED).to_dict()["rhs"] is None
    assert PropertyResult("p", "c", FAILED).to_dict()["converged"] is False


# ----------------------------------------------------------------------------------------
# CheckReport
# ----------------------------------------------------------------------------------------
def _report(*statuses, **kw):
    results = [PropertyResult(f"p{i}", "c", s, tried=i, passed=i,
                              note=("why" if s in (SKIPPED, NOT_RUN) else ""))
               for i, s in enumerate(statuses)]
    return CheckReport("m", {"a": 1}, 3, 10, results, **kw)


def test_check_report_outcomes():
    ok = _report(PASSED, SKIPPED, MAPPED)
    assert ok.ok and ok.status is PASSED and ok.exit_code() == 0 and ok.exit_code(True) == 0
    assert ok.summary() == "all properties hold" and ok.converged
    inc = _report(PASSED, INCONCLUSIVE, INCONCLUSIVE)
    assert inc.ok and inc.status is INCONCLUSIVE
    assert inc.exit_code() == 0 and inc.exit_code(strict=True) == 1
    assert [r.name for r in inc.inconclusive] == ["p1", "p2"]
    assert inc.summary() == "no property failed; inconclusive: p1, p2"
    assert not inc.converged
    bad = _report(PASSED, FAILED, NOT_RUN, FAILED, INCONCLUSIVE, NOT_RUN, seconds=4.0)
    assert not bad.ok and bad.status is FAILED
    assert bad.exit_code() == 1 and bad.exit_code(strict=True) == 1
    assert [r.name for r in bad.failed] == ["p1", "p3"]
    assert [r.name for r in bad.not_run] == ["p2", "p5"]
    assert bad.summary() == ("FAILED: p1, p3; 2 not run (they need a property that failed); "
                             "inconclusive: p4")
    assert _report(FAILED).summary() == "FAILED: p0"
    assert bad.wall_time == 4.0 and type(bad.wall_time) is float
    assert type(bad.exit_code()) is int
    assert _report().ok and _report().status is PASSED


def test_check_report_table():
    rep = _report(PASSED, FAILED, SKIPPED, NOT_RUN, SKIPPED)
    rep.results[1].counterexample = {"x": 1.0}
    rep.results[2].note = "other reason"
    rep.results[0].warnings = ["divide by zero (3x)"]
    rep.results[1].warnings = ["shown in the details"]
    assert rep.table() == "\n".join([
        "property  tried  passed  result   counterexample",
        "--------  -----  ------  -------  --------------",
        "p0        0      0       passed   -",
        "p1        1      1       failed   x=1",
        "p2        2      2       skipped  -",
        "p3        3      3       not-run  -",
        "p4        4      4       skipped  -",
        "",
        rep.results[1].describe(),
        "",
        "not run:",
        "  p3: why",
        "",
        "skipped:",
        "  p2: other reason",
        "  p4: why",
        "",
        "warnings caught while checking (not printed as they came):",
        "  p0: divide by zero (3x)"])
    plain = _report(PASSED, INCONCLUSIVE, MAPPED)
    assert plain.table().split("\n\n")[1:] == [plain.results[1].describe() + "\n"
                                               + plain.results[2].describe()]
    assert "\n\n" not in _report(PASSED).table()


def test_check_report_to_dict():
    rep = _report(PASSED, FAILED, INCONCLUSIVE, NOT_RUN, seconds=1.23456, policy="pol")
    d = rep.to_dict()
    assert d == {"metric": "m", "params": {"a": 1}, "policy": "pol", "seed": 3,
                 "examples": 10, "ok": False, "failed": ["p1"], "inconclusive": ["p2"],
                 "not_run": ["p3"], "summary": rep.summary(), "seconds": 1.235,
                 "status": "failed", "converged": False,
                 "properties": [r.to_dict() for r in rep.results]}
    assert _report(PASSED).to_dict()["converged"] is True


# ----------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------
def test_fmt_and_jsonable():
    assert fmt(0.1234567891) == "0.123457"
    assert fmt(np.float64(2.0) / 3, 3) == "0.667"
    assert fmt([1.0, 0.5]) == "(1, 0.5)"
    assert fmt(np.array([[1.0, 2.0], [3.0, 4.0]])) == "(1, 2, 3, 4)"
    assert fmt((1.23456789, 2), 2) == "(1.2, 2)"
    assert fmt(7) == "7" and fmt("s") == "s"
    assert jsonable({"a": np.array([1.0, -math.inf])}) == {"a": [1.0, "-inf"]}


def test_seeded_and_key():
    a, b = seeded(3, "x"), seeded(3, "x")
    assert a.random() == b.random()
    assert seeded(3, "x").random() == random.Random("3/x").random()
    assert seeded(np.int64(3), "x").random() == random.Random("3/x").random()
    assert seeded(3, "y").random() != seeded(3, "x").random()
    k = E._key
    x = np.array([1.0, 2.0])
    assert k(x) == ("a", (2,), "<f8", x.tobytes())
    assert k([x, 1]) == (k(x), 1) and k((0.5,)) == (("f", (0.5).hex()),)
    assert k(0.1) == ("f", (0.1).hex()) and k(3) == 3
    assert k(np.array([1.0, 2.0], np.float32)) != k(x)
    assert k(np.zeros((2, 1))) != k(np.zeros((1, 2)))
    assert k(0.0) != k(-0.0)


def test_judge():
    assert E._judge(lambda e: Verdict(e > 0), 1).ok
    v = E._judge(lambda e: 1 / e, 0)
    assert v == Verdict(False, note="raised ZeroDivisionError: division by zero")

    def long(e):
        raise ValueError("a   b\n" + "c" * 400)

    v = E._judge(long, 0)
    assert v.note == "raised ValueError: " + ("a b " + "c" * 400)[:300]
    assert not v.ok
    with pytest.raises(TypeError, match="must return a Verdict, got bool"):
        E._judge(lambda e: True, 0)
    for err in (KeyboardInterrupt, MemoryError):
        def boom(e, err=err):
            raise err()
        with pytest.raises(err):
            E._judge(boom, 0)


def test_without_local_constants_restores():
    from hypothesis.internal.conjecture import providers
    before = providers._get_local_constants
    with E._without_local_constants():
        inside = providers._get_local_constants
        assert inside is not before
        assert inside() == providers.Constants()
    assert providers._get_local_constants is before


# ----------------------------------------------------------------------------------------
# search
# ----------------------------------------------------------------------------------------
def test_search_passes_and_counts():
    seen = []

    def check(x):
        seen.append(x)
        return Verdict(True)

    r = _search(check, examples=25)
    assert r.status is PASSED and r.tried == r.passed == len(set(seen)) >= 20
    assert r.tried <= 25 and r.counterexample is None and r.note == ""
    assert r.seconds > 0 and r.shrink_evaluations == 0 and not r.shrink_limited
    assert (r.name, r.claim) == ("p", "claim")


def test_search_failure_shrinks_to_the_boundary():
    r = _search(lambda x: Verdict.compare(("x", x), "<", ("limit", 100), x < 100, "n"),
                examples=200)
    assert r.status is FAILED and r.counterexample == {"x": 100}
    assert (r.lhs, r.relation, r.rhs, r.note) == (("x", 100), "<", ("limit", 100), "n")
    assert r.shrink_evaluations > 0 and not r.shrink_limited
    assert r.passed == r.tried - 1  # examples before the first failure held


def test_search_shrink_budget():
    calls = []

    def check(x):
        calls.append(x)
        return Verdict(x < 100)

    r = _search(check, examples=200, shrink_limit=2)
    assert r.status is FAILED and r.shrink_evaluations == 2 and r.shrink_limited
    assert r.counterexample["x"] >= 100 and len(calls) == r.tried + 2
    z = _search(lambda x: Verdict(x < 100), examples=200, shrink_limit=0)
    assert z.shrink_evaluations == 0 and z.shrink_limited


def test_search_counts_mapped_and_inconclusive():
    def check(x):
        if x % 3 == 0:
            return Verdict.unjudged("solve: max_iterations")
        if x % 3 == 1:
            return Verdict(True, mapped=True)
        return Verdict(True)

    r = _search(check, strategy=st.integers(0, 10**6), examples=40)
    assert r.status is INCONCLUSIVE
    assert r.tried == r.passed + r.mapped + r.inconclusive
    assert r.inconclusive >= 2 and r.mapped >= 1 and r.passed >= 1
    assert r.note == (f"{r.inconclusive} of {r.tried} examples could not be judged, no "
                      f"counterexample among the others: {r.inconclusive} x solve: "
                      "max_iterations")
    one = _search(lambda x: Verdict.unjudged("once") if x == 0 else Verdict(True),
                  strategy=st.just(0) | st.integers(1, 10**6), examples=20)
    if one.inconclusive == 1:
        assert one.note.endswith("among the others: once")
    m = _search(lambda x: Verdict(True, mapped=x % 2 == 0), strategy=st.integers(0, 10**6))
    assert m.status is MAPPED and m.mapped >= 1 and m.passed >= 1
    assert m.tried == m.passed + m.mapped and m.note == ""


def test_search_inconclusive_notes_grouped():
    r = _search(lambda x: Verdict.unjudged("a" if x % 2 else "b"),
                strategy=st.integers(0, 10**6), examples=30)
    counts = {"a": 0, "b": 0}
    assert r.status is INCONCLUSIVE and r.passed == 0
    head, why = r.note.split(": ", 1)
    assert head == (f"{r.tried} of {r.tried} examples could not be judged, no "
                    "counterexample among the others")
    for part in why.split("; "):
        n, _, note = part.partition(" x ")
        counts[note or n] += int(n) if note else 1
    assert counts["a"] + counts["b"] == r.tried == r.inconclusive


def test_search_skips_without_examples():
    r = _search(lambda x: Verdict(True), strategy=st.integers().filter(lambda x: False),
                examples=5)
    assert r.status is SKIPPED and r.note == "no valid example could be generated"
    assert r.tried == 0


def test_search_exception_is_a_counterexample_and_input_checked():
    r = _search(lambda x: Verdict(1 / (x - 7) != 0), strategy=st.integers(0, 20),
                examples=100)
    assert r.status is FAILED and r.counterexample == {"x": 7}
    assert r.note == "raised ZeroDivisionError: division by zero"
    for bad in (0, -1, 2.0, True, "3"):
        with pytest.raises(InputError, match=f"examples must be a positive integer, got "
                           f"{bad!r}".replace("(", r"\(")):
            _search(lambda x: Verdict(True), examples=bad)
    assert _search(lambda x: Verdict(True), examples=np.int64(3)).tried <= 3
    assert _search(lambda x: Verdict(True), examples=1).tried == 1


def test_search_is_deterministic_and_caches():
    calls = []

    def check(x):
        calls.append(x)
        return Verdict(x < 500)

    a = _search(check, examples=50, seed=4)
    n = len(calls)
    assert n == len(set(calls))  # each example judged once
    b = _search(check, examples=50, seed=4)
    assert a.to_dict() | {"seconds": 0} == b.to_dict() | {"seconds": 0}
    assert calls[:n] == calls[n:]


# ----------------------------------------------------------------------------------------
# combine
# ----------------------------------------------------------------------------------------
def test_combine():
    p = PropertyResult("a", "x", PASSED, tried=3, passed=3, seconds=1.0, note="one")
    m = PropertyResult("a", "x", MAPPED, tried=2, passed=1, mapped=1, seconds=0.5,
                       shrink_evaluations=1)
    f = PropertyResult("a", "x", FAILED, tried=4, passed=3, counterexample={"x": 1},
                       lhs=("l", 1), rhs=("r", 2), relation="<=", shrink_evaluations=2,
                       shrink_limited=True, note="two", inconclusive=1)
    out = combine("n", "c", [p, m, f])
    assert (out.name, out.claim, out.status) == ("n", "c", FAILED)
    assert (out.tried, out.passed, out.mapped, out.inconclusive) == (9, 7, 1, 1)
    assert out.counterexample == {"x": 1} and out.lhs == ("l", 1) and out.rhs == ("r", 2)
    assert out.relation == "<=" and out.shrink_evaluations == 3 and out.shrink_limited
    assert out.seconds == 1.5 and out.note == "one two"
    assert combine("n", "c", [p, m]).status is MAPPED
    assert not combine("n", "c", [p, m]).shrink_limited
    i = PropertyResult("a", "x", INCONCLUSIVE)
    assert combine("n", "c", [m, i, p]).status is INCONCLUSIVE
    s = PropertyResult("a", "x", SKIPPED)
    r = PropertyResult("a", "x", NOT_RUN)
    assert combine("n", "c", [r, s]).status is SKIPPED
    assert combine("n", "c", [s, p]).status is PASSED
    assert combine("n", "c", [r]).status is NOT_RUN
    assert E.ORDER == {FAILED: 0, INCONCLUSIVE: 1, MAPPED: 2, PASSED: 3, SKIPPED: 4,
                       NOT_RUN: 5}


# ----------------------------------------------------------------------------------------
# after the first mutation run (survivors of testing_engine)
# ----------------------------------------------------------------------------------------
def test_search_has_no_deadline():
    import time

    r = _search(lambda x: time.sleep(0.3) or Verdict(True), examples=1)
    assert r.status is PASSED and r.tried == 1 and 0.3 <= r.seconds < 60


def test_search_uses_its_random_source():
    def drawn(seed):
        seen = []
        _search(lambda x: seen.append(x) or Verdict(True), strategy=st.integers(0, 10**9),
                examples=10, seed=seed)
        return seen

    assert drawn(3) == drawn(3) and drawn(3) != drawn(4)


def test_search_counts_twice_seen_notes_and_one_example():
    r = _search(lambda x: Verdict.unjudged("two") if x < 2 else Verdict(True),
                strategy=st.integers(0, 2), examples=50)
    assert r.tried == 3 and r.inconclusive == 2 and r.passed == 1
    assert r.note.endswith("among the others: 2 x two")
    one = _search(lambda x: Verdict(True), examples=1)
    assert one.status is PASSED and one.tried == one.passed == 1 and one.note == ""
    assert 0 <= one.seconds < 60


def test_check_report_lists_joined():
    rep = _report(FAILED, FAILED, FAILED, SKIPPED, SKIPPED)
    assert rep.summary() == "FAILED: p0, p1, p2"
    rep.results[0].warnings = ["a", "b"]
    rep.results[3].warnings = ["c (2x)", "d"]
    text = rep.table()
    assert "skipped:\n  p3, p4: why" in text
    assert text.endswith("warnings caught while checking (not printed as they came):\n"
                         "  p3: c (2x); d")
    assert "warnings while checking: a; b" in text
