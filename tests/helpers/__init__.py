"""Shared helpers of the test suite: the test metrics (``helpers.metrics``), the metrics
written to be wrong (``helpers.broken_metrics``, imported only in subprocesses: importing it
registers them), dense references (``helpers.linalg``, ``helpers.lp_rows``) and a clock
(``helpers.tick_clock``)."""

from __future__ import annotations

from pathlib import Path

#: this folder, the tests' folder and the repository's
HELPERS = Path(__file__).resolve().parent
TESTS = HELPERS.parent
ROOT = TESTS.parent
