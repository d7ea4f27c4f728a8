"""A base for the 4-D conformal test metrics of the certificate tests:
``F = f(x) |v|`` on ``[-1, 1]**4`` with ``f`` the subclass's ``conformal_factor_sx``."""

from __future__ import annotations

import casadi as ca

from finsler import Box, Metric


class Conformal4D(Metric):
    """``F = conformal_factor_sx(x) |v|`` on the box ``[-1, 1]**4``."""

    @property
    def domain(self) -> Box:
        return Box((-1.0,) * 4, (1.0,) * 4)

    def F_sx(self, x: ca.SX, v: ca.SX) -> ca.SX:
        return self.conformal_factor_sx(x) * ca.norm_2(v)
