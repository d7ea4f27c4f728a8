"""Bad input to the metric API raises clear errors; the `geodesics metrics/cost` CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import finsler
from finsler import InputError, UnknownMetricError
from validation.cli import app

runner = CliRunner()


def test_unknown_metric_and_parameter() -> None:
    with pytest.raises(UnknownMetricError, match="did you mean 'matsumoto'"):
        finsler.get_metric("matsumotoo")
    with pytest.raises(UnknownMetricError, match="no parameter 'slope'"):
        finsler.get_metric("matsumoto", slope=2.0)
    with pytest.raises(InputError, match="positive"):
        finsler.get_metric("carlike", c_p=-1.0)
    with pytest.raises(InputError, match="wind"):
        finsler.get_metric("randers", wind_x=1.2)
    assert finsler.get_metric("matsumoto", height=0.5).convex_radius == pytest.approx(
        2 / (2 * np.sqrt(3))
    )


def test_wrong_shapes_and_values() -> None:
    m = finsler.get_metric("matsumoto")
    with pytest.raises(InputError, match=r"shape \(N, 2\)"):
        m.cost(np.zeros((4, 3)), np.zeros((4, 3)))
    with pytest.raises(InputError, match="same number of rows"):
        m.cost(np.zeros((4, 2)), np.zeros((3, 2)))
    with pytest.raises(InputError, match="NaN or inf"):
        m.cost(np.array([[0.0, np.inf]]), np.zeros((1, 2)))
    with pytest.raises(InputError, match="NaN or inf"):
        m.F(torch.tensor([[0.0, float("nan")]]), torch.zeros(1, 2))
    with pytest.raises(InputError, match="same kind"):
        m.cost(np.zeros((1, 2)), torch.zeros(1, 2))
    with pytest.raises(InputError, match="quadrature order"):
        m.segment_length(np.zeros((1, 2)), np.ones((1, 2)) * 0.1, order=0)
    with pytest.raises(InputError, match="paths must have shape"):
        m.path_costs(np.zeros((3, 2)))


def test_zero_vector_gives_zero_cost() -> None:
    m = finsler.get_metric("matsumoto")
    x = np.array([[0.3, 0.1], [0.2, 0.2]])
    assert np.array_equal(m.cost(x, x), [0.0, 0.0])
    assert float(m.cost(torch.tensor(x), torch.tensor(x)).abs().max()) == 0.0


def test_single_points_return_scalars() -> None:
    m = finsler.get_metric("euclidean")
    c = m.cost(np.array([0.0, 0.0]), np.array([0.3, 0.4]))
    assert np.ndim(c) == 0 and float(c) == pytest.approx(0.5)


def test_cli_metrics_table_and_json() -> None:
    res = runner.invoke(app, ["metrics"])
    assert res.exit_code == 0, res.output
    for name in finsler.list_metrics():
        assert name in res.output
    assert "NOT Finsler" in res.output
    res = runner.invoke(app, ["metrics", "--json"])
    rows = json.loads(res.output)
    assert {r["name"] for r in rows} == set(finsler.list_metrics())


def test_cli_cost_equals_api() -> None:
    res = runner.invoke(
        app, ["cost", "--metric", "matsumoto", "--start", "0.1,0.2", "--goal", "-0.5,0.3", "--json"]
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    m = finsler.get_metric("matsumoto")
    s, g = np.array([0.1, 0.2]), np.array([-0.5, 0.3])
    assert out["cost"] == pytest.approx(float(m.cost(s, g)), rel=1e-14)
    assert out["cost_symmetric"] == pytest.approx(float(m.cost_symmetric(s, g)), rel=1e-14)
    # the accurate length (adaptive Gauss-Kronrod) against scipy's QUADPACK on F along the
    # segment, within the error the command states
    from scipy.integrate import quad

    ref, _ = quad(lambda t: float(m.F(s + t * (g - s), g - s)), 0.0, 1.0, epsabs=1e-14,
                  epsrel=1e-14, limit=200)
    assert out["segment_length_converged"] is True
    assert 0 < out["segment_length_error"] < 1e-9
    assert abs(out["segment_length"] - ref) <= out["segment_length_error"] + 1e-14


def test_load_pairs_validates_files(tmp_path) -> None:
    m = finsler.get_metric("matsumoto")
    good = finsler.default_pairs(m, 5)
    np.save(tmp_path / "good.npy", good)
    assert np.array_equal(finsler.load_pairs(tmp_path / "good.npy", m), good)
    assert np.array_equal(good, finsler.default_pairs(m, 5))  # deterministic
    with pytest.raises(InputError, match="does not exist"):
        finsler.load_pairs(tmp_path / "missing.npy", m)
    (tmp_path / "corrupt.npy").write_bytes(b"not a numpy file")
    with pytest.raises(InputError, match="not a readable"):
        finsler.load_pairs(tmp_path / "corrupt.npy", m)
    np.save(tmp_path / "dim.npy", np.zeros((4, 2, 3)))
    with pytest.raises(InputError, match=r"shape \(K, 2, 2\)"):
        finsler.load_pairs(tmp_path / "dim.npy", m)
    bad = good.copy()
    bad[1, 1] = [2.0, 0.0]
    np.save(tmp_path / "out.npy", bad)
    with pytest.raises(finsler.DomainError, match="outside"):
        finsler.load_pairs(tmp_path / "out.npy", m)
