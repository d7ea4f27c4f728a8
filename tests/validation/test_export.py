"""A solved path drawn and exported: `validation.export` and ``geodesics solve --out
FILE.csv|.npy|.json --plot FILE.png`` (one pair as many)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
import solvers
import validation
from finsler import InputError
from validation.cli import app

PNG = b"\x89PNG\r\n\x1a\n"


def _csv(path):
    lines = path.read_text().splitlines()
    return lines[0].split(","), np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])


@pytest.fixture(scope="module")
def solved():
    m = finsler.get_metric("matsumoto")
    return m, solvers.solve_geodesic(m, [0.1, -0.5], [-0.3, 0.6], segments=16)


def test_export_one_path(solved, tmp_path):
    m, r = solved
    header, rows = _csv(validation.export_paths(r, tmp_path / "p.csv", m))
    assert header == ["x", "y"] and rows.shape == (r.segments + 1, m.dim)
    np.testing.assert_allclose(rows, r.points, rtol=0, atol=0)  # repr: exact round trip
    arr = np.load(validation.export_paths(r, tmp_path / "p.npy"))
    np.testing.assert_array_equal(arr, r.points)
    doc = json.loads(validation.export_paths(r, tmp_path / "p.json").read_text())
    assert np.asarray(doc["points"]).shape == (17, 2) and doc["status"] == "success"
    header, rows = _csv(validation.export_paths(r.points, tmp_path / "q.csv"))
    assert header == ["x0", "x1"] and rows.shape == (17, 2)


def test_export_many_paths(solved, tmp_path):
    m, r = solved
    header, rows = _csv(validation.export_paths([r, r], tmp_path / "p.csv", m))
    assert header == ["pair", "point", "x", "y"] and rows.shape == (34, 4)
    assert rows[17, :2].tolist() == [1, 0]
    assert np.load(validation.export_paths([r, r], tmp_path / "p.npy")).shape == (2, 17, 2)
    with pytest.raises(InputError, match="different sizes"):
        validation.export_paths([r.points, r.points[:5]], tmp_path / "bad.npy")
    with pytest.raises(InputError, match=r"\.csv, \.npy, \.json"):
        validation.export_paths(r, tmp_path / "p.txt")
    assert not (tmp_path / "bad.npy").exists() and not (tmp_path / "p.txt").exists()


@pytest.mark.parametrize("name", ["matsumoto", "poincare-slab", "panda-pole"])
def test_plot_geodesic_per_dimension(name, tmp_path):
    m = finsler.get_metric(name)
    s, g = finsler.default_pairs(m)[0]
    path = np.linspace(s, g, 9)  # any (n+1, dim) path is drawn
    fig = validation.plot_geodesic(m, path, tmp_path / "p.png")
    data = (tmp_path / "p.png").read_bytes()
    assert data.startswith(PNG) and len(data) > 10_000
    labels = " ".join(ax.get_xlabel() for ax in fig.axes)
    if m.dim > 2:
        assert "arc length" in labels
    if name == "panda-pole":  # joint angles and the end effector seen twice
        assert len(fig.axes) == 3 and "end effector" in fig.axes[1].get_title()
    with pytest.raises(InputError, match="must end in"):
        validation.plot_geodesic(m, path, tmp_path / "p.jpg")


def test_cli_one_pair_writes_csv_and_png(tmp_path):
    csv, png = tmp_path / "p.csv", tmp_path / "p.png"
    res = CliRunner().invoke(app, ["solve", "--metric", "matsumoto", "--start", "0.1,-0.5",
                                   "--goal", "-0.3,0.6", "--segments", "16", "--out", str(csv),
                                   "--plot", str(png)])
    assert res.exit_code == 0, res.output
    header, rows = _csv(csv)
    assert header == ["x", "y"] and rows.shape == (17, 2)
    np.testing.assert_allclose(rows[[0, -1]], [[0.1, -0.5], [-0.3, 0.6]])
    assert png.read_bytes().startswith(PNG)
    assert f"written                   {csv}" in res.stdout


def test_cli_many_pairs_and_refusals(tmp_path):
    m = finsler.get_metric("matsumoto")
    np.save(tmp_path / "pp.npy", finsler.sample_pairs(m, 3, 1))
    runner = CliRunner()
    base = ["solve", "--metric", "matsumoto", "--pairs", str(tmp_path / "pp.npy"),
            "--segments", "8", "--no-progress"]
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "m.npy")])
    assert res.exit_code == 0, res.output
    assert np.load(tmp_path / "m.npy").shape == (3, 9, 2)
    assert not (tmp_path / "m.npy.parts").exists()
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "m.csv")])
    header, rows = _csv(tmp_path / "m.csv")
    assert header[:2] == ["pair", "point"] and rows.shape == (27, 4)
    for extra, words in ((["--plot", str(tmp_path / "x.png")], "--plot draws one pair"),
                         (["--out", str(tmp_path / "t.npy"), "--tol", "1e-6"], "--tol")):
        res = runner.invoke(app, [*base, *extra])
        assert res.exit_code == 2 and words in res.output
    res = runner.invoke(app, ["solve", "--metric", "matsumoto", "--start", "0,0", "--goal",
                              "0.1,0.1", "--plot", str(tmp_path / "x.jpg")])
    assert res.exit_code == 2 and ".png, .pdf, .svg" in res.output
    assert not list(tmp_path.glob("x.*")) and not (tmp_path / "t.npy").exists()
