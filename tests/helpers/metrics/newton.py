"""The test metrics of ``tests/solvers/newton/test_newton.py``: Cheaper, Bump, WallAbove,
Tilt, Kink."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import casadi as ca

import finsler


@dataclass(frozen=True)
class Cheaper(finsler.Metric):
    """``F = exp(-3 x_0) |v|``: travel is cheaper to the right, so a geodesic between two
    points near the domain's right side presses against it. On the box ``[-1, 1]**2``
    or, with ``disk``, the unit disk."""

    disk: bool = False

    name: ClassVar[str] = "test-cheaper-right"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.5)
    reversible: ClassVar[bool] = True

    @property
    def domain(self) -> finsler.Domain:
        return finsler.Disk(1.0) if self.disk else finsler.Box((-1.0, -1.0), (1.0, 1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return ca.exp(-3.0 * x[0]) * ca.sqrt(ca.dot(v, v))


@dataclass(frozen=True)
class Bump(finsler.Metric):
    """``F = (1 + 5 exp(-|x|**2 / 0.09)) |v|`` on ``[-1, 1]**2``: a costly bump at the
    centre, symmetric about the x-axis, so the straight path from ``(-0.8, 0)`` to ``(0.8,
    0)`` is a critical point that Newton from the straight line never leaves."""

    name: ClassVar[str] = "test-bump"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.5)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + 5.0 * ca.exp(-ca.dot(x, x) / 0.09)) * ca.sqrt(ca.dot(v, v))


class WallAbove(finsler.Metric):
    """The bump of :class:`_Bump`, a wall across the upper half (``3 exp(-(x_0 / 0.1)^2)``,
    only for ``x_1 > 0``) and a mild surcharge ``0.15`` on the lower half: the route below
    is the shorter, but a coarse path steps over the wall with two vertices on either side
    of it (``C(p, q) = F(p, q - p)`` sees F at the vertices only), so at 4 segments the
    route above looks the shorter."""

    name: ClassVar[str] = "test-wall-above"
    task: ClassVar[finsler.Task] = finsler.Task(depth=6, eps=0.5)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        bump = 5.0 * ca.exp(-ca.dot(x, x) / 0.09)
        wall = 3.0 * ca.exp(-(x[0] / 0.1) ** 2) / (1 + ca.exp(-x[1] / 0.05))
        low = 0.15 / (1 + ca.exp(x[1] / 0.05))
        return (1 + bump + wall + low) * ca.sqrt(ca.dot(v, v))


@dataclass(frozen=True)
class Tilt(finsler.Metric):
    """``F = exp(c x_0) |v|`` on ``[-1, 1]**2``: with ``c > 0`` travel is cheaper to the
    left (the energy pushes points at the left side outwards), ``c < 0`` to the right."""

    c: float = 3.0
    name: ClassVar[str] = "test-tilt"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.5)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return ca.exp(self.c * x[0]) * ca.sqrt(ca.dot(v, v))


@dataclass(frozen=True)
class Kink(finsler.Metric):
    """``F = (1 + sqrt|x_0|) |v|``: finite everywhere, its derivative in ``x_0`` is
    infinite at ``x_0 = 0``."""

    name: ClassVar[str] = "test-kink"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.5)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + ca.sqrt(ca.fabs(x[0]))) * ca.sqrt(ca.dot(v, v))
