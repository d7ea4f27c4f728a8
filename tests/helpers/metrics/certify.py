"""The test metrics of ``tests/solvers/certificates/test_certify.py``: Bowl."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import casadi as ca

import finsler


@dataclass(frozen=True)
class Bowl(finsler.Metric):
    """F(x, v) = (1 + c |x|**2) |v|: Hess_x F = 2 c |v| I exactly, so the in-triangle
    correction Hz R**2 / 2 = c R**2 is exactly what the linear interpolant of F over an
    equilateral triangle overshoots F by at its centre (sum_i lambda_i |z_i - z|**2 = R**2
    there). Not registered: certify takes the object."""

    c: float = 4.0
    name: ClassVar[str] = "bowl-test"
    task: ClassVar[finsler.Task] = finsler.Task(depth=4, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: finsler.Disk(radius=1.0))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return (1 + self.c * ca.dot(x, x)) * ca.sqrt(ca.dot(v, v))
