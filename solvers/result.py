"""Result objects of the solvers: every solve returns one, with its status.

Non-convergence is a `Status`, never a silent number; ``strict=True`` in the API
(or ``result.strict()``) turns a non-converged status into a `SolverError`. Every
result derives from `finsler.status.Result` (``status``, ``converged``, ``wall_time``,
``to_dict``, ``strict``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np

from finsler.errors import InputError
from finsler.status import (
    CertifyStatus,
    CertifyStop,
    DistanceStatus,
    LPStatus,
    Result,
    SolverError,
    Status,
    json_ready,
)
from solvers.chebyshev import interpolation_matrix

__all__ = [
    "Certificate",
    "CertifyResult",
    "DistanceResult",
    "DistanceStatus",
    "GeodesicResult",
    "MidpointResult",
    "MinMaxResult",
    "Result",
    "SolverError",
    "Status",
]


@dataclass
class MinMaxResult(Result):
    """Min-max refinement of a discrete geodesic: minimise the largest segment cost.

    ``points`` ``(n+1, dim)``; ``segment_costs`` ``(n,)`` recomputed in float64 from the
    points with ``metric.cost``; ``cap_relaxed`` tells whether the cap on the max (just
    above the starting value) had to be removed.
    """

    points: np.ndarray
    segment_costs: np.ndarray
    max_segment_cost: float
    status: Status
    iterations: int
    wall_time: float
    cap_relaxed: bool


@dataclass
class GeodesicResult(Result):
    """Discrete geodesic of the task (energy minimiser of ``sum_i C(p_i, p_{i+1})**2``).

    Shapes: ``points`` ``(n+1, dim)`` with ``points[0] = start``, ``points[n] = goal``;
    ``segment_costs`` ``(n,)``. ``length`` is ``sum C`` (eq. 4 costs); ``length_quadrature``
    the polyline's length (eq. 58) by adaptive Gauss-Kronrod quadrature, with its estimated
    absolute error ``length_quadrature_error`` (``Metric.path_length_error``):
    ``length_quadrature + length_quadrature_error`` bounds the distance from above.
    ``status`` is IPOPT's status of the returned solve; ``seeds_tried`` initial curves of
    the seed plan were solved (the caller's
    ``initial`` paths are counted only when they are the only starts, ``global_seeds=False``;
    they appear in ``seed_energies`` either way), ``seeds_agreeing`` of them reached the
    best energy (relative 1e-6). ``nonconvex_points`` counts path points where ``F(x, .)``
    is not convex (for metrics not convex everywhere; there the discrete minimiser may
    chatter). ``minmax`` holds the min-max refinement when it was requested. ``levels``
    summarises the multiresolution ladder: one dict per size solved (``segments``,
    ``solved`` candidates, ``iterations``, ``wall_time``); ``seed_energies`` holds the
    energies of the candidates solved at the final size (names ``seed@coarse`` for those
    carried up the ladder). Solves with ``tol`` also fill ``length_estimate`` (of the
    continuum distance along this path), ``error_estimate`` (absolute), ``order`` (observed
    order of the polyline lengths, None if not measurable) and ``order_seen`` (the expected
    order 2 observed; False e.g. through non-convex regions, where the estimate is the
    plain difference of the last two sizes), ``tol_reached`` and ``tol_levels`` (one
    dict per size: ``segments``, ``length``, ``quadrature_error``, ...). ``method`` names
    what produced ``points``: ``"newton"`` (the batched Newton solve of
    `solvers.newton.driver`), ``"ipopt"``, or ``"none"`` (trivial and short pairs);
    ``residual`` is the path's first-order optimality residual: the largest entry of the
    projected gradient of ``sum C**2`` in the interior points, times the domain's size,
    over ``sum C**2`` (`solvers.newton.energy.energy_residual`; ``1e-10`` is this package's
    convergence tolerance) where ``F`` is smooth (``metric.smooth``). For a metric whose
    ``F`` has kinks and that provides ``smooth_square_sx`` (car-like's ``max``) the
    energy's gradient need not vanish at a minimiser, so ``residual`` is instead the KKT
    residual of the reformulated (slack) problem at the path's exact slacks:
    stationarity with the least-norm multipliers of the active constraints, slack
    stationarity, complementarity and domain feasibility, scaled the same way
    (`solvers.newton.kkt.kkt_residual`); 0 exactly at a KKT point. Measured on
    IPOPT's car-like optima: 2e-8 to 1e-5 at 32 segments (the energy's gradient there:
    up to 4); on 4 fresh pairs at 256 (``benchmarks/nonsmooth_residual.py``) 1e-7 to
    2e-6 and one 1.5e-3 (IPOPT's slack can sit off its exact value within IPOPT's
    complementarity tolerance); above 1 on paths moved by 1e-3.
    For a batch, ``wall_time`` is the batch's time over its pairs.

    Evidence of global optimality (agreement within one seed family is no evidence):
    ``seed_families`` breaks the seeds down by family (`solvers.seeding.plans.seed_family`:
    ``straight``, ``bulge``, ``random``, ``graph``, the metric's own ``seed_curves``
    families, ``restart``, ``polish``, ``warp``, ``initial``): ``{family: {"tried",
    "agreeing", "best_energy"}}``, ``tried`` / ``agreeing`` counted on the candidates solved from
    the seeds (as ``seeds_tried`` / ``seeds_agreeing``, the ladder's first size),
    ``best_energy`` the family's lowest energy at the final size (``None``: none of its
    candidates was carried there converged). ``alternative_gap`` is the relative energy
    gap ``e / energy - 1`` of the best other local optimum found at the final size
    (``None``: every candidate there agrees with the best, within 1e-6); a small gap
    says two basins nearly tie.
    """

    metric: str
    points: np.ndarray
    energy: float
    length: float
    length_quadrature: float
    segment_costs: np.ndarray
    max_segment_cost: float
    status: Status
    iterations: int
    wall_time: float
    seeds_tried: int
    seeds_agreeing: int
    seed_energies: dict[str, float] = field(default_factory=dict)
    best_seed: str = ""
    nonconvex_points: int = 0
    minmax: MinMaxResult | None = None
    levels: list[dict[str, Any]] = field(default_factory=list)
    length_estimate: float | None = None
    error_estimate: float | None = None
    order: float | None = None
    order_seen: bool | None = None
    tol: float | None = None
    tol_reached: bool | None = None
    tol_levels: list[dict[str, Any]] = field(default_factory=list)
    length_quadrature_error: float | None = None
    method: str = "ipopt"
    residual: float | None = None
    seed_families: dict[str, dict[str, Any]] = field(default_factory=dict)
    alternative_gap: float | None = None

    @property
    def segments(self) -> int:
        return int(self.points.shape[0] - 1)

    @property
    def cost_ratio(self) -> float:
        """Largest over mean segment cost (1 for exactly equal segment costs)."""
        mean = float(np.mean(self.segment_costs))
        return self.max_segment_cost / mean if mean > 0 else 1.0

    def success(self, eps: float) -> bool:
        """The paper's task criterion on the exact ceiling: every segment cost of the
        min-max refined path (or, without refinement, of this path) is ``<= eps``."""
        if not (np.isfinite(eps) and eps > 0):
            raise InputError(f"eps must be positive and finite, got {eps!r}")
        m = self.minmax.max_segment_cost if self.minmax is not None else self.max_segment_cost
        return bool(m <= eps)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the schema of ``geodesics solve``): ``length`` is always the
        sum of the costs C; a solve with ``tol`` adds ``length_estimate`` (the continuum
        length) and ``error_estimate`` (None where no estimate exists, e.g. a single
        size). ``status`` is `Status.label`, ``ipopt_status`` IPOPT's own word;
        non-finite numbers (a failed solve's energy) are ``None``."""
        est = self.error_estimate
        out: dict[str, Any] = {
            "points": self.points.tolist(),
            "energy": self.energy,
            "length": self.length,
            "length_quadrature": self.length_quadrature,
            "length_quadrature_error": self.length_quadrature_error,
            "max_segment_cost": self.max_segment_cost,
            "status": self.status.label,
            "ipopt_status": self.status.value,
            "iterations": self.iterations,
            "wall_time": self.wall_time,
            "seeds_tried": self.seeds_tried,
            "seeds_agreeing": self.seeds_agreeing,
            "nonconvex_points": self.nonconvex_points,
            "method": self.method,
            "residual": self.residual,
            "best_seed": self.best_seed,
            "seed_families": {k: dict(v) for k, v in self.seed_families.items()},
            "alternative_gap": self.alternative_gap,
        }
        out["segments"] = self.segments
        if est is not None:
            # accuracy on request: the continuum length, with its error if there is one
            out["length_estimate"] = self.length_estimate
            out["error_estimate"] = est if np.isfinite(est) else None
            out["order"] = self.order
            out["order_seen"] = self.order_seen
            out["tol"] = self.tol
            out["tol_reached"] = self.tol_reached
            out["tol_levels"] = self.tol_levels
        if self.minmax is not None:
            out["minmax_max_segment_cost"] = self.minmax.max_segment_cost
            out["minmax_status"] = self.minmax.status.label
        return json_ready(out)


@dataclass
class MidpointResult(Result):
    """Midpoint ``p_{n/2}`` ``(dim,)`` of the discrete geodesic, with the full result
    (``status`` and ``wall_time`` are the geodesic's)."""

    point: np.ndarray
    geodesic: GeodesicResult

    @property
    def status(self) -> Status:  # type: ignore[override]
        return self.geodesic.status

    @property
    def wall_time(self) -> float:  # type: ignore[override]
        return self.geodesic.wall_time

    def to_dict(self) -> dict[str, Any]:
        """``point``, ``status``, ``converged``, ``wall_time`` and the geodesic's
        ``to_dict()`` under ``geodesic``."""
        return {"point": json_ready(self.point), "status": self.status.label,
                "converged": self.converged, "wall_time": self.wall_time,
                "geodesic": self.geodesic.to_dict()}


@dataclass
class DistanceResult(Result):
    """Continuum distance ``d(start, goal)`` from the pseudospectral transcription.

    ``distance`` is the length of the finest polynomial curve; ``error_estimate`` the
    difference to the previous (half-degree) level plus a rounding floor, an estimate of
    ``|distance - d|`` valid in the regime of spectral convergence (smooth metric, no active
    domain constraint). ``degrees`` and ``lengths`` list every level. ``nodes`` ``(N+1, dim)``
    are the curve's values at the Chebyshev-Gauss-Lobatto nodes of ``[0, 1]``;
    `curve` evaluates the polynomial at parameters ``t`` in ``[0, 1]`` (proportional
    to arc length at the optimum). ``upper_bound`` is the eq. (58) quadrature length of the
    globally seeded discrete path (``discrete``), an independent upper bound of the distance
    where the metric is Finsler; a ``distance`` above it means the transcription has not
    resolved the geodesic (the status is then never ``CONVERGED``).
    """

    distance: float
    error_estimate: float
    rtol: float
    status: DistanceStatus
    degrees: list[int]
    lengths: list[float]
    nodes: np.ndarray
    min_convexity: float
    wall_time: float
    ipopt_status: Status
    upper_bound: float = float("inf")
    discrete: GeodesicResult | None = None

    def to_dict(self, with_discrete: bool = False) -> dict[str, Any]:
        """JSON-ready summary: every field but ``nodes`` (``(N+1, dim)`` lists) and
        ``discrete`` (the discrete solve's own ``to_dict()``, only if ``with_discrete``);
        ``ipopt_status`` is IPOPT's own word, ``upper_bound`` ``None`` when there is none
        (infinite)."""
        out = super().to_dict()
        out["ipopt_status"] = self.ipopt_status.value
        if not with_discrete:
            out.pop("discrete")
        return out

    def curve(self, t: Any) -> np.ndarray:
        """Points of the curve at parameters ``t`` ``(T,)`` in ``[0, 1]`` -> ``(T, dim)``."""
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(t)) or np.any(t < 0) or np.any(t > 1):
            raise InputError("curve parameters t must be finite and lie in [0, 1]")
        n = self.nodes.shape[0] - 1
        return interpolation_matrix(n, 2.0 * t - 1.0) @ self.nodes


class Certificate(Result):
    """Base of every result of [`solvers.certify`][solvers.certify]: a proven interval
    ``lower <= d(start, goal) <= upper``, whichever certificate made it
    ([`CertifyResult`][solvers.result.CertifyResult] in 2-D, ``NDResult`` in 3-D and up,
    ``SplitCertifyResult`` for a conformal metric).

    Every certificate carries ``metric`` (its name), ``start`` / ``goal``, ``lower``,
    ``upper``, ``gap = (upper - lower) / upper``, the ``path`` of the upper bound,
    ``times`` (seconds, ``"total"`` among them), ``stopped_by`` (what ended the
    refinement, a `finsler.status.CertifyStop`), ``status`` (a `solvers.CertifyStatus`),
    ``message`` and the class's ``rigour`` (what each part of the interval rests on).
    The fields beyond these say how the bound was found and differ by certificate.
    """

    rigour: ClassVar[dict[str, str]]
    metric: str
    start: np.ndarray
    goal: np.ndarray
    lower: float
    upper: float
    gap: float
    times: dict[str, float]
    stopped_by: CertifyStop
    status: CertifyStatus
    message: str

    @property
    def certified(self) -> bool:
        """True if both bounds are finite and ``lower <= upper``."""
        return bool(np.isfinite(self.lower) and np.isfinite(self.upper)
                    and self.lower <= self.upper)


class MeshCertificate(Certificate):
    """What the mesh certificates share ([`CertifyResult`][solvers.result.CertifyResult] in
    2-D, ``NDResult`` beyond): the outcome fields as members of the status family (words
    are accepted and converted), ``wall_time`` from ``times["total"]`` and a
    field-by-field ``to_dict``. Subclasses are dataclasses with ``lower``, ``upper``,
    ``times``, ``path``, ``stopped_by``, ``lp_status``, ``solver_status`` and ``status``
    fields."""

    def __post_init__(self) -> None:
        self.stopped_by = CertifyStop(self.stopped_by)
        self.lp_status = LPStatus.from_solver(self.lp_status)
        self.solver_status = Status.from_label(self.solver_status)

    @property
    def wall_time(self) -> float:
        """Seconds of the whole certificate (``times["total"]``)."""
        return float(self.times.get("total", 0.0))

    @property
    def converged(self) -> bool:
        """True if the refinement reached its target gap (``status`` is ``CERTIFIED``)."""
        return self.status.converged

    def to_dict(self, with_path: bool = False) -> dict[str, Any]:
        """JSON-ready dict in field order (``path`` only if ``with_path``; labels, lists,
        non-finite floats as None)."""
        return {f.name: json_ready(getattr(self, f.name)) for f in fields(self)
                if with_path or f.name != "path"}


@dataclass
class CertifyResult(MeshCertificate):
    """A certified interval ``lower <= d(start, goal) <= upper``.

    ``gap = (upper - lower) / upper``. ``upper`` is a proven upper bound of the length of
    ``path`` ``(n+1, 2)`` (`finsler.Metric.path_length_bounds`; ``length`` and
    ``length_error`` are the adaptive-quadrature estimate of it): the solver's (or the
    given) path
    (``upper_source == "path"``) or, where ``F(z, .)`` is not convex, the same path with
    every segment replaced by a zigzag along the two directions of the convexification
    when that is shorter (``"zigzag"``: switchbacks, the curves whose lengths approach the
    infimum there). ``path_upper`` / ``path_gap`` are the bound and gap of the solver's
    path itself: a small ``path_gap`` certifies that path near-globally optimal.
    ``convexity`` is ``"convex"``
    (``F(z, .)`` convex on the whole domain) or ``"convexified"`` (not convex somewhere:
    the dual condition equals that of the convexification, see the module docstring);
    ``convexity_note`` says it in words. ``rounds`` lists, per LP solve, the triangles,
    rows used, lower bound and gap. ``times`` in seconds: ``solve`` (upper bound), ``mesh``,
    ``bounds`` (F and its Hessians), ``lp`` and ``total``. ``lp_status`` is cvxpy's status
    of the last LP; ``max_row_ratio`` the largest ``grad phi . v / bound`` over every row
    of the last potential before the final check (``<= 1`` up to the LP solver's
    feasibility tolerance; the potential is divided by it when above 1). ``lp_rows`` counts
    the rows of the last LP (edges of the inner polygons), ``lp_rows_total`` the sampled
    rows they imply (3 x triangles x directions). ``stopped_by`` says what ended the
    refinement: ``target_gap`` (reached), ``max_rounds`` or ``max_triangles`` (the work
    budgets of [`MeshSpec`][solvers.MeshSpec]), ``no_refinement`` (no triangle left to refine), or
    ``time_limit`` (the caller's wall-clock limit: only then can the result depend on the
    machine's speed), or the failure's label. ``status`` (`solvers.CertifyStatus`)
    says the same in the toolkit's one family of statuses: a failure of the refinement (an
    LP solver failure, corrections that do not shrink) is a status with the best interval
    proven so far (lower bound 0 if none) and ``message``, never an exception.
    ``solver_status`` is the upper-bound solve's `solvers.Status` (``Status.GIVEN``
    for a given path; its label, e.g. ``"success"``, in JSON) and ``lp_status`` the last
    LP's `finsler.status.LPStatus` (a ``str`` enum of cvxpy's words).
    """

    rigour: ClassVar[dict[str, str]] = {
        "upper": "proven: path length with interval bound of the quadrature error "
                 "(Metric.path_length_bounds)",
        "lower": "proven: piecewise-quadratic dual potential (LP) whose rows hold on every "
                 "triangle by interval enclosures of F's Hessians (outward rounding); the "
                 "potential divided by its largest row ratio over all rows",
        "region": "proven: triangles dropped only outside the ellipse a curve shorter than "
                  "the upper bound cannot leave (a proven speed floor F >= m |v|)",
    }
    """What each part of the interval rests on (as ``NDResult.rigour``)."""

    metric: str
    start: np.ndarray
    goal: np.ndarray
    lower: float
    upper: float
    length: float
    length_error: float
    gap: float
    upper_source: str
    path_upper: float
    path_gap: float
    triangles: int
    vertices: int
    unknowns: int
    directions: int
    lp_rows: int
    lp_rows_total: int
    lp_status: LPStatus
    lp_solver: str
    max_row_ratio: float
    convexity: str
    convexity_note: str
    solver_status: Status
    mesh: dict[str, Any]
    times: dict[str, float]
    rounds: list[dict[str, Any]] = field(default_factory=list)
    path: np.ndarray | None = None
    stopped_by: CertifyStop = CertifyStop.TARGET_GAP
    status: CertifyStatus = CertifyStatus.CERTIFIED
    message: str = ""

