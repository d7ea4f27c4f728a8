"""The solvers' statuses: re-exported from `finsler.status`, the toolkit's one family
of statuses in the ground layer (the same objects; ``learn`` and ``validation`` import them
from there). Read `finsler.status` for what ``label`` and ``converged`` mean."""

from __future__ import annotations

from finsler.status import (
    CertifyStatus,
    CertifyStop,
    DistanceStatus,
    ExpStatus,
    LogStatus,
    LPStatus,
    NewtonStatus,
    Outcome,
    PropertyOutcome,
    Status,
    families,
)

__all__ = [
    "CertifyStatus",
    "CertifyStop",
    "DistanceStatus",
    "ExpStatus",
    "LPStatus",
    "LogStatus",
    "NewtonStatus",
    "Outcome",
    "PropertyOutcome",
    "Status",
    "families",
]
