"""Metrics written to be wrong in one way each: fixtures of
``tests/validation/testing/test_check.py``.

Importing this module registers them (as a user's ``--metric-module`` would), so the tests
import it only in a subprocess (``geodesics check --metric-module tests/helpers/broken_metrics.py
--metric NAME``, or a user's pytest file), never into the test session's registry.

Each mistake is one a user can make writing a metric; the property that must name it is in
``EXPECTED``:

* ``broken-domain``: ``|v| (1 + sqrt(0.81 - |x|**2))`` on the unit disk: a square root
  whose argument was meant to stay positive, NaN for ``|x| > 0.9`` (inside the declared
  domain);
* ``broken-finite-positive``: ``|v| - 2.5 v_0 v_1 / |v|``: a cross term too strong,
  negative for directions near the diagonal (``sin 2 theta > 0.8``) at every point
  (finite and positive along the coordinate axes, where ``domain`` looks);
* ``broken-homogeneity``: ``sqrt(v.v + 0.01)`` for ``sqrt(v.v)`` (an epsilon added to
  smooth the norm at 0: not 1-homogeneous, and ``F(x, 0) != 0``; still subadditive,
  strongly convex, smooth and symmetric);
* ``broken-subadditivity``: ``|v| (1 + 0.3 cos 4 theta)``, ``theta`` the angle of ``v``:
  a four-lobed unit ball that is not convex (``h + h'' = 1 - 4.5 cos 4 theta`` changes
  sign), declared not smooth (so strong convexity is not asked; subadditivity must see
  it);
* ``broken-convex-cap``: ``|v| (1 + c(x) cos 4 theta)`` with ``c(x) = 3 max(0, x_0 -
  0.6)**3`` on the unit disk: Finsler except in the cap ``x_0 > 0.6 + (1/45)**(1/3) =
  0.881`` (2.4% of the disk), where ``c > 1/15`` makes the unit ball non-convex; declared
  convex everywhere;
* ``broken-negative``: ``-|v|``, a sign slip: negative everywhere, the domain's centre
  included, so the fault is F's (``finite-positive``), not the domain's extent;
* ``broken-reversible``: a drift term ``0.3 v_0`` in a metric declared reversible;
* ``broken-positive``: a Randers drift ``<b(x), v>`` with ``|b(x)| = 1.5 |x_0| > 1`` near
  the sides of the box, where ``F`` is negative against the drift (found by ``domain``
  along the coordinate axes, with the region ``|x0| > 2/3``);
* ``broken-lowered``: the Poincare disk with a hand-written numpy/torch evaluator (a
  ``lowered_F`` override) whose exponent is 2.02 for 2 -- the symbolic ``F`` the solver
  uses is right;
* ``broken-smooth``: ``(1 + 0.3 |x_0|) |v|``, a kink across ``x_0 = 0``, left declared
  smooth (the default);
* ``broken-closed-form``: the Poincare disk whose closed-form distance lacks the factor 2
  in ``arccosh(1 + 2 |x - y|**2 / ((1 - |x|**2) (1 - |y|**2)))``.

``VALID`` lists metrics written right that must pass (exit 0; inconclusive results
allowed): ``valid-nonsmooth`` is ``(1 + 0.3 |x_0|) |v|`` declared ``smooth = False``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from finsler import Box, ClosedFormMetric, Disk, Domain, Metric, Task, register_metric

EXPECTED = {
    "broken-domain": "domain",
    "broken-finite-positive": "finite-positive",
    "broken-homogeneity": "homogeneity",
    "broken-subadditivity": "subadditivity",
    "broken-convex-cap": "strong-convexity",
    "broken-negative": "finite-positive",
    "broken-reversible": "reversibility",
    "broken-positive": "domain",
    "broken-lowered": "lowered-forms",
    "broken-smooth": "smoothness",
    "broken-closed-form": "closed-form-distance",
}

VALID = ("valid-nonsmooth",)


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
class Negative(Metric):
    """``F(x, v) = -|v|`` on ``[-1, 1]**2``: the sign is wrong everywhere."""

    name: ClassVar[str] = "broken-negative"
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return -_norm(v)


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


def _cos4(v: ca.SX) -> ca.SX:
    """``cos 4 theta`` of the angle of ``v`` (2-D), as a polynomial in ``v / |v|``."""
    r2 = ca.dot(v, v)
    return (v[0] ** 4 - 6 * v[0] ** 2 * v[1] ** 2 + v[1] ** 4) / (r2 * r2)


@register_metric
@dataclass(frozen=True)
class NaNOutside(Metric):
    """``F(x, v) = |v| (1 + sqrt(0.81 - |x|**2))`` on the unit disk: NaN for ``|x| > 0.9``."""

    name: ClassVar[str] = "broken-domain"
    task: ClassVar[Task] = Task(depth=4, eps=0.3)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return _norm(v) * (1 + ca.sqrt(0.81 - ca.dot(x, x)))


@register_metric
@dataclass(frozen=True)
class NegativeOnDiagonals(Metric):
    """``F(x, v) = |v| - 2.5 v_0 v_1 / |v|`` on ``[-1, 1]**2``."""

    name: ClassVar[str] = "broken-finite-positive"
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return _norm(v) - 2.5 * v[0] * v[1] / _norm(v)


@register_metric
@dataclass(frozen=True)
class FourLobes(Metric):
    """``F(x, v) = |v| (1 + 0.3 cos 4 theta)`` on ``[-1, 1]**2``, declared not smooth."""

    name: ClassVar[str] = "broken-subadditivity"
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    smooth: ClassVar[bool] = False
    convexity_note: ClassVar[str] = "claimed convex, declared not smooth"
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return _norm(v) * (1 + 0.3 * _cos4(v))


@register_metric
@dataclass(frozen=True)
class ConvexCap(Metric):
    """``F(x, v) = |v| (1 + c(x) cos 4 theta)``, ``c(x) = 3 max(0, x_0 - 0.6)**3``, on the
    unit disk: its unit ball is not convex where ``c > 1/15``, ``x_0 > 0.881`` (2.4% of
    the disk); declared Finsler everywhere."""

    name: ClassVar[str] = "broken-convex-cap"
    task: ClassVar[Task] = Task(depth=4, eps=0.3)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        c = 3.0 * ca.fmax(0.0, x[0] - 0.6) ** 3
        return _norm(v) * (1 + c * _cos4(v))


@register_metric
@dataclass(frozen=True)
class KinkedDeclaredSmooth(Metric):
    """``F(x, v) = (1 + 0.3 |x_0|) |v|`` on ``[-1, 1]**2``, left declared smooth."""

    name: ClassVar[str] = "broken-smooth"
    task: ClassVar[Task] = Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + 0.3 * ca.fabs(x[0])) * _norm(v)


@register_metric
@dataclass(frozen=True)
class KinkedDeclaredNotSmooth(KinkedDeclaredSmooth):
    """The same ``(1 + 0.3 |x_0|) |v|``, correctly declared not smooth: a valid metric."""

    name: ClassVar[str] = "valid-nonsmooth"
    smooth: ClassVar[bool] = False
    convexity_note: ClassVar[str] = "Riemannian (conformal), not smooth across x0 = 0"
