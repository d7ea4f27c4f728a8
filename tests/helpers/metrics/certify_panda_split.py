"""The test metrics of
``tests/solvers/certificates/conformal/test_certify_panda_split.py``: ScaledEuclidean."""

from __future__ import annotations

from typing import ClassVar

import casadi as ca

from tests.helpers.metrics.conformal import Conformal4D


class ScaledEuclidean(Conformal4D):
    """``F = (1.5 + 2) |v|`` on a 4-D box, written as a sum of two constants."""

    name: ClassVar[str] = "test-scaled-euclidean"

    def conformal_factor_sx(self, x: ca.SX) -> ca.SX:
        return ca.SX(1.5) + ca.SX(2.0) + 0.0 * x[0]
