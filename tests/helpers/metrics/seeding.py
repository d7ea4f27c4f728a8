"""The test metrics of ``tests/solvers/seeding/test_seeding.py``: Detour."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import finsler
from finsler import Box


@dataclass(frozen=True)
class Detour(finsler.Metric):
    """A user metric (Euclidean in a box) declaring its own seed curves."""

    name: ClassVar[str] = "test-detour"
    bad: bool = False

    @property
    def domain(self) -> Box:
        return Box((-1.0, -1.0), (1.0, 1.0))

    def F_sx(self, x, v):
        import casadi as ca
        return ca.sqrt(ca.dot(v, v))

    def seed_curves(self, starts, goals, t):
        line = starts[:, None] + t[None, :, None] * (goals - starts)[:, None]
        if self.bad:
            return {"my detour!": line[:, None]}
        return {"detour": line[:, None] + 0.2 * np.sin(np.pi * t)[None, None, :, None]}
