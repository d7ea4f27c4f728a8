"""validation.curves / validation.figures / `geodesics plot-curves`: learning curves of a
hand-made sweep directory, checked against means and standard errors computed by hand.

The sweep (metrics.csv written literally below)::

    envA/midpoint/seed-{0,1,2}   envA/seq/seed-{3,5}   envB/midpoint/seed-0
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from types import SimpleNamespace

import matplotlib.image
import numpy as np
import pytest
from typer.testing import CliRunner

from finsler import InputError
from validation import curves as cv
from validation import figures as fg
from validation.cli import app
from validation.cli.plot import plot_curves

HEADER = ("iteration,timesteps,timesteps_paper,timesteps_derivative,wall_seconds,"
          "success_rate,mean_length,mean_max_segment_cost")

# (timesteps, wall_seconds, success_rate) per evaluation
RUNS = {
    ("envA", "midpoint", 0): [(0, 0.5, 0.0), (100, 1.0, 0.4), (200, 2.0, 0.8), (300, 3.0, 1.0)],
    ("envA", "midpoint", 1): [(0, 0.2, 0.1), (100, 1.5, 0.5), (200, 2.5, 0.7)],
    ("envA", "midpoint", 2): [(0, 0.3, 0.2), (150, 1.2, 0.3), (300, 4.0, 0.9)],
    ("envA", "seq", 3): [(0, 0.1, 0.0), (50, 0.4, 0.25), (400, 5.0, 0.5)],
    ("envA", "seq", 5): [(0, 0.1, 0.0), (80, 0.6, 0.75)],
    ("envB", "midpoint", 0): [(0, 0.1, 0.5), (10, 0.2, 0.6)],
}


def _write_run(root: Path, env: str, var: str, seed: int,
               evals: list[tuple[int, float, float]]) -> Path:
    d = root / env / var / f"seed-{seed}"
    d.mkdir(parents=True)
    lines = [HEADER] + [f"{i},{t},{t // 2},0,{w},{s},1.5,0.1"
                        for i, (t, w, s) in enumerate(evals)]
    (d / "metrics.csv").write_text("\n".join(lines) + "\n")
    (d / "config.json").write_text("{}")
    return d


@pytest.fixture
def sweep_dir(tmp_path: Path) -> Path:
    root = tmp_path / "sweep"
    for (env, var, seed), evals in RUNS.items():
        _write_run(root, env, var, seed, evals)
    (root / "sweep.json").write_text("{}")  # files beside the runs are ignored
    return root


def _se(*v: float) -> float:
    """Standard error by hand: sample std (n - 1) over sqrt(n)."""
    n = len(v)
    m = sum(v) / n
    return math.sqrt(sum((x - m) ** 2 for x in v) / (n - 1)) / math.sqrt(n)


# ----------------------------------------------------------------------------------------
# reading and curves
# ----------------------------------------------------------------------------------------
def test_read_sweep_finds_every_run(sweep_dir: Path) -> None:
    sw = cv.read_sweep(sweep_dir)
    assert sw.envs == ["envA", "envB"]
    assert sw.variants("envA") == ["midpoint", "seq"] and sw.variants("envB") == ["midpoint"]
    assert [r.seed for r in sw.runs[("envA", "seq")]] == [3, 5]
    assert len(sw) == 6
    assert sw.runs[("envA", "midpoint")][1].values("success_rate").tolist() == [0.1, 0.5, 0.7]


def test_mean_and_stderr_on_the_union_grid(sweep_dir: Path) -> None:
    c = cv.learning_curves(cv.read_sweep(sweep_dir))[("envA", "midpoint")]
    after_200 = np.nextafter(200.0, np.inf)  # seed 1's log ends at 200: dropped after it
    assert c.x.tolist() == [0, 100, 150, 200, after_200, 300]
    # x = 0: all three seeds at their first evaluation
    assert c.mean[0] == pytest.approx(0.1, abs=1e-15)
    assert c.stderr[0] == pytest.approx(0.1 / math.sqrt(3), rel=1e-12)
    # x = 100: seed 2 still holds its value from x = 0 (step function)
    assert c.mean[1] == pytest.approx((0.4 + 0.5 + 0.2) / 3, rel=1e-12)
    assert c.stderr[1] == pytest.approx(_se(0.4, 0.5, 0.2), rel=1e-12)
    assert c.stderr[1] == pytest.approx(0.0881917103688197, rel=1e-12)
    # x = 150: 0.4, 0.5, 0.3 -> mean 0.4, std 0.1
    assert c.mean[2] == pytest.approx(0.4, rel=1e-12)
    assert c.stderr[2] == pytest.approx(0.1 / math.sqrt(3), rel=1e-12)
    # x = 200: 0.8, 0.7, 0.3; just after 200 seed 1 has stopped: 0.8, 0.3
    assert c.mean[3] == pytest.approx(0.6, rel=1e-12)
    assert c.stderr[3] == pytest.approx(_se(0.8, 0.7, 0.3), rel=1e-12)
    assert c.mean[4] == pytest.approx(0.55, rel=1e-12)
    assert c.stderr[4] == pytest.approx(0.25, rel=1e-12)
    # x = 300: only 1.0 and 0.9 -> se = |1.0 - 0.9| / 2 = 0.05
    assert c.n_seeds.tolist() == [3, 3, 3, 3, 2, 2]
    assert c.mean[5] == pytest.approx(0.95, rel=1e-12)
    assert c.stderr[5] == pytest.approx(0.05, rel=1e-12)
    assert c.seeds == (0, 1, 2)


def test_given_grid_wall_time_and_seeds_outside_their_range(sweep_dir: Path) -> None:
    sw = cv.read_sweep(sweep_dir)
    c = cv.learning_curves(sw, grid=[50, 250, 350])[("envA", "midpoint")]
    assert c.n_seeds.tolist() == [3, 2, 0]
    assert c.mean[0] == pytest.approx(0.1, rel=1e-12)
    assert c.mean[1] == pytest.approx((0.8 + 0.3) / 2, rel=1e-12)
    assert c.stderr[1] == pytest.approx(0.25, rel=1e-12)  # |0.8 - 0.3| / 2
    assert math.isnan(c.mean[2]) and math.isnan(c.stderr[2])
    w = cv.learning_curves(sw, x="wall_seconds", grid=[0.25, 1.3, 3.5])[("envA", "midpoint")]
    # 0.25 s: only seed 1 has evaluated (seeds 0 and 2 first evaluate at 0.5 s and 0.3 s)
    assert w.n_seeds.tolist() == [1, 3, 1]
    assert w.mean[0] == pytest.approx(0.1) and math.isnan(w.stderr[0])  # one seed: NaN
    assert w.mean[1] == pytest.approx((0.4 + 0.1 + 0.3) / 3, rel=1e-12)
    assert w.stderr[1] == pytest.approx(_se(0.4, 0.1, 0.3), rel=1e-12)
    assert w.mean[2] == pytest.approx(0.3)  # seed 2 only (seeds 0, 1 ended at 3.0, 2.5 s)
    one = cv.learning_curves(sw)[("envB", "midpoint")]
    assert one.n_seeds.tolist() == [1, 1] and np.isnan(one.stderr).all()
    lin = cv.learning_curves(sw, grid=5)[("envA", "seq")]
    assert lin.x.tolist() == [0, 100, 200, 300, 400]
    # seed 5 stops after x = 80: from x = 100 on, seed 3 alone
    assert lin.mean.tolist() == [0.0, 0.25, 0.25, 0.25, 0.5]
    assert lin.n_seeds.tolist() == [2, 1, 1, 1, 1]


def test_learning_curves_rejects_bad_arguments(sweep_dir: Path) -> None:
    sw = cv.read_sweep(sweep_dir)
    with pytest.raises(InputError, match="x must be"):
        cv.learning_curves(sw, x="iteration")
    with pytest.raises(InputError, match="no column 'nosuch'"):
        cv.learning_curves(sw, column="nosuch")
    with pytest.raises(InputError, match="increasing"):
        cv.learning_curves(sw, grid=[3.0, 1.0])


# ----------------------------------------------------------------------------------------
# running mean threshold
# ----------------------------------------------------------------------------------------
def test_running_mean_threshold_by_hand() -> None:
    sr = [0.2, 0.9, 0.9, 0.9, 0.9, 0.8, 1.0, 1.0, 0.9, 0.9]
    rows = [{"timesteps": 100 * i, "wall_seconds": 1.5 * i, "success_rate": s}
            for i, s in enumerate(sr)]
    # running means of 5: 0.76 (i=4), 0.88 (i=5), 0.90 (i=6): reached at i = 6
    hit = cv.running_mean_threshold(rows, 0.9)
    assert hit is not None
    assert (hit.index, hit.timesteps, hit.wall_seconds) == (6, 600.0, 9.0)
    assert hit.running_mean == pytest.approx(0.9)
    assert cv.running_mean_threshold(rows, 0.85).index == 5
    assert cv.running_mean_threshold(rows, 0.95) is None  # best window mean is 0.92
    assert cv.running_mean_threshold(rows[:4], 0.0) is None  # no full window
    assert cv.running_mean_threshold(rows, 0.9, window=1).index == 1
    with pytest.raises(InputError, match="window"):
        cv.running_mean_threshold(rows, 0.9, window=0)


# ----------------------------------------------------------------------------------------
# the CLI and the figure
# ----------------------------------------------------------------------------------------
def _csv_rows(path: Path) -> dict[tuple[str, str, str, float], dict[str, str]]:
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["env", "variant", "x_kind", "x", "mean", "stderr", "n_seeds"]
    return {(r["env"], r["variant"], r["x_kind"], float(r["x"])): r for r in rows}


def test_plot_curves_cli_writes_png_and_csv(sweep_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "figs" / "fig2.png"
    res = CliRunner().invoke(app, ["plot-curves", str(sweep_dir), "--out", str(out)])
    assert res.exit_code == 0, res.output
    img = matplotlib.image.imread(out)
    assert img.ndim == 3 and img.shape[0] > 400 and img.shape[1] > 800
    rows = _csv_rows(out.with_suffix(".csv"))
    r = rows[("envA", "midpoint", "timesteps", 100.0)]
    assert float(r["mean"]) == pytest.approx((0.4 + 0.5 + 0.2) / 3, rel=1e-12)
    assert float(r["stderr"]) == pytest.approx(_se(0.4, 0.5, 0.2), rel=1e-12)
    assert r["n_seeds"] == "3"
    r = rows[("envA", "midpoint", "timesteps", 300.0)]
    assert (float(r["mean"]), float(r["stderr"]), r["n_seeds"]) == \
        (pytest.approx(0.95), pytest.approx(0.05), "2")
    r = rows[("envA", "seq", "timesteps", 80.0)]  # seed 3 holds 0.25 from x = 50
    assert float(r["mean"]) == pytest.approx(0.5)
    assert float(r["stderr"]) == pytest.approx(_se(0.25, 0.75), rel=1e-12)
    r = rows[("envA", "midpoint", "wall_seconds", 1.2)]  # 0.4 (s0), 0.1 (s1), 0.3 (s2)
    assert float(r["mean"]) == pytest.approx((0.4 + 0.1 + 0.3) / 3, rel=1e-12)
    r = rows[("envB", "midpoint", "wall_seconds", 0.2)]
    assert float(r["mean"]) == 0.6 and r["stderr"] == "nan" and r["n_seeds"] == "1"
    r = rows[("envA", "seq", "timesteps", float(np.nextafter(80.0, np.inf)))]
    assert (float(r["mean"]), r["stderr"], r["n_seeds"]) == (0.25, "nan", "1")
    # every (env, variant) on both x axes: evaluation points plus the ends of shorter logs,
    # (5 + 1) + (4 + 1) + 2 timesteps points, (10 + 2) + (4 + 1) + 2 wall points
    assert sum(k[2] == "timesteps" for k in rows) == 13
    assert sum(k[2] == "wall_seconds" for k in rows) == 19


def test_figure_has_one_panel_per_env_and_x_axis(sweep_dir: Path, tmp_path: Path) -> None:
    fig, png, _ = plot_curves(sweep_dir, tmp_path / "f.png")
    axes = fig.axes
    assert len(axes) == 4  # 2 environments x (evaluations of C, wall time)
    assert [a.get_title() for a in axes] == ["envA", "envB", "envA", "envB"]
    assert "all-inclusive" in axes[0].get_xlabel() and "(s)" in axes[2].get_xlabel()
    labels = [t.get_text() for t in axes[0].get_legend().get_texts()]
    assert labels == ["midpoint (3 seeds)", "seq (2 seeds)"]
    assert len(axes[0].collections) == 2  # one band per variant
    assert png.stat().st_size > 10_000


def _cli_fails(args: list[str], out: Path, *needles: str) -> None:
    res = CliRunner().invoke(app, ["plot-curves", *args, "--out", str(out)])
    assert res.exit_code == 2, res.output
    msg = res.output.strip()
    assert msg.startswith("error: ") and "\n" not in msg and "Traceback" not in res.output
    for n in needles:
        assert n in msg, msg
    assert not out.parent.exists() or not any(out.parent.iterdir())  # nothing written


def test_plot_curves_bad_input(sweep_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "o" / "fig.png"
    _cli_fails([str(tmp_path / "nosuch")], out, "does not exist")
    (tmp_path / "empty").mkdir()
    _cli_fails([str(tmp_path / "empty")], out, "no runs")
    bad = sweep_dir / "envA" / "seq" / "seed-5" / "metrics.csv"
    good = bad.read_text()
    bad.write_text(good.rsplit(",", 3)[0])  # last row truncated
    _cli_fails([str(sweep_dir)], out, str(bad), "corrupt")
    bad.write_bytes(b"\x89PNG\x00\xff\xfe garbage")
    _cli_fails([str(sweep_dir)], out, str(bad), "corrupt")
    bad.write_text(HEADER + "\n")
    _cli_fails([str(sweep_dir)], out, str(bad), "no evaluation rows")
    bad.write_text(good.replace("0.6,", "oops,"))  # wall_seconds not a number
    _cli_fails([str(sweep_dir)], out, str(bad), "wall_seconds")
    bad.unlink()
    _cli_fails([str(sweep_dir)], out, str(bad), "missing")
    bad.write_text(good)
    _cli_fails([str(sweep_dir), "--column", "nosuch"], out, "nosuch")
    _cli_fails([str(sweep_dir)], tmp_path / "p" / "fig.txt", ".png")


# ----------------------------------------------------------------------------------------
# the report's learning curve: honest x axes
# ----------------------------------------------------------------------------------------
def test_report_learning_curve_labels_the_all_inclusive_count() -> None:
    cmp = SimpleNamespace(exact=SimpleNamespace(ceiling_rate=1.0),
                          straight=SimpleNamespace(success_rate=0.3),
                          metric="matsumoto", depth=6, eps=0.1)
    rows = [{"timesteps": 10 * i, "timesteps_paper": 2 * i, "wall_seconds": float(i),
             "success_rate": 0.1 * i} for i in range(5)]
    fig = fg.learning_curve(rows, cmp)
    labels = [a.get_xlabel() for a in fig.axes]
    assert len(labels) == 3
    assert "all-inclusive" in labels[0] and "minutes" in labels[1]
    assert "paper" in labels[2] and "all-inclusive" not in labels[2]
    # logarithmic evaluations (the rise is early): the row at 0 evaluations is not drawn
    assert fig.axes[2].lines[0].get_xdata().tolist() == [2, 4, 6, 8]
    assert all(a.get_xscale() == "log" for a in fig.axes) and "log axis" in labels[0]
    same = [dict(r, timesteps_paper=r["timesteps"]) for r in rows]
    assert len(fg.learning_curve(same, cmp).axes) == 2
    assert fg.learning_curve([], cmp) is None
    old = [{k: v for k, v in r.items() if k != "timesteps_paper"} for r in rows]
    old_fig = fg.learning_curve(old, cmp)  # log written before the contract
    assert len(old_fig.axes) == 2 and "not known" in old_fig.axes[0].get_xlabel()


def test_length_ratio_figure_shows_ratio_minus_one_on_a_log_axis() -> None:
    """1.001 and 1.01 land a decade apart; the straight line has a panel's curve of its own;
    a ratio at or below 1 is drawn at the floor and counted."""
    r = {"learned": np.array([1.001, 1.01, 1.0, np.nan]),
         "searched": np.array([1.0005, 1.002, 1.0, 1.0]),
         "straight": np.array([1.2, 1.5, 2.5, 1.0])}
    cmp = SimpleNamespace(metric="matsumoto", pairs=np.zeros((4, 2, 2)),
                          searched=object(), ratios=lambda w, ms="length": r[w])
    fig = fg.length_ratios(cmp)
    left, right = fig.axes
    assert left.get_xscale() == right.get_xscale() == "log"
    assert "ratio - 1" in left.get_xlabel()
    labels = [t.get_text() for t in left.get_legend().get_texts()]
    assert "median 0.1 %, 1 at <= 1e-06" in labels[0]
    steps = {ln.get_label().split(" (")[0]: ln.get_xdata() for ln in right.lines}
    assert set(steps) == {"learned", "learned + route search", "straight line"}
    np.testing.assert_allclose(sorted(steps["learned"]), [1e-6, 1e-3, 1e-2], rtol=1e-6)
