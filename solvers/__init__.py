"""solvers: exact geodesics by batched Newton (IPOPT: reference, fallback), global seeding, min-max
refinement of the task ceiling, continuum distances with error estimates, batches.

Public API::

    solve_geodesic(metric, start, goal, segments=None, *, seeds=None, initial=(),
                   global_seeds=True, minmax=False, strict=False, tol=None) -> GeodesicResult
    midpoint(metric, start, goal, segments=None, **kw) -> MidpointResult
    refine_minmax(metric, result) -> MinMaxResult
    distance(metric, start, goal, rtol=None, *, strict=False) -> DistanceResult
    distance_field(metric, source, resolution=None, *, stencil=None, ...) -> DistanceField
    distance_matrix(metric, points (K, dim), *, exact=False, ...) -> DistanceMatrix
    solve_batch(metric, pairs (K, 2, dim), segments=None, *, minmax=False, workers=None,
                progress=True, initial_paths=None, global_seeds=True, tol=None)
                -> list[GeodesicResult]
    exp_map(metric, x, v, t=1.0, return_curve=False) -> ExpResult
    log_map(metric, x, y) -> LogResult

Every result carries a status of one family (`solvers.status`): ``status.label`` is
what the API, JSON and the command line print.
"""

from __future__ import annotations

import sys
import types
from typing import TYPE_CHECKING, Any

from finsler.infra.lazy import lazy_exports

if TYPE_CHECKING:
    from solvers.certify import CertifyResult, MeshSpec, certify
    from solvers.distance import DistanceField, distance_field, distance_matrix
    from solvers.expmap import ExpResult, LogResult, exp_map, log_map
    from solvers.geodesic import (
        check_pairs,
        check_segments,
        midpoint,
        refine_minmax,
        solve_batch,
        solve_geodesic,
    )
    from solvers.result import (
        DistanceResult,
        GeodesicResult,
        MidpointResult,
        MinMaxResult,
        SolverError,
    )
    from solvers.seeding import SeedPlan
    from solvers.spectral import distance
    from solvers.status import (
        CertifyStatus,
        DistanceStatus,
        ExpStatus,
        LogStatus,
        Outcome,
        Status,
    )

# Public names -> defining module, imported on first use (PEP 562), so that `import solvers`
# (and the `geodesics` command line's --help) does not pay for scipy.integrate, the Newton
# stack and IPOPT until a solver is called. `from solvers import solve_batch` works as before.
_LAZY = {
    "CertifyResult": "solvers.certify",
    "CertifyStatus": "solvers.status",
    "DistanceField": "solvers.distance",
    "DistanceResult": "solvers.result",
    "DistanceStatus": "solvers.status",
    "ExpResult": "solvers.expmap",
    "ExpStatus": "solvers.status",
    "GeodesicResult": "solvers.result",
    "LogResult": "solvers.expmap",
    "LogStatus": "solvers.status",
    "MeshSpec": "solvers.certify",
    "MidpointResult": "solvers.result",
    "MinMaxResult": "solvers.result",
    "Outcome": "solvers.status",
    "SeedPlan": "solvers.seeding",
    "SolverError": "solvers.result",
    "Status": "solvers.status",
    "certify": "solvers.certify",
    "check_pairs": "solvers.geodesic",
    "check_segments": "solvers.geodesic",
    "distance": "solvers.spectral",
    "distance_field": "solvers.distance",
    "distance_matrix": "solvers.distance",
    "exp_map": "solvers.expmap",
    "log_map": "solvers.expmap",
    "midpoint": "solvers.geodesic",
    "refine_minmax": "solvers.geodesic",
    "solve_batch": "solvers.geodesic",
    "solve_geodesic": "solvers.geodesic",
}

__all__ = [
    "CertifyResult",
    "CertifyStatus",
    "DistanceField",
    "DistanceResult",
    "DistanceStatus",
    "ExpResult",
    "ExpStatus",
    "GeodesicResult",
    "LogResult",
    "LogStatus",
    "MeshSpec",
    "MidpointResult",
    "MinMaxResult",
    "Outcome",
    "SeedPlan",
    "SolverError",
    "Status",
    "certify",
    "check_pairs",
    "check_segments",
    "distance",
    "distance_field",
    "distance_matrix",
    "exp_map",
    "log_map",
    "midpoint",
    "refine_minmax",
    "solve_batch",
    "solve_geodesic",
]


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals(), __all__)


class _Package(types.ModuleType):
    """The package module, keeping ``solvers.certify`` the function as the eager package did:
    importing a submodule binds it on its package, and ``solvers.certify`` (the module) would
    then hide the function of the same name."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and name in _LAZY:
            if _LAZY[name] == value.__name__ and hasattr(value, name):
                value = getattr(value, name)
            elif _LAZY[name] != value.__name__:
                # a subpackage named like a public function of another module (the
                # package ``solvers.distance`` of distance fields beside the function
                # ``solvers.distance``): the function stays the attribute
                import importlib

                value = getattr(importlib.import_module(_LAZY[name]), name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
