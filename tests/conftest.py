"""Shared configuration of the test suite.

The folders mirror the packages (``tests/solvers/newton/test_newton.py`` tests
``solvers/newton/``); shared helpers and the test metrics are in the package
``tests/helpers/`` (``from helpers.metrics.conformal import Conformal4D``), importable
because this folder is on ``sys.path``. Test file names are unique across folders (pytest
imports them by name).

Markers: ``slow`` (deselected by default; ``-m slow``) and ``mutation`` (the fast focused
tests a mutation run selects: ``benchmarks/mutation.py`` runs a group's test files with
``-m mutation``).
"""

from __future__ import annotations

import sys
from pathlib import Path

_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:  # for ``import helpers`` in every import mode
    sys.path.insert(0, _TESTS)
