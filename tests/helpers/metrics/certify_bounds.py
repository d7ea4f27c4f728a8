"""The test metrics of ``tests/solvers/certificates/plane/test_certify_bounds.py``:
Singular, Ridge, Tilt."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import casadi as ca

import finsler


@dataclass(frozen=True)
class Singular(finsler.Metric):
    """F not finite at ``x_1 = -2``, by a floating-point error of each kind: ``invalid``
    (sqrt of a negative number, NaN), ``divide`` (by zero, inf), ``over`` (exp overflow)."""

    kind: str = "invalid"
    name: ClassVar[str] = "singular-bounds-test"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        norm = ca.sqrt(ca.dot(v, v))
        if self.kind == "invalid":
            return ca.sqrt(x[0] + 1) * norm
        if self.kind == "divide":
            return norm / (x[0] + 2)
        return ca.exp(-1000 * x[0]) * norm


@dataclass(frozen=True)
class Ridge(finsler.Metric):
    """F(x, v) = (1 + 4 x_1**2) |v|: ``Hess_z F`` constant (a tight enclosure), ``Hess_v F``
    growing with ``x_1`` (a loose one over wide boxes)."""

    name: ClassVar[str] = "ridge-bounds-test"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + 4 * x[0] ** 2) * ca.sqrt(ca.dot(v, v))


@dataclass(frozen=True)
class Tilt(finsler.Metric):
    """F(x, v) = (1 + x_1 + x_2 / 2) |v|: ``Hess_z F = 0`` (Hz and its centre value both 0
    up to rounding), ``Hess_v F`` varying mildly with x (a tight Ht)."""

    name: ClassVar[str] = "tilt-bounds-test"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + x[0] + 0.5 * x[1]) * ca.sqrt(ca.dot(v, v))
