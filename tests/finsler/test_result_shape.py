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
    import solvers.geodesic.batches as bj

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


# ----------------------------------------------------------------------------------------
# every public *Result / *Report class of the packages, found by walking their modules
# ----------------------------------------------------------------------------------------
PACKAGES = ("finsler", "solvers", "learn", "validation")


def _public_result_classes(packages: tuple[str, ...] = PACKAGES) -> dict[str, type]:
    """``module.Class`` -> class for every public class named ``*Result`` / ``*Report``
    defined in a module of ``packages`` (private modules and names skipped)."""
    import importlib
    import pkgutil

    found: dict[str, type] = {}
    for pkg_name in packages:
        pkg = importlib.import_module(pkg_name)
        for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{pkg_name}."):
            if any(part.startswith("_") for part in info.name.split(".")):
                continue
            mod = importlib.import_module(info.name)
            for name, obj in vars(mod).items():
                if (isinstance(obj, type) and not name.startswith("_")
                        and name.endswith(("Result", "Report"))
                        and obj.__module__ == mod.__name__ and obj is not Result):
                    found[f"{obj.__module__}.{name}"] = obj
    return found


def _not_on_the_base(classes: dict[str, type]) -> list[str]:
    return sorted(k for k, c in classes.items() if not issubclass(c, Result))


def test_every_public_result_class_derives_from_the_base() -> None:
    classes = _public_result_classes()
    # the walk finds the types of every package (not an empty scan that passes)
    for name in ("solvers.result.CertifyResult", "learn.evaluation.EvalResult",
                 "learn.sweep.SweepResult", "validation.testing.engine.CheckReport",
                 "validation.propositions.Lemma1Report"):
        assert name in classes, name
    assert _not_on_the_base(classes) == []
    for name, cls in classes.items():
        for attr in ("status", "converged", "wall_time", "to_dict", "strict"):
            assert hasattr(cls, attr) or attr in getattr(cls, "__dataclass_fields__", {}), (
                name, attr)


def test_the_walk_catches_a_result_off_the_base(tmp_path: Any,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    # a package with one result type that does not derive from the base is reported
    pkg = tmp_path / "offbase_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "mod.py").write_text("class LooseResult:\n    status = 'passed'\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert _not_on_the_base(_public_result_classes(("offbase_pkg",))) == [
        "offbase_pkg.mod.LooseResult"]


def _learn_and_validation_results() -> dict[str, Any]:
    """One result of each learn / validation type, built directly (cheap)."""
    from learn.evaluation import EvalResult
    from learn.midpoint.search import SearchResult
    from validation.propositions import Prop1Result
    from validation.testing.engine import CheckReport, PropertyResult

    ok = np.array([True, True])
    ev = EvalResult(1.0, 2.0, 0.1, 0.2, 3, ok, np.array([1.0, 3.0]), np.array([0.1, 0.1]),
                    wall_time=0.5)
    prop = PropertyResult("p", "claim", "passed", tried=4, passed=4, seconds=0.25)
    return {
        "EvalResult": ev,
        "SearchResult": SearchResult(np.zeros((2, 3, 2)), 12, wall_time=0.1),
        "PropertyResult": prop,
        "CheckReport": CheckReport("m", {}, 0, 4, [prop], seconds=0.3),
        "Prop1Result": Prop1Result("m", np.zeros(2), np.ones(2), np.array([0.1, 0.01]),
                                   np.array([1.1, 1.01]), np.array([0.1, 0.01]), 1.0, 1.0),
    }


def test_learn_and_validation_results_share_the_shape() -> None:
    from finsler.status import EvalStatus, SearchStatus

    res = _learn_and_validation_results()
    for kind, r in res.items():
        assert isinstance(r, Result) and r.converged, kind
        assert r.strict() is r
        d = r.to_dict()
        assert json.loads(json.dumps(d, allow_nan=False)) == d, kind
        assert d["status"] == r.status.label and d["converged"] is True, kind
    assert res["EvalResult"].status is EvalStatus.SUCCESS
    assert res["SearchResult"].status is SearchStatus.COMPLETED
    assert res["CheckReport"].wall_time == 0.3 and res["PropertyResult"].wall_time == 0.25


def test_learn_and_validation_results_raise_when_not_converged() -> None:
    from finsler.status import EvalStatus, SearchStatus

    res = _learn_and_validation_results()
    ev = dataclasses.replace(res["EvalResult"], success=np.array([True, False]),
                             length=np.array([1.0, np.inf]))
    assert ev.status is EvalStatus.NOT_FINITE
    d = ev.to_dict()
    assert d["per_pair"][1]["length"] is None  # standard JSON: no Infinity
    json.dumps(d, allow_nan=False)
    partial = dataclasses.replace(res["EvalResult"], success=np.array([True, False]))
    assert partial.status is EvalStatus.PARTIAL
    paths = np.zeros((2, 3, 2))
    paths[1, 1, 0] = np.nan
    bad_search = dataclasses.replace(res["SearchResult"], paths=paths)
    assert bad_search.status is SearchStatus.NOT_FINITE
    json.dumps(bad_search.to_dict(), allow_nan=False)
    failed = dataclasses.replace(res["PropertyResult"], status="failed")
    report = dataclasses.replace(res["CheckReport"], results=[failed])
    assert report.status is PropertyOutcome.FAILED
    inconclusive = dataclasses.replace(res["PropertyResult"], status="inconclusive")
    assert dataclasses.replace(res["CheckReport"], results=[inconclusive]).status \
        is PropertyOutcome.INCONCLUSIVE
    farther = dataclasses.replace(res["Prop1Result"], ratio=np.array([1.01, 1.1]))
    assert farther.status is PropertyOutcome.FAILED
    for bad in (ev, partial, bad_search, failed, report, farther):
        with pytest.raises(SolverError, match=bad.status.label):
            bad.strict()


def test_certify_statuses_are_members(results: dict[str, Any]) -> None:
    from finsler.status import LPStatus

    res = results["CertifyResult"]
    assert res.solver_status is Status.SUCCESS
    assert res.lp_status is LPStatus.OPTIMAL and res.lp_status == "optimal"
    d = res.to_dict()
    assert d["solver_status"] == "success" and d["lp_status"] == "optimal"
    m = finsler.get_metric("poincare")
    s, g = PAIR
    given = solvers.certify(m, s, g, LOOSE, path=np.linspace(s, g, 9))
    assert given.solver_status is Status.GIVEN and given.to_dict()["solver_status"] == "given"
