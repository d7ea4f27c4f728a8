"""Every property at once: :func:`check` (what ``geodesics check`` runs)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from finsler import Metric
from finsler.errors import InputError
from finsler.spec import MetricSpec
from validation.testing.distance import DistanceOracle, distance_properties
from validation.testing.engine import SKIPPED, CheckReport, PropertyResult
from validation.testing.metric import (
    check_domain,
    check_finite_positive,
    check_homogeneity,
    check_lowered_forms,
    check_reversibility,
    check_smoothness,
    check_strong_convexity,
    check_subadditivity,
    solve_region,
)
from validation.testing.policy import (
    MAX_LENGTH_RATIO,
    MIDPOINT_RTOL,
    MIN_SUCCESS,
    SYMMETRY_RTOL,
    policy_properties,
)

__all__ = ["PREREQUISITES", "check", "solved_examples_for"]

#: Properties of F without which solved distances mean nothing: when one fails, the
#: distance and policy properties are skipped (and say why).
PREREQUISITES = ("domain", "finite-positive", "homogeneity", "lowered-forms")


def solved_examples_for(examples: int) -> int:
    """Examples of the properties that solve geodesics, for ``examples`` of those that do
    not: ``examples // 30``, at least 3 (the first one hypothesis draws is degenerate)."""
    return max(3, int(examples) // 30)


def _params(metric: Metric) -> dict[str, Any]:
    """The metric's parameters (its identity, :class:`finsler.MetricSpec`); none for a
    metric that is not a dataclass."""
    try:
        return dict(MetricSpec.of(metric).params)
    except InputError:
        return {}


def check(
    metric: Metric,
    *,
    policy: Any = None,
    examples: int = 100,
    seed: int = 0,
    solved_examples: int | None = None,
    convex_shrink: float | None = None,
    oracle: DistanceOracle | None = None,
    closed_form: Callable[..., Any] | None = None,
    closed_form_geodesic: Callable[..., Any] | None = None,
    policy_pairs: int | None = None,
    midpoint_rtol: float = MIDPOINT_RTOL,
    symmetry_rtol: float = SYMMETRY_RTOL,
    min_success: float = MIN_SUCCESS,
    max_length_ratio: float = MAX_LENGTH_RATIO,
    progress: Callable[[PropertyResult], None] | None = None,
) -> CheckReport:
    """Check ``metric`` (and ``policy``, if given) with every property of
    :mod:`validation.testing`; deterministic for a given ``seed``.

    ``examples``: hypothesis examples per property of ``F``; properties that solve
    geodesics use ``solved_examples`` (default :func:`solved_examples_for`), the policy's
    success and length ratio ``policy_pairs`` fresh pairs (default ``examples // 10``, at
    least 4). ``convex_shrink``: the region (the domain scaled about its centre) where a
    metric documented as not convex everywhere is claimed convex (default: the convex core
    its convexity map finds). ``oracle``: how distances are solved (default
    :class:`~validation.testing.DiscreteDistance`). ``closed_form`` /
    ``closed_form_geodesic``: a distance / geodesic to check the solver against (default:
    the metric's own, if it has one). ``progress`` is called with each result as it is
    found. Returns a :class:`CheckReport`; ``report.ok`` is False if a property failed.
    """
    if isinstance(examples, bool) or not isinstance(examples, int) or examples < 1:
        raise InputError(f"examples must be a positive integer, got {examples!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    solved = solved_examples_for(examples) if solved_examples is None else int(solved_examples)
    pairs = max(4, examples // 10) if policy_pairs is None else int(policy_pairs)
    t0 = time.perf_counter()
    report = CheckReport(metric.name, _params(metric), seed, examples,
                         policy=None if policy is None else str(getattr(policy, "source", "")
                                                                or type(policy).__name__))

    def add(r: PropertyResult) -> PropertyResult:
        report.results.append(r)
        if progress is not None:
            progress(r)
        return r

    kw = {"examples": examples, "seed": seed}
    for fn in (check_domain, check_finite_positive, check_homogeneity):
        add(fn(metric, **kw))
    add(check_subadditivity(metric, convex_shrink=convex_shrink, **kw))
    add(check_strong_convexity(metric, convex_shrink=convex_shrink, **kw))
    for fn in (check_reversibility, check_lowered_forms, check_smoothness):
        add(fn(metric, **kw))
    broken = [r.name for r in report.results if r.name in PREREQUISITES and not r.ok]
    # where F(x, .) is documented not convex, solved lengths are not distances with
    # reliable errors: distances (and policies' midpoints) are checked on the convex region
    region = 1.0 if broken else solve_region(metric, convex_shrink, seed)
    later: list[tuple[str, Callable[[], list[PropertyResult]]]] = [
        ("distance", lambda: distance_properties(
            metric, examples=solved, seed=seed, oracle=oracle, shrink=region,
            closed_form=closed_form, closed_form_geodesic=closed_form_geodesic))]
    if policy is not None:
        later.append(("policy", lambda: policy_properties(
            policy, metric, examples=examples, solved_examples=solved, pairs=pairs,
            seed=seed, shrink=region, midpoint_rtol=midpoint_rtol,
            symmetry_rtol=symmetry_rtol, min_success=min_success,
            max_length_ratio=max_length_ratio)))
    for _what, run in later:
        if broken:
            for r in run_skipped(_what, broken, metric, policy):
                add(r)
            continue
        for r in run():
            add(r)
    report.seconds = time.perf_counter() - t0
    return report


_NAMES = {
    "distance": ("distance-zero", "distance-positive", "triangle-inequality",
                 "segment-bound", "distance-symmetry", "closed-form-distance", "certificate",
                 "midpoint-halves"),
    "policy": ("policy-midpoint", "policy-symmetry", "policy-success", "policy-length-ratio"),
}


def run_skipped(what: str, broken: list[str], metric: Metric, policy: Any
                ) -> list[PropertyResult]:
    """The ``what`` properties, reported skipped because ``broken`` properties of F
    failed."""
    note = (f"skipped: {metric.name} fails {', '.join(broken)}, so solved distances (and a "
            "policy's errors against them) mean nothing until that is fixed")
    return [PropertyResult(n, "", SKIPPED, note=note) for n in _NAMES[what]]
