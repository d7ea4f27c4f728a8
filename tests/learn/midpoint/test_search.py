"""Policy-guided route search (learn.search): never longer than the policy's own path
before equalizing, equalizing never raises the largest segment or the energy (exactly
equal segments on the Euclidean metric), finds the route the policy misses (checked
against the exact solver), counts every evaluation of C, and rejects impossible
settings."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import finsler
import learn
import solvers
from finsler import InputError
from learn import SearchSpec, equalize_paths, search_paths
from learn.midpoint.networks import predictor
from learn.midpoint.search import _regenerate_windows
from validation.cli import app

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def matsumoto():
    return learn.load_policy("matsumoto")


def test_search_is_never_longer_than_the_policys_path(matsumoto) -> None:
    m = matsumoto.metric
    pairs = finsler.sample_pairs(m, 40, 2024)
    plain = matsumoto.generate(pairs[:, 0], pairs[:, 1])
    res = matsumoto.search(pairs[:, 0], pairs[:, 1], SearchSpec(equalize=0))
    assert res.paths.shape == plain.shape == (40, 65, 2)
    assert res.paths.dtype == np.float64
    np.testing.assert_array_equal(res.paths[:, 0], pairs[:, 0])
    np.testing.assert_array_equal(res.paths[:, -1], pairs[:, 1])
    m.domain.check(res.paths.reshape(-1, 2), "searched path points")
    a = m.path_costs(plain).sum(1)
    b = m.path_costs(res.paths).sum(1)
    assert np.all(b <= a * (1 + 1e-12))
    assert np.mean(b) < np.mean(a)  # and it does shorten some
    # success is kept: at a threshold the policy misses on some pairs, every pair it
    # meets is still met
    eps = float(np.quantile(m.path_costs(plain).max(1), 0.5))
    plain_ok = m.path_costs(plain).max(1) <= eps
    tight = matsumoto.search(pairs[:, 0], pairs[:, 1], SearchSpec(equalize=0), eps=eps).paths
    tight_cost = m.path_costs(tight)
    assert 0 < plain_ok.sum() < len(pairs)
    assert np.all(tight_cost.max(1)[plain_ok] <= eps)
    assert np.all(tight_cost.sum(1) <= a * (1 + 1e-12))


def test_search_finds_the_route_the_policy_misses(matsumoto) -> None:
    """A short pair near the rim (tuning pairs, seed 4242, no. 244) where the replaced
    Matsumoto policy (benchmarks/previous_policies) takes a path 37% longer than the exact
    geodesic: the search is within 6% of the exact solver (measured: 2.2%). The path-energy
    policy with the actor relative to each pair's length (issue 25, shipped before the
    model-free one) takes the right route by itself (measured: 2.7% longer); the shipped
    model-free policy does not (13% longer: its ratio tail,
    benchmarks/results/policies/route-search-moved.md)."""
    m = matsumoto.metric
    old = learn.load_policy(ROOT / "benchmarks" / "previous_policies" / "matsumoto")
    pair = np.array([[[-0.2539245465809705, 0.9261021595305758],
                      [-0.01485772429641242, 0.7581015806701776]]])
    exact = solvers.solve_geodesic(m, pair[0, 0], pair[0, 1], 64)
    assert exact.converged
    plain = m.path_costs(old.generate(pair[:, 0], pair[:, 1])).sum()
    searched = m.path_costs(old.search(pair[:, 0], pair[:, 1]).paths).sum()
    assert plain > 1.2 * exact.length  # the policy alone takes the wrong route
    assert searched < 1.06 * exact.length
    energy = learn.load_policy(ROOT / "benchmarks" / "previous_policies"
                               / "matsumoto-path-energy")
    assert m.path_costs(energy.generate(pair[:, 0], pair[:, 1])).sum() < 1.05 * exact.length


def test_search_counts_every_evaluation_of_c(matsumoto, monkeypatch) -> None:
    m = matsumoto.metric
    pairs = finsler.sample_pairs(m, 5, 7)
    counted = []
    original = type(m).path_costs

    def spy(self, points, check=None):
        arr = np.asarray(points)
        counted.append(arr.shape[0] * (arr.shape[1] - 1))
        return original(self, points, check=check)

    monkeypatch.setattr(type(m), "path_costs", spy)
    spec = SearchSpec(levels=2, directions=4, radii=(0.5,), polish=1, windows=1, equalize=2)
    res = matsumoto.search(pairs[:, 0], pairs[:, 1], spec)
    assert res.evaluations == sum(counted)
    # by hand: 2 levels x 10 candidates x 64 segments, + 1 sweep x 4 costs x 63 points,
    # + the path's 64 segment costs (kept up to date from then on), + windows of w = 32..2
    # segments (64/w at offset 0, 64/w - 1 at w/2; the new trees' costs only), + 64 per
    # equalizing round
    assert spec.candidates == 10
    windows = sum(w * (2 * (64 // w) - 1) for w in (32, 16, 8, 4, 2))
    assert res.evaluations_per_path == 2 * 10 * 64 + 4 * 63 + 64 + windows + 2 * 64


def test_search_without_levels_or_polish_is_the_policy(matsumoto) -> None:
    pairs = finsler.sample_pairs(matsumoto.metric, 10, 3)
    spec = SearchSpec(levels=0, polish=0, windows=0, equalize=0)
    res = matsumoto.search(pairs[:, 0], pairs[:, 1], spec)
    np.testing.assert_array_equal(res.paths, matsumoto.generate(pairs[:, 0], pairs[:, 1]))
    assert res.evaluations == 0


def test_search_in_seven_dimensions() -> None:
    pol = learn.load_policy("panda-pole")
    m = pol.metric
    pairs = finsler.default_pairs(m)[:4]
    spec = SearchSpec(levels=1, radii=(0.25, 0.5), windows=1, equalize=0)
    res = pol.search(pairs[:, 0], pairs[:, 1], spec)
    assert res.paths.shape == (4, 2**pol.depth + 1, 7)
    m.domain.check(res.paths.reshape(-1, 7), "searched path points")
    plain = pol.generate(pairs[:, 0], pairs[:, 1])
    assert np.all(m.path_costs(res.paths).sum(1) <= m.path_costs(plain).sum(1) * (1 + 1e-12))
    again = pol.search(pairs[:, 0], pairs[:, 1], spec)
    np.testing.assert_array_equal(again.paths, res.paths)  # same seed, same result


def test_actor_in_pieces_predicts_what_one_call_does(matsumoto) -> None:
    """The search and generation call the actor in pieces of PREDICT_ROWS rows on a CPU
    (for speed); the midpoints, and so the searched paths, are those of one call."""
    m = matsumoto.metric
    pairs = torch.as_tensor(finsler.sample_pairs(m, 50, 8))
    one = predictor(matsumoto.actor, m, rows=None)
    with torch.no_grad():
        ref = one(pairs[:, 0], pairs[:, 1])
        for rows in (1, 7, 49, 50, 4096):
            got = predictor(matsumoto.actor, m, rows=rows)(pairs[:, 0], pairs[:, 1])
            assert got.dtype == torch.float64 and got.shape == (50, 2)
            np.testing.assert_allclose(got.numpy(), ref.numpy(), rtol=0, atol=1e-6)
        m.domain.check(ref.numpy(), "predicted midpoints")  # projected into the domain
    spec = SearchSpec(levels=1, directions=4, radii=(0.5,), windows=1)
    a = search_paths(m, one, pairs[:6, 0], pairs[:6, 1], 4, matsumoto.eps, spec)
    b = search_paths(m, predictor(matsumoto.actor, m, rows=5), pairs[:6, 0], pairs[:6, 1],
                     4, matsumoto.eps, spec)
    np.testing.assert_allclose(b.paths, a.paths, rtol=0, atol=1e-6)
    assert a.evaluations == b.evaluations > 0


@pytest.mark.parametrize("rows", [0, -3, 2.5, True, "64"])
def test_predictor_rejects_bad_rows(matsumoto, rows) -> None:
    with pytest.raises(InputError, match="rows"):
        predictor(matsumoto.actor, matsumoto.metric, rows=rows)


@pytest.mark.parametrize("bad", [
    dict(levels=-1), dict(directions=1), dict(polish=1.5), dict(radii=(0.0,)),
    dict(radii=("a",)), dict(radii=(float("nan"),)), dict(levels=True), dict(seed=-2),
    dict(equalize=-1), dict(equalize=0.5), dict(windows=-1), dict(windows="2"),
])
def test_search_spec_rejects_impossible_settings(bad) -> None:
    with pytest.raises(InputError, match="SearchSpec"):
        SearchSpec(**bad)


def test_windows_straighten_a_zigzag_euclidean_path() -> None:
    """With the exact Euclidean midpoint as the 'actor', re-generating windows turns a path
    that zigzags at its odd points into the evenly spaced straight path (closed form): the
    two half-path windows are replaced (shorter), the middle one is not (no shorter)."""
    import torch

    m = finsler.get_metric("euclidean")
    s, g = np.array([-0.6, -0.3]), np.array([0.5, 0.4])
    t = np.arange(65) / 64
    straight = s + t[:, None] * (g - s)
    normal = np.array([-(g - s)[1], (g - s)[0]]) / np.linalg.norm(g - s)
    zig = straight + 0.01 * (np.arange(65) % 2)[:, None] * normal
    paths = torch.as_tensor(np.stack([zig, straight]))

    def exact_midpoint(a, b):
        return 0.5 * (a + b)

    costs = torch.tensor(m.path_costs(paths.numpy()))
    out, out_costs, evals = _regenerate_windows(m, exact_midpoint, paths, costs, 5, eps=1.0)
    np.testing.assert_allclose(out.numpy(), np.stack([straight, straight]), atol=1e-15)
    # the costs it carries are the new path's
    np.testing.assert_allclose(out_costs.numpy(), m.path_costs(out.numpy()), rtol=1e-12)
    assert evals == 2 * (2 * 32 + 1 * 32)  # the new trees' segments only


def test_equalize_gives_equal_segments_on_a_straight_euclidean_path() -> None:
    """Euclidean C is additive along straight pieces: one round puts the points of an
    unevenly spaced straight path exactly at i/n of the way (closed form)."""
    m = finsler.get_metric("euclidean")
    rng = np.random.default_rng(5)
    s, g = np.array([-0.7, 0.2]), np.array([0.6, -0.4])
    t = np.sort(np.concatenate([[0.0, 1.0], rng.uniform(0, 1, 15)]))
    path = (s + t[:, None] * (g - s))[None]
    out, evals = equalize_paths(m, path, rounds=1)
    want = s + (np.arange(17) / 16)[:, None] * (g - s)
    np.testing.assert_allclose(out[0], want, atol=1e-14)
    assert evals == 2 * 16
    c = m.path_costs(out)[0]
    np.testing.assert_allclose(c, np.linalg.norm(g - s) / 16, rtol=1e-12)


def test_equalize_never_raises_the_largest_segment_or_the_energy() -> None:
    """Panda (7-D, curved): the first Panda policy's paths (eq. (6), kept in
    benchmarks/previous_policies; today's policy splits more evenly, 1.15 on these pairs)
    split unevenly; equalizing keeps the ends, stays in the domain, never raises a path's
    largest segment cost or its energy, keeps the length within sqrt(n sum C**2), and
    evens the split out."""
    pol = learn.load_policy(ROOT / "benchmarks" / "previous_policies" / "panda-pole")
    m = pol.metric
    pairs = finsler.sample_pairs(m, 24, 99)
    plain = pol.generate(pairs[:, 0], pairs[:, 1])
    out, evals = equalize_paths(m, plain, rounds=3)
    assert evals == 24 * 32 * 4
    np.testing.assert_array_equal(out[:, [0, -1]], plain[:, [0, -1]])
    m.domain.check(out.reshape(-1, 7), "equalized path points")
    c0, c1 = m.path_costs(plain), m.path_costs(out)
    n = c0.shape[1]
    assert np.all(c1.max(1) <= c0.max(1))
    assert np.all((c1**2).sum(1) <= (c0**2).sum(1))
    assert np.all(c1.sum(1) <= np.sqrt(n * (c0**2).sum(1)) * (1 + 1e-12))
    spread0 = c0.max(1) / c0.mean(1)
    spread1 = c1.max(1) / c1.mean(1)
    assert spread0.mean() > 1.2 and spread1.mean() < 1.1
    # the search applies it by default: its paths are the equalized ones
    res = pol.search(pairs[:, 0], pairs[:, 1], SearchSpec(levels=0, polish=0, windows=0))
    np.testing.assert_array_equal(res.paths, out)


@pytest.mark.parametrize("bad, match", [
    (np.zeros((2, 5, 3)), "shape"), (np.full((1, 5, 2), np.nan), "NaN"),
])
def test_equalize_rejects_bad_paths(bad, match) -> None:
    with pytest.raises(InputError, match=match):
        equalize_paths(finsler.get_metric("euclidean"), bad)
    with pytest.raises(InputError, match="rounds"):
        equalize_paths(finsler.get_metric("euclidean"), np.zeros((1, 3, 2)), rounds=-1)


def test_evaluate_cli_search(matsumoto, tmp_path) -> None:
    pairs = finsler.sample_pairs(matsumoto.metric, 6, 11)
    np.save(tmp_path / "p.npy", pairs)
    runner = CliRunner()
    plain = runner.invoke(app, ["evaluate", "--env", "matsumoto", "--pairs",
                                str(tmp_path / "p.npy"), "--json"])
    searched = runner.invoke(app, ["evaluate", "--env", "matsumoto", "--pairs",
                                   str(tmp_path / "p.npy"), "--json", "--search"])
    assert plain.exit_code == 0 and searched.exit_code == 0, searched.output
    a, b = json.loads(plain.output), json.loads(searched.output)
    assert "search" not in a and b["search"]["evaluations_of_C_per_path"] > 0
    want = matsumoto.metric.path_costs(matsumoto.search(pairs[:, 0], pairs[:, 1]).paths)
    for row, old, c in zip(b["per_pair"], a["per_pair"], want):
        assert row["length"] == pytest.approx(c.sum(), rel=1e-12)
        assert row["max_segment_cost"] == pytest.approx(c.max(), rel=1e-12)
        # the search never loses success: its largest segment is never above the policy's
        # (its length may be, slightly: equalizing trades length for even segments; the
        # never-longer property without equalizing is tested above)
        assert row["max_segment_cost"] <= old["max_segment_cost"] * (1 + 1e-12)
        assert row["length"] <= old["length"] * 1.034


@settings(max_examples=30, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(["matsumoto", "carlike", "randers", "poincare", "sphere"]),
       seed=st.integers(0, 2**31 - 1), n=st.sampled_from([2, 3, 8, 17]),
       rounds=st.integers(1, 4))
def test_equalize_invariants_on_random_paths(name, seed, n, rounds) -> None:
    """Any metric, any path through the domain (random points, uneven steps): equalizing
    keeps the ends, stays in the domain, never raises a path's largest segment cost or its
    energy, and counts its evaluations of C exactly."""
    m = finsler.get_metric(name)
    rng = np.random.default_rng(seed)
    paths = m.domain.sample(4 * (n + 1), rng).reshape(4, n + 1, m.dim)
    out, evals = equalize_paths(m, paths, rounds)
    np.testing.assert_array_equal(out[:, [0, -1]], paths[:, [0, -1]])
    assert np.all(m.domain.contains(out.reshape(-1, m.dim)))
    c0, c1 = m.path_costs(paths), m.path_costs(out)
    assert np.all(c1.max(1) <= c0.max(1))
    assert np.all((c1**2).sum(1) <= (c0**2).sum(1))
    assert evals == (0 if n < 2 else 4 * n * (rounds + 1))
