"""Shared configuration of the test suite.

The folders mirror the packages (``tests/solvers/newton/test_newton.py`` tests
``solvers/newton/``); shared helpers and the test metrics are in the package
``tests/helpers/`` (``from tests.helpers.metrics.conformal import Conformal4D``). Every
folder of ``tests/`` is a package, so pytest imports the tests as ``tests.<folder>...`` with
the repository's root on ``sys.path``, and ``tests/`` itself never is: there, its folders
named like the packages (``tests/finsler/``, ...) would shadow them.

Markers: ``slow`` (deselected by default; ``-m slow``) and ``mutation`` (the fast focused
tests a mutation run selects: ``benchmarks/mutation.py`` runs a group's test files with
``-m mutation``).
"""

from __future__ import annotations
