"""Valid metrics with a singular derivative, shared by the fast tests of the bound code
(``tests/solvers/certificates/plane/test_certify_bounds.py``,
``tests/finsler/metrics/test_length_bounds.py``). Not registered: the tests build them
directly."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import casadi as ca

import finsler


@dataclass(frozen=True)
class Cone(finsler.Metric):
    """F(x, v) = (1 + |x|) |v|: F is finite everywhere, ``Hess_v F`` too, but ``Hess_x F``
    is unbounded at the origin (an infinite enclosure of Hz alone)."""

    name: ClassVar[str] = "cone-bounds-test"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + ca.sqrt(ca.dot(x, x))) * ca.sqrt(ca.dot(v, v))
