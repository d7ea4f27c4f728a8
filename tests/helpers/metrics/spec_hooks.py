"""The test metrics of ``tests/finsler/test_spec_hooks.py``: Plain, Hill."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import finsler
from finsler import Box


@dataclass(frozen=True)
class Plain(finsler.Metric):
    """A user metric with no hooks: Euclidean on the plane."""

    name: ClassVar[str] = "test-plain"

    @property
    def domain(self) -> Box:
        return Box((-1.0, -1.0), (1.0, 1.0))

    def F_sx(self, x, v):
        import casadi as ca
        return ca.sqrt(ca.dot(v, v))


@dataclass(frozen=True)
class Hill(Plain):
    """The same metric declaring two hooks by overriding them."""

    name: ClassVar[str] = "test-hill"

    def height_map(self, points):
        return np.asarray(points)[:, 0] ** 2

    @property
    def convex_radius(self) -> float:
        return 3.0
