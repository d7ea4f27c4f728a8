"""solvers: exact geodesics by batched Newton (IPOPT: reference, fallback), global seeding, min-max
refinement of the task ceiling, continuum distances with error estimates, batches.

Public API::

    solve_geodesic(metric, start, goal, segments=None, *, seeds=None, initial=(),
                   global_seeds=True, minmax=False, strict=False, tol=None) -> GeodesicResult
    midpoint(metric, start, goal, segments=None, **kw) -> MidpointResult
    refine_minmax(metric, result) -> MinMaxResult
    distance(metric, start, goal, rtol=None, *, strict=False) -> DistanceResult
    solve_batch(metric, pairs (K, 2, dim), segments=None, *, minmax=False, workers=None,
                progress=True, initial_paths=None, global_seeds=True, tol=None)
                -> list[GeodesicResult]
    exp_map(metric, x, v, t=1.0, return_curve=False) -> ExpResult
    log_map(metric, x, y) -> LogResult

Every result carries a status of one family (:mod:`solvers.status`): ``status.label`` is
what the API, JSON and the command line print.
"""

from solvers.certify import CertifyResult, MeshSpec, certify
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

__all__ = [
    "CertifyResult",
    "CertifyStatus",
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
    "exp_map",
    "log_map",
    "midpoint",
    "refine_minmax",
    "solve_batch",
    "solve_geodesic",
]
