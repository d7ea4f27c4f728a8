"""One shape of result (issue 49, item 2): every public result type derives from
:class:`finsler.status.Result`, says ``status`` / ``converged`` / ``wall_time``, has a
``to_dict`` that standard JSON holds (no NaN, no Infinity), and ``strict()`` raises
:class:`solvers.SolverError` on a non-converged result of each type; ``strict=True`` in the
API does the same."""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import numpy as np
import pytest

import finsler
import solvers
from finsler.status import CertifyStop, Outcome, PropertyOutcome, Result, json_ready
from solvers import (
    CertifyStatus,
    DistanceStatus,
    ExpStatus,
    LogStatus,
    MeshSpec,
    SolverError,
    Status,
)

PAIR = (np.array([0.1, 0.2]), np.array([0.4, -0.3]))
QUICK = MeshSpec(h_path=0.2, directions=16, target_gap=1e-9, max_rounds=1)  # budget ends
LOOSE = MeshSpec(h_path=0.2, directions=16, target_gap=0.5)  # certified in one round


@pytest.fixture(scope="module")
def results() -> dict[str, Any]:
    """One result of each public type, from the public API (poincare: closed-form
    distance, cheap)."""
    m = finsler.get_metric("poincare")
    s, g = PAIR
    geo = solvers.solve_geodesic(m, s, g, 8, minmax=True)
    return {
        "GeodesicResult": geo,
        "MinMaxResult": geo.minmax,
        "MidpointResult": solvers.midpoint(m, s, g, 8),
        "tol": solvers.solve_geodesic(m, s, g, 8, tol=1e-3),
        "batch": solvers.solve_batch(m, np.stack([s, g])[None], 8, progress=False)[0],
        "DistanceResult": solvers.distance(m, s, g),
        "ExpResult": solvers.exp_map(m, s, np.array([0.3, 0.1])),
        "LogResult": solvers.log_map(m, s, g),
        "CertifyResult": solvers.certify(m, s, g, LOOSE),
    }


# a non-converged status of each result type's family
NOT_CONVERGED: dict[str, Outcome] = {
    "GeodesicResult": Status.MAX_ITERATIONS, "MinMaxResult": Status.MAX_ITERATIONS,
    "tol": Status.RESTORATION_FAILED, "batch": Status.INFEASIBLE,
    "DistanceResult": DistanceStatus.SOLVER_FAILED, "ExpResult": ExpStatus.LEFT_DOMAIN,
    "LogResult": LogStatus.NOT_CONVERGED, "CertifyResult": CertifyStatus.LP_FAILED,
}
KINDS = ["GeodesicResult", "MinMaxResult", "MidpointResult", "tol", "batch",
         "DistanceResult", "ExpResult", "LogResult", "CertifyResult"]


def _not_converged(res: Any, kind: str) -> Any:
    if kind == "MidpointResult":  # its status is its geodesic's
        return dataclasses.replace(res, geodesic=_not_converged(res.geodesic,
                                                                "GeodesicResult"))
    return dataclasses.replace(res, status=NOT_CONVERGED[kind])


def test_every_public_result_type_is_listed() -> None:
    public = {name for name in solvers.__all__ if name.endswith("Result")}
    assert public == {k for k in KINDS if k[0].isupper()}


@pytest.mark.parametrize("kind", KINDS)
def test_result_shares_the_base(results: dict[str, Any], kind: str) -> None:
    res = results[kind]
    assert isinstance(res, Result)
    assert isinstance(res.status, Outcome) and res.converged is res.status.converged
    assert res.converged, res.status  # the pair is an easy one: every method converges
    assert isinstance(res.wall_time, float) and res.wall_time >= 0
    assert res.strict() is res


@pytest.mark.parametrize("kind", KINDS)
def test_to_dict_is_standard_json(results: dict[str, Any], kind: str) -> None:
    res = results[kind]
    d = res.to_dict()
    text = json.dumps(d, allow_nan=False)  # raises on NaN / Infinity
    back = json.loads(text)
    assert back == d  # only JSON types: lists, not arrays; labels, not enums
    assert back["status"] == res.status.label
    for key in ("points", "point", "velocity", "distance", "lower", "upper"):
        if hasattr(res, key) and not callable(getattr(res, key)):
            want = getattr(res, key)
            np.testing.assert_array_equal(np.asarray(back[key]), np.asarray(want))


@pytest.mark.parametrize("kind", KINDS)
def test_strict_raises_on_a_non_converged_result(results: dict[str, Any], kind: str) -> None:
    bad = _not_converged(results[kind], kind)
    assert not bad.converged
    with pytest.raises(SolverError, match=bad.status.label) as err:
        bad.strict()
    assert err.value.result is bad
    json.dumps(bad.to_dict(), allow_nan=False)


def test_non_finite_numbers_are_null_in_json(results: dict[str, Any]) -> None:
    res = dataclasses.replace(results["GeodesicResult"], energy=float("inf"),
                              status=Status.INFEASIBLE)
    assert res.to_dict()["energy"] is None
    dist = results["DistanceResult"]
    assert dataclasses.replace(dist, upper_bound=float("inf")).to_dict()["upper_bound"] is None
    assert json_ready({"a": np.float64("nan"), "b": [np.inf, 1.5]}) == {"a": None,
                                                                          "b": [None, 1.5]}


def test_strict_in_the_api() -> None:
    m = finsler.get_metric("poincare")
    s, g = PAIR
    # the disk's boundary is reached long before t = 1 at this speed
    with pytest.raises(SolverError, match="left_domain"):
        solvers.exp_map(m, s, np.array([30.0, 0.0]), strict=True)
    with pytest.raises(SolverError, match="budget_reached") as err:
        solvers.certify(m, s, g, QUICK, strict=True)
    assert err.value.result.stopped_by is CertifyStop.MAX_ROUNDS
    assert not solvers.certify(m, s, g, QUICK).converged  # default stays False


def test_string_outcomes_are_members_with_their_old_words() -> None:
    from validation.testing.engine import NOT_RUN, PropertyResult

    r = PropertyResult("p", "claim", "not-run")
    assert r.status is NOT_RUN is PropertyOutcome.NOT_RUN
    assert r.status == "not-run" and r.to_dict()["status"] == "not-run"
    assert {"not-run": 1}[r.status] == 1
    with pytest.raises(finsler.InputError, match="unknown property status"):
        PropertyResult("p", "claim", "passd")
    assert CertifyStop("max_rounds") is CertifyStop.MAX_ROUNDS


def test_strict_in_solve_batch(results: dict[str, Any], monkeypatch: pytest.MonkeyPatch
                               ) -> None:
    import solvers.batch_jobs as bj

    m = finsler.get_metric("poincare")
    pairs = np.stack(PAIR)[None]
    ok = solvers.solve_batch(m, pairs, 8, progress=False, strict=True)  # converges: no raise
    assert ok[0].converged
    bad = _not_converged(results["batch"], "batch")
    monkeypatch.setattr(bj, "_solve_checked", lambda job, store, progress: [bad])
    assert solvers.solve_batch(m, pairs, 8, progress=False) == [bad]  # default: returned
    with pytest.raises(SolverError, match="1 of 1 pairs did not converge") as err:
        solvers.solve_batch(m, pairs, 8, progress=False, strict=True)
    assert err.value.result == [bad]
