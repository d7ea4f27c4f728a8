"""Lower bounds for conformal metrics in any dimension (issue 46, item 3): the hook equals
``F``, affine enclosures contain every sampled value, the lower bound never exceeds a
closed-form distance or a path's length, a broken enclosure is caught, dispatch, CLI."""

from __future__ import annotations

import importlib
import json

import casadi as ca
import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
from finsler import InputError
from finsler.enclosures.affine import enclose_affine
from finsler.enclosures.intervals import Interval, enclose
from finsler.lowering import lower
from solvers import CertifyStatus, ConformalSpec, certify
from solvers.certificates.conformal.certificate import ConformalCertifyResult, certify_conformal
from validation.cli import app

cc = importlib.import_module("solvers.certificates.conformal.certificate")
affine_mod = importlib.import_module("finsler.enclosures.affine")
runner = CliRunner()

#: small budgets: the tests check soundness, not tightness
QUICK = ConformalSpec(max_boxes=4000, s_cells=8, r_cells=4)


def _factor(m: finsler.Metric) -> object:
    q = ca.SX.sym("q", m.dim)
    return lower(ca.Function("f", [q], [m.conformal_factor_sx(q)]))


@pytest.mark.parametrize("name", finsler.list_metrics(provides="conformal_factor_sx"))
def test_factor_hook_equals_F(name: str) -> None:
    """F(q, v) = f(q) |v| on random points and vectors: a wrong hook would make the bound
    unsound, so it is checked against the metric's own F."""
    m = finsler.get_metric(name)
    rng = np.random.default_rng(3)
    q = m.domain.sample(200, rng)
    v = rng.normal(size=q.shape)
    (f,) = _factor(m)(q)
    np.testing.assert_allclose(np.asarray(f).reshape(-1) * np.linalg.norm(v, axis=1),
                               m.F(q, v), rtol=1e-12)


@pytest.mark.parametrize("name", ["panda-pole", "poincare", "sphere"])
def test_affine_enclosure_contains_samples_and_vertices(name: str) -> None:
    m = finsler.get_metric(name)
    fn = _factor(m)
    lo0, hi0 = (np.asarray(b, float) for b in m.domain.bounds())
    rng = np.random.default_rng(5)
    n = 400
    for w in (0.5, 0.1, 0.01):
        c = lo0 + rng.uniform(size=(n, m.dim)) * (hi0 - lo0) * 0.8 + 0.1 * (hi0 - lo0)
        lo, hi = c - w / 2, c + w / 2
        (iv,) = enclose_affine(fn, lo, hi)
        (nat,) = enclose(fn, Interval(lo, hi))[0:1]
        assert np.all(iv.lo >= nat[0].lo) and np.all(iv.hi <= nat[0].hi)  # intersected
        pts = [c, lo, hi] + [lo + rng.uniform(size=lo.shape) * w for _ in range(20)]
        for p in pts:
            (val,) = fn(p)
            assert np.all(iv.contains(np.asarray(val).reshape(-1))), (name, w)


def test_affine_keeps_correlations() -> None:
    """x * y - y * x and sin(x)**2 + cos(x)**2: affine forms cancel what the natural
    extension cannot."""
    x = ca.SX.sym("x", 2)
    fn = lower(ca.Function("g", [x], [ca.vertcat(x[0] * x[1] - x[1] * x[0] + x[0],
                                                   ca.sin(x[0]) ** 2 + ca.cos(x[0]) ** 2)]))
    lo, hi = np.array([[0.9, 1.9]]), np.array([[1.1, 2.1]])
    a, b = enclose_affine(fn, lo, hi)
    assert a.lo[0] <= 0.9 and a.hi[0] >= 1.1 and a.hi[0] - a.lo[0] < 0.21
    assert b.lo[0] <= 1.0 <= b.hi[0] and b.hi[0] - b.lo[0] < 0.05


def test_broken_affine_radius_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    """The containment check can fail: forms whose radius is halved (a margin with the
    wrong sign) miss sampled values of the Panda factor."""
    m = finsler.get_metric("panda-pole")
    fn = _factor(m)
    real = affine_mod._Affine.radius
    monkeypatch.setattr(affine_mod._Affine, "radius", lambda self: 0.5 * real(self))
    rng = np.random.default_rng(1)
    lo0, hi0 = (np.asarray(b, float) for b in m.domain.bounds())
    c = lo0 + rng.uniform(size=(200, 7)) * (hi0 - lo0)
    lo, hi = c - 0.05, c + 0.05
    (iv,) = enclose_affine(fn, lo, hi)
    missed = 0
    for _ in range(20):
        (val,) = fn(lo + rng.uniform(size=lo.shape) * 0.1)
        missed += int(np.sum(~iv.contains(np.asarray(val).reshape(-1))))
    assert missed > 0


@pytest.mark.parametrize("name", ["poincare", "sphere"])
def test_lower_bound_below_the_exact_distance(name: str) -> None:
    m = finsler.get_metric(name)
    pairs = finsler.sample_pairs(m, 4, 20261140)
    exact = m.distance(pairs[:, 0], pairs[:, 1])
    for (x, y), d in zip(pairs, exact, strict=True):
        r = certify_conformal(m, x, y, QUICK, path=m.geodesic(x[None], y[None],
                                                               np.linspace(0, 1, 65))[0])
        assert r.lower <= d * (1 + 1e-12) <= r.upper * (1 + 1e-9)
        assert r.lower >= r.trivial and r.lower > 0.5 * d
        assert r.ratio == pytest.approx(r.lower / r.upper)
        assert r.enclosures <= QUICK.max_boxes


def test_broken_enclosure_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    """Enclosures raised by 20 % (a margin with the wrong sign): the check of every box
    against the factor's value at its centre raises; without that check the 'lower
    bounds' exceed the exact Poincare distance, so the soundness test above can fail."""
    m = finsler.get_metric("poincare")
    real = cc._enclose_factor
    monkeypatch.setattr(cc, "_enclose_factor", lambda fn, lo, hi: 1.2 * real(fn, lo, hi))
    pairs = finsler.sample_pairs(m, 3, 20261140)
    exact = m.distance(pairs[:, 0], pairs[:, 1])

    def run(x: np.ndarray, y: np.ndarray) -> float:
        path = m.geodesic(x[None], y[None], np.linspace(0, 1, 65))[0]
        return certify_conformal(m, x, y, QUICK, path=path).lower

    with pytest.raises(RuntimeError, match="enclosure"):
        run(*pairs[0])
    monkeypatch.setattr(cc, "CHECK_VALUES", False)
    over = []
    for (x, y), d in zip(pairs, exact, strict=True):
        try:
            over.append(run(x, y) > d)
        except RuntimeError:  # the region emptied: caught too
            over.append(True)
    assert any(over)


def test_euclidean_4d_through_solvers_certify() -> None:
    """f = 1: the bound is |y - x| up to the 1e-9 slack; solvers.certify dispatches n-D
    conformal metrics here."""
    m = finsler.get_metric("euclidean", n=4)
    x, y = np.array([-0.5, 0.2, 0.1, -0.3]), np.array([0.4, -0.6, 0.3, 0.5])
    r = certify(m, x, y, QUICK, path=np.stack([x, y]))
    assert isinstance(r, ConformalCertifyResult)
    d = float(np.linalg.norm(y - x))
    assert d * (1 - 1e-8) <= r.lower <= d <= r.upper
    assert r.status is CertifyStatus.CERTIFIED and r.converged
    assert json.dumps(r.to_dict())


@pytest.mark.parametrize("k", [0, 1])
def test_panda_lower_bound_below_the_path_length(k: int) -> None:
    m = finsler.get_metric("panda-pole")
    x, y = finsler.sample_pairs(m, 2, 20261141)[k]
    r = certify_conformal(m, x, y, ConformalSpec(max_boxes=20000, s_cells=8, r_cells=4))
    length = float(m.path_length_error(r.path).value)
    assert 0 < r.trivial <= r.lower <= length <= r.upper * (1 + 1e-9)
    assert r.min_factor > 1.0  # f >= 1 + 3 / 0.4 at least; the boxes prove some of it
    assert r.enclosures <= 20000


def test_input_errors() -> None:
    with pytest.raises(InputError, match="not conformal"):
        certify_conformal("matsumoto", [0.1, 0.0], [0.0, 0.2])
    with pytest.raises(InputError, match="start equals goal"):
        certify_conformal("poincare", [0.1, 0.0], [0.1, 0.0])
    with pytest.raises(InputError, match="max_boxes"):
        ConformalSpec(max_boxes=0)
    with pytest.raises(InputError, match="refine_tol"):
        ConformalSpec(refine_tol=1.5)


def test_cli_certify_conformal_json() -> None:
    res = runner.invoke(app, ["certify", "--metric", "euclidean", "--metric-param", "n=4",
                              "--start", "-0.5,0.2,0.1,-0.3", "--goal", "0.4,-0.6,0.3,0.5",
                              "--max-boxes", "2000", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    d = float(np.linalg.norm([0.9, -0.8, 0.2, 0.8]))
    assert out["lower"] <= d <= out["upper"] and out["status"] == "certified"
