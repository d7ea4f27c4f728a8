"""Fast focused tests of validation/testing/policy.py (mutation testing of
the property suite). No CasADi, no solve: a Euclidean metric in numpy (exact distances are
|y - x|, exact geodesics straight lines) and a stand-in ``solvers`` module that solves it
in closed form, with statuses set by the test; policies wrong in one known way (a midpoint
pushed along or across the pair by a set fraction) whose midpoint errors, symmetry gaps,
success rates and length ratios are worked out by hand."""

from __future__ import annotations

import math
import sys
import types
from dataclasses import dataclass, field

import numpy as np
import pytest

from finsler import DEFAULT_EVAL_SEED, VALIDATION_SEED, Box, Disk, InputError, Task, sample_pairs
from validation.testing import policy as P
from validation.testing.engine import FAILED, INCONCLUSIVE, MAPPED, PASSED, SKIPPED

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


class Flat:
    """Euclidean by duck typing: C(x, y) = |y - x|."""

    def __init__(self, domain=None, reversible=True, depth=2, eps=0.3, name="flat"):
        self.domain = domain if domain is not None else Box((-1.0, -1.0), (1.0, 1.0))
        self.dim = self.domain.dim
        self.reversible = reversible
        self.task = Task(depth, eps)
        self.name = name

    def cost(self, x, y, check=True):
        assert check is False
        return np.linalg.norm(np.asarray(y) - np.asarray(x), axis=-1)

    def segment_length(self, a, b, check=True):
        assert check is False
        return np.linalg.norm(np.asarray(b) - np.asarray(a), axis=-1)

    def path_costs(self, paths, check=True):
        assert check is False and paths.dtype == np.float64  # as a lowered function needs
        return np.linalg.norm(np.diff(paths, axis=1), axis=-1)


@dataclass
class Status:
    label: str


@dataclass
class Res:
    points: np.ndarray
    length: float
    converged: bool
    status: Status
    segments: int
    nonconvex_points: int = 0


@dataclass
class FakeSolvers:
    """Closed-form Euclidean solves; ``whole`` / ``halves`` / ``batch`` decide statuses."""

    calls: list = field(default_factory=list)
    batch_calls: list = field(default_factory=list)
    unconverged: set = field(default_factory=set)  # "whole", "half"
    nonconvex: bool = False
    zero_length: bool = False
    batch_converged: object = None  # None: all; else a list of bools
    pending: int = 0  # halves still to come after a whole

    length_zero_rows: tuple = ()

    def solve_geodesic(self, m, a, b, n):
        assert isinstance(m, Flat)
        a, b = np.asarray(a, float), np.asarray(b, float)
        if self.pending:
            kind, self.pending = "half", self.pending - 1
        else:
            kind, self.pending = "whole", (0 if self.nonconvex else 2)
        self.calls.append((a.copy(), b.copy(), n))
        pts = a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a)
        ok = kind not in self.unconverged
        length = 0.0 if self.zero_length else float(np.linalg.norm(b - a))
        return Res(pts, length, ok, Status("converged" if ok else "max_iterations"), n,
                   1 if (self.nonconvex and kind == "whole") else 0)

    def solve_batch(self, m, arr, n, workers=None, progress=None):
        assert isinstance(m, Flat)
        self.batch_calls.append((arr.copy(), n, workers, progress))
        conv = self.batch_converged or [True] * len(arr)
        out = []
        for i, ((a, b), ok) in enumerate(zip(arr, conv, strict=True)):
            out.append(Res(a + np.linspace(0, 1, n + 1)[:, None] * (b - a),
                           0.0 if i in self.length_zero_rows else float(np.linalg.norm(b - a)),
                           ok,
                           Status("converged" if ok else "infeasible"), n))
        return out


@pytest.fixture()
def solv(monkeypatch):
    fake = FakeSolvers()
    mod = types.ModuleType("solvers")
    mod.solve_geodesic = fake.solve_geodesic
    mod.solve_batch = fake.solve_batch
    monkeypatch.setitem(sys.modules, "solvers", mod)
    return fake


def _perp(d):
    return np.array([-d[1], d[0]])


class Shifted:
    """Midpoint x + a (y - x) + b |y - x| perp; paths through it, straight halves."""

    def __init__(self, metric, along=0.5, across=0.0, depth=None, eps=None):
        self.metric, self.a, self.b = metric, along, across
        if depth is not None:
            self.depth = depth
        if eps is not None:
            self.eps = eps

    def midpoint(self, x, y):
        x, y = np.asarray(x, float), np.asarray(y, float)
        d = y - x
        return x + self.a * d + self.b * np.stack([-d[:, 1], d[:, 0]], 1)

    def generate(self, x, y):
        m = self.midpoint(x, y)
        n = 2 ** getattr(self, "depth", self.metric.task.depth)
        h = n // 2
        t = np.linspace(0.0, 1.0, h + 1)[None, :, None]
        first = x[:, None] + t * (m - x)[:, None]
        second = m[:, None] + t * (y - m)[:, None]
        return np.concatenate([first, second[:, 1:]], axis=1)


def _note(x, y, pol, n, rtol):
    """The failure note recomputed from the counterexample."""
    m = pol.midpoint(x[None], y[None])[0]
    d = np.linalg.norm(y - x)
    err = max(abs(np.linalg.norm(m - x) - d / 2), abs(np.linalg.norm(y - m) - d / 2)) / d
    off = np.linalg.norm(m - (x + y) / 2) / d
    return (f"midpoint error {err:.3g} (allowed {rtol:g}), exact discrete lengths at {n} "
            f"segments; predicted m = {tuple(round(float(v), 6) for v in m)}, exact midpoint "
            f"{tuple(round(float(v), 6) for v in (x + y) / 2)}, offset C/d {off:.3g}")


# ----------------------------------------------------------------------------------------
# constants, helpers
# ----------------------------------------------------------------------------------------
def test_defaults():
    assert (P.MIDPOINT_RTOL, P.SYMMETRY_RTOL, P.MIN_SUCCESS, P.MAX_LENGTH_RATIO) == (
        0.25, 0.25, 0.8, 1.3)
    assert P._vec(np.array([[1, 2]])) == [1.0, 2.0]
    assert all(type(v) is float for v in P._vec(np.array([1, 2])))


def test_midpoints_shape_and_finiteness():
    m = Flat()

    class Bad:
        def __init__(self, out):
            self.out = out

        def midpoint(self, x, y):
            return self.out

    x = np.zeros((2, 2))
    got = P._midpoints(Bad([[1, 2], [3, 4]]), m, x, x)
    assert got.dtype == np.float64 and got.tolist() == [[1.0, 2.0], [3.0, 4.0]]
    np.testing.assert_array_equal(P._midpoints(Bad([1, 2, 3, 4]), m, x, x), [[1, 2], [3, 4]])
    with pytest.raises(InputError) as err:
        P._midpoints(Bad(np.zeros((3, 2))), m, x, x)
    assert str(err.value) == ("policy.midpoint returned shape (3, 2) or non-finite values, "
                              "expected (2, 2)")
    with pytest.raises(InputError):
        P._midpoints(Bad([[1.0, np.nan], [0.0, 0.0]]), m, x, x)
    with pytest.raises(InputError):
        P._midpoints(Bad([[1.0, np.inf], [0.0, 0.0]]), m, x, x)


def test_depth_and_no_midpoints():
    m = Flat(depth=3)
    assert P._depth(types.SimpleNamespace(), m) == 3
    assert P._depth(types.SimpleNamespace(depth=5), m) == 5
    assert P._no_midpoints(types.SimpleNamespace())
    assert P._no_midpoints(types.SimpleNamespace(midpoint=3))
    assert not P._no_midpoints(Shifted(m))


# ----------------------------------------------------------------------------------------
# policy-midpoint
# ----------------------------------------------------------------------------------------
def test_exact_midpoints_pass(solv):
    m = Flat()
    r = P.check_policy_midpoint(Shifted(m), m, examples=6, seed=1)
    assert r.status == PASSED and r.name == "policy-midpoint"
    assert r.claim == "|d(x, m) - d(x, y)/2| <= 0.25 d(x, y) for the predicted midpoint m"
    assert r.tried == r.passed >= 3
    # every pair drawn is at least 1e-3 of the domain's size (2) apart; whole at 4
    # segments, halves at 2, in that order
    wholes = solv.calls[0::3]
    assert all(np.linalg.norm(b - a) >= 2e-3 for a, b, _ in wholes)
    assert [c[2] for c in solv.calls] == [4, 2, 2] * (len(solv.calls) // 3)
    for i in range(0, len(solv.calls), 3):
        (x, y, _), (a1, b1, _), (a2, b2, _) = solv.calls[i:i + 3]
        mid = (x + y) / 2
        np.testing.assert_array_equal(a1, x)
        np.testing.assert_allclose(b1, mid, rtol=0, atol=1e-15)
        np.testing.assert_allclose(a2, mid, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(b2, y)


def test_min_separation_scales_with_the_domain(solv):
    m = Flat(domain=Box((0.0, 0.0), (400.0, 10.0)))
    P.check_policy_midpoint(Shifted(m), m, examples=8, seed=2)
    assert all(np.linalg.norm(b - a) >= 0.4 for a, b, _ in solv.calls[0::3])


@pytest.mark.parametrize(("along", "across", "side"), [(0.6, 0.3, "d(x, m)"),
                                                       (0.4, 0.3, "d(m, y)")])
def test_a_pushed_midpoint_fails_with_its_error(solv, along, across, side):
    """m = x + 0.6 (y - x) + 0.3 |y - x| perp: d(x, m) = sqrt(0.45) d = 0.6708 d, an error
    of 0.1708; d(m, y) = 0.5 d exactly. Mirrored (0.4): the error is on d(m, y)."""
    m = Flat()
    pol = Shifted(m, along, across)
    r = P.check_policy_midpoint(pol, m, examples=5, seed=3, rtol=0.15)
    assert r.status == FAILED
    x, y = np.array(r.counterexample["x"]), np.array(r.counterexample["y"])
    d = float(np.linalg.norm(y - x))
    assert r.lhs[0] == side and r.lhs[1] == pytest.approx(math.sqrt(0.45) * d, rel=1e-12)
    assert r.rhs == ("d(x, y) / 2", pytest.approx(0.5 * d, rel=1e-12)) and r.relation == "=="
    assert r.note == _note(x, y, pol, 4, 0.15)
    assert "midpoint error 0.171 (allowed 0.15)" in r.note and "offset C/d 0.316" in r.note
    ok = P.check_policy_midpoint(pol, m, examples=5, seed=3, rtol=0.18)
    assert ok.status == PASSED


def test_policy_depth_sets_the_segments(solv):
    m = Flat(depth=2)
    pol = Shifted(m, 0.6, 0.3, depth=3)
    r = P.check_policy_midpoint(pol, m, examples=3, seed=0, rtol=0.1)
    assert r.status == FAILED and "at 8 segments" in r.note
    assert {c[2] for c in solv.calls} == {8, 4}


def test_depth_one_halves_get_two_segments(solv):
    m = Flat(depth=1)
    P.check_policy_midpoint(Shifted(m), m, examples=3, seed=0)
    assert [c[2] for c in solv.calls[:3]] == [2, 2, 2]


def test_non_convex_geodesics_are_mapped(solv):
    solv.nonconvex = True
    m = Flat()
    r = P.check_policy_midpoint(Shifted(m, 0.9, 0.5), m, examples=4, seed=0, rtol=0.01)
    assert r.status == MAPPED and r.mapped == r.tried >= 3
    assert all(c[2] == 4 for c in solv.calls)  # the halves are not solved


@pytest.mark.parametrize(("which", "segments"), [("whole", 4), ("half", 2)])
def test_unconverged_solves_are_inconclusive(solv, which, segments):
    solv.unconverged = {which}
    m = Flat()
    r = P.check_policy_midpoint(Shifted(m, 0.9, 0.5), m, examples=4, seed=0, rtol=0.01)
    assert r.status == INCONCLUSIVE and r.inconclusive == r.tried
    assert (f"an exact solve did not converge (max_iterations, {segments} segments)"
            in r.note)


def test_zero_length_pairs_hold(solv):
    solv.zero_length = True
    m = Flat()
    r = P.check_policy_midpoint(Shifted(m, 0.9, 0.5), m, examples=4, seed=0, rtol=0.01)
    assert r.status == PASSED


def test_midpoint_skipped_and_raising(solv):
    m = Flat()
    r = P.check_policy_midpoint(types.SimpleNamespace(), m)
    assert r.name == "policy-midpoint"
    assert r.status == SKIPPED and r.note == "SimpleNamespace predicts no midpoints"
    assert r.claim == "|d(x, m) - d(x, y)/2| <= 0.25 d(x, y) for the predicted midpoint m"

    class Nan(Shifted):
        def midpoint(self, x, y):
            return np.full((len(x), 2), np.nan)

    r = P.check_policy_midpoint(Nan(m), m, examples=3)
    assert r.status == FAILED and r.note.startswith(
        "raised InputError: policy.midpoint returned shape (1, 2) or non-finite values")


def test_shrunk_region_and_seed(solv):
    m = Flat()
    r = P.check_policy_midpoint(Shifted(m), m, examples=6, seed=4, shrink=0.25)
    assert r.status == PASSED
    assert r.note == "Pairs drawn from the domain scaled by 0.25 about its centre."
    pts = np.array([p for c in solv.calls[0::3] for p in c[:2]])
    assert np.abs(pts).max() <= 0.25
    first = [c[0].tolist() for c in solv.calls[0::3]]
    solv.calls.clear()
    P.check_policy_midpoint(Shifted(m), m, examples=6, seed=4, shrink=0.25)
    assert [c[0].tolist() for c in solv.calls[0::3]] == first
    solv.calls.clear()
    r = P.check_policy_midpoint(Shifted(m), m, examples=6, seed=5)
    assert [c[0].tolist() for c in solv.calls[0::3]] != first and r.note == ""
    solv.calls.clear()
    P.check_policy_midpoint(Shifted(m), m, seed=4)
    assert len(solv.calls) // 3 >= 2  # default 3 examples (the first may repeat)
    assert len(solv.calls) // 3 <= 3


def test_shrink_limit_bounds_the_shrinking(solv):
    m = Flat()
    pol = Shifted(m, 0.6, 0.3)
    r = P.check_policy_midpoint(pol, m, examples=5, seed=3, rtol=0.15)
    assert r.status == FAILED and r.shrink_evaluations <= 4
    r0 = P.check_policy_midpoint(pol, m, examples=5, seed=3, rtol=0.15, shrink_limit=0)
    assert r0.shrink_evaluations == 0 and r0.shrink_limited


# ----------------------------------------------------------------------------------------
# policy-symmetry
# ----------------------------------------------------------------------------------------
def test_symmetry_skipped():
    r = P.check_policy_symmetry(Shifted(Flat()), Flat(reversible=False, name="oneway"))
    assert r.status == SKIPPED and r.note == "oneway is not reversible"
    assert r.claim == "L(pi(x, y), pi(y, x)) <= 0.25 L(x, y) on a reversible metric"
    assert r.name == "policy-symmetry"
    r = P.check_policy_symmetry(types.SimpleNamespace(), Flat())
    assert r.status == SKIPPED and r.note == "SimpleNamespace predicts no midpoints"
    assert r.name == "policy-symmetry"
    assert r.claim == "L(pi(x, y), pi(y, x)) <= 0.25 L(x, y) on a reversible metric"


def test_symmetry_of_a_biased_policy():
    """pi(x, y) = x + 0.6 (y - x), pi(y, x) = x + 0.4 (y - x): the gap is 0.2 L(x, y)."""
    m = Flat()
    pol = Shifted(m, 0.6)
    r = P.check_policy_symmetry(pol, m, examples=20, seed=2, rtol=0.15)
    assert r.status == FAILED and r.name == "policy-symmetry"
    x, y = np.array(r.counterexample["x"]), np.array(r.counterexample["y"])
    L = float(np.linalg.norm(y - x))
    assert r.lhs == ("L(pi(x, y), pi(y, x))", pytest.approx(0.2 * L, rel=1e-9))
    assert r.rhs == ("0.15 L(x, y)", pytest.approx(0.15 * L, rel=1e-12))
    assert r.relation == "<="
    a, b = x + 0.6 * (y - x), y + 0.6 * (x - y)
    assert r.note == (f"pi(x, y) = {tuple(round(float(v), 6) for v in a)}, "
                      f"pi(y, x) = {tuple(round(float(v), 6) for v in b)}")
    assert P.check_policy_symmetry(pol, m, examples=20, seed=2, rtol=0.21).status == PASSED
    exact = P.check_policy_symmetry(Shifted(m), m, examples=20, seed=2)
    assert exact.status == PASSED and exact.tried == exact.passed >= 15
    many = P.check_policy_symmetry(Shifted(m), m)
    assert many.tried > 50  # default 100 examples


def test_symmetry_pairs_are_apart_and_seeded():
    m = Flat()
    seen = []

    class Rec(Shifted):
        def midpoint(self, x, y):
            seen.append((np.array(x[0]), np.array(y[0])))
            return super().midpoint(x, y)

    P.check_policy_symmetry(Rec(m), m, examples=10, seed=1)
    assert all(np.linalg.norm(b - a) >= 2e-3 for a, b in seen)
    first = [a.tolist() for a, _ in seen]
    seen.clear()
    P.check_policy_symmetry(Rec(m), m, examples=10, seed=1)
    assert [a.tolist() for a, _ in seen] == first
    seen.clear()
    P.check_policy_symmetry(Rec(m), m, examples=10, seed=2)
    assert [a.tolist() for a, _ in seen] != first


# ----------------------------------------------------------------------------------------
# fresh pairs, policy-success and policy-length-ratio
# ----------------------------------------------------------------------------------------
def _fresh_seed(seed):
    return int(np.random.SeedSequence([seed, 24, 1]).generate_state(1)[0])


def test_fresh_pairs_seed(monkeypatch):
    m = Flat()
    s = _fresh_seed(7)
    np.testing.assert_array_equal(P.fresh_pairs(m, 5, 7), sample_pairs(m, 5, s))
    assert s not in (DEFAULT_EVAL_SEED, VALIDATION_SEED)
    monkeypatch.setattr(P, "DEFAULT_EVAL_SEED", s)
    np.testing.assert_array_equal(P.fresh_pairs(m, 5, 7), sample_pairs(m, 5, s + 1))
    monkeypatch.setattr(P, "DEFAULT_EVAL_SEED", DEFAULT_EVAL_SEED)
    monkeypatch.setattr(P, "VALIDATION_SEED", s)
    np.testing.assert_array_equal(P.fresh_pairs(m, 5, 7), sample_pairs(m, 5, s + 1))


def test_success_and_ratio_of_a_straight_policy(solv):
    """Straight paths at 4 segments: every cost is L / 4, success iff L <= 4 eps; the
    length ratio is exactly 1."""
    m = Flat(eps=0.3)
    pol = Shifted(m)
    s, r = P.check_policy_success(pol, m, pairs=12, seed=3, min_success=0.0)
    arr = sample_pairs(m, 12, _fresh_seed(3))
    L = np.linalg.norm(arr[:, 1] - arr[:, 0], axis=1)
    ok = L / 4 <= 0.3
    assert s.name == "policy-success" and s.status == PASSED
    assert s.claim == "success rate (every C <= eps 0.3) >= 0 on 12 fresh pairs"
    assert (s.tried, s.passed) == (12, int(ok.sum()))
    assert s.lhs == ("success rate", pytest.approx(ok.mean(), abs=1e-15))
    assert s.rhs == ("required", 0.0) and s.relation == ">=" and s.counterexample is None
    assert r.name == "policy-length-ratio" and r.status == PASSED
    assert r.claim == "mean length learned / exact (sum of C, 4 segments) <= 1.3 on 12 fresh pairs"
    assert (r.tried, r.passed) == (12, 12) and r.counterexample is None
    assert r.lhs == ("mean ratio", pytest.approx(1.0, abs=1e-12))
    assert r.rhs == ("allowed", 1.3) and r.relation == "<="
    assert r.note.endswith("; 0 exact solves did not converge")
    assert s.seconds == r.seconds > 0.0
    (call,) = solv.batch_calls
    np.testing.assert_array_equal(call[0], arr)
    assert call[1:] == (4, 1, False)
    # the required rate at its edge
    rate = ok.mean()
    s2, _ = P.check_policy_success(pol, m, pairs=12, seed=3, min_success=float(rate))
    assert s2.status == PASSED
    s3, _ = P.check_policy_success(pol, m, pairs=12, seed=3, min_success=float(rate) + 1e-9)
    assert s3.status == FAILED
    k = int(np.argmax(L))
    assert s3.counterexample == {"x": arr[k, 0].tolist(), "y": arr[k, 1].tolist()}
    assert s3.note == (f"the worst pair (shown; an aggregate is not shrunk) has a segment "
                       f"cost {L[k] / 4:.4g} against eps 0.3")


def test_success_eps_from_argument_policy_and_task(solv):
    m = Flat(eps=0.01)
    arr = sample_pairs(m, 10, _fresh_seed(0))
    worst = np.linalg.norm(arr[:, 1] - arr[:, 0], axis=1) / 4
    e = float(np.median(worst))
    want = float((worst <= e).mean())
    s, _ = P.check_policy_success(Shifted(m), m, eps=e)
    assert s.lhs[1] == pytest.approx(want) and f"eps {e:g}" in s.claim
    s, _ = P.check_policy_success(Shifted(m, eps=e), m)
    assert s.lhs[1] == pytest.approx(want)
    s, _ = P.check_policy_success(Shifted(m), m)
    assert s.lhs[1] == pytest.approx(float((worst <= 0.01).mean()))
    assert s.status == FAILED and s.rhs == ("required", 0.8)
    assert s.tried == 10  # default pairs


def test_length_ratio_of_a_detour(solv):
    """Midpoint pushed across by 0.5 |y - x|: each half is sqrt(0.5) |y - x| long, the
    ratio sqrt(2) = 1.414 on every pair."""
    m = Flat(eps=10.0)
    pol = Shifted(m, 0.5, 0.5)
    _, r = P.check_policy_success(pol, m, pairs=6, seed=1)
    assert r.status == FAILED and r.passed == 0 and r.tried == 6
    assert r.lhs == ("mean ratio", pytest.approx(math.sqrt(2), rel=1e-12))
    assert r.counterexample is not None
    assert r.note.startswith("the pair shown has the largest ratio 1.414 (an aggregate is not "
                             "shrunk)")
    _, ok = P.check_policy_success(pol, m, pairs=6, seed=1, max_length_ratio=1.42)
    assert ok.status == PASSED and ok.passed == 6


def test_length_ratio_worst_pair_and_unconverged(solv):
    """Pushed across by 0.5 |y - x| only when x0 < 0: ratio sqrt(2) there, 1 elsewhere."""
    m = Flat(eps=10.0)

    class Half(Shifted):
        def midpoint(self, x, y):
            out = super().midpoint(x, y)
            d = y - x
            push = 0.5 * np.stack([-d[:, 1], d[:, 0]], 1) * (x[:, :1] < 0)
            return out + push

    pol = Half(m)
    arr = sample_pairs(m, 8, _fresh_seed(2))
    conv = [True, False, True, True, True, True, False, True]
    solv.batch_converged = conv
    _, r = P.check_policy_success(pol, m, pairs=8, seed=2, max_length_ratio=1.2)
    ratio = np.where(arr[:, 0, 0] < 0, math.sqrt(2), 1.0)
    used = np.array(conv)
    assert r.tried == 6 and r.passed == int((ratio[used] <= 1.2).sum())
    assert r.lhs[1] == pytest.approx(ratio[used].mean(), rel=1e-12)
    assert r.note.endswith("; 2 exact solves did not converge")
    j = int(np.flatnonzero(used & (ratio > 1.1))[0])
    assert r.counterexample == {"x": arr[j, 0].tolist(), "y": arr[j, 1].tolist()}
    assert r.status == (FAILED if ratio[used].mean() > 1.2 else PASSED)


def test_length_ratio_inconclusive_when_nothing_converged(solv):
    m = Flat()
    solv.batch_converged = [False] * 4
    _, r = P.check_policy_success(Shifted(m), m, pairs=4)
    assert r.name == "policy-length-ratio"
    assert r.status == INCONCLUSIVE and (r.tried, r.inconclusive) == (4, 4)
    assert r.note == "no exact solve converged (4 segments, statuses ['infeasible'])"
    assert r.claim == "mean length learned / exact (sum of C, 4 segments) <= 1.3 on 4 fresh pairs"


def test_generate_shape_checked(solv):
    m = Flat()

    class Short(Shifted):
        def generate(self, x, y):
            return super().generate(x, y)[:, :-1]

    with pytest.raises(InputError) as err:
        P.check_policy_success(Short(m), m, pairs=3)
    assert str(err.value) == "policy.generate returned shape (3, 4, 2), expected (3, 5, 2)"
    deep = Shifted(m, depth=3)
    _, r = P.check_policy_success(deep, m, pairs=3)
    assert "8 segments" in r.claim and solv.batch_calls[-1][1] == 8
    with pytest.raises(InputError) as err:
        P.check_policy_success(Short(m, depth=3), m, pairs=3)
    assert str(err.value) == "policy.generate returned shape (3, 8, 2), expected (3, 9, 2)"
    solv.batch_converged = [False] * 3
    _, r = P.check_policy_success(deep, m, pairs=3)
    assert r.note == "no exact solve converged (8 segments, statuses ['infeasible'])"


def test_policy_properties_passes_everything(monkeypatch):
    calls = {}

    def rec(name, out):
        def f(*args, **kw):
            calls[name] = (args, kw)
            return out
        return f

    monkeypatch.setattr(P, "check_policy_midpoint", rec("mid", "M"))
    monkeypatch.setattr(P, "check_policy_symmetry", rec("sym", "S"))
    monkeypatch.setattr(P, "check_policy_success", rec("succ", ["A", "B"]))
    m, other = Flat(), Flat(domain=Disk())
    pol = Shifted(m)
    assert P.policy_properties(pol) == ["M", "S", "A", "B"]
    assert calls["mid"] == ((pol, m), {"examples": 3, "seed": 0, "rtol": 0.25, "shrink": 1.0})
    assert calls["sym"] == ((pol, m), {"examples": 100, "seed": 0, "rtol": 0.25})
    assert calls["succ"] == ((pol, m), {"pairs": 10, "seed": 0, "min_success": 0.8,
                                        "max_length_ratio": 1.3})
    P.policy_properties(pol, other, examples=7, solved_examples=2, pairs=5, seed=9,
                        shrink=0.5, midpoint_rtol=0.1, symmetry_rtol=0.2, min_success=0.3,
                        max_length_ratio=1.1)
    assert calls["mid"] == ((pol, other), {"examples": 2, "seed": 9, "rtol": 0.1,
                                           "shrink": 0.5})
    assert calls["sym"] == ((pol, other), {"examples": 7, "seed": 9, "rtol": 0.2})
    assert calls["succ"] == ((pol, other), {"pairs": 5, "seed": 9, "min_success": 0.3,
                                            "max_length_ratio": 1.1})


# ----------------------------------------------------------------------------------------
# second pass over the survivors of the first testing_policy run (93.2 %)
# ----------------------------------------------------------------------------------------
def _reference_examples(m, name, seed, examples):
    """The pairs the engine's search draws for a property (its strategy, the seeded stream
    named after the property), with a check that always holds."""
    from validation.testing.engine import Verdict, search, seeded

    seen = []

    def ok(pair):
        seen.append((pair[0].tolist(), pair[1].tolist()))
        return Verdict(True)

    search(name, "c", P._pair_strategy(m, 1.0), ok, lambda p: {}, examples=examples,
           rng=seeded(seed, name))
    return seen


def test_default_examples_seed_and_stream(solv):
    m = Flat()
    seen = []

    class Rec(Shifted):
        def midpoint(self, x, y):
            seen.append((x[0].tolist(), y[0].tolist()))
            return super().midpoint(x, y)

    P.check_policy_symmetry(Rec(m), m)
    want = _reference_examples(m, "policy-symmetry", 0, 100)
    assert seen[0::2] == want and len(want) > 50
    seen.clear()
    P.check_policy_midpoint(Rec(m), m)
    assert seen == _reference_examples(m, "policy-midpoint", 0, 3)
    seen.clear()
    P.check_policy_midpoint(Rec(m), m, seed=3, examples=5)
    assert seen == _reference_examples(m, "policy-midpoint", 3, 5)


def test_min_separation_is_a_thousandth_of_the_longest_side():
    """Box 1000 x 0.5: pairs closer than 1 are never judged (hypothesis draws many with
    the same first coordinate, 0.5 or less apart)."""
    m = Flat(domain=Box((0.0, 0.0), (1000.0, 0.5)))
    seen = []

    class Rec(Shifted):
        def midpoint(self, x, y):
            seen.append(np.linalg.norm(y[0] - x[0]))
            return super().midpoint(x, y)

    P.check_policy_symmetry(Rec(m), m, examples=60, seed=0)
    assert len(seen) > 40 and min(seen) >= 1.0


def test_a_pushed_midpoint_fails_on_short_pairs(solv):
    """All pairs of the box [0, 0.5]^2 are shorter than 1: still judged."""
    m = Flat(domain=Box((0.0, 0.0), (0.5, 0.5)))
    r = P.check_policy_midpoint(Shifted(m, 0.6, 0.3), m, examples=5, seed=3, rtol=0.15)
    assert r.status == FAILED


def test_success_and_ratio_limits_are_inclusive(solv):
    """eps equal to a pair's worst cost counts it a success; a length limit equal to the
    mean (and largest) ratio passes: both recomputed with the same float operations."""
    m = Flat()
    pol = Shifted(m, 0.5, 0.25)
    arr = sample_pairs(m, 6, _fresh_seed(4))
    paths = pol.generate(arr[:, 0], arr[:, 1])
    costs = m.path_costs(paths, check=False)
    worst = costs.max(axis=1)
    e = float(np.sort(worst)[2])
    s, _ = P.check_policy_success(pol, m, pairs=6, seed=4, eps=e)
    assert s.passed == 3
    ratio = np.array([costs[i].sum() / float(np.linalg.norm(arr[i, 1] - arr[i, 0]))
                      for i in range(6)])
    mean = float(np.nanmean(ratio))
    _, r = P.check_policy_success(pol, m, pairs=6, seed=4, max_length_ratio=mean)
    assert r.status == PASSED and r.lhs[1] == mean
    top = float(ratio.max())
    _, r = P.check_policy_success(pol, m, pairs=6, seed=4, max_length_ratio=top)
    assert r.passed == 6


def test_a_zero_length_exact_solve_is_left_out(solv):
    m = Flat(eps=10.0)
    solv.length_zero_rows = (1,)
    _, r = P.check_policy_success(Shifted(m), m, pairs=5, seed=0)
    assert r.tried == 4 and r.status == PASSED
    assert r.lhs[1] == pytest.approx(1.0, abs=1e-12)


def test_largest_ratio_pair_is_shown(solv):
    """Pushed across by |x0| |y - x| only when x0 < 0 (ratio 2 sqrt(1/4 + x0^2), largest
    at the most negative x0); a seed whose first pair is not pushed, so the pair shown is
    found by its ratio, not by its place."""
    m = Flat(eps=10.0)

    class Half(Shifted):
        def midpoint(self, x, y):
            out = super().midpoint(x, y)
            d = y - x
            push = np.abs(x[:, :1]) * (x[:, :1] < 0)
            return out + push * np.stack([-d[:, 1], d[:, 0]], 1)

    seed = next(s for s in range(50)
                if sample_pairs(m, 6, _fresh_seed(s))[0, 0, 0] >= 0
                and (sample_pairs(m, 6, _fresh_seed(s))[:, 0, 0] < 0).any())
    arr = sample_pairs(m, 6, _fresh_seed(seed))
    _, r = P.check_policy_success(Half(m), m, pairs=6, seed=seed, max_length_ratio=1.0)
    j = int(np.argmin(arr[:, 0, 0]))
    assert j != 0 and arr[j, 0, 0] < 0
    assert r.counterexample == {"x": arr[j, 0].tolist(), "y": arr[j, 1].tolist()}


def test_success_seconds_half_the_wall_time_each(solv):
    import time

    m = Flat()
    t0 = time.perf_counter()
    s, r = P.check_policy_success(Shifted(m), m, pairs=4)
    wall = time.perf_counter() - t0
    assert 0.0 < s.seconds == r.seconds <= 0.5 * wall


def test_generated_paths_reach_the_metric_as_float64(solv):
    m = Flat()

    class Ints(Shifted):
        def generate(self, x, y):
            return np.rint(super().generate(x, y)).astype(np.int64)

    s, _ = P.check_policy_success(Ints(m), m, pairs=3)
    assert s.tried == 3


def test_symmetry_claim_and_note_digits():
    """Both predicted midpoints shifted by (0.00123456789, 0): the gap is unchanged, the
    note shows each coordinate to 6 decimals."""
    m = Flat()

    class Off(Shifted):
        def midpoint(self, x, y):
            return super().midpoint(x, y) + np.array([1.23456789e-3, 0.0])

    pol = Off(m, 0.6)
    r = P.check_policy_symmetry(pol, m, examples=20, seed=2, rtol=0.15)
    assert r.status == FAILED
    assert r.claim == "L(pi(x, y), pi(y, x)) <= 0.15 L(x, y) on a reversible metric"
    x, y = np.array(r.counterexample["x"]), np.array(r.counterexample["y"])
    a = x + 0.6 * (y - x) + [1.23456789e-3, 0.0]
    b = y + 0.6 * (x - y) + [1.23456789e-3, 0.0]
    assert r.note == (f"pi(x, y) = ({round(float(a[0]), 6)}, {round(float(a[1]), 6)}), "
                      f"pi(y, x) = ({round(float(b[0]), 6)}, {round(float(b[1]), 6)})")
    ok = P.check_policy_symmetry(pol, m, examples=5, seed=2)
    assert ok.status == PASSED
    assert ok.claim == "L(pi(x, y), pi(y, x)) <= 0.25 L(x, y) on a reversible metric"
