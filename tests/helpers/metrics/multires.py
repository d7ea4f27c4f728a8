"""The test metrics of ``tests/solvers/geodesic/test_multires.py``: RenamedMatsumoto,
RenamedPoincare, NotUniquePoincare, HookedPoincare."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from finsler import Matsumoto, Poincare
from solvers import SeedPlan


# ----------------------------------------------------------------------------------------
# SeedPlan.default by capability, never by name
# ----------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class RenamedMatsumoto(Matsumoto):
    name: ClassVar[str] = "not-matsumoto"


@dataclasses.dataclass(frozen=True)
class RenamedPoincare(Poincare):
    name: ClassVar[str] = "matsumoto"  # a misleading name must not matter


@dataclasses.dataclass(frozen=True)
class NotUniquePoincare(Poincare):
    name: ClassVar[str] = "poincare-no-claim"
    unique_geodesics: ClassVar[bool] = False


@dataclasses.dataclass(frozen=True)
class HookedPoincare(Poincare):
    name: ClassVar[str] = "hooked"

    def seed_plan(self) -> SeedPlan:
        return SeedPlan(bulges=(0.2,), random=7, coarse=8)
