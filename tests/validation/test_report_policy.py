"""Which policy a report uses: ``validation.report.load_report_policy``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from finsler import InputError
from validation.report import load_report_policy


def test_quick_run_of_another_environment_is_not_reused(tmp_path: Path) -> None:
    # an earlier --quick run for carlike left in --out: asked for euclidean (no shipped
    # policy), the report must neither load the carlike policy nor train over it
    run = tmp_path / "quick_run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"env": "carlike", "method": "midpoint"}))
    with pytest.raises(InputError, match="quick run for 'carlike', not 'euclidean'"):
        load_report_policy("euclidean", None, True, tmp_path, progress=False)
    assert sorted(p.name for p in run.iterdir()) == ["config.json"]


def test_without_quick_an_environment_with_no_shipped_policy_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no shipped policy for 'euclidean'"):
        load_report_policy("euclidean", None, False, tmp_path, progress=False)
