"""The lowered numpy/torch programs equal CasADi's own evaluation."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch

import finsler
from finsler.lowering import lower

METRICS = finsler.list_metrics()


def _casadi_reference(fn: ca.Function, *args: np.ndarray) -> np.ndarray:
    """Evaluate a CasADi function point by point through CasADi's own VM (map)."""
    n = args[0].shape[0]
    out = fn.map(n)(*(a.T for a in args))
    return np.asarray(out).T


@pytest.mark.parametrize("name", METRICS)
def test_lowered_F_equals_casadi_numpy_and_torch(name: str) -> None:
    m = finsler.get_metric(name)
    rng = np.random.default_rng(1)
    n = 400
    x = m.domain.sample(n, rng)
    v = rng.normal(size=(n, m.dim)) * rng.uniform(0.01, 3.0, size=(n, 1))
    ref = _casadi_reference(m.casadi_F, x, v)[:, 0]
    got_np = m.F(x, v)
    got_t = m.F(torch.from_numpy(x), torch.from_numpy(v)).numpy()
    scale = np.maximum(1.0, np.abs(ref))
    assert got_np.dtype == np.float64
    assert np.max(np.abs(got_np - ref) / scale) < 1e-12
    assert np.max(np.abs(got_t - ref) / scale) < 1e-12


@pytest.mark.parametrize("name", METRICS)
def test_lowered_cost_equals_casadi_cost(name: str) -> None:
    m = finsler.get_metric(name)
    rng = np.random.default_rng(2)
    x = m.domain.sample(300, rng)
    y = m.domain.sample(300, rng)
    ref = _casadi_reference(m.casadi_cost, x, y)[:, 0]
    scale = np.maximum(1.0, np.abs(ref))
    assert np.max(np.abs(m.cost(x, y) - ref) / scale) < 1e-12
    got_t = m.cost(torch.from_numpy(x), torch.from_numpy(y)).numpy()
    assert np.max(np.abs(got_t - ref) / scale) < 1e-12


@pytest.mark.parametrize("name", METRICS)
def test_lowered_hessian_equals_casadi(name: str) -> None:
    m = finsler.get_metric(name)
    rng = np.random.default_rng(3)
    x = m.domain.sample(20, rng)
    v = rng.normal(size=(20, m.dim))
    (h,) = m.lowered_hessian(x, v)
    for i in range(20):
        ref = np.asarray(m.casadi_hessian(x[i], v[i]))
        got = h[i].reshape(m.dim, m.dim).T
        assert np.allclose(got, ref, rtol=1e-10, atol=1e-10)


def test_lowering_covers_many_operations() -> None:
    """A function using most scalar operations CasADi emits, lowered and compared."""
    x = ca.SX.sym("x", 3)
    a, b, c = x[0], x[1], x[2]
    exprs = [
        ca.exp(a) - ca.log(b) + ca.sqrt(b) * a**2,
        ca.sin(a) * ca.cos(b) + ca.tan(c / 4),
        ca.asin(a / 3) + ca.acos(c / 3) + ca.atan(b),
        ca.atan2(a, c) + ca.fmin(a, b) + ca.fmax(b, c),
        ca.fabs(a - c) + ca.sign(a - b) + ca.floor(b * 3) + ca.ceil(c),
        ca.sinh(a) + ca.cosh(c) + ca.tanh(b) + ca.asinh(a) + ca.atanh(a / 3),
        ca.if_else(a < b, a * 3, b / 2) + ca.if_else(a >= c, 1.0, -1.0),
        ca.power(b, c) + ca.power(b, 3.5) + 1.0 / c,
        ca.fmod(b * 7, 2.0) + ca.erf(a) + ca.log1p(b) + ca.expm1(a),
        ca.logic_and(a > 0, b > 1) + ca.logic_or(a > 0.5, c < 0.5) + ca.logic_not(a > 0),
        ca.hypot(a, c) + ca.copysign(b, a - 0.1) + ca.acosh(b + 1),
    ]
    fn = ca.Function("many", [x], [ca.vertcat(*exprs)])
    rng = np.random.default_rng(4)
    pts = np.column_stack(
        [rng.uniform(-0.9, 0.9, 200), rng.uniform(0.2, 2.0, 200), rng.uniform(0.3, 2.0, 200)]
    )
    ref = _casadi_reference(fn, pts)
    low = lower(fn)
    (got,) = low(pts)
    assert np.max(np.abs(got - ref)) < 1e-12
    (got_t,) = low(torch.from_numpy(pts))
    assert np.max(np.abs(got_t.numpy() - ref)) < 1e-12


def test_lowered_torch_is_differentiable_and_matches_casadi_gradient() -> None:
    m = finsler.get_metric("matsumoto")
    rng = np.random.default_rng(5)
    x = m.domain.sample(10, rng) * 0.9
    v = rng.normal(size=(10, 2))
    xt = torch.tensor(x, requires_grad=True)
    vt = torch.tensor(v, requires_grad=True)
    m.F(xt, vt).sum().backward()
    xs, vs = ca.SX.sym("x", 2), ca.SX.sym("v", 2)
    f = m.F_sx(xs, vs)
    grad = ca.Function("g", [xs, vs], [ca.gradient(f, xs), ca.gradient(f, vs)])
    for i in range(10):
        gx, gv = (np.asarray(t).ravel() for t in grad(x[i], v[i]))
        assert np.allclose(xt.grad[i].numpy(), gx, rtol=1e-10, atol=1e-12)
        assert np.allclose(vt.grad[i].numpy(), gv, rtol=1e-10, atol=1e-12)


def test_lowered_torch_runs_in_float32_and_keeps_dtype() -> None:
    m = finsler.get_metric("carlike")
    rng = np.random.default_rng(6)
    x = torch.tensor(m.domain.sample(5, rng), dtype=torch.float32)
    y = torch.tensor(m.domain.sample(5, rng), dtype=torch.float32)
    c = m.cost(x, y)
    assert c.dtype == torch.float32 and c.shape == (5,)
    ref = m.cost(x.double().numpy(), y.double().numpy())
    assert np.allclose(c.numpy(), ref, rtol=1e-4)


def test_lowered_program_is_cached_per_metric(monkeypatch) -> None:
    """Lowering runs once per metric instance, however often the metric is evaluated, and
    again for an instance with other parameters (whose program differs)."""
    import finsler.metrics.base as fm

    calls = []
    real = fm.lower

    def counting(fn):
        calls.append(fn.name())
        return real(fn)

    monkeypatch.setattr(fm, "lower", counting)
    m = type(finsler.get_metric("matsumoto"))()  # a new instance (the registry shares its own)
    x = np.array([[0.1, 0.2], [0.3, -0.1]])
    for _ in range(3):
        m.cost(x, x[::-1])
    assert len(calls) == 1
    assert "B.sqrt" in m.lowered_F.source
    w = type(finsler.get_metric("randers"))(wind_x=0.1)  # a new instance
    w.cost(x, x[::-1])
    w.cost(x, x[::-1])
    assert len(calls) == 2 and calls[0] != calls[1]


def test_max_through_abs_keeps_values_and_bounds_the_gradient_at_a_kink() -> None:
    """``fmax``/``fmin`` through ``abs``: the many-operations function keeps its values
    (to 1e-12; the car-like F bit for bit), and the interval enclosure of car-like's
    ``grad_v F`` on boxes across its kink (``r_min |v_th| = forward speed``) is bounded,
    holds every sampled gradient and shrinks with the box, where the plain program's is
    unbounded."""
    from finsler.enclosures.intervals import Interval, enclose
    from finsler.lowering import max_through_abs

    x = ca.SX.sym("x", 3)
    a, b, c = x[0], x[1], x[2]
    many = ca.Function("many", [x], [ca.vertcat(
        ca.fmin(a, b) + ca.fmax(b, c), ca.fmax(a * b, 0.0) - ca.fmin(c, -a),
        ca.if_else(a < b, a * 3, b / 2) + ca.sin(ca.fmax(a, c)) + ca.sqrt(b))])
    rng = np.random.default_rng(9)
    pts = rng.uniform(-1.0, 1.0, (300, 3)) + np.array([0.0, 1.5, 0.0])
    rewritten = max_through_abs(many)
    assert "fmax" in str(many.call([x])[0]) and "fmax" not in str(rewritten.call([x])[0])
    assert np.max(np.abs(lower(rewritten)(pts)[0] - lower(many)(pts)[0])) < 1e-12

    m = finsler.get_metric("carlike")
    z, v = ca.SX.sym("z", 3), ca.SX.sym("v", 3)
    plain = ca.Function("f", [z, v], [m.F_sx(z, v)])
    fz = max_through_abs(plain)(z, v)
    zs, vs = rng.uniform(-0.5, 0.5, (500, 3)), rng.normal(size=(500, 3))
    assert np.array_equal(lower(max_through_abs(plain))(zs, vs)[0], lower(plain)(zs, vs)[0])
    new = lower(ca.Function("g", [z, v], [ca.gradient(fz, v)]))
    old = lower(ca.Function("g", [z, v], [ca.gradient(m.F_sx(z, v), v)]))
    z0, w0 = np.array([0.1, 0.2, 0.3]), np.array([0.0, 0.0, 1.0])
    w0[:2] = 0.5 * np.array([np.cos(0.3), np.sin(0.3)])  # on the kink at z0
    widths = []
    for r in (1e-2, 1e-3):
        box_z, box_w = Interval(z0 - r, z0 + r), Interval(w0 - r, w0 + r)
        (g_new,) = enclose(new, box_z, box_w)
        (g_old,) = enclose(old, box_z, box_w)
        assert not all(np.isfinite(i.lo) and np.isfinite(i.hi) for i in g_old)
        sz = z0 + rng.uniform(-r, r, (2000, 3))
        sv = w0 + rng.uniform(-r, r, (2000, 3))
        (sampled,) = old(sz, sv)
        for j, iv in enumerate(g_new):
            assert np.isfinite(iv.lo) and np.isfinite(iv.hi)
            assert iv.lo <= sampled[:, j].min() and sampled[:, j].max() <= iv.hi
        widths.append(max(float(iv.hi - iv.lo) for iv in g_new))
    assert widths[1] < 0.3 * widths[0], widths
