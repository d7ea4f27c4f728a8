"""One family of statuses, and the one shape of every result, in the ground layer.

Every solve, distance, exp, log, certificate, batched Newton problem, property check and
learning run ends with a member of an enum of this module, all subclasses of
`Outcome` (``solvers``, ``learn`` and ``validation`` import them from here;
`solvers.status` re-exports the solver families). They share one vocabulary:

- ``status.label`` is the toolkit's name of the outcome (``Status.SUCCESS`` ->
  ``"success"``), what JSON results, reports and the command line print; ``str(status)`` is
  the label too. A name means the same in every family (``success``, ``trivial``,
  ``not_convex``, ``max_iterations`` ...).
- ``status.converged`` says whether the number it comes with can be trusted as the answer
  asked for; a result's own ``converged`` is its status's.
- A computation that fails (IPOPT stops, an integrator underflows, an LP solver fails, a
  bound cannot be refined within its budget) returns its status; exceptions are for bad
  input ([`finsler.InputError`][finsler.InputError]) and, with ``strict=True``, for asking that a
  non-converged status be raised ([`SolverError`][finsler.status.SolverError]).

Every public result type derives from [`Result`][finsler.status.Result]: ``status``, ``converged``,
``wall_time``, ``to_dict()`` (JSON-ready: no NaN or infinity, enums as labels) and
``strict()`` (raise `SolverError` unless converged, else return the result). To add
a field to a result: add it to the result's dataclass (the base's ``to_dict`` picks it up;
results with a documented JSON schema, e.g. ``GeodesicResult``, list it in their own
``to_dict``).

`families` lists the status enums (the property suite and the CLI read it).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from typing import Any, TypeVar

__all__ = [
    "CertifyStatus",
    "CertifyStop",
    "DistanceStatus",
    "EvalStatus",
    "ExpStatus",
    "LPStatus",
    "LogStatus",
    "NewtonStatus",
    "Outcome",
    "PropertyOutcome",
    "Result",
    "RunAction",
    "RunStatus",
    "RunStop",
    "SearchStatus",
    "SolverError",
    "Status",
    "SweepStatus",
    "families",
    "json_ready",
]


class Outcome(enum.Enum):
    """Base of every status enum of the toolkit (no members of its own)."""

    @property
    def label(self) -> str:
        """The toolkit's name of the status: the member's name in lower case."""
        return self.name.lower()

    @property
    def converged(self) -> bool:  # pragma: no cover - every family overrides it
        raise NotImplementedError

    def __str__(self) -> str:
        return self.label


class Status(Outcome):
    """IPOPT's return status (``return_status`` of CasADi's ``nlpsol`` stats), plus the
    toolkit's own ``TRIVIAL`` (start == goal: nothing to solve) and ``SHORT`` (start and goal
    closer than `solvers.inputs.SHORT_PAIR` times the domain's size: the straight
    segment, equally divided, is the geodesic to within ``O(|g - s|**2)`` ~ 1e-14 in
    coordinates, below what IPOPT resolves, and ``F**2`` is not differentiable at zero
    velocity, so no NLP is solved)."""

    SUCCESS = "Solve_Succeeded"
    ACCEPTABLE = "Solved_To_Acceptable_Level"
    INFEASIBLE = "Infeasible_Problem_Detected"
    SEARCH_DIRECTION_TOO_SMALL = "Search_Direction_Becomes_Too_Small"
    DIVERGING_ITERATES = "Diverging_Iterates"
    USER_STOP = "User_Requested_Stop"
    FEASIBLE_POINT_FOUND = "Feasible_Point_Found"
    MAX_ITERATIONS = "Maximum_Iterations_Exceeded"
    RESTORATION_FAILED = "Restoration_Failed"
    STEP_COMPUTATION_ERROR = "Error_In_Step_Computation"
    MAX_CPU_TIME = "Maximum_CpuTime_Exceeded"
    MAX_WALL_TIME = "Maximum_WallTime_Exceeded"
    NOT_ENOUGH_DEGREES_OF_FREEDOM = "Not_Enough_Degrees_Of_Freedom"
    INVALID_PROBLEM = "Invalid_Problem_Definition"
    INVALID_OPTION = "Invalid_Option"
    INVALID_NUMBER = "Invalid_Number_Detected"
    UNRECOVERABLE = "Unrecoverable_Exception"
    NONIPOPT_EXCEPTION = "NonIpopt_Exception_Thrown"
    INSUFFICIENT_MEMORY = "Insufficient_Memory"
    INTERNAL_ERROR = "Internal_Error"
    TRIVIAL = "Trivial_Start_Equals_Goal"
    SHORT = "Short_Pair_Straight_Segment"
    GIVEN = "Given_Path"
    """No solve: the caller gave the path (``CertifyResult.solver_status`` of a certificate
    of a given path); the path is taken as it is, so it counts as converged."""
    UNKNOWN = "Unknown"

    @classmethod
    def from_ipopt(cls, text: str) -> Status:
        """Map IPOPT's ``return_status`` string to the enum (``UNKNOWN`` if unrecognised)."""
        for s in cls:
            if s.value == text:
                return s
        return cls.UNKNOWN

    @classmethod
    def from_label(cls, label: str | Status) -> Status:
        """The member whose `label` is ``label`` (``"success"`` -> ``SUCCESS``; a
        member is returned as it is; ``UNKNOWN`` if unrecognised)."""
        if isinstance(label, Status):
            return label
        for s in cls:
            if s.label == label:
                return s
        return cls.UNKNOWN

    @property
    def converged(self) -> bool:
        """Only a full IPOPT success, a trivial / short pair, or a path given by the caller
        counts as converged."""
        return self in (Status.SUCCESS, Status.TRIVIAL, Status.SHORT, Status.GIVEN)



class DistanceStatus(Outcome):
    """Outcome of [`solvers.distance`][solvers.distance]."""

    CONVERGED = "converged"
    """The error estimate is below ``rtol * distance``."""
    TOLERANCE_NOT_REACHED = "tolerance_not_reached"
    """The finest discretisation was solved but the estimate is above the tolerance."""
    NOT_CONVEX = "not_convex"
    """The path crosses a region where ``F(x, .)`` is not convex: the continuum infimum is
    the length for the convexified metric, discretised paths chatter, and the number is
    only the length of a smooth local minimiser (an upper bound of the infimum)."""
    SOLVER_FAILED = "solver_failed"
    """IPOPT did not converge at some level."""
    TRIVIAL = "trivial"
    """Start equals goal."""

    @property
    def converged(self) -> bool:
        return self in (DistanceStatus.CONVERGED, DistanceStatus.TRIVIAL)


class ExpStatus(Outcome):
    """Outcome of `exp_map`."""

    SUCCESS = "success"
    """Integrated to ``t``."""
    LEFT_DOMAIN = "left_domain"
    """The curve reached the boundary of the domain at ``t_end < t``."""
    NOT_CONVEX = "not_convex"
    """The curve reached a region where ``F(x, .)`` is not strongly convex at ``t_end``:
    beyond it the geodesic equation does not describe locally shortest curves."""
    INTEGRATION_FAILED = "integration_failed"
    """The integrator failed (step size underflow or non-finite values)."""

    @property
    def converged(self) -> bool:
        return self is ExpStatus.SUCCESS


class LogStatus(Outcome):
    """Outcome of `log_map`."""

    SUCCESS = "success"
    """``|exp(x, v) - y| <= tol`` and ``F(x, v)`` agrees with the solver's distance."""
    TRIVIAL = "trivial"
    """``x == y``: ``v = 0``."""
    NOT_CONVERGED = "not_converged"
    """Shooting stopped above the tolerance (``residual`` says by how much)."""
    OTHER_GEODESIC = "other_geodesic"
    """Shooting converged to a geodesic longer than the shortest path found by the solver
    (relative gap above `OTHER_GEODESIC_RTOL`): ``v`` is not the log."""

    @property
    def converged(self) -> bool:
        return self in (LogStatus.SUCCESS, LogStatus.TRIVIAL)


class NewtonStatus(int, Outcome):
    """Outcome of one problem of `newton_energy`."""

    RUNNING = 0
    CONVERGED = 1
    """``residual <= gtol``: a first-order point of the energy (relative gradient)."""
    MAX_ITERATIONS = 2
    STALLED = 3
    """No acceptable step even with the largest shift (round-off, or a kink of ``F``)."""
    BOUNDARY = 4
    """Steps kept leaving the domain: the optimum has an active domain constraint."""
    NOT_FINITE = 5
    """The energy or its derivatives are not finite at the start."""
    DROPPED = 6
    """Stopped by the caller (e.g. a seed clearly losing against another of its pair)."""

    @property
    def converged(self) -> bool:
        return self is NewtonStatus.CONVERGED


class CertifyStatus(Outcome):
    """Outcome of `solvers.certify` (``CertifyResult.status``). The interval
    ``[lower, upper]`` it comes with is proven in every case; the status says whether the
    refinement reached its target gap."""

    CERTIFIED = "certified"
    """The gap reached ``MeshSpec.target_gap``."""
    BUDGET_REACHED = "budget_reached"
    """A work budget of `solvers.MeshSpec` ended the refinement above the target gap
    (``max_rounds``, ``max_triangles``, or no triangle left to refine: ``stopped_by``)."""
    TIME_LIMIT = "time_limit"
    """The caller's wall-clock limit ended the refinement (only then can the interval
    depend on the machine's speed)."""
    CORRECTIONS_TOO_LARGE = "corrections_too_large"
    """The second-order corrections of the bound stayed above ``F`` on some triangles
    within the budget: the lower bound is the best earlier round's, or the trivial 0."""
    LP_FAILED = "lp_failed"
    """The LP solver failed: the lower bound is the best earlier round's, or the trivial 0."""

    @property
    def converged(self) -> bool:
        return self is CertifyStatus.CERTIFIED


class CertifyStop(str, Outcome):
    """What ended `solvers.certify`'s refinement (``CertifyResult.stopped_by``);
    a ``str`` enum, so ``result.stopped_by == "max_rounds"`` keeps working."""

    TARGET_GAP = "target_gap"
    """The gap reached ``MeshSpec.target_gap``."""
    MAX_ROUNDS = "max_rounds"
    """The ``max_rounds`` budget of [`solvers.MeshSpec`][solvers.MeshSpec]."""
    MAX_TRIANGLES = "max_triangles"
    """The ``max_triangles`` budget of [`solvers.MeshSpec`][solvers.MeshSpec]."""
    NO_REFINEMENT = "no_refinement"
    """No triangle (cell, box) left to refine."""
    LP_ROUNDS = "lp_rounds"
    """The n-D certificate (`solvers.certificates.nd`): the LP rounds of the last mesh found
    no verified bound."""
    MAX_CELLS = "max_cells"
    """`solvers.certificates.nd.certificate`: the ``max_cells`` budget of its mesh."""
    MAX_BOXES = "max_boxes"
    """The conformal certificate's ``max_boxes`` budget."""
    MAX_LIVE = "max_live"
    """The conformal certificate's ``max_live`` budget (boxes kept at once)."""
    TIME_LIMIT = "time_limit"
    """The caller's wall-clock limit."""
    CORRECTIONS_TOO_LARGE = "corrections_too_large"
    """As `CertifyStatus.CORRECTIONS_TOO_LARGE`."""
    LP_FAILED = "lp_failed"
    """As [`CertifyStatus.LP_FAILED`][finsler.status.CertifyStatus.LP_FAILED]."""

    __hash__ = str.__hash__  # a dict keyed by the old string finds the member

    @property
    def converged(self) -> bool:
        return self is CertifyStop.TARGET_GAP


class PropertyOutcome(str, Outcome):
    """Outcome of one property of the property suite (``PropertyResult.status`` of
    `validation.testing`). A ``str`` enum whose values are the suite's JSON words
    (``"not-run"`` keeps its hyphen: `label` is the value here), so
    ``result.status == "passed"`` keeps working. ``converged``: the property holds where
    it applies (passed, or failed only in the region the metric documents as excluded)."""

    PASSED = "passed"
    """No counterexample among the examples tried."""
    FAILED = "failed"
    """A counterexample (shrunk)."""
    INCONCLUSIVE = "inconclusive"
    """No counterexample, but some examples could not be judged."""
    MAPPED = "mapped"
    """Failures only inside a region the metric documents as excluded."""
    SKIPPED = "skipped"
    """The property does not apply to this metric."""
    NOT_RUN = "not-run"
    """A property it needs failed: no example was judged."""

    @property
    def label(self) -> str:
        """The suite's word (``"not-run"`` with its hyphen, as in its JSON since it began)."""
        return str(self.value)

    __hash__ = str.__hash__  # a dict keyed by the old string finds the member

    @property
    def converged(self) -> bool:
        return self in (PropertyOutcome.PASSED, PropertyOutcome.MAPPED)


class RunStop(str, Outcome):
    """What ended a learning run (``result.json``'s ``stopped_by``, `learn.loop`); a
    ``str`` enum, so ``stopped_by == "timesteps"`` keeps working. ``converged``: the run is
    finished (``result.json`` written)."""

    TIMESTEPS = "timesteps"
    """The budget of evaluations of C was spent."""
    MINUTES = "minutes"
    """The wall-clock limit ``minutes`` was reached (the run is finished)."""
    INTERRUPTED = "interrupted"
    """SIGINT or SIGTERM: the checkpoint is saved, the run is resumable, not finished."""

    __hash__ = str.__hash__  # a dict keyed by the old string finds the member

    @property
    def converged(self) -> bool:
        return self is not RunStop.INTERRUPTED


class RunStatus(str, Outcome):
    """The state of a run directory (`learn.runs.run_status`); a ``str`` enum whose
    values are the words it always returned. ``converged``: the run is finished."""

    FINISHED = "finished"
    """``result.json`` is there."""
    UNFINISHED = "unfinished"
    """A resumable checkpoint, no result yet."""
    ABSENT = "absent"
    """Nothing to resume: no run there, or one that stopped before its first checkpoint."""

    __hash__ = str.__hash__

    @property
    def converged(self) -> bool:
        return self is RunStatus.FINISHED


class RunAction(str, Outcome):
    """What a sweep did with one run (`learn.runs.run_one`, the ``action`` of
    ``sweep.json``); a ``str`` enum of the words it always wrote. ``converged``: this
    sweep trained the run to its end (a ``skipped`` run was finished before, as a
    ``skipped`` property was not judged: nothing was computed here)."""

    STARTED = "started"
    """Trained from the start to the end."""
    RESUMED = "resumed"
    """Resumed from its checkpoint and trained to the end."""
    SKIPPED = "skipped"
    """Finished already: nothing to do."""
    FAILED = "failed"
    """Training raised (or its process died); the error is recorded beside it."""
    PENDING = "pending"
    """Not reached (the sweep was interrupted first)."""

    __hash__ = str.__hash__

    @property
    def converged(self) -> bool:
        return self in (RunAction.STARTED, RunAction.RESUMED)


class LPStatus(str, Outcome):
    """Status of the last linear (or cone) program of a certificate
    (``CertifyResult.lp_status``): cvxpy's words, as a ``str`` enum so
    ``lp_status == "optimal"`` keeps working. ``converged``: the solver returned a
    potential (``optimal``, or ``optimal_inaccurate``: the certificate rescales the
    potential by its largest row ratio, so its bound is proven either way)."""

    OPTIMAL = "optimal"
    OPTIMAL_INACCURATE = "optimal_inaccurate"
    INFEASIBLE = "infeasible"
    INFEASIBLE_INACCURATE = "infeasible_inaccurate"
    UNBOUNDED = "unbounded"
    UNBOUNDED_INACCURATE = "unbounded_inaccurate"
    INFEASIBLE_OR_UNBOUNDED = "infeasible_or_unbounded"
    USER_LIMIT = "user_limit"
    SOLVER_ERROR = "solver_error"
    NOT_SOLVED = "not_solved"
    """No LP was solved (the refinement ended before its first LP, or every LP failed)."""
    UNKNOWN = "unknown"
    """A word of the LP solver this enum does not know."""

    __hash__ = str.__hash__

    @classmethod
    def from_solver(cls, text: str) -> LPStatus:
        """Map the LP solver's status word to the enum (``UNKNOWN`` if unrecognised)."""
        try:
            return cls(str(text))
        except ValueError:
            return cls.UNKNOWN

    @property
    def converged(self) -> bool:
        return self in (LPStatus.OPTIMAL, LPStatus.OPTIMAL_INACCURATE)


class EvalStatus(str, Outcome):
    """Outcome of evaluating paths on a pair set (``EvalResult.status`` of
    `learn.policy.evaluate_paths`). ``converged``: every path met the test."""

    SUCCESS = "success"
    """Every pair's path has every segment cost ``<= eps``."""
    PARTIAL = "partial"
    """Some paths have a segment above ``eps`` (``success_rate`` says how many held)."""
    NOT_FINITE = "not_finite"
    """Some path's length is not finite (a point outside the domain, a NaN)."""

    __hash__ = str.__hash__

    @property
    def converged(self) -> bool:
        return self is EvalStatus.SUCCESS


class SearchStatus(str, Outcome):
    """Outcome of the midpoint search (``SearchResult.status`` of `learn.search`)."""

    COMPLETED = "completed"
    """Every path was built to its depth with finite points."""
    NOT_FINITE = "not_finite"
    """Some path holds a non-finite point."""

    __hash__ = str.__hash__

    @property
    def converged(self) -> bool:
        return self is SearchStatus.COMPLETED


class SweepStatus(str, Outcome):
    """Outcome of a sweep of learning runs (``SweepResult.status`` of
    `learn.sweep.run_sweep`), from its runs' `RunAction`."""

    COMPLETED = "completed"
    """Every run is finished (trained here, resumed, or finished before)."""
    FAILED = "failed"
    """Some run failed (its error is recorded beside it)."""
    INTERRUPTED = "interrupted"
    """Some run was not reached (the sweep was interrupted) and none failed."""

    __hash__ = str.__hash__

    @property
    def converged(self) -> bool:
        return self is SweepStatus.COMPLETED


def families() -> tuple[type[Outcome], ...]:
    """Every status enum of the toolkit."""
    return (Status, DistanceStatus, ExpStatus, LogStatus, CertifyStatus, NewtonStatus,
            CertifyStop, PropertyOutcome, RunStop, RunStatus, RunAction, LPStatus, EvalStatus,
            SearchStatus, SweepStatus)


# ----------------------------------------------------------------------------------------
# the one shape of a result
# ----------------------------------------------------------------------------------------
class SolverError(RuntimeError):
    """Raised by ``strict=True`` solves (and `Result.strict`) that did not converge
    (the result is attached as ``.result``)."""

    def __init__(self, message: str, result: Any = None) -> None:
        super().__init__(message)
        self.result = result


def json_ready(o: Any) -> Any:
    """JSON-ready copy: statuses as their labels, results as their ``to_dict()``, numpy
    scalars and arrays as Python values, NaN and infinite floats as ``None`` (standard JSON
    cannot hold them)."""
    if isinstance(o, Outcome):
        return o.label
    if isinstance(o, Result):
        return o.to_dict()
    if isinstance(o, dict):
        return {str(k): json_ready(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_ready(v) for v in o]
    if hasattr(o, "tolist") and hasattr(o, "dtype"):  # numpy array or scalar
        return json_ready(o.tolist())
    if isinstance(o, bool) or o is None or isinstance(o, str):
        return o
    if isinstance(o, int):
        return int(o)
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    return o


_R = TypeVar("_R", bound="Result")


class Result:
    """Base of every public result type of the toolkit (a mixin of the result dataclasses:
    it declares no dataclass fields).

    A result has a ``status`` (a member of `families`) and ``wall_time`` (seconds);
    ``converged`` is its status's. `to_dict` is JSON-ready; `strict` raises
    `SolverError` on a non-converged result and returns the result otherwise, so
    ``solve_geodesic(...).strict()`` equals ``solve_geodesic(..., strict=True)``.
    """

    status: Outcome
    wall_time: float

    @property
    def converged(self) -> bool:
        """True if the status says the result can be trusted as the answer asked for."""
        return bool(self.status.converged)

    def strict(self: _R) -> _R:
        """This result, or `SolverError` (with the result attached) if it did not
        converge."""
        if not self.converged:
            raise SolverError(f"{type(self).__name__} did not converge: status "
                              f"{self.status.label}", self)
        return self

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the result's dataclass fields (statuses as labels, nested
        results as their ``to_dict()``, arrays as lists, non-finite floats as ``None``),
        plus ``converged``. Result types with a documented schema override it."""
        out: dict[str, Any] = {}
        if dataclasses.is_dataclass(self):
            for f in dataclasses.fields(self):
                out[f.name] = json_ready(getattr(self, f.name))
        out.setdefault("status", json_ready(self.status))
        out.setdefault("wall_time", json_ready(self.wall_time))
        out["converged"] = self.converged
        return out
