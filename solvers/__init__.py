"""solvers: exact geodesics by direct transcription with IPOPT, global seeding, min-max
refinement of the task ceiling, continuum distances with error estimates, batches.

Public API::

    solve_geodesic(metric, start, goal, segments=None, *, seeds=None, minmax=False,
                   strict=False) -> GeodesicResult
    midpoint(metric, start, goal, segments=None, **kw) -> MidpointResult
    refine_minmax(metric, result) -> MinMaxResult
    distance(metric, start, goal, rtol=None, *, strict=False) -> DistanceResult
    solve_batch(metric, pairs (K, 2, dim), segments=None, *, minmax=False, workers=None,
                progress=True) -> list[GeodesicResult]
"""

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
    DistanceStatus,
    GeodesicResult,
    MidpointResult,
    MinMaxResult,
    SolverError,
    Status,
)
from solvers.seeding import SeedPlan
from solvers.spectral import distance

__all__ = [
    "DistanceResult",
    "DistanceStatus",
    "GeodesicResult",
    "MidpointResult",
    "MinMaxResult",
    "SeedPlan",
    "SolverError",
    "Status",
    "check_pairs",
    "check_segments",
    "distance",
    "midpoint",
    "refine_minmax",
    "solve_batch",
    "solve_geodesic",
]
