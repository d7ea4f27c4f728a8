"""The split lower bound (issue 46, item 3): a conformal factor bounded part by part.

The parts sum to the factor; the bound never exceeds an exact distance (scaled Euclidean:
every part constant) nor, part by part, the part's length of the solver's own path (a
path of ``F``-length at most the upper bound: each part's bound must lie below its length
along it); double counting a part is caught by that check."""

from __future__ import annotations

import importlib
import itertools

import casadi as ca
import numpy as np
import pytest

import finsler
from finsler import Metric
from solvers import ConformalSpec
from solvers.certificates.conformal.split import certify_conformal_split, factor_parts

from tests.helpers.metrics.certify_panda_split import ScaledEuclidean

split_mod = importlib.import_module("solvers.certificates.conformal.split")
cc = importlib.import_module("solvers.certificates.conformal.certificate")
QUICK = ConformalSpec(max_boxes=6000, s_cells=8, r_cells=4)


def _part_lengths(m: Metric, pts: np.ndarray, group: bool = False
                  ) -> tuple[float, list[float]]:
    """The constant and each part's length along the polyline (fine midpoint rule);
    ``group``: the parts as the split bounds them by default (nested ones merged)."""
    const, parts = factor_parts(m)
    if group:
        parts = split_mod._grouped(parts, 4)
    t = (np.arange(200) + 0.5) / 200
    out = [0.0] * len(parts)
    for a, b in itertools.pairwise(pts):
        q = a + t[:, None] * (b - a)
        for k, (_, fn) in enumerate(parts):
            out[k] += float(np.sum(np.asarray(fn(q.T)).reshape(-1))) / 200 * float(
                np.linalg.norm(b - a))
    return const, out


def test_parts_sum_to_the_factor() -> None:
    m = finsler.get_metric("panda-pole")
    const, parts = factor_parts(m)
    assert const == pytest.approx(8.5) and len(parts) == 4
    assert [len(dep) for dep, _ in parts] == [2, 3, 4, 6]
    q = m.domain.sample(50, np.random.default_rng(2))
    total = const + sum(np.asarray(fn(q.T)).reshape(-1) for _, fn in parts)
    np.testing.assert_allclose(total * np.linalg.norm(np.ones(7)), m.F(q, np.ones((50, 7))),
                               rtol=1e-12)


def test_constant_parts_give_the_exact_distance() -> None:
    m = ScaledEuclidean()
    x, y = np.array([-0.5, 0.2, 0.1, -0.3]), np.array([0.4, -0.6, 0.3, 0.5])
    d = 3.5 * float(np.linalg.norm(y - x))
    r = certify_conformal_split(m, x, y, QUICK, path=np.stack([x, y]))
    assert r.constant == 3.5 and r.parts == []
    assert d * (1 - 1e-8) <= r.lower <= d <= r.upper * (1 + 1e-12)
    assert r.status.label == "certified" and r.converged and r.gap <= QUICK.target_gap


@pytest.fixture(scope="module", params=[False, True], ids=["parts", "grouped"])
def panda_split(request: pytest.FixtureRequest
                ) -> tuple[Metric, np.ndarray, np.ndarray, object, bool]:
    m = finsler.get_metric("panda-pole")
    x, y = finsler.sample_pairs(m, 2, 20261150)[1]
    spec = ConformalSpec(max_boxes=20000, s_cells=12, r_cells=6)
    return m, x, y, certify_conformal_split(m, x, y, spec, group=request.param), request.param


def test_panda_parts_below_the_solver_path(panda_split: tuple) -> None:
    m, _, _, r, group = panda_split
    const, lengths = _part_lengths(m, r.full.path, group)
    euclid = float(np.sum(np.linalg.norm(np.diff(r.full.path, axis=0), axis=1)))
    assert len(r.parts) == len(lengths) == len(r.shares) == (2 if group else 4)
    assert r.part_dims == ([4, 4] if group else [2, 3, 4, 4])
    assert 0.0 < sum(r.shares) <= const
    for part, length, c in zip(r.parts, lengths, r.shares, strict=True):
        assert 0.0 < part.lower <= (length + c * euclid) * (1 + 1e-6)
    assert r.split_lower <= const * euclid + sum(lengths) + 1e-9
    assert r.merged is not None and r.merged.active_dims == 4
    assert r.lower <= r.upper and r.lower >= max(r.full.lower, r.merged.lower)
    assert r.ratio == pytest.approx(r.lower / r.upper)
    # a gap of 1e-1 or more is not certified at the default target: the status says so
    assert r.gap == pytest.approx(1 - r.ratio)
    assert (r.status.label == "certified") == (r.gap <= ConformalSpec().target_gap)
    assert r.to_dict()["status"] == r.status.label


def test_double_counted_part_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    """A part counted twice (a wrong grouping): its bound exceeds its length along the
    solver's path, so the check above can fail."""
    m = finsler.get_metric("panda-pole")
    x, y = finsler.sample_pairs(m, 2, 20261150)[1]
    const, parts = factor_parts(m)
    doubled = (const, [(dep, ca.Function("twice", [q := ca.SX.sym("q", 7)], [2 * fn(q)]))
                       for dep, fn in parts])
    monkeypatch.setattr(split_mod, "factor_parts", lambda metric: doubled)
    r = certify_conformal_split(m, x, y, ConformalSpec(max_boxes=20000, s_cells=12,
                                                        r_cells=6), group=False)
    _, lengths = _part_lengths(m, r.full.path)
    euclid = float(np.sum(np.linalg.norm(np.diff(r.full.path, axis=0), axis=1)))
    assert any(p.lower > ln + c * euclid
               for p, ln, c in zip(r.parts, lengths, r.shares, strict=True))


def test_projected_enclosure_below_every_value() -> None:
    """The whole factor's enclosure over boxes in q1..q4 with q5, q6 over their whole range
    lies below the factor at random points of the boxes with any q5, q6 (and q7); with the
    projected coordinates held at one value it does not (the check can fail)."""
    m = finsler.get_metric("panda-pole")
    fn, active = cc._factor_function(m, True, None, ".test", (4, 5))
    assert active.tolist() == [True] * 4 + [False] * 3
    lo0, hi0 = (np.asarray(b, float) for b in m.domain.bounds())
    rng = np.random.default_rng(4)
    c = lo0[:4] + 0.05 + rng.uniform(size=(300, 4)) * (hi0 - lo0 - 0.1)[:4]
    lo, hi = c - 0.05, c + 0.05
    q = np.concatenate([lo + rng.uniform(size=lo.shape) * 0.1,
                        lo0 + rng.uniform(size=(300, 7)) * (hi0 - lo0)], axis=1)
    q = np.concatenate([q[:, :4], q[:, 8:]], axis=1)
    vals = np.asarray(m.F(q, np.eye(7)[np.zeros(300, int)]), float)
    good = cc._Projected(fn, active, (4, 5), lo0, hi0)
    assert np.all(good.enclose(lo, hi) <= vals)
    assert np.all(good.value(c) >= good.enclose(lo, hi))
    mid = 0.5 * (lo0 + hi0)
    cut = cc._Projected(fn, active, (4, 5), mid, mid)  # q5, q6 held at their middle
    assert np.any(cut.enclose(lo, hi) > vals)
