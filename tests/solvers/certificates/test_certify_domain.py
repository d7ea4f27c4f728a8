"""solvers.certificates.domain: a box is dropped from a certificate only where it misses the
domain (checked against points of the box that the domain contains), boxes that do miss
it are dropped, and a box domain drops nothing but empty boxes."""

from __future__ import annotations

import numpy as np
import pytest

import finsler
from solvers.certificates.domain import domain_constraints, outside_domain


@pytest.mark.parametrize("name", ["poincare-slab", "carlike", "poincare"])
def test_a_box_holding_a_domain_point_is_never_dropped(name: str) -> None:
    m = finsler.get_metric(name)
    cons = domain_constraints(m)
    assert cons is not None  # each has a disk factor
    lo_d, hi_d = (np.asarray(b, float) for b in m.domain.bounds())
    rng = np.random.default_rng(7)
    n, dim = 400, m.dim
    c = rng.uniform(lo_d - 0.2, hi_d + 0.2, (n, dim))
    half = rng.uniform(0.0, 0.15, (n, dim)) * (hi_d - lo_d)
    lo, hi = c - half, c + half
    out = outside_domain(cons, lo, hi)
    u = rng.uniform(size=(n, 300, dim))
    pts = lo[:, None] + u * (hi - lo)[:, None]
    hit = m.domain.contains(pts.reshape(-1, dim)).reshape(n, -1).any(axis=1)
    assert not np.any(out & hit)  # sound
    assert np.count_nonzero(out & ~hit) > 0.5 * np.count_nonzero(~hit)  # and useful


def test_boxes_beyond_the_disk_are_dropped_and_empty_boxes_too() -> None:
    m = finsler.get_metric("poincare-slab")  # disk of radius 0.7 x [-1, 1]
    cons = domain_constraints(m)
    lo = np.array([[0.55, 0.55, -0.1], [0.3, 0.3, -0.1], [0.0, 0.0, 0.2]])
    hi = np.array([[0.7, 0.7, 0.1], [0.5, 0.5, 0.1], [0.1, 0.1, 0.1]])  # last: lo > hi
    np.testing.assert_array_equal(outside_domain(cons, lo, hi), [True, False, True])
    # a box domain has no constraints: only empty boxes are dropped
    box = finsler.get_metric("randers")
    assert domain_constraints(box) is None
    np.testing.assert_array_equal(
        outside_domain(None, np.array([[0.0, 0.0], [1.0, 0.0]]),
                       np.array([[1.0, 1.0], [0.0, 1.0]])), [False, True])
