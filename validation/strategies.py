"""Hypothesis strategies shared by every property test: metrics, points in a metric's
domain, pairs and triples of points, and short pairs for Proposition 1.

Points are drawn coordinate-wise from the domain's parametrisation (box coordinates;
radius fraction and angle for disks; products concatenate), so hypothesis can shrink
them, and every drawn point lies in the domain by construction.

Example::

    from hypothesis import given
    from validation import strategies as vs

    @given(vs.metric_and_pair(names=vs.CLOSED_FORM_2D))
    def test_something(mp):
        metric, x, y = mp
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from hypothesis import strategies as st

import finsler
from finsler import Box, Disk, Domain, Metric, Product

__all__ = [
    "CLOSED_FORM",
    "CLOSED_FORM_2D",
    "FINSLER_2D",
    "close_pairs",
    "metric_and_pair",
    "metric_and_triple",
    "metrics",
    "pairs",
    "points",
    "triples",
]

# The metrics are asked what they can do (finsler.list_metrics filters on hooks and
# properties); no list of names is kept here. Registered when this module is imported.
#: Registered metrics with a closed-form distance (the ``distance`` hook).
CLOSED_FORM: tuple[str, ...] = tuple(finsler.list_metrics(provides="distance"))
#: The 2-D closed-form metrics (the defaults of the grid checks of Proposition 2).
CLOSED_FORM_2D: tuple[str, ...] = tuple(finsler.list_metrics(provides="distance", dim=2))
#: 2-D metrics that are Finsler (strongly convex, smooth) on their whole domain.
FINSLER_2D: tuple[str, ...] = tuple(
    n for n in finsler.list_metrics(dim=2, convex_everywhere=True)
    if finsler.get_metric(n).smooth)


def metrics(names: Sequence[str] | None = None) -> st.SearchStrategy[Metric]:
    """A registered metric with default parameters, drawn from ``names`` (default: all)."""
    pool = list(names) if names is not None else finsler.list_metrics()
    return st.sampled_from(pool).map(finsler.get_metric)


def _unit() -> st.SearchStrategy[float]:
    return st.floats(0.0, 1.0, allow_nan=False, allow_infinity=False)


def _domain_point(domain: Domain, shrink: float) -> st.SearchStrategy[np.ndarray]:
    if isinstance(domain, Box):
        lo, hi = domain.bounds()
        c, r = 0.5 * (lo + hi), 0.5 * (hi - lo) * shrink
        return st.lists(_unit(), min_size=domain.dim, max_size=domain.dim).map(
            lambda u: c + r * (2.0 * np.asarray(u) - 1.0)
        )
    if isinstance(domain, Disk):
        c = np.asarray(domain.center, float)
        rad = domain.radius * shrink
        return st.tuples(_unit(), st.floats(0.0, 2 * math.pi, exclude_max=True)).map(
            lambda ra: c
            + rad * math.sqrt(ra[0]) * np.array([math.cos(ra[1]), math.sin(ra[1])])
        )
    if isinstance(domain, Product):
        parts = [_domain_point(f, shrink) for f in domain.factors]
        return st.tuples(*parts).map(lambda ps: np.concatenate(ps))
    # unknown domain kind: seeded uniform sampling (no shrinking, but valid points)
    return st.integers(0, 2**32 - 1).map(
        lambda s: domain.sample(1, np.random.default_rng(s))[0]
    )


def points(metric: Metric, shrink: float = 1.0) -> st.SearchStrategy[np.ndarray]:
    """A point ``(dim,)`` float64 in the metric's domain (scaled about its centre by
    ``shrink`` in ``(0, 1]``, to keep away from the boundary)."""
    if not 0.0 < shrink <= 1.0:
        raise ValueError(f"shrink must be in (0, 1], got {shrink}")
    return _domain_point(metric.domain, shrink)


def pairs(
    metric: Metric, shrink: float = 1.0, min_separation: float = 0.0
) -> st.SearchStrategy[tuple[np.ndarray, np.ndarray]]:
    """Two points ``(x, y)`` of the domain with Euclidean separation ``>= min_separation``."""
    p = points(metric, shrink)
    return st.tuples(p, p).filter(
        lambda xy: float(np.linalg.norm(xy[1] - xy[0])) >= min_separation
    )


def triples(
    metric: Metric, shrink: float = 1.0
) -> st.SearchStrategy[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Three points ``(x, y, z)`` of the domain."""
    p = points(metric, shrink)
    return st.tuples(p, p, p)


def close_pairs(
    metric: Metric, max_step: float, shrink: float = 0.9
) -> st.SearchStrategy[tuple[np.ndarray, np.ndarray]]:
    """A point ``x`` and ``y = x + t u`` with ``u`` a unit vector and ``0 < t <= max_step``,
    both in the domain (``x`` drawn with ``shrink`` < 1 leaves room for the step)."""
    dim = metric.dim

    def build(args: tuple[np.ndarray, list[float], float]) -> tuple[np.ndarray, np.ndarray]:
        x, g, t = args
        u = np.asarray(g, float)
        u = u / np.linalg.norm(u)
        return x, x + t * u

    direction = st.lists(
        st.floats(-1.0, 1.0, allow_nan=False), min_size=dim, max_size=dim
    ).filter(lambda g: float(np.linalg.norm(g)) > 0.1)
    return (
        st.tuples(points(metric, shrink), direction, st.floats(max_step * 1e-3, max_step))
        .map(build)
        .filter(lambda xy: bool(metric.domain.contains(xy[1]).all()))
    )


def metric_and_pair(
    names: Sequence[str] | None = None, shrink: float = 1.0
) -> st.SearchStrategy[tuple[Metric, np.ndarray, np.ndarray]]:
    """``(metric, x, y)`` with ``x, y`` in the metric's domain."""
    return metrics(names).flatmap(
        lambda m: pairs(m, shrink).map(lambda xy: (m, xy[0], xy[1]))
    )


def metric_and_triple(
    names: Sequence[str] | None = None, shrink: float = 1.0
) -> st.SearchStrategy[tuple[Metric, np.ndarray, np.ndarray, np.ndarray]]:
    """``(metric, x, y, z)`` with the three points in the metric's domain."""
    return metrics(names).flatmap(
        lambda m: triples(m, shrink).map(lambda p: (m, p[0], p[1], p[2]))
    )
