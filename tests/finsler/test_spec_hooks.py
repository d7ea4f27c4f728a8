"""A metric's identity (finsler.spec.MetricSpec) and its declared hooks (finsler.hooks)."""

from __future__ import annotations

import ast
import json
import pickle
from pathlib import Path

import numpy as np
import pytest

import finsler
from finsler import InputError, MetricSpec, metric_spec

from tests.helpers.metrics.spec_hooks import Hill, Plain

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", ["matsumoto", "carlike", "euclidean", "randers", "sphere"])
def test_spec_round_trip_through_json(name: str) -> None:
    metric = finsler.get_metric(name)
    spec = MetricSpec.of(metric)
    again = MetricSpec.from_dict(json.loads(json.dumps(spec.to_dict())))
    assert again == spec and hash(again) == hash(spec)
    rebuilt = again.build()
    assert type(rebuilt) is type(metric)
    x = np.array([[0.1] * metric.dim])
    v = np.array([[0.3] + [-0.2] * (metric.dim - 1)])
    assert np.allclose(rebuilt.F(x, v), metric.F(x, v), rtol=0, atol=0)


def test_spec_compare_names_the_differing_parameter() -> None:
    a = metric_spec("matsumoto")
    b = metric_spec("matsumoto", {"height": 2.0})
    assert a != b
    assert a.param_differences(b) == {"height": (1.0, 2.0)}
    assert a == metric_spec("matsumoto", {"height": 1.0, "radius": 1.0})
    assert b.build().height == 2.0


def test_spec_refuses_bad_input() -> None:
    with pytest.raises(InputError, match="no parameter 'heigth'"):
        metric_spec("matsumoto", {"heigth": 2.0})
    with pytest.raises(InputError):
        metric_spec("no-such-metric")
    with pytest.raises(InputError, match="'name'"):
        MetricSpec.from_dict({"params": {}})


def test_declared_hooks_are_found_by_asking_the_metric() -> None:
    plain, hill = Plain(), Hill()
    assert plain.hooks() == ()
    assert not plain.provides("height_map")
    assert set(hill.hooks()) == {"height_map", "convex_radius"}
    assert hill.provides("height_map") and hill.provides("convex_radius")
    assert np.allclose(hill.height_map(np.array([[2.0, 1.0]])), [4.0])
    assert hill.convex_radius == 3.0
    assert plain.convex_radius is None and plain.seed_plan() is None
    with pytest.raises(InputError, match="does not provide the hook 'height_map'"):
        plain.height_map(np.zeros((1, 2)))
    with pytest.raises(InputError):
        plain.provides("no_such_hook")
    assert not plain.provides("seed_curves")
    with pytest.raises(InputError, match="does not provide the hook 'seed_curves'"):
        plain.seed_curves(np.zeros((1, 2)), np.ones((1, 2)), np.linspace(0, 1, 5))
    # the toolkit's own metrics declare theirs the same way
    assert {"height_map", "convex_radius"} <= set(finsler.get_metric("matsumoto").hooks())
    assert finsler.get_metric("carlike").provides("smooth_square_sx")
    assert finsler.get_metric("carlike").provides("seed_curves")
    assert finsler.HOOKS.index("seed_curves") == finsler.HOOKS.index("seed_plan") + 1


def _metric_probes(path: Path) -> list[str]:
    """``getattr(metric, ...)``/``hasattr(metric, ...)`` and ``isinstance(x, <concrete
    metric class>)`` calls in one file."""
    concrete = {n for n in finsler.__all__ if isinstance(getattr(finsler, n), type)
                and issubclass(getattr(finsler, n), finsler.Metric)
                and getattr(finsler, n) is not finsler.Metric}
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
            continue
        if node.func.id in ("getattr", "hasattr") and node.args:
            target = ast.unparse(node.args[0])
            if "metric" in target.lower() and "config" not in target:
                found.append(f"{path}:{node.lineno} {ast.unparse(node)}")
        if node.func.id == "isinstance" and len(node.args) == 2:
            names = {n.id if isinstance(n, ast.Name) else getattr(n, "attr", "")
                     for n in ast.walk(node.args[1])}
            if names & concrete:
                found.append(f"{path}:{node.lineno} {ast.unparse(node)}")
    return found


def test_no_getattr_or_concrete_isinstance_on_metrics_outside_finsler() -> None:
    files = [p for pkg in ("solvers", "learn", "validation") for p in (ROOT / pkg).rglob("*.py")]
    assert files
    probes = [hit for p in files for hit in _metric_probes(p)]
    assert probes == []


def test_derived_geometry_is_built_once_per_metric_and_not_pickled() -> None:


    m = finsler.get_metric("matsumoto")
    builds: list[int] = []

    def build() -> list[int]:
        builds.append(1)
        return [len(builds)]

    first = m.derived("test.thing", build)
    assert m.derived("test.thing", build) is first and builds == [1]
    other = type(m)()  # an equal metric, another instance
    assert other.derived("test.thing", build) == [2]  # per instance, not per class
    with pytest.raises(finsler.InputError, match="key"):
        m.derived("", build)
    x, v = np.array([[0.1, 0.2]]), np.array([[0.3, -0.1]])
    f_before = m.F(x, v)  # lowers F into the instance
    clone = pickle.loads(pickle.dumps(m))
    assert clone == m and "_derived" not in clone.__dict__ and "lowered_F" not in clone.__dict__
    assert np.array_equal(clone.F(x, v), f_before)


def test_a_metric_asked_for_again_is_the_same_instance_with_its_derived_geometry() -> None:
    from finsler import registry

    m = finsler.get_metric("randers", wind_x=0.125)
    assert finsler.get_metric("randers", wind_x=0.125) is m
    assert MetricSpec.from_dict(MetricSpec.of(m).to_dict()).build() is m
    assert finsler.get_metric("randers", wind_x=0.25) is not m
    assert finsler.get_metric("randers", wind_x=0.25) == finsler.get_metric("randers",
                                                                            wind_x=0.25)
    built = m.derived("test.shared", lambda: object())
    assert finsler.get_metric("randers", wind_x=0.125).derived("test.shared", object) is built
    # bounded: the oldest instances are let go
    for k in range(registry.SHARED_INSTANCES + 1):
        finsler.get_metric("randers", wind_x=0.5, wind_y=0.001 * (k + 1))
    assert finsler.get_metric("randers", wind_x=0.125) is not m
