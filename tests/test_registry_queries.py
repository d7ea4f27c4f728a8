"""Code asks the metrics what they can do (``finsler.list_metrics(provides=..., dim=...)``)
instead of keeping lists of their names."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

import finsler
from finsler import Box
from finsler.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class _Flat(finsler.Metric):
    """A user's 2-D metric with a closed form: Euclidean on a box."""

    name: ClassVar[str] = "test-flat-closed"

    @property
    def domain(self) -> Box:
        return Box((-1.0, -1.0), (1.0, 1.0))

    def F_sx(self, x, v):
        import casadi as ca
        return ca.sqrt(ca.dot(v, v))

    def distance(self, x, y):
        return np.linalg.norm(np.asarray(y) - np.asarray(x), axis=-1)


@dataclass(frozen=True)
class _FlatNoForm(_Flat):
    name: ClassVar[str] = "test-flat-open"

    # no closed form: the hook is not overridden
    distance = finsler.Metric.distance


def test_list_metrics_filters_by_what_a_metric_provides() -> None:
    finsler.register_metric(_Flat)
    finsler.register_metric(_FlatNoForm)
    try:
        closed = finsler.list_metrics(provides="distance")
        assert "test-flat-closed" in closed and "test-flat-open" not in closed
        # the registered metrics answer for themselves
        for name in finsler.list_metrics():
            m = finsler.get_metric(name)
            assert (name in closed) == m.provides("distance")
        two = finsler.list_metrics(dim=2)
        assert "carlike" not in two and "panda-pole" not in two and "matsumoto" in two
        assert "matsumoto" not in finsler.list_metrics(convex_everywhere=True)
        assert finsler.list_metrics() == list(finsler.registry._REGISTRY)
        with pytest.raises(InputError):
            finsler.list_metrics(provides="no_such_hook")
    finally:
        finsler.registry.unregister_metric("test-flat-closed")
        finsler.registry.unregister_metric("test-flat-open")


def _name_lists(path: Path, names: set[str]) -> list[str]:
    """List, tuple and set literals holding two or more registered metric names."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.List, ast.Tuple, ast.Set)):
            hits = [e.value for e in node.elts
                    if isinstance(e, ast.Constant) and e.value in names]
            if len(hits) >= 2:
                found.append(f"{path.relative_to(ROOT)}:{node.lineno} {hits}")
    return found


def test_no_list_of_metric_names_outside_finsler() -> None:
    names = set(finsler.list_metrics())
    found = []
    for pkg in ("solvers", "learn", "validation"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            found += _name_lists(path, names)
    assert not found, "ask finsler.list_metrics(provides=..., dim=...) instead:\n" + \
        "\n".join(found)
