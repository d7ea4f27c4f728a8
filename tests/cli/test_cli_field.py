"""``geodesics field``: the grid, the figure and the goal lines; one error line for a bad
source."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from validation.cli import app


def test_field_writes_grid_and_figure(tmp_path):
    r = CliRunner().invoke(app, ["field", "--metric", "poincare", "--source", "0.1,-0.2",
                                 "--goal", "0.5,0.3", "--resolution", "40", "--out",
                                 str(tmp_path)])
    assert r.exit_code == 0, r.output
    values = np.load(tmp_path / "field.npy")
    doc = json.loads((tmp_path / "field.json").read_text())
    assert values.shape == tuple(doc["grid"]["shape"])
    assert (tmp_path / "field.png").stat().st_size > 1000
    line = next(ln for ln in r.output.splitlines() if ln.startswith("goal [0.5, 0.3]"))
    assert abs(float(line.split("distance ")[1].split()[0]) - 1.47881) < 5e-3


def test_bad_source_is_one_error_line(tmp_path):
    for source in ("0.9,0", "nan,0"):
        r = CliRunner().invoke(app, ["field", "--metric", "poincare", "--source", source,
                                     "--out", str(tmp_path)])
        assert r.exit_code == 2
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), r.output
