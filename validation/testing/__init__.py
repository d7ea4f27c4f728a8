"""Property-based tests a user points at their own metric and policy.

The toolkit's own metrics pass these tests; a metric you write gets the same checks,
three ways:

* **pytest classes** to subclass (as geomstats ships test cases for its manifolds)::

      # test_wavy.py -- run with `pytest test_wavy.py`
      from validation.testing import DistanceTests, MetricTests
      from wavy import Wavy

      class TestWavy(MetricTests, DistanceTests):
          metric = Wavy(a=0.2)       # or a registered name: metric = "wavy"

  and `PolicyTests` with ``policy = learn.load_policy(...)`` (or a run directory);
* **functions**, one per property, each returning a `PropertyResult`
  (``result.assert_ok()`` raises with the report), and `check` for all of them;
* the command ``geodesics check --metric NAME [--metric-module FILE] [--run DIR]``.

Properties (names as in the table of ``geodesics check``):

* of ``F`` (`validation.testing.metric`): ``domain`` (projection), ``finite-positive``,
  ``homogeneity`` (positive 1-homogeneity), ``subadditivity`` (the triangle inequality of
  ``F(x, .)``, i.e. a convex indicatrix), ``strong-convexity`` (the fundamental tensor),
  ``reversibility`` (as declared), ``lowered-forms`` (numpy/torch against the symbolic
  CasADi ``F``), ``smoothness`` (``F**2`` is C^2 where declared smooth). A metric that
  documents where ``F(x, .)`` is not convex (``convex_everywhere = False``) gets that
  region *mapped* (status ``mapped``, with how much of the domain and how near its centre)
  instead of an error, and the claim tested on its convex part;
* of the solved distance (`validation.testing.distance`): ``distance-zero``,
  ``distance-positive``, ``triangle-inequality``, ``segment-bound`` (the straight
  segment's length bounds ``d``), ``distance-symmetry`` (reversible metrics),
  ``closed-form-distance`` (a distance or geodesic you supply, or the metric's own,
  against the solver), ``certificate`` (the certified interval contains the solved
  distance: 2-D and 3-D, and conformal metrics beyond), ``midpoint-halves``; all within
  the solver's stated errors;
* of a policy (`validation.testing.policy`): ``policy-midpoint`` (against exact
  midpoints where Proposition 1 holds), ``policy-symmetry`` (reversible metrics),
  ``policy-success`` and ``policy-length-ratio`` on fresh pairs.

Every failure names the property, gives the smallest counterexample hypothesis's
shrinking reached (within a budget of evaluations) and the values on both sides. Searches
are seeded: the same seed gives the same examples and results.

Outcomes: ``passed``, ``failed`` (a counterexample), ``inconclusive`` (some examples could
not be judged -- a solve that did not converge is never a counterexample --, no
counterexample among the others), ``mapped``, ``skipped`` (does not apply) and, in
`check`, ``not-run``: properties depend on others (`suite.NEEDS`), and once
one of F's own properties fails, what needs it is not run (the root cause is the first
failed property). ``domain``, ``finite-positive``, ``strong-convexity`` and
``smoothness`` add seeded sweeps of many points (`validation.testing.regions`) to
hypothesis's draws, so a small bad region is found and its size reported.
"""

from validation.testing.cases import DistanceTests, MetricTests, PolicyTests
from validation.testing.distance import (
    ContinuumDistance,
    DiscreteDistance,
    DistanceOracle,
    Solved,
    check_certificate,
    check_closed_form,
    check_distance_positive,
    check_distance_symmetry,
    check_distance_zero,
    check_midpoint_halves,
    check_segment_bound,
    check_triangle_inequality,
    distance_properties,
)
from validation.testing.engine import (
    CheckReport,
    PropertyFailure,
    PropertyResult,
    Verdict,
    search,
)
from validation.testing.metric import (
    ConvexityMap,
    check_domain,
    check_finite_positive,
    check_homogeneity,
    check_lowered_forms,
    check_reversibility,
    check_smoothness,
    check_strong_convexity,
    check_subadditivity,
    convexity_map,
    metric_properties,
)
from validation.testing.policy import (
    check_policy_midpoint,
    check_policy_success,
    check_policy_symmetry,
    policy_properties,
)
from validation.testing.suite import check

__all__ = [
    "CheckReport",
    "ContinuumDistance",
    "ConvexityMap",
    "DiscreteDistance",
    "DistanceOracle",
    "DistanceTests",
    "MetricTests",
    "PolicyTests",
    "PropertyFailure",
    "PropertyResult",
    "Solved",
    "Verdict",
    "check",
    "check_certificate",
    "check_closed_form",
    "check_distance_positive",
    "check_distance_symmetry",
    "check_distance_zero",
    "check_domain",
    "check_finite_positive",
    "check_homogeneity",
    "check_lowered_forms",
    "check_midpoint_halves",
    "check_policy_midpoint",
    "check_policy_success",
    "check_policy_symmetry",
    "check_reversibility",
    "check_segment_bound",
    "check_smoothness",
    "check_strong_convexity",
    "check_subadditivity",
    "check_triangle_inequality",
    "convexity_map",
    "distance_properties",
    "metric_properties",
    "policy_properties",
    "search",
]
