"""One solve request down the solve path: what `solve_geodesic` and `solve_batch` checked
at the public boundary, handed as one object to every step below them (`pair_solver`,
`tolerance`, the chunks of `batches`, Ray tasks), instead of a row of positional
arguments that each step unpacks and passes on.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from finsler.errors import InputError
from finsler.metrics.base import Metric
from finsler.spec import MetricSpec
from solvers.seeding.plans import SeedPlan

__all__ = ["SolveRequest", "seed_plan"]


def seed_plan(metric: Metric, seeds: Any, method: str) -> SeedPlan:
    """The plan of a request: ``seeds`` checked, or `SeedPlan.default` for the metric and
    the resolved ``method`` when None."""
    plan = seeds if seeds is not None else SeedPlan.default(metric, method)
    if not isinstance(plan, SeedPlan):
        raise InputError(f"seeds must be a SeedPlan, got {type(plan).__name__}")
    return plan


@dataclass(frozen=True)
class SolveRequest:
    """A checked request to solve pairs of one metric; nothing below the public entry
    points checks it again.

    A request pickles by its metric's [`MetricSpec`][finsler.spec.MetricSpec] (a worker
    process or Ray task rebuilds the metric once, with what the metric derived, instead of
    receiving the CasADi objects)."""

    metric: Metric
    """The metric (an object, not a name)."""
    segments: int
    """Segments ``n`` of the discrete geodesic (checked, `solvers.inputs.check_segments`)."""
    plan: SeedPlan
    """The seed plan (default: `SeedPlan.default` for the metric and ``method``)."""
    method: str
    """``"newton"`` or ``"ipopt"`` (resolved from ``"auto"``)."""
    global_seeds: bool = True
    """Solve the plan's seeds (False: only the caller-given paths, a warm start)."""
    minmax: bool = False
    """Attach the min-max refinement to every result."""
    tol: float | None = None
    """Relative accuracy of the length (None: solve at ``segments`` only)."""
    max_segments: int | None = None
    """Largest size ``tol`` may double to (checked with ``tol``)."""
    device: Any = None
    """Torch device of the Newton method (None: numpy)."""
    warm: bool = False
    """The given paths are nearly converged: IPOPT's warm options."""

    def at(self, segments: int, **changes: Any) -> SolveRequest:
        """The same request at another size (and any other field changed)."""
        return dataclasses.replace(self, segments=segments, **changes)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                  if f.name != "metric"}
        return _rebuild, (MetricSpec.of(self.metric), fields)


def _rebuild(spec: MetricSpec, fields: dict[str, Any]) -> SolveRequest:
    """A pickled request's metric rebuilt from its spec (once per process: the registry
    shares its instances)."""
    return SolveRequest(metric=spec.build(), **fields)
