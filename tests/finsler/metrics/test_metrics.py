"""The paper's metrics against independent numpy transcriptions, the derived costs, and
the closed-form references."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
import torch

import finsler
from finsler.metrics import panda


def matsumoto_numpy(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Eqs. (20)-(21) with h(p) = -|p|^2, transcribed independently."""
    dhdx, dhdy = -2 * p[:, 0], -2 * p[:, 1]
    beta = v[:, 0] * dhdx + v[:, 1] * dhdy
    alpha = np.sqrt(v[:, 0] ** 2 + v[:, 1] ** 2 + beta**2)
    return alpha**2 / (alpha - beta)


def carlike_numpy(x: np.ndarray, v: np.ndarray, c_p: float = 100.0, r: float = 0.5) -> np.ndarray:
    """Eqs. (22)-(24), transcribed independently."""
    th = x[:, 2]
    vx, vy, vt = v.T
    h = -vx * np.sin(th) + vy * np.cos(th)
    xi = np.maximum(r * np.abs(vt) - vx * np.cos(th) - vy * np.sin(th), 0.0)
    return np.sqrt(vx**2 + vy**2 + c_p * (h**2 + xi**2))


def test_matsumoto_equals_numpy_transcription() -> None:
    m = finsler.get_metric("matsumoto")
    rng = np.random.default_rng(10)
    x = m.domain.sample(2000, rng)
    v = rng.normal(size=(2000, 2))
    assert np.allclose(m.F(x, v), matsumoto_numpy(x, v), rtol=1e-13, atol=0)
    y = m.domain.sample(2000, rng)
    assert np.allclose(m.cost(x, y), matsumoto_numpy(x, y - x), rtol=1e-13, atol=0)


def test_matsumoto_downhill_is_cheaper_than_uphill() -> None:
    """Sanity of the sign convention: the mountain is at the centre (h = -|p|^2)."""
    m = finsler.get_metric("matsumoto")
    p = np.array([0.5, 0.0])
    up = m.F(p, np.array([-0.1, 0.0]))  # towards the centre, uphill
    down = m.F(p, np.array([0.1, 0.0]))
    assert up > 0.1 > down


@pytest.mark.parametrize("params", [{}, {"c_p": 10.0, "r_min": 0.2}])
def test_carlike_equals_numpy_transcription(params: dict) -> None:
    m = finsler.get_metric("carlike", **params)
    rng = np.random.default_rng(11)
    x = m.domain.sample(2000, rng)
    v = rng.normal(size=(2000, 3))
    ref = carlike_numpy(x, v, params.get("c_p", 100.0), params.get("r_min", 0.5))
    assert np.allclose(m.F(x, v), ref, rtol=1e-13, atol=0)


def test_carlike_penalises_sideways_and_backwards_motion() -> None:
    m = finsler.get_metric("carlike")
    x = np.array([0.0, 0.0, 0.0])  # heading along +x
    forward = m.F(x, np.array([1.0, 0.0, 0.0]))
    sideways = m.F(x, np.array([0.0, 1.0, 0.0]))
    backward = m.F(x, np.array([-1.0, 0.0, 0.0]))
    assert forward == pytest.approx(1.0)
    assert sideways == pytest.approx(math.sqrt(101.0))
    assert backward == pytest.approx(math.sqrt(1.0 + 100.0))


def test_panda_cost_from_pinocchio_frame_positions() -> None:
    """eq. (60) checked from Pinocchio's own kinematics, through the metric's lowered cost."""
    m = finsler.get_metric("panda-pole")
    model = panda.load_panda_model()
    data = model.createData()
    ids = [model.getFrameId(n) for n in panda.FRAME_NAMES]
    rng = np.random.default_rng(12)
    q = m.domain.sample(30, rng)
    y = m.domain.sample(30, rng)
    got = m.cost(q, y)
    for i in range(30):
        pin.forwardKinematics(model, data, q[i])
        pin.updateFramePlacements(model, data)
        pos = np.array([data.oMf[j].translation for j in ids])
        w = 1.0 + np.sum(((pos[:, 0] - 0.4) ** 2 + (pos[:, 1] - 0.0) ** 2) ** -0.5)
        assert got[i] == pytest.approx(w * np.linalg.norm(y[i] - q[i]), rel=1e-10)
    fp = m.frame_positions(q[:3])
    for i in range(3):
        pin.forwardKinematics(model, data, q[i])
        pin.updateFramePlacements(model, data)
        ref = np.array([data.oMf[j].translation for j in ids])
        assert np.allclose(fp[i], ref, atol=1e-12)
    fpt = m.frame_positions(torch.from_numpy(q[:3]))
    assert np.allclose(fpt.numpy(), fp, atol=1e-14)


@pytest.mark.parametrize("name", ["euclidean", "minkowski", "randers", "poincare", "sphere"])
def test_closed_form_distance_and_geodesic_are_consistent(name: str) -> None:
    """The closed-form geodesic has the closed-form length (quadrature of F along it) and its
    points split the distance in the stated fractions."""
    m = finsler.get_metric(name)
    rng = np.random.default_rng(13)
    x, y = m.domain.sample(20, rng), m.domain.sample(20, rng)
    d = m.distance(x, y)
    t = np.linspace(0, 1, 2049)
    g = m.geodesic(x, y, t)
    assert np.allclose(g[:, 0], x, atol=1e-12) and np.allclose(g[:, -1], y, atol=1e-12)
    assert np.all(m.domain.contains(g.reshape(-1, 2), tol=1e-9))
    # length of the fine polyline, each piece by 4-point Gauss-Legendre quadrature
    pieces = m.segment_length(g[:, :-1].reshape(-1, 2), g[:, 1:].reshape(-1, 2), order=4)
    length = pieces.reshape(20, -1).sum(1)
    assert np.allclose(length, d, rtol=1e-6)
    half = m.distance(x, g[:, 1024])
    assert np.allclose(half, d / 2, rtol=1e-9, atol=1e-12)


def test_randers_distance_is_travel_time_with_wind() -> None:
    m = finsler.get_metric("randers", wind_x=0.5, wind_y=0.0)
    x = np.array([[0.0, 0.0], [0.0, 0.0]])
    y = np.array([[0.6, 0.0], [-0.6, 0.0]])
    # with the wind: speed 1.5; against it: 0.5
    assert np.allclose(m.distance(x, y), [0.4, 1.2])
    assert np.allclose(m.cost(x, y), [0.4, 1.2])


def test_poincare_and_sphere_known_values() -> None:
    p = finsler.get_metric("poincare")
    r = 0.5
    assert p.distance(np.zeros((1, 2)), np.array([[r, 0.0]]))[0] == pytest.approx(
        2 * math.atanh(r)
    )
    s = finsler.get_metric("sphere")
    # u = tan(phi/2) for polar angle phi from the north pole
    u = math.tan(math.radians(30) / 2)
    assert s.distance(np.zeros((1, 2)), np.array([[0.0, u]]))[0] == pytest.approx(
        math.radians(30)
    )


def test_cost_symmetric_and_segment_length() -> None:
    m = finsler.get_metric("poincare")
    x = np.array([[0.1, 0.2]])
    y = np.array([[-0.3, 0.4]])
    d = y - x
    expect = 0.5 * (m.F(x, d) + m.F(y, d))
    assert m.cost_symmetric(x, y) == pytest.approx(expect[0])
    # segment length converges with the quadrature order, to the integral computed by scipy
    from scipy.integrate import quad

    ref = quad(lambda t: m.F(x[0] + t * d[0], d[0]), 0, 1, epsabs=1e-14)[0]
    assert m.segment_length(x, y, order=12)[0] == pytest.approx(ref, rel=1e-12)
    assert m.segment_length(x, y, order=12)[0] >= m.distance(x, y)[0] - 1e-12
    got_t = m.segment_length(torch.from_numpy(x), torch.from_numpy(y), order=12)
    assert float(got_t[0]) == pytest.approx(ref, rel=1e-12)


def test_path_costs_shape_and_values() -> None:
    m = finsler.get_metric("euclidean")
    paths = np.stack([np.linspace([0, 0], [0.8, 0.6], 5)] * 3)
    c = m.path_costs(paths)
    assert c.shape == (3, 4)
    assert np.allclose(c, 0.25)


def test_metric_info_rows() -> None:
    rows = {n: finsler.get_metric(n).info() for n in finsler.list_metrics()}
    assert rows["matsumoto"]["depth"] == 6 and rows["matsumoto"]["eps"] == 0.1
    assert rows["carlike"]["depth"] == 8 and rows["carlike"]["dim"] == 3
    assert rows["panda-pole"]["depth"] == 5 and rows["panda-pole"]["eps"] == 20
    assert "NOT Finsler" in rows["matsumoto"]["convexity"]
    assert rows["panda-pole"]["reversible"] and not rows["matsumoto"]["reversible"]
