"""The test metrics of ``tests/validation/test_report_certify.py``: Valley."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import casadi as ca

from finsler import Task

from tests.helpers.metrics.conformal import Conformal4D


@dataclass(frozen=True)
class Valley(Conformal4D):
    """``F = (1 + q1**2 + q2**2 / 2 + (q3 q4)**2 / 5) |v|`` on ``[-1, 1]**4``: along the q1
    axis (q2 = q3 = 0) the distance is ``b - a + (b**3 - a**3) / 3`` (``f >= 1 + q1**2``
    everywhere, with equality on that straight path)."""

    name: ClassVar[str] = "test-report-valley-4d"
    task: ClassVar[Task] = Task(depth=3, eps=0.2)

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        return 1.0 + x[0] ** 2 + 0.5 * x[1] ** 2 + 0.2 * (x[2] * x[3]) ** 2
