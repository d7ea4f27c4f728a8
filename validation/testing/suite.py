"""Every property at once: `check` (what ``geodesics check`` runs)."""

from __future__ import annotations

import os
import re
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from finsler import Metric
from finsler.errors import InputError
from finsler.spec import MetricSpec
from validation.testing.distance import DistanceOracle, DistanceSuite, distance_checks
from validation.testing.engine import FAILED, NOT_RUN, CheckReport, PropertyResult
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
    check_policy_midpoint,
    check_policy_success,
    check_policy_symmetry,
)

__all__ = ["NEEDS", "PREREQUISITES", "check", "solved_examples_for"]

#: Properties of F without which solved distances (and a policy's errors against them)
#: mean nothing: every distance and policy property needs all of them.
PREREQUISITES = ("domain", "finite-positive", "homogeneity", "subadditivity",
                 "strong-convexity", "lowered-forms", "smoothness")

#: What each property needs: when one of them fails (or was not run), the property is
#: reported ``not-run`` naming it, instead of failing as a consequence (e.g. ``nan ==
#: nan`` in lowered-forms once F is NaN somewhere, subadditivity once homogeneity fails).
#: A ``mapped`` or ``skipped`` property does not block what needs it.
NEEDS: dict[str, tuple[str, ...]] = {
    "domain": (),
    "finite-positive": ("domain",),
    "homogeneity": ("domain",),
    "subadditivity": ("finite-positive", "homogeneity"),
    "strong-convexity": ("finite-positive", "homogeneity"),
    "reversibility": ("finite-positive",),
    "lowered-forms": ("domain",),
    "smoothness": ("domain",),
    **{n: PREREQUISITES for n in (
        "distance-zero", "distance-positive", "triangle-inequality", "segment-bound",
        "closed-form-distance", "certificate", "midpoint-halves", "policy-midpoint",
        "policy-success", "policy-length-ratio")},
    "distance-symmetry": (*PREREQUISITES, "reversibility"),
    "policy-symmetry": (*PREREQUISITES, "reversibility"),
}


def solved_examples_for(examples: int) -> int:
    """Examples of the properties that solve geodesics, for ``examples`` of those that do
    not: ``examples // 30``, at least 3 (the first one hypothesis draws is degenerate)."""
    return max(3, int(examples) // 30)


def _params(metric: Metric) -> dict[str, Any]:
    """The metric's parameters (its identity, `finsler.MetricSpec`); none for a
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
    `validation.testing`; deterministic for a given ``seed``.

    ``examples``: hypothesis examples per property of ``F``; properties that solve
    geodesics use ``solved_examples`` (default `solved_examples_for`), the policy's
    success and length ratio ``policy_pairs`` fresh pairs (default ``examples // 10``, at
    least 4). ``convex_shrink``: the region (the domain scaled about its centre) where a
    metric documented as not convex everywhere is claimed convex (default: the convex core
    its convexity map finds). ``oracle``: how distances are solved (default
    [`DiscreteDistance`][validation.testing.DiscreteDistance]). ``closed_form`` /
    ``closed_form_geodesic``: a distance / geodesic to check the solver against (default:
    the metric's own, if it has one). ``progress`` is called with each result as it is
    found. Returns a `CheckReport`; ``report.ok`` is False if a property failed.
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
    status: dict[str, str] = {}
    roots: dict[str, tuple[str, ...]] = {}  # the failed properties behind a not-run one

    def blocked(name: str) -> tuple[str, ...]:
        out: list[str] = []
        for need in NEEDS.get(name, ()):
            if status.get(need) == FAILED:
                out.append(need)
            elif status.get(need) == NOT_RUN:
                out += roots[need]
        return tuple(dict.fromkeys(out))

    def run(names: tuple[str, ...], fn: Callable[[], Any]) -> None:
        why = tuple(dict.fromkeys(b for n in names for b in blocked(n)))
        if why:
            results = [_not_run(n, why, metric) for n in names]
        else:
            results = _quietly(fn)
            results = results if isinstance(results, list) else [results]
        for r in results:
            r.needs = NEEDS.get(r.name, ())
            status[r.name] = r.status
            if r.status == NOT_RUN:
                roots[r.name] = why
            add(r)

    run(("domain",), lambda: check_domain(metric, **kw))
    run(("finite-positive",), lambda: check_finite_positive(metric, **kw))
    run(("homogeneity",), lambda: check_homogeneity(metric, **kw))
    run(("subadditivity",), lambda: check_subadditivity(metric, convex_shrink=convex_shrink,
                                                        **kw))
    run(("strong-convexity",), lambda: check_strong_convexity(
        metric, convex_shrink=convex_shrink, **kw))
    run(("reversibility",), lambda: check_reversibility(metric, **kw))
    run(("lowered-forms",), lambda: check_lowered_forms(metric, **kw))
    run(("smoothness",), lambda: check_smoothness(metric, **kw))
    # where F(x, .) is documented not convex, solved lengths are not distances with
    # reliable errors: distances (and policies' midpoints) are checked on the convex region
    # (not mapped when none of them runs; one blocked alone, distance-symmetry behind a
    # failed reversibility, leaves the others on that region)
    if all(blocked(n) for n in _NAMES["distance"]):
        region = 1.0
    else:
        region = solve_region(metric, convex_shrink, seed)
    suite = DistanceSuite.make(metric, oracle, seed, region)
    for name, fn in distance_checks(suite, solved, closed_form, closed_form_geodesic):
        run((name,), fn)
    if policy is not None:
        run(("policy-midpoint",), lambda: check_policy_midpoint(
            policy, metric, examples=solved, seed=seed, rtol=midpoint_rtol, shrink=region))
        run(("policy-symmetry",), lambda: check_policy_symmetry(
            policy, metric, examples=examples, seed=seed, rtol=symmetry_rtol))
        run(("policy-success", "policy-length-ratio"), lambda: check_policy_success(
            policy, metric, pairs=pairs, seed=seed, min_success=min_success,
            max_length_ratio=max_length_ratio))
    report.seconds = time.perf_counter() - t0
    return report


def _quietly(fn: Callable[[], Any]) -> Any:
    """Run one property with warnings caught (numpy's RuntimeWarnings on invalid values
    are findings, not noise on stderr) and summarised on its results, and what native
    code writes to stderr meanwhile (CasADi's "NaN detected" of a solve) with them."""
    with _native_stderr() as lines, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn()
    counts: dict[str, int] = {}
    for w in caught:
        key = f"{w.category.__name__}: {' '.join(str(w.message).split())[:120]}"
        counts[key] = counts.get(key, 0) + 1
    for line in lines:
        # e.g. CasADi - <date> <time> WARNING("...: NaN detected ..., at (row 66, col 0).")
        text = re.sub(r"^CasADi - \S+ \S+ ", "CasADi ", " ".join(line.split()))
        text = re.sub(r"\(row \d+, col \d+\)", "(row ., col .)", text)
        if text:
            key = f"stderr: {text[:120]}"
            counts[key] = counts.get(key, 0) + 1
    text = [f"{k} ({n}x)" if n > 1 else k for k, n in counts.items()]
    for r in out if isinstance(out, list) else [out]:
        r.warnings = list(text)
    return out


@contextmanager
def _native_stderr() -> Iterator[list[str]]:
    """Collect what is written to the process's stderr file descriptor (native code:
    CasADi and IPOPT print there, not through Python) into a list of lines; nothing is
    collected where stderr has no descriptor (a test runner's captured stream)."""
    lines: list[str] = []
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        yield lines
        return
    sys.stderr.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), fd)
        try:
            yield lines
        finally:
            sys.stderr.flush()
            os.dup2(saved, fd)
            os.close(saved)
            tmp.seek(0)
            lines.extend(tmp.read().decode(errors="replace").splitlines())


def _not_run(name: str, why: tuple[str, ...], metric: Metric) -> PropertyResult:
    return PropertyResult(name, "", NOT_RUN, note=(
        f"needs {', '.join(why)}, which {'fails' if len(why) == 1 else 'fail'} on "
        f"{metric.name}: its verdict would mean nothing until that is fixed"))


_NAMES = {
    "distance": ("distance-zero", "distance-positive", "triangle-inequality",
                 "segment-bound", "distance-symmetry", "closed-form-distance", "certificate",
                 "midpoint-halves"),
    "policy": ("policy-midpoint", "policy-symmetry", "policy-success", "policy-length-ratio"),
}
