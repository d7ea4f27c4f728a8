"""The test metrics of ``tests/validation/testing/test_check.py``: Squared, Flat,
FlatConformal4D."""

from __future__ import annotations

import casadi as ca

from finsler import Box, Metric, Task

from tests.helpers.metrics.conformal import Conformal4D


# ----------------------------------------------------------------------------------------
# the functions
# ----------------------------------------------------------------------------------------
class Squared(Metric):
    """F = |v|**2 (the square root forgotten): not 1-homogeneous, not subadditive."""

    name = "squared-test"
    task = Task(depth=3, eps=0.5)
    reversible = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return ca.dot(v, v)


# ----------------------------------------------------------------------------------------
# every distance and policy property able to fail, alone (issue 48)
# ----------------------------------------------------------------------------------------
class Flat(Metric):
    """F = |v| on a box, with no closed-form hook (so closed-form-distance does not apply
    and every distance property below is judged against the fake oracle alone)."""

    name = "flat-test"
    task = Task(depth=3, eps=0.5)
    reversible = True

    def __init__(self, dim: int = 3, half: float = 0.5) -> None:
        self._box = Box((-half,) * dim, (half,) * dim)

    domain = property(lambda self: self._box)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return ca.sqrt(ca.dot(v, v))


class FlatConformal4D(Conformal4D):
    """``F = 1 |v|`` on ``[-1, 1]**4`` through the conformal hook, with no closed form: the
    certificate beyond 3-D is the conformal lower bound."""

    name = "flat-conformal-4d-test"
    task = Task(depth=3, eps=0.5)
    reversible = True

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        return ca.SX(1.0)
