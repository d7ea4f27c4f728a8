"""The property suite as pytest classes to subclass: set ``metric`` (and ``policy``) as
class attributes, and pytest runs every property as a test method::

    from validation.testing import DistanceTests, MetricTests

    class TestWavy(MetricTests, DistanceTests):
        metric = Wavy(a=0.2)          # an instance, or a registered name

The classes need no pytest import (a property that does not apply calls ``pytest.skip``
only then). Every test method calls the function of the same property and raises
`PropertyFailure` (an ``AssertionError``) on a counterexample,
whose message names the property, the shrunk counterexample and the values on both sides.
Attributes (all optional but ``metric`` / ``policy``) tune the examples, the seed and the
regions and tolerances; instance attributes set by a fixture override them (how the
project's own tests run one class over every registered metric).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import finsler
from finsler import Metric
from validation.testing import distance as _d
from validation.testing import metric as _m
from validation.testing import policy as _p
from validation.testing.engine import INCONCLUSIVE, SKIPPED, PropertyResult

__all__ = ["DistanceTests", "MetricTests", "PolicyTests"]


def _outcome(result: PropertyResult) -> None:
    """Skip a property that does not apply or could not be judged (inconclusive: a solve
    that did not converge is not a counterexample), raise on a failure."""
    if result.status in (SKIPPED, INCONCLUSIVE):
        import pytest

        pytest.skip(f"{result.name} {result.status}: {result.note}")
    result.assert_ok()


class _Case:
    """What every suite class knows: the metric, the examples and the seed."""

    metric: Any = None
    """The metric to check: a [`finsler.Metric`][finsler.Metric] instance or a registered name."""
    examples: int = 100
    """Hypothesis examples per property of F (and per policy symmetry check)."""
    seed: int = 0
    """Seed of every search: the same seed gives the same examples."""
    convex_shrink: float | None = None
    """For a metric documented as not convex everywhere: the domain scaled by this about
    its centre is where F(x, .) is claimed convex (tested); None: the convex core the
    convexity map finds."""

    def get_metric(self) -> Metric:
        m = self.metric
        if m is None:
            raise TypeError(f"{type(self).__name__} must set `metric` (a finsler.Metric or "
                            "a registered name)")
        return m if isinstance(m, Metric) else finsler.get_metric(m)

    def option(self, name: str) -> Any:
        """A class or instance attribute, functions returned as they are (not bound)."""
        if name in self.__dict__:
            return self.__dict__[name]
        return getattr(type(self), name)


class MetricTests(_Case):
    """Properties of ``F(x, v)`` (`validation.testing.metric`)."""

    def _kw(self) -> dict[str, Any]:
        return {"examples": self.examples, "seed": self.seed}

    def test_domain(self) -> None:
        _outcome(_m.check_domain(self.get_metric(), **self._kw()))

    def test_finite_and_positive(self) -> None:
        _outcome(_m.check_finite_positive(self.get_metric(), **self._kw()))

    def test_homogeneity(self) -> None:
        _outcome(_m.check_homogeneity(self.get_metric(), **self._kw()))

    def test_subadditivity(self) -> None:
        _outcome(_m.check_subadditivity(self.get_metric(), convex_shrink=self.convex_shrink,
                                        **self._kw()))

    def test_strong_convexity(self) -> None:
        _outcome(_m.check_strong_convexity(self.get_metric(),
                                           convex_shrink=self.convex_shrink, **self._kw()))

    def test_reversibility(self) -> None:
        _outcome(_m.check_reversibility(self.get_metric(), **self._kw()))

    def test_lowered_forms(self) -> None:
        _outcome(_m.check_lowered_forms(self.get_metric(), **self._kw()))

    def test_smoothness(self) -> None:
        _outcome(_m.check_smoothness(self.get_metric(), **self._kw()))


def _shared(metric: Metric, key: str, entry: tuple[Any, ...], build: Callable[[], Any]) -> Any:
    """``build()`` once per metric and ``entry``, shared by the test methods of a class
    (pytest makes one instance per method). Kept on the metric (`Metric.derived`, the
    toolkit's one cache of things derived from a metric), not in a module dict keyed by
    the metric; ``entry`` is compared by identity for objects (an oracle, a policy) and by
    value for numbers and names, so nothing is keyed by ``id()`` or needs to be hashable."""
    table: list[tuple[tuple[Any, ...], Any]] = metric.derived(key, list)
    for known, value in table:
        if len(known) == len(entry) and all(
                a is b or (isinstance(a, (int, float, str, type(None)))
                           and type(a) is type(b) and a == b)
                for a, b in zip(known, entry, strict=True)):
            return value
    value = build()
    table.append((entry, value))
    return value


class DistanceTests(_Case):
    """Properties of the solved distance (`validation.testing.distance`)."""

    solved_examples: int = 3
    """Triples per distance property (the first one drawn is degenerate)."""
    distance_oracle: Any = None
    """How distances are solved: a `DiscreteDistance` (the default) or
    `ContinuumDistance`, or any object with ``solve(metric, x, y) -> Solved``."""
    distance_shrink: float | None = None
    """Draw points from the domain scaled by this about its centre; None: the whole domain,
    or for a metric documented not convex everywhere its convex region (as ``geodesics
    check`` does)."""
    closed_form_distance: Callable[..., Any] | None = None
    """A closed-form ``distance(x (N, dim), y (N, dim)) -> (N,)`` to check the solver
    against (default: the metric's own, for a `finsler.ClosedFormMetric`)."""
    closed_form_geodesic: Callable[..., Any] | None = None
    """A closed-form ``geodesic(x, y, t (T,)) -> (N, T, dim)`` at arc-length fractions."""
    certify_examples: int = 2
    """Pairs for the certificate property (2-D metrics; the first one drawn is x = y)."""

    def suite(self) -> _d.DistanceSuite:
        """The shared `DistanceSuite` of this
        configuration (solves cached across the test methods)."""
        m = self.get_metric()
        oracle = self.option("distance_oracle") or _d.DiscreteDistance()
        shrink = self.distance_shrink
        if shrink is None:
            shrink = _m.solve_region(m, self.convex_shrink, self.seed)
        return _shared(m, "validation.testing.distance_suites",
                       (type(self).__qualname__, oracle, self.seed, shrink),
                       lambda: _d.DistanceSuite.make(m, oracle, self.seed, shrink))

    def test_distance_zero(self) -> None:
        _outcome(_d.check_distance_zero(self.suite(), max(self.solved_examples, 20)))

    def test_distance_positive(self) -> None:
        _outcome(_d.check_distance_positive(self.suite(), self.solved_examples))

    def test_triangle_inequality(self) -> None:
        _outcome(_d.check_triangle_inequality(self.suite(), self.solved_examples))

    def test_segment_bound(self) -> None:
        _outcome(_d.check_segment_bound(self.suite(), self.solved_examples))

    def test_distance_symmetry(self) -> None:
        _outcome(_d.check_distance_symmetry(self.suite(), self.solved_examples))

    def test_closed_form_distance(self) -> None:
        _outcome(_d.check_closed_form(self.suite(), self.solved_examples,
                                      self.option("closed_form_distance"),
                                      self.option("closed_form_geodesic")))

    def test_certificate(self) -> None:
        _outcome(_d.check_certificate(self.suite(), self.certify_examples))

    def test_midpoint_halves(self) -> None:
        _outcome(_d.check_midpoint_halves(self.suite(), max(2, self.solved_examples - 1)))


class PolicyTests(_Case):
    """Properties of a learned midpoint policy (`validation.testing.policy`).

    ``policy``: an object with ``midpoint`` and ``generate`` (e.g. ``learn.load_policy``),
    or a run directory / environment name to load with `learn.load_any_policy`;
    ``metric`` defaults to the policy's."""

    policy: Any = None
    solved_examples: int = 3
    """Pairs for the midpoint error against exact solves."""
    pairs: int = 10
    """Fresh pairs for the success rate and the length ratio."""
    midpoint_rtol: float = _p.MIDPOINT_RTOL
    symmetry_rtol: float = _p.SYMMETRY_RTOL
    min_success: float = _p.MIN_SUCCESS
    max_length_ratio: float = _p.MAX_LENGTH_RATIO
    policy_shrink: float | None = None
    """Draw the midpoint pairs from the domain scaled by this; None: as ``distance_shrink``
    (the convex region of a metric documented not convex everywhere)."""
    _loaded: ClassVar[dict[str, Any]] = {}

    def get_policy(self) -> Any:
        pol = self.policy
        if pol is None:
            raise TypeError(f"{type(self).__name__} must set `policy`")
        if isinstance(pol, str):
            if pol not in PolicyTests._loaded:
                import learn

                PolicyTests._loaded[pol] = learn.load_any_policy(pol)
            return PolicyTests._loaded[pol]
        return pol

    def get_metric(self) -> Metric:
        return super().get_metric() if self.metric is not None else self.get_policy().metric

    def test_policy_midpoint(self) -> None:
        m = self.get_metric()
        shrink = self.policy_shrink
        if shrink is None:
            shrink = _m.solve_region(m, self.convex_shrink, self.seed)
        _outcome(_p.check_policy_midpoint(self.get_policy(), m, examples=self.solved_examples,
                                          seed=self.seed, rtol=self.midpoint_rtol,
                                          shrink=shrink))

    def test_policy_symmetry(self) -> None:
        _outcome(_p.check_policy_symmetry(self.get_policy(), self.get_metric(),
                                          examples=self.examples, seed=self.seed,
                                          rtol=self.symmetry_rtol))

    def _fresh(self) -> list[PropertyResult]:
        pol, m = self.get_policy(), self.get_metric()
        # fresh-pair results per policy configuration, shared by the success and ratio tests
        return _shared(m, "validation.testing.policy_runs",
                       (pol, self.pairs, self.seed, self.min_success, self.max_length_ratio),
                       lambda: _p.check_policy_success(
                           pol, m, pairs=self.pairs, seed=self.seed,
                           min_success=self.min_success,
                           max_length_ratio=self.max_length_ratio))

    def test_policy_success(self) -> None:
        _outcome(self._fresh()[0])

    def test_policy_length_ratio(self) -> None:
        _outcome(self._fresh()[1])
