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
    check_batch(metric, pairs, segments=None, **same) -> BatchJob   # solve_batch's checks
    run_batch(job, *, progress=True, checkpoint_dir=None) -> list[GeodesicResult]
    certify(metric, start, goal, settings=None, *, path=None) -> Certificate
    certify_settings(metric, preset="default", **overrides) -> MeshSpec | NDSpec | ConformalSpec
    exp_map(metric, x, v, t=1.0, return_curve=False) -> ExpResult
    log_map(metric, x, y) -> LogResult

Every result carries a status of one family (`solvers.status`): ``status.label`` is
what the API, JSON and the command line print.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from finsler.infra.lazy import lazy_exports

if TYPE_CHECKING:
    from solvers.certificates.conformal.certificate import ConformalSpec
    from solvers.certificates.dispatch import (
        CertifySettings,
        certificate_kind,
        certify,
        certify_settings,
    )
    from solvers.certificates.nd.certificate import NDSpec
    from solvers.certificates.plane.certificate import MeshSpec
    from solvers.continuum.expmap import ExpResult, LogResult, exp_map, log_map
    from solvers.continuum.spectral import distance
    from solvers.fields import DistanceField, distance_field, distance_matrix
    from solvers.geodesic.batches import BatchJob, check_batch, run_batch, solve_batch
    from solvers.geodesic.pair_solver import refine_minmax
    from solvers.geodesic.solve import midpoint, solve_geodesic
    from solvers.inputs import check_pairs, check_segments
    from solvers.result import (
        Certificate,
        CertifyResult,
        DistanceResult,
        GeodesicResult,
        MidpointResult,
        MinMaxResult,
        SolverError,
    )
    from solvers.seeding.plans import SeedPlan
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
# stack and IPOPT until a solver is called.
_LAZY = {
    "BatchJob": "solvers.geodesic.batches",
    "Certificate": "solvers.result",
    "CertifyResult": "solvers.result",
    "CertifySettings": "solvers.certificates.dispatch",
    "ConformalSpec": "solvers.certificates.conformal.certificate",
    "CertifyStatus": "solvers.status",
    "DistanceField": "solvers.fields",
    "DistanceResult": "solvers.result",
    "DistanceStatus": "solvers.status",
    "ExpResult": "solvers.continuum.expmap",
    "ExpStatus": "solvers.status",
    "GeodesicResult": "solvers.result",
    "LogResult": "solvers.continuum.expmap",
    "LogStatus": "solvers.status",
    "MeshSpec": "solvers.certificates.plane.certificate",
    "MidpointResult": "solvers.result",
    "MinMaxResult": "solvers.result",
    "NDSpec": "solvers.certificates.nd.certificate",
    "Outcome": "solvers.status",
    "SeedPlan": "solvers.seeding.plans",
    "SolverError": "solvers.result",
    "Status": "solvers.status",
    "certificate_kind": "solvers.certificates.dispatch",
    "certify": "solvers.certificates.dispatch",
    "certify_settings": "solvers.certificates.dispatch",
    "check_batch": "solvers.geodesic.batches",
    "check_pairs": "solvers.inputs",
    "check_segments": "solvers.inputs",
    "distance": "solvers.continuum.spectral",
    "distance_field": "solvers.fields",
    "distance_matrix": "solvers.fields",
    "exp_map": "solvers.continuum.expmap",
    "log_map": "solvers.continuum.expmap",
    "midpoint": "solvers.geodesic.solve",
    "refine_minmax": "solvers.geodesic.pair_solver",
    "run_batch": "solvers.geodesic.batches",
    "solve_batch": "solvers.geodesic.batches",
    "solve_geodesic": "solvers.geodesic.solve",
}

__all__ = [
    "BatchJob",
    "Certificate",
    "CertifyResult",
    "CertifySettings",
    "CertifyStatus",
    "ConformalSpec",
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
    "NDSpec",
    "Outcome",
    "SeedPlan",
    "SolverError",
    "Status",
    "certificate_kind",
    "certify",
    "certify_settings",
    "check_batch",
    "check_pairs",
    "check_segments",
    "distance",
    "distance_field",
    "distance_matrix",
    "exp_map",
    "log_map",
    "midpoint",
    "refine_minmax",
    "run_batch",
    "solve_batch",
    "solve_geodesic",
]


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals(), __all__)

