"""Reports show certificates beyond 2-D (issue 46, item 5): a 3-D metric with a closed-form
distance (``poincare-slab``) and a 4-D conformal test metric (the split lower bound of
``solvers.certify``), checked against exact distances; the JSON, the markdown and the
CLI's lines carry the rows; ``certify=0`` shows none."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import finsler
from validation import StraightLine, build_report
from validation.report_certify import cli_lines, md_certified, preset_for

from tests.helpers.metrics.report_certify import Valley


def _report(tmp: Path, metric: finsler.Metric, pairs: np.ndarray, certify: int | None
            ) -> tuple[dict, str]:
    doc = build_report(None, tmp, pairs=pairs, policy=StraightLine(metric), workers=1,
                       progress=False, continuum=False, quick=True, certify=certify)
    on_disk = json.loads((tmp / "report.json").read_text())  # strict JSON: no NaN
    assert on_disk.get("certified") == doc.get("certified")
    return doc, (tmp / "report.md").read_text()


@pytest.fixture(scope="module")
def slab(tmp_path_factory) -> tuple[finsler.Metric, np.ndarray, dict, str]:
    m = finsler.get_metric("poincare-slab")
    pairs = finsler.sample_pairs(m, 2, 20261231)
    doc, md = _report(tmp_path_factory.mktemp("slab"), m, pairs, 1)
    return m, pairs, doc, md


def test_3d_report_interval_contains_the_closed_form(slab) -> None:
    m, pairs, doc, md = slab
    cert = doc["certified"]
    assert cert["mesh"] == preset_for(m, True) == "coarse" and len(cert["pairs"]) == 1
    r = cert["pairs"][0]
    d = float(m.distance(pairs[:1, 0], pairs[:1, 1])[0])
    assert r["lower"] <= d <= r["upper"]
    assert r["gap"] < 0.2 and r["lower"] > 0
    assert r["status"] in ("certified", "budget_reached")
    assert r["work"]["cells"] > 0 and r["cpu_seconds"] > 0
    assert set(r["rigour"]) >= {"upper", "lower"}
    # the learned (straight) path is never shorter than d: its excess bound is >= 0
    assert r["learned_excess_bound"] >= (r["learned_length_proven_upper"] / d - 1) - 1e-12
    assert r["learned_length_proven_upper"] >= d
    assert "## Certified distances" in md and f"{r['lower']:.6g}" in md
    assert any(f"{r['lower']:.6g} <= d <= {r['upper']:.6g}" in line for line in cli_lines(doc))


def test_4d_conformal_report_gives_a_lower_bound_above_the_trivial_one(tmp_path) -> None:
    m = Valley()
    rng = np.random.default_rng(20261231)
    a, b = np.sort(rng.uniform(-0.9, 0.9, 2))
    c = rng.uniform(-0.9, 0.9)
    pairs = np.array([[[a, 0.0, 0.0, c], [b, 0.0, 0.0, c]]])
    d = float(b - a + (b**3 - a**3) / 3.0)
    doc, md = _report(tmp_path, m, pairs, None)  # quick default: every pair (here one)
    (r,) = doc["certified"]["pairs"]
    assert r["lower"] <= d * (1 + 1e-12)
    assert r["upper"] >= d * (1 - 1e-12)
    assert r["lower"] > r["trivial_lower"] * (1 + 1e-3)
    assert r["bound_by"] in ("full", "split", "merged") and r["upper_source"] == "path"
    assert r["ratio"] == pytest.approx(r["lower"] / r["upper"], rel=1e-12)
    assert "boxes" in r["work"] or "enclosures" in r["work"]
    assert "trivial bound" in md and r["bound_by"] in md
    lines = md_certified(doc)
    assert any(line.startswith("| 0 |") and r["status"] in line for line in lines)


def test_certify_zero_shows_no_certificate(tmp_path) -> None:
    m = finsler.get_metric("randers")
    doc, md = _report(tmp_path, m, finsler.default_pairs(m)[:2], 0)
    assert "certified" not in doc and "Certified distances" not in md
    assert cli_lines(doc) == []
