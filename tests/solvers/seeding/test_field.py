"""The lattice field (solvers.seeding.field): moves chosen by the metric, graph distances against
closed forms, routes in other basins, one forward search per start."""

from __future__ import annotations

import numpy as np
import pytest

import finsler
from finsler import InputError
from solvers.seeding.field import FieldSpec, LatticeField, lattice_field


@pytest.mark.parametrize("name", ["euclidean", "randers", "poincare"])
def test_graph_distances_bound_the_closed_form_from_above_and_come_close(name: str) -> None:
    """Every edge weighs the eq. (58) length of its segment, an upper bound of the
    distance, so graph distances are never below the closed form; with moves up to 6
    cells, kept when 3 % cheaper than any split, they stay within a few percent of it
    away from the start (the lattice's error is in its directions, not its lengths)."""
    m = finsler.get_metric(name)
    f = LatticeField(m, FieldSpec(resolution=48))
    s = np.array([0.1, -0.2])
    d_graph = f.distances(s)
    d_true = np.asarray(m.distance(np.repeat(s[None], len(f.nodes), 0), f.nodes))
    far = d_true > 0.3
    assert np.all(np.isfinite(d_graph))
    assert np.all(d_graph >= d_true * (1 - 1e-9))
    rel = d_graph[far] / d_true[far] - 1
    assert np.median(rel) < 0.02 and np.max(rel) < 0.06


def test_translation_invariant_costs_are_exact_per_class() -> None:
    """Car-like F depends on the heading alone: a move's cost is computed once per heading
    value, and equals the eq. (58) length evaluated where the edge lies; the lattice keeps
    long moves along the heading and short ones across it (sideways costs 10x)."""
    m = finsler.get_metric("carlike")
    f = lattice_field(m)
    r, c, w = f.edges
    pick = np.random.default_rng(0).choice(len(r), 2000, replace=False)
    direct = m.segment_length(f.nodes[r[pick]], f.nodes[c[pick]], 4, check=False)
    np.testing.assert_allclose(w[pick], direct, rtol=1e-12)
    step = (f.nodes[c] - f.nodes[r]) / f.h
    theta = f.nodes[r, 2]
    along = np.abs(step[:, 0] * np.cos(theta) + step[:, 1] * np.sin(theta))
    side = np.abs(-step[:, 0] * np.sin(theta) + step[:, 1] * np.cos(theta))
    assert along.max() > 5.5 and np.percentile(side, 99) < 2.5
    assert f.size[1] < 100 * f.size[0]  # pruned: the full set would be ~1800 per node


def test_routes_join_the_pair_and_lie_in_other_basins() -> None:
    m = finsler.get_metric("carlike")
    f = lattice_field(m)
    s, g = finsler.sample_pairs(m, 1, 5)[0]
    routes = f.routes(s, g, 3, 8.0, ratio=np.inf)
    assert len(routes) == 3
    for p in routes:
        np.testing.assert_array_equal(p[0], s)
        np.testing.assert_array_equal(p[-1], g)
        assert np.all(m.domain.contains(p))
    # the second route passes through a node at least 8 cells from every node of the first
    first = routes[0][1:-1] / f.h
    gap = np.min(np.linalg.norm(routes[1][1:-1, None] / f.h - first[None], axis=-1), 1)
    assert gap.max() >= 8.0 - 1e-9
    lengths = [float(np.sum(m.segment_length(p[:-1], p[1:], 4))) for p in routes]
    assert lengths[0] <= min(lengths[1:]) * (1 + 1e-12)
    # a ratio of 1 admits only routes as short as the shortest
    assert len(f.routes(s, g, 3, 8.0, ratio=1.0)) == 1


def test_goals_of_one_start_share_its_forward_search(monkeypatch) -> None:
    m = finsler.get_metric("carlike")
    f = LatticeField(m, FieldSpec(resolution=24, reach=3))
    calls = []
    search = f._search
    monkeypatch.setattr(f, "_search", lambda g, p, fw: calls.append(fw) or search(g, p, fw))
    pairs = finsler.sample_pairs(m, 4, 9)
    for g in pairs[:, 1]:
        f.routes(pairs[0, 0], g, 1, 4.0)
    assert calls.count(True) == 1 and calls.count(False) == 4


def test_bad_specs_are_refused() -> None:
    for bad in (dict(resolution=1), dict(resolution=2.5), dict(resolution=5000),
                dict(reach=0), dict(prune=1.0), dict(prune=-0.1), dict(link=True)):
        with pytest.raises(InputError, match="FieldSpec"):
            FieldSpec(**bad)
    with pytest.raises(InputError, match="2-D and 3-D"):
        lattice_field(finsler.get_metric("panda-pole"))
