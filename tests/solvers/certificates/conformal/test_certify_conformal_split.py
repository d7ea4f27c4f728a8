"""The split bound behind the front door (issue 46, item 3): ``solvers.certify`` and
``geodesics certify`` give a conformal metric of dimension > 3 the best of the full run,
the factor split into its parts and the whole factor projected, as one result type
(:class:`SplitCertifyResult`, a :class:`ConformalCertifyResult`).

Soundness against a closed form that fits the parts form: on ``[-1, 1]**4`` with ``f = 1
+ q1**2 + q2**2 / 2 + (q3 q4)**2 / 5`` and a pair that moves along ``q1`` with ``q2 = q3 =
0``, every path pays at least ``int (1 + q1**2) |dq1|`` (the other parts are >= 0 and the
projection on ``q1`` is 1-Lipschitz) and the segment pays exactly that, so ``d = |b - a +
(b**3 - a**3) / 3|``. The bound must lie below it, and above the single bound of
:func:`certify_conformal` with the same total work; shares of the constant that sum above
it (a wrong split) push the bound over the exact distance, so the check can fail."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
from finsler.registry import unregister_metric
from solvers import CertifyStatus, ConformalSpec, certify
from solvers.certificates.conformal.certificate import ConformalCertifyResult, certify_conformal
from solvers.certificates.conformal.split import (
    SplitCertifyResult,
    certify_conformal_best,
    certify_conformal_split,
)
from validation.cli import app

from tests.helpers.metrics.certify_conformal_split import Valley

split_mod = importlib.import_module("solvers.certificates.conformal.split")
runner = CliRunner()
SPEC = ConformalSpec(max_boxes=12000, r_cells=4)


def _pairs() -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Pairs moving along q1 (q2 = q3 = 0, q4 anything) with their exact distance."""
    rng = np.random.default_rng(20261217)
    out = []
    for _ in range(3):
        a, b = np.sort(rng.uniform(-0.95, 0.95, 2))
        c = rng.uniform(-0.9, 0.9)
        out.append((np.array([a, 0.0, 0.0, c]), np.array([b, 0.0, 0.0, c]),
                    float(b - a + (b**3 - a**3) / 3.0)))
    return out


@pytest.fixture(scope="module")
def valley() -> list[tuple[float, SplitCertifyResult, ConformalCertifyResult]]:
    m = Valley()
    out = []
    for x, y, d in _pairs():
        path = np.linspace(x, y, 9)
        out.append((d, certify(m, x, y, SPEC, path=path),
                    certify_conformal(m, x, y, SPEC, path=path)))
    return out


def test_split_bound_below_the_closed_form(valley: list) -> None:
    for d, r, single in valley:
        assert isinstance(r, SplitCertifyResult) and isinstance(r, ConformalCertifyResult)
        assert r.lower <= d * (1 + 1e-12) <= r.upper * (1 + 1e-9)
        assert r.split_lower <= d * (1 + 1e-12)  # the parts' sum itself, not clamped
        assert r.lower >= single.lower  # >= the single bound with the same total work
        assert r.lower >= r.full.lower and r.lower >= r.trivial
        assert r.enclosures <= SPEC.max_boxes
        assert r.ratio == pytest.approx(r.lower / r.upper)
    # the split is what makes it tight here: the q1 part is bounded in one coordinate
    assert min(r.ratio for _, r, _ in valley) > 0.985
    assert all(r.lower > single.lower and r.bound_by == "split" for _, r, single in valley)


def test_parts_in_their_own_coordinates() -> None:
    """Each part is bounded in its own coordinates (q1 alone: 1-D; parts on disjoint
    coordinates are not grouped); the parts without length along the path (q2, q3 q4 at
    0) are left out with no share; the sum stays below the exact distance."""
    m = Valley()
    x, y, d = _pairs()[0]
    for group in (True, False):
        r = certify_conformal_split(m, x, y, SPEC, path=np.linspace(x, y, 9), group=group)
        assert r.part_dims == [1] and 1 - 1e-14 < r.constant < 1.0 and r.parts[0].active_dims == 1
        assert 0.0 < sum(r.shares) <= 1.0
        assert d * 0.985 < r.split_lower <= d * (1 + 1e-12)


def test_shares_above_the_constant_are_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    """Shares of the constant summing above it (a wrong split): the 'bound' exceeds the
    exact distance, or the part's region empties (an error), so the soundness test above
    can fail."""
    m = Valley()
    real = split_mod._shares
    x, y, d = _pairs()[0]
    for factor in (1.5, 2.0):
        monkeypatch.setattr(split_mod, "_shares",
                            lambda c, parts, path, k=factor: k * real(c, parts, path))
        try:
            r = certify_conformal_split(m, x, y, SPEC, path=np.linspace(x, y, 9))
        except RuntimeError as err:
            assert "no box of the region" in str(err)
        else:
            assert r.split_lower > d


def test_result_shape(valley: list) -> None:
    _, r, _ = valley[0]
    doc = r.to_dict()
    text = json.dumps(doc, allow_nan=False)
    assert doc["status"] == r.status.label and doc["bound_by"] in ("full", "split", "merged")
    assert doc["stopped_by"] == r.stopped_by.value and "path" not in doc
    assert doc["full"]["lower"] == r.full.lower and len(doc["parts"]) == len(r.parts)
    assert "largest of" in r.method and r.bound_by in r.method
    assert (r.status is CertifyStatus.CERTIFIED) == (r.gap <= SPEC.target_gap)
    assert json.loads(text)["enclosures"] == r.enclosures


def test_budget_shared() -> None:
    """``max_boxes`` is the work of all runs together."""
    m = Valley()
    x, y, _ = _pairs()[1]
    r = certify_conformal_best(m, x, y, SPEC, path=np.linspace(x, y, 9))
    budgets = [r.full.spec["max_boxes"], *r.spec["part_max_boxes"]]
    assert sum(budgets) <= SPEC.max_boxes and r.enclosures <= SPEC.max_boxes
    assert r.merged is None  # the factor depends on 4 coordinates: nothing to project


@pytest.fixture
def registered() -> object:
    finsler.register_metric(Valley)
    yield Valley
    unregister_metric(Valley.name)


def test_cli_prints_the_best_bound(registered: object) -> None:
    x, y, d = _pairs()[2]
    args = ["certify", "--metric", Valley.name, "--start", ",".join(map(str, x)),
            "--goal", ",".join(map(str, y)), "--max-boxes", "12000"]
    res = runner.invoke(app, [*args, "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["lower"] <= d <= out["upper"] * (1 + 1e-9)
    assert out["bound_by"] in ("full", "split", "merged")
    assert out["lower"] == max(out["full"]["lower"], min(out["split_lower"], out["upper"]))
    assert out["status"] in ("certified", "budget_reached")
    text = runner.invoke(app, args)
    assert text.exit_code == 0, text.output
    assert "bounds : full run" in text.stdout and "the largest" in text.stdout
    assert f"lower  = {out['lower']:.10g}" in text.stdout


def test_box_ranges_contain_every_point() -> None:
    """The (s, r) ranges of boxes (the tightened ones: ``|P c| - sum h_j |w_j|``, ``sqrt(|P
    c|**2 + 2 sum h_j |(P c)_j| + |h|**2)``) contain (s, r) of random points of the boxes,
    and are no wider than the centre -+ half-diagonal ranges; the exact ranges of thin
    boxes along the chord are much tighter than those."""
    cc = importlib.import_module("solvers.certificates.conformal.certificate")
    rng = np.random.default_rng(7)
    for dim in (2, 4, 6):
        x = rng.normal(size=dim)
        u = rng.normal(size=dim)
        u /= np.linalg.norm(u)
        c = x + rng.normal(size=(400, dim)) * rng.choice([0.05, 1.0, 3.0], size=(400, 1))
        h = rng.uniform(0.0, 0.5, size=(400, dim)) * rng.choice([0.1, 1.0], size=(400, dim))
        lo, hi = c - h, c + h
        s_lo, s_hi, r_lo, r_hi = cc._box_sr(lo, hi, x, u)
        for _ in range(30):
            q = lo + rng.uniform(size=lo.shape) * (hi - lo)
            s = (q - x) @ u
            r = np.linalg.norm(q - x - s[:, None] * u, axis=1)
            assert np.all((s_lo <= s) & (s <= s_hi) & (r_lo <= r) & (r <= r_hi))
        perp = (c - x) - ((c - x) @ u)[:, None] * u
        rc, hd = np.linalg.norm(perp, axis=1), np.linalg.norm(h, axis=1)
        assert np.all(r_lo >= np.maximum(rc - hd, 0) * (1 - 1e-9) - 1e-9)
        assert np.all(r_hi <= (rc + hd) * (1 + 1e-9) + 1e-9)
    # a box long along the chord, far from it: the half-diagonal would spill over r = 1
    u = np.array([1.0, 0.0, 0.0, 0.0])
    s_lo, s_hi, r_lo, r_hi = cc._box_sr(np.array([[0.0, 1.9, -0.05, -0.05]]),
                                        np.array([[2.0, 2.1, 0.05, 0.05]]), np.zeros(4), u)
    assert r_lo[0] > 1.85 and r_hi[0] < 2.11
