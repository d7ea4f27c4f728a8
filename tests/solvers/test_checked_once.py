"""Input is checked once, at the public boundary (issue 49, item 3): from the command line
to the solver, a start/goal pair, the metric and the size enter the checks of
:mod:`solvers.inputs` once each (before: 7 entries without --tol, 12 with it)."""

from __future__ import annotations

import collections
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from typer.testing import CliRunner

import finsler
import finsler.domains
import solvers
import solvers.inputs
from validation.cli import app

CHECKS = {"as_metric", "check_pairs", "check_segments", "check_point"}


@contextmanager
def counting() -> Iterator[collections.Counter]:
    """Count calls of the checks of solvers.inputs, and of Domain.check made by them or by
    the solvers (not the metric's own evaluation checks)."""
    counts: collections.Counter = collections.Counter()
    inputs, domains = solvers.inputs.__file__, finsler.domains.__file__

    def prof(frame, event, arg):
        if event != "call":
            return
        code = frame.f_code
        if code.co_filename == inputs and code.co_name in CHECKS:
            counts[code.co_name] += 1
        elif code.co_filename == domains and code.co_name == "check":
            caller = frame.f_back.f_code.co_filename
            if "finsler" not in caller:
                counts["domain.check"] += 1

    sys.setprofile(prof)
    try:
        yield counts
    finally:
        sys.setprofile(None)


@pytest.mark.parametrize("tol", [None, "1e-4"])
def test_cli_solve_checks_each_input_once(tol: str | None) -> None:
    args = ["solve", "--metric", "poincare", "--start", "0.1,0.2", "--goal", "0.4,-0.3",
            "--segments", "16", "--json", *(["--tol", tol] if tol else [])]
    with counting() as counts:
        res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    # one check of the metric, the pair (starts and goals: two domain checks), the size;
    # with --tol also max_segments (a size of its own)
    assert counts["as_metric"] == 1 and counts["check_pairs"] == 1, counts
    assert counts["check_point"] == 0 and counts["domain.check"] == 2, counts
    assert counts["check_segments"] == (2 if tol else 1), counts


def test_solve_geodesic_checks_each_input_once() -> None:
    m = finsler.get_metric("poincare")
    with counting() as counts:
        r = solvers.solve_geodesic(m, [0.1, 0.2], [0.4, -0.3], 16, tol=1e-4, minmax=True)
    assert r.converged
    assert counts["check_point"] == 2 and counts["domain.check"] == 2, counts  # start, goal
    assert counts["as_metric"] == 1 and counts["check_pairs"] == 0, counts
    assert counts["check_segments"] == 2, counts  # segments and max_segments


def test_checks_still_fail_at_the_boundary() -> None:
    m = finsler.get_metric("poincare")
    with pytest.raises(finsler.DomainError, match="--goal"):
        solvers.solve_batch(m, np.array([[[0.1, 0.2], [2.0, 0.0]]]), 8, progress=False,
                            names=("--start", "--goal"))
    with pytest.raises(finsler.InputError, match="tol must be"):
        solvers.solve_geodesic(m, [0.1, 0.2], [0.4, -0.3], 8, tol=2.0)
    with pytest.raises(finsler.InputError, match="max_segments"):
        solvers.solve_batch(m, np.array([[[0.1, 0.2], [0.4, 0.0]]]), 32768, tol=1e-3,
                            progress=False)
    res = CliRunner().invoke(app, ["solve", "--metric", "poincare", "--start", "0.1,0.2",
                                   "--goal", "2,0"])
    assert res.exit_code == 2 and "--goal" in res.output


@pytest.mark.parametrize("given_path", [False, True])
def test_certify_checks_each_input_once(given_path: bool) -> None:
    # before: the pair entered the checks 6 times (certify's two domain checks, then
    # solve_geodesic's check_point twice, each with its own domain check)
    m = finsler.get_metric("poincare")
    s, g = np.array([0.1, 0.2]), np.array([0.4, -0.3])
    path = np.linspace(s, g, 9) if given_path else None
    with counting() as counts:
        r = solvers.certify(m, s, g, solvers.MeshSpec(h_path=0.2, directions=16,
                                                      target_gap=0.5), path=path)
    assert r.converged and r.lower <= float(m.distance(s, g)[0]) <= r.upper
    assert counts["as_metric"] == 1 and counts["check_point"] == 0, counts
    # start and goal, plus the given path's own check
    assert counts["domain.check"] == (3 if given_path else 2), counts
    assert counts["check_segments"] == (0 if given_path else 1), counts  # the solve's size


def test_certify_still_refuses_bad_input_at_the_boundary() -> None:
    m = finsler.get_metric("poincare")
    with pytest.raises(finsler.DomainError, match="goal"):
        solvers.certify(m, [0.1, 0.2], [2.0, 0.0])
    with pytest.raises(finsler.InputError, match="segments"):
        solvers.certify(m, [0.1, 0.2], [0.4, -0.3], solvers.MeshSpec(segments=1 << 17))
