"""Metrics written to be wrong in one way each: fixtures of ``tests/test_check.py``.

Importing this module registers them (as a user's ``--metric-module`` would), so the tests
import it only in a subprocess (``geodesics check --metric-module tests/broken_metrics.py
--metric NAME``, or a user's pytest file), never into the test session's registry.

Each mistake is one a user can make writing a metric; the property that must name it is in
``EXPECTED``:

* ``broken-homogeneity``: ``sqrt(v.v + 0.01)`` for ``sqrt(v.v)`` (an epsilon added to
  smooth the norm at 0: not 1-homogeneous, and ``F(x, 0) != 0``; still subadditive,
  strongly convex, smooth and symmetric);
* ``broken-reversible``: a drift term ``0.3 v_0`` in a metric declared reversible;
* ``broken-positive``: a Randers drift ``<b(x), v>`` with ``|b(x)| = 1.5 |x_0| > 1`` near
  the sides of the box, where ``F`` is negative against the drift (and, as for any
  convex ``F`` that is negative somewhere, its fundamental tensor is indefinite there);
* ``broken-lowered``: the Poincare disk with a hand-written numpy/torch evaluator (a
  ``lowered_F`` override) whose exponent is 2.02 for 2 -- the symbolic ``F`` the solver
  uses is right;
* ``broken-closed-form``: the Poincare disk whose closed-form distance lacks the factor 2
  in ``arccosh(1 + 2 |x - y|**2 / ((1 - |x|**2) (1 - |y|**2)))``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from finsler import Box, ClosedFormMetric, Disk, Domain, Metric, Task, register_metric

EXPECTED = {
    "broken-homogeneity": "homogeneity",
    "broken-reversible": "reversibility",
    "broken-positive": "finite-positive",
    "broken-lowered": "lowered-forms",
    "broken-closed-form": "closed-form-distance",
}


def _norm(v: ca.SX) -> ca.SX:
    return ca.sqrt(ca.dot(v, v))


@register_metric
@dataclass(frozen=True)
class NotHomogeneous(Metric):
    """``F(x, v) = (1 + x_0**2 / 2) sqrt(v.v + 0.01)`` on ``[-1, 1]**2``: the epsilon should
    not be there."""

    name: ClassVar[str] = "broken-homogeneity"
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + 0.5 * x[0] ** 2) * ca.sqrt(ca.dot(v, v) + 0.01)


@register_metric
@dataclass(frozen=True)
class ClaimsReversible(Metric):
    """``F(x, v) = |v| + 0.3 v_0`` on ``[-1, 1]**2`` (a Randers norm), declared reversible."""

    name: ClassVar[str] = "broken-reversible"
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return _norm(v) + 0.3 * v[0]


@register_metric
@dataclass(frozen=True)
class NegativeSomewhere(Metric):
    """``F(x, v) = |v| + 1.5 x_0 v_0`` on ``[-1, 1]**2``: a drift stronger than 1 where
    ``|x_0| > 2/3``."""

    name: ClassVar[str] = "broken-positive"
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return _norm(v) + 1.5 * x[0] * v[0]


class _HandWritten:
    """A hand-written evaluator in the lowered program's calling convention: ``(x, v)``
    batches ``(N, 2)`` (numpy or torch) -> ``((N, 1),)``; the typo: ``|x|**2.02``."""

    def __call__(self, x: Any, v: Any) -> tuple[Any]:
        r2 = (x * x).sum(-1)
        f = 2.0 * (v * v).sum(-1) ** 0.5 / (1.0 - r2**1.01)
        return (f[:, None],)


@register_metric
@dataclass(frozen=True)
class DriftingLowered(Metric):
    """The Poincare disk ``F = 2 |v| / (1 - |x|**2)`` (radius 0.8) with a hand-written
    numpy/torch evaluator that computes ``1 - |x|**2.02``."""

    name: ClassVar[str] = "broken-lowered"
    task: ClassVar[Task] = Task(depth=4, eps=0.3)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Disk(radius=0.8))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return 2.0 * _norm(v) / (1.0 - ca.dot(x, x))

    @functools.cached_property
    def lowered_F(self) -> Any:  # type: ignore[override]
        return _HandWritten()


@register_metric
@dataclass(frozen=True)
class WrongClosedForm(ClosedFormMetric):
    """The Poincare disk (radius 0.8) with a closed-form distance missing a factor 2."""

    name: ClassVar[str] = "broken-closed-form"
    task: ClassVar[Task] = Task(depth=4, eps=0.3)
    reversible: ClassVar[bool] = True

    @property
    def domain(self) -> Domain:
        return Disk(radius=0.8)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return 2.0 * _norm(v) / (1.0 - ca.dot(x, x))

    def _distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        num = np.sum((x - y) ** 2, axis=1)  # should be 2 * ...
        den = (1 - np.sum(x * x, axis=1)) * (1 - np.sum(y * y, axis=1))
        return np.arccosh(1.0 + num / den)
