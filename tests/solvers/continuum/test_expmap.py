"""exp/log maps (solvers.continuum.expmap) against closed forms derived by hand, independent of the
symbolic spray: Poincare (Moebius maps), sphere (great circles), straight lines of the
constant metrics (Randers, Minkowski, Euclidean); the issue-14 bar on log; bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

import finsler
import solvers
from finsler import DomainError, InputError
from solvers import ExpStatus, LogStatus, SolverError, exp_map, log_map


def _pairs(metric: finsler.Metric, k: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([metric.domain.sample(k, rng), metric.domain.sample(k, rng)], 1)


def poincare_velocity(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Initial velocity of the unit-interval geodesic from x to y in the Poincare disk.

    The Moebius map z = (u + zx) / (1 + conj(zx) u) sends the diameter u(t) = tanh(t d / 2)
    w/|w| to the geodesic; dz/du = 1 - |zx|^2 at u = 0, so v = d/2 (1 - |x|^2) w/|w| with
    w = (zy - zx) / (1 - conj(zx) zy) and d = arccosh(1 + 2|x-y|^2 / ((1-|x|^2)(1-|y|^2)))."""
    zx, zy = complex(*x), complex(*y)
    w = (zy - zx) / (1 - zx.conjugate() * zy)
    d = math.acosh(1 + 2 * np.sum((x - y) ** 2) / ((1 - x @ x) * (1 - y @ y)))
    v = d / 2 * (1 - abs(zx) ** 2) * w / abs(w)
    return np.array([v.real, v.imag])


def sphere_velocity(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Initial velocity, in the stereographic chart, of the great-circle arc from x to y on
    [0, 1]: p(t) = cos(th t) a + sin(th t) u with u = (b - cos th a) / sin th, p'(0) = th u,
    pushed forward by pi(p) = p[:2] / (1 + p[2])."""
    s = finsler.Sphere

    a, b = s.to_sphere(x[None])[0], s.to_sphere(y[None])[0]
    th = math.acos(np.clip(a @ b, -1, 1))
    w = th * (b - math.cos(th) * a) / math.sin(th)
    return w[:2] / (1 + a[2]) - a[:2] * w[2] / (1 + a[2]) ** 2


@pytest.mark.parametrize("name,velocity", [("poincare", poincare_velocity),
                                           ("sphere", sphere_velocity)])
def test_exp_follows_the_closed_form_geodesic(name, velocity):
    m = finsler.get_metric(name)
    ts = np.linspace(0.0, 1.0, 9)
    for x, y in _pairs(m, 4, seed=1):
        v = velocity(x, y)
        r = exp_map(m, x, v, return_curve=9)
        assert r.status is ExpStatus.SUCCESS and r.t_end == 1.0
        exact = m.geodesic(x[None], y[None], ts)[0]
        np.testing.assert_allclose(r.point, y, rtol=0, atol=1e-10)
        np.testing.assert_allclose(r.curve, exact, rtol=0, atol=1e-10)
        np.testing.assert_allclose(r.times, ts, rtol=0, atol=1e-15)
        # constant speed = the exact distance (the velocity was built from the closed form)
        d = m.distance(x[None], y[None])[0]
        assert abs(r.speed - d) <= 1e-12 * d
        assert r.speed_drift < 1e-10


@pytest.mark.parametrize("name", ["randers", "minkowski", "euclidean"])
def test_exp_of_constant_metrics_is_a_straight_line(name):
    m = finsler.get_metric(name)
    for x, y in _pairs(m, 3, seed=2):
        for s in (0.25, 1.0):
            r = exp_map(m, x, y - x, t=s)
            assert r.converged
            np.testing.assert_allclose(r.point, x + s * (y - x), rtol=0, atol=1e-12)
            np.testing.assert_allclose(r.point_velocity, y - x, rtol=0, atol=1e-12)


def test_exp_of_randers_is_not_reversible():
    m = finsler.get_metric("randers")  # wind (0.5, 0.2): downwind is faster
    x, v = np.zeros(2), np.array([0.3, 0.0])
    fwd, back = exp_map(m, x, v), exp_map(m, x, -v)
    np.testing.assert_allclose(back.point, -fwd.point, atol=1e-12)
    # time to travel |d| = 0.3 with / against the wind: F(v) = |d| / (|W| cos + ...) by hand
    w = np.array([0.5, 0.2])

    def travel_time(d: np.ndarray) -> float:  # |d - T w| = T, positive root
        a, b, c = 1 - w @ w, 2 * (d @ w), -(d @ d)
        return (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)

    assert abs(fwd.speed - travel_time(v)) < 1e-14
    assert abs(back.speed - travel_time(-v)) < 1e-14
    assert back.speed > 1.5 * fwd.speed


def test_exp_is_positively_homogeneous():
    m = finsler.get_metric("poincare")
    x, v = np.array([0.2, -0.1]), np.array([0.4, 0.7])
    a = exp_map(m, x, v, t=1.0)
    b = exp_map(m, x, 2.0 * v, t=0.5)
    np.testing.assert_allclose(a.point, b.point, atol=1e-12)
    assert abs(b.speed - 2 * a.speed) < 1e-14


@pytest.mark.parametrize("name", ["poincare", "randers"])
def test_log_bar_of_issue_14(name):
    """exp(x, log(x, y)) within 1e-8 of y and F(x, log(x, y)) = d(x, y) to 1e-8."""
    m = finsler.get_metric(name)
    for x, y in _pairs(m, 5, seed=3):
        r = log_map(m, x, y)
        assert r.status is LogStatus.SUCCESS, r
        back = exp_map(m, x, r.velocity)
        assert np.max(np.abs(back.point - y)) <= 1e-8
        d = m.distance(x[None], y[None])[0]
        assert abs(float(m.F(x, r.velocity)) - d) <= 1e-8 * d
        if name == "poincare":  # the velocity itself, against the hand-derived one
            np.testing.assert_allclose(r.velocity, poincare_velocity(x, y), rtol=0, atol=1e-8)
        else:
            np.testing.assert_allclose(r.velocity, y - x, rtol=0, atol=1e-8)


def test_log_on_the_sphere_and_trivial_pair():
    m = finsler.get_metric("sphere")
    x, y = np.array([0.5, 0.3]), np.array([-0.6, -0.2])
    r = log_map(m, x, y)
    assert r.converged
    np.testing.assert_allclose(r.velocity, sphere_velocity(x, y), rtol=0, atol=1e-8)
    t = log_map(m, x, x)
    assert t.status is LogStatus.TRIVIAL and np.all(t.velocity == 0)


def test_matsumoto_inside_the_convex_disk_and_refused_outside():
    m = finsler.get_metric("matsumoto")
    x, y = np.array([0.1, 0.05]), np.array([-0.1, 0.15])
    r = log_map(m, x, y)
    assert r.converged
    back = exp_map(m, x, r.velocity)
    assert np.max(np.abs(back.point - y)) <= 1e-8
    # uphill and downhill differ (asymmetric): log(y, x) is not -log(x, y)
    r2 = log_map(m, y, x)
    assert r2.converged and abs(r2.length - r.length) > 1e-3
    # refused where F(x, .) is not strongly convex (|p| > 1/(2 sqrt 3) ~ 0.2887)
    with pytest.raises(InputError, match="not strongly convex"):
        exp_map(m, np.array([0.5, 0.0]), np.array([1.0, 0.0]))
    with pytest.raises(InputError, match="not strongly convex"):
        log_map(m, np.array([0.5, 0.0]), np.array([-0.5, 0.1]))


def test_exp_stops_where_convexity_is_lost_and_at_the_boundary():
    m = finsler.get_metric("matsumoto")
    # a radial geodesic stays on its diameter (symmetry) and meets the non-convex region
    # at the analytic radius 1 / (2 sqrt 3)
    r = exp_map(m, np.array([0.1, 0.0]), np.array([0.5, 0.0]))
    assert r.status is ExpStatus.NOT_CONVEX and r.t_end < 1.0
    assert abs(r.point[1]) < 1e-12
    assert abs(r.point[0] - 1 / (2 * math.sqrt(3))) < 1e-9
    with pytest.raises(SolverError, match="not_convex"):
        exp_map(m, np.array([0.1, 0.0]), np.array([0.5, 0.0]), strict=True)
    # Poincare: a diameter leaves the disk of radius 0.8 where tanh(s / 2) = 0.8, i.e. at
    # s = 2 atanh(0.8) = ln 9, reached at t = ln 9 / F(0, v) = ln 9 / 2 for v = (1, 0)
    p = exp_map("poincare", np.zeros(2), np.array([1.0, 0.0]), t=5.0)
    assert p.status is ExpStatus.LEFT_DOMAIN
    assert abs(p.t_end - math.log(9) / 2) < 1e-9
    np.testing.assert_allclose(p.point, [0.8, 0.0], atol=1e-10)


def test_bad_input():
    m = finsler.get_metric("poincare")
    x = np.array([0.1, 0.2])
    with pytest.raises(InputError, match="shape"):
        exp_map(m, x, np.zeros(3))
    with pytest.raises(InputError, match="NaN"):
        exp_map(m, x, np.array([np.nan, 0.0]))
    with pytest.raises(DomainError):
        exp_map(m, np.array([0.9, 0.0]), np.array([0.1, 0.0]))
    with pytest.raises(InputError, match="t must be"):
        exp_map(m, x, np.array([0.1, 0.0]), t=-1.0)
    with pytest.raises(InputError, match="return_curve"):
        exp_map(m, x, np.array([0.1, 0.0]), return_curve=1)
    with pytest.raises(InputError, match="not smooth"):
        exp_map("carlike", np.zeros(3), np.array([1.0, 0.0, 0.0]))
    with pytest.raises(DomainError):
        log_map(m, x, np.array([0.0, 0.85]))
    with pytest.raises(InputError, match="tol"):
        log_map(m, x, np.array([0.0, 0.5]), tol=0.0)
    with pytest.raises(InputError, match=r"unknown|registered|metric"):
        exp_map("no-such-metric", x, x)


def test_zero_velocity_and_zero_time():
    r = exp_map("randers", np.array([0.2, 0.1]), np.zeros(2), return_curve=3)
    assert r.converged and np.all(r.point == [0.2, 0.1]) and r.curve.shape == (3, 2)
    r = exp_map("randers", np.array([0.2, 0.1]), np.ones(2), t=0)
    assert np.all(r.point == [0.2, 0.1])


def test_exports():
    assert solvers.exp_map is exp_map and solvers.log_map is log_map


def test_cli_exp_and_log():
    import json

    from typer.testing import CliRunner

    from validation.cli import app

    run = CliRunner()
    out = run.invoke(app, ["log", "--metric", "poincare", "--start", "0.1,0.2", "--goal",
                           "-0.3,-0.4", "--json"])
    assert out.exit_code == 0, out.output
    v = json.loads(out.output)["velocity"]
    np.testing.assert_allclose(v, poincare_velocity(np.array([0.1, 0.2]),
                                                    np.array([-0.3, -0.4])), atol=1e-8)
    out = run.invoke(app, ["exp", "--metric", "poincare", "--start", "0.1,0.2", "--velocity",
                           ",".join(repr(c) for c in v), "--json"])
    assert out.exit_code == 0, out.output
    np.testing.assert_allclose(json.loads(out.output)["point"], [-0.3, -0.4], atol=1e-8)
    out = run.invoke(app, ["exp", "--metric", "poincare", "--start", "0,0", "--velocity",
                           "1,0", "--t", "5"])
    assert out.exit_code == 1 and "left_domain" in out.output
    out = run.invoke(app, ["log", "--metric", "matsumoto", "--start", "0.5,0", "--goal",
                           "-0.5,0.1"])
    assert out.exit_code == 2 and "not strongly convex" in out.output


def _peers_module():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[3] / "benchmarks" / "peers.py"
    spec = importlib.util.spec_from_file_location("peers_benchmark", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_peers_benchmark_scoring_judges_paths_and_log_velocities():
    """benchmarks/peers.py: a missing peer is skipped with the reason; a path leaving the
    domain and a velocity whose geodesic (exp_map) misses the goal are failures; errors are
    against the exact distance."""
    peers = _peers_module()
    skip = peers.run_peer("geomstats", "/nonexistent/python", {})
    assert "does not exist" in skip["skipped"]
    m = finsler.get_metric("randers")
    pairs = np.array([[[-0.5, 0.1], [0.5, 0.3]], [[0.2, -0.6], [-0.4, 0.7]]])
    t = np.linspace(0, 1, 9)[:, None]
    line = [(s + t * (g - s)).tolist() for s, g in pairs]
    bent = np.array(line[1])
    bent[4, 0] = 1.2  # outside the box [-1, 1]^2
    rows = [
        {"peer": "p", "method": "paths", "setting": "", "kind": "path",
         "per_pair": [{"seconds": 0.1, "error": None, "path": line[0]},
                      {"seconds": 0.3, "error": None, "path": bent.tolist()}]},
        {"peer": "p", "method": "logs", "setting": "", "kind": "log",
         "per_pair": [{"seconds": 0.1, "error": None, "velocity": (pairs[0, 1] - pairs[0, 0])
                       .tolist()},
                      {"seconds": 0.1, "error": None,
                       "velocity": (1.01 * (pairs[1, 1] - pairs[1, 0])).tolist()}]},
    ]
    exact = m.distance(pairs[:, 0], pairs[:, 1])
    peers.score(m, pairs, rows, exact)
    p0, p1 = rows[0]["per_pair"]
    assert p0["failed"] is None and abs(p0["err"]) < 1e-14
    assert p1["failed"] == "path leaves the domain" and p1["err"] is None
    l0, l1 = rows[1]["per_pair"]
    assert l0["failed"] is None and l0["miss"] < 1e-12 and abs(l0["err"]) < 1e-14
    # 1 % too fast: the straight geodesic overshoots by 1 % of |y - x|
    miss = 0.01 * np.max(np.abs(pairs[1, 1] - pairs[1, 0]))
    assert abs(l1["miss"] - miss) < 1e-10 and l1["failed"].startswith("misses the goal")
    text = "\n".join(peers.summarise("randers", rows, True))
    assert text.count(" 1/2") == 2 and "path leaves the domain" in text
