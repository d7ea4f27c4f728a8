"""The test metrics of ``tests/validation/testing/test_distance.py``: Flat, Ring."""

from __future__ import annotations

import casadi as ca
import numpy as np

from finsler import Box, Metric, Task


class Flat(Metric):
    """F = |v| without a closed form."""

    name = "flat-test"
    task = Task(depth=3, eps=0.5)
    reversible = True
    domain = property(lambda self: Box((-1.0, -1.0), (1.0, 1.0)))

    def F_sx(self, x, v):
        return ca.sqrt(ca.dot(v, v))


class Annulus(Box):
    """The square without the disk |x| < 0.5: a segment through the hole leaves it."""

    def contains(self, x, tol=1e-12):
        x = np.asarray(x, float)
        return super().contains(x, tol) & (np.linalg.norm(x, axis=-1) >= 0.5 - tol)


class Ring(Flat):
    name = "ring-test"
    domain = property(lambda self: Annulus((-1.0, -1.0), (1.0, 1.0)))
