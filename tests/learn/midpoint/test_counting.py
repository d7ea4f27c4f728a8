"""The evaluation counting of the midpoint learner (issue 22, mutation testing):
``Trainer.collect`` and ``Trainer.update`` called directly on a tiny Euclidean trainer,
their counters against hand counts, their targets against the closed-form costs and their
losses against a replay of the same minibatches. Fast: no training runs."""

from __future__ import annotations

import copy
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import finsler
import learn
from learn import Trainer, build_tree
from learn.midpoint.losses import PathEnergy, RouteSearch
from learn.midpoint.term import ActorTerm, TermOutput

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


def _trainer(tmp_path: Path, **over: Any) -> Trainer:
    base = dict(timesteps=10_000, collection_size=40, minibatch_size=16, epochs=1,
                eval_every=1, depth=2, hidden=(8, 8), eval_pairs=4,
                depth_schedule="full", path_energy_weight=0.0)
    base.update(over)
    cfg = learn.default_config("euclidean", **base)
    return Trainer(cfg, tmp_path / "run", progress=False)


class _FixedDomain:
    def __init__(self, points: Any) -> None:
        self.points = points

    def sample(self, n: int, rng: Any) -> np.ndarray:
        return next(self.points)


class _FixedSamples:
    """A metric whose domain hands out given points (the route search's draws)."""

    def __init__(self, metric: finsler.Metric, points: Any) -> None:
        self._metric = metric
        self.domain = _FixedDomain(points)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._metric, name)


def _norm(s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    return torch.linalg.norm(g - s, dim=-1)


# ---- collect -----------------------------------------------------------------------------
@pytest.mark.parametrize("zero_pairs", [True, False])
def test_collect_counts_trees_pairs_and_leaf_evaluations(tmp_path: Path,
                                                         zero_pairs: bool) -> None:
    """Depth 2: a tree has 1 + 2 + 4 = 7 pairs, plus 2**2 + 1 = 5 zero pairs when asked:
    ceil(40 / 12) = 4 trees (ceil(40 / 7) = 6 without), 4 leaves each evaluated."""
    tr = _trainer(tmp_path, zero_pairs=zero_pairs)
    rng = copy.deepcopy(tr.np_rng)
    s, g, c, ts = tr.collect()
    per_tree = 12 if zero_pairs else 7
    n_trees = math.ceil(40 / per_tree)
    assert ts == n_trees * 4 and tr.trees == n_trees
    n_pairs = n_trees * per_tree
    assert s.shape == g.shape == (n_pairs, 2) and c.shape == (n_pairs,)
    assert s.dtype == g.dtype == c.dtype == torch.float64
    # levels in order: n_trees roots, 2 n_trees, 4 n_trees leaves (each tree's in order)
    a, b = n_trees, 3 * n_trees
    leaves = slice(b, b + 4 * n_trees)
    assert torch.allclose(c[leaves], _norm(s[leaves], g[leaves]), rtol=1e-12, atol=0)
    # a tree's leaves are a chain from its root's start to its goal; the Monte-Carlo
    # target of every pair is the sum of the leaf costs below it
    ls, lg, lc = (t[leaves].reshape(n_trees, 4, *t.shape[1:]) for t in (s, g, c))
    assert torch.equal(ls[:, 1:], lg[:, :-1])
    assert torch.equal(ls[:, 0], s[:a]) and torch.equal(lg[:, -1], g[:a])
    # the roots are the uniformly sampled pairs (the run's generator, in order)
    ends = tr.metric.domain.sample(2 * n_trees, rng).reshape(n_trees, 2, 2)
    assert np.array_equal(s[:a].numpy(), ends[:, 0]) and np.array_equal(g[:a].numpy(),
                                                                         ends[:, 1])
    assert torch.allclose(c[:a], lc.sum(1), rtol=1e-12, atol=0)
    mid = c[a:b].reshape(n_trees, 2)
    assert torch.allclose(mid, lc.reshape(n_trees, 2, 2).sum(-1), rtol=1e-12, atol=0)
    assert torch.all(c[:a] >= _norm(s[:a], g[:a]) * (1 - 1e-12))
    if zero_pairs:
        z = slice(b + 4 * n_trees, None)
        assert torch.equal(s[z], g[z]) and torch.all(c[z] == 0)
        assert s[z].shape[0] == 5 * n_trees
    # the next collection draws new trees and counts them too
    s2, _, _, ts2 = tr.collect()
    assert ts2 == ts and tr.trees == 2 * n_trees and not torch.equal(s2[:a], s[:a])


@pytest.mark.parametrize(("size", "trees"), [(48, 2), (49, 3), (72, 3)])
def test_collect_sizes_the_batch_by_whole_trees_with_their_zero_pairs(tmp_path: Path,
                                                                     size: int,
                                                                     trees: int) -> None:
    """Depth 3: a tree gives 1 + 2 + 4 + 8 = 15 pairs and 2**3 + 1 = 9 zero pairs."""
    tr = _trainer(tmp_path, depth=3, collection_size=size, zero_pairs=True)
    s, _, _, ts = tr.collect()
    assert tr.trees == trees == math.ceil(size / 24)
    assert ts == 8 * trees and s.shape[0] == 24 * trees


def test_collect_follows_the_paper_depth_schedule(tmp_path: Path) -> None:
    """Paper schedule, D = 2, T = 14: c_d = floor(14 / 7) + 1 = 3 trees per depth; with
    one tree per collection (collection_size 1) the depths are 0, 0, 0, 1, 1, 1, 2, 2."""
    tr = _trainer(tmp_path, depth_schedule="paper", timesteps=14, collection_size=1,
                  zero_pairs=False)
    got = []
    for _ in range(8):
        s, _, _, ts = tr.collect()
        depth = round(math.log2(ts))
        assert ts == 2**depth and s.shape[0] == 2 ** (depth + 1) - 1
        got.append(depth)
    assert got == [0, 0, 0, 1, 1, 1, 2, 2] and tr.trees == 8


def test_collect_td_targets_at_depth_one(tmp_path: Path) -> None:
    """Depth 1, lambda 0: the root's target is the critic's values of its two halves."""
    tr = _trainer(tmp_path, depth=1, targets="td", td_lambda=0.0, zero_pairs=False)
    s, g, c, _ = tr.collect()
    n = s.shape[0] // 3
    with torch.no_grad():
        v = tr.critic(s[n:].float(), g[n:].float()).double().reshape(n, 2)
    assert torch.allclose(c[:n], v.sum(1), rtol=1e-6)
    assert not torch.allclose(c[:n], c[n:].reshape(n, 2).sum(1), rtol=1e-3)


def test_collect_td_targets_with_lambda_one_are_the_monte_carlo_ones(tmp_path: Path) -> None:
    mc = _trainer(tmp_path / "a", targets="mc", zero_pairs=False)
    td = _trainer(tmp_path / "b", targets="td", td_lambda=1.0, zero_pairs=False)
    out_mc, out_td = mc.collect(), td.collect()
    for x, y in zip(out_mc, out_td, strict=True):
        if isinstance(x, torch.Tensor):
            assert torch.allclose(x, y, rtol=1e-12, atol=1e-15)
        else:
            assert x == y
    # lambda 0: the targets of the upper levels are the critic's values of the children
    t0 = _trainer(tmp_path / "c", targets="td", td_lambda=0.0, zero_pairs=False)
    s, g, c, _ = t0.collect()
    n = s.shape[0] // 7
    leaves = slice(3 * n, 7 * n)
    assert torch.allclose(c[leaves], _norm(s[leaves], g[leaves]), rtol=1e-12)
    with torch.no_grad():
        v = t0.critic(s[n:3 * n].float(), g[n:3 * n].float()).double().reshape(n, 2)
    assert torch.allclose(c[:n], v.sum(1), rtol=1e-6)
    assert not torch.allclose(c[:n], out_mc[2][:n], rtol=1e-3)


# ---- update ------------------------------------------------------------------------------
class _Counted(ActorTerm):
    """A term with known counts: ``prepare`` 7 evaluations, every step 3 (2 of them
    differentiated), and 5 critic pairs of its own."""

    name = "counted-test"

    def __init__(self, loss: float | None = None) -> None:
        self.steps = 0
        self.loss = loss

    def prepare(self, trainer: Any) -> int:
        assert isinstance(trainer, Trainer)
        return 7

    def critic_data(self, trainer: Any) -> tuple[torch.Tensor, ...]:
        assert isinstance(trainer, Trainer)
        s = torch.zeros(5, 2, dtype=torch.float64)
        s[:, 0] = torch.linspace(-0.5, 0.5, 5)
        return s, s + 0.5, torch.full((5,), 0.5 * math.sqrt(2), dtype=torch.float64)

    def step(self, trainer: Any) -> TermOutput:
        assert isinstance(trainer, Trainer)
        self.steps += 1
        loss = None if self.loss is None else torch.tensor(self.loss)
        return TermOutput(loss, evaluations=3, derivative=2)


@pytest.mark.parametrize(("epochs", "n"), [(1, 16), (3, 35), (2, 11)])
def test_update_counts_every_step_of_every_epoch(tmp_path: Path, epochs: int,
                                                  n: int) -> None:
    tr = _trainer(tmp_path, epochs=epochs)
    term = _Counted()
    tr.terms = [term]
    s, g, c, _ = tr.collect()
    s, g, c = s[:n], g[:n], c[:n]
    before = (tr.timesteps, tr.timesteps_derivative, tr.updates)
    lc, la = tr.update(s, g, c)
    steps = epochs * math.ceil((n + 5) / 16)  # the term's 5 critic pairs join the batch
    assert term.steps == steps and tr.updates == before[2] + steps
    assert tr.timesteps == before[0] + 7 + 3 * steps
    assert tr.timesteps_derivative == before[1] + 2 * steps
    assert math.isfinite(lc) and math.isfinite(la) and lc >= 0
    tr.update(s, g, c)
    assert tr.updates == before[2] + 2 * steps and tr.timesteps == before[0] + 2 * (7 + 3 * steps)


@pytest.mark.parametrize(("epochs", "n", "steps"), [(2, 35, 6), (1, 8, 1)])
def test_update_losses_are_the_means_over_its_minibatches(tmp_path: Path, epochs: int,
                                                          n: int, steps: int) -> None:
    """With the optimiser steps switched off the networks stay fixed, so the returned
    losses are the means over the minibatches (replayed with the same random stream) of
    the critic's squared error (eq. 5) on the collection plus the term's critic data, and
    the actor's loss (eq. 6) plus the term's loss (here a constant 2)."""
    tr = _trainer(tmp_path, epochs=epochs, minibatch_size=16)
    tr.terms = [_Counted(loss=2.0)]
    tr._step_if_finite = lambda *a: None  # type: ignore[method-assign]
    s, g, c, _ = tr.collect()
    extra = tr.terms[0].critic_data(tr)
    s, g, c = s[:n], g[:n], c[:n]
    m_all = n + 5
    replay = torch.Generator().manual_seed(0)
    replay.set_state(tr.gen.get_state())
    s32 = torch.cat([s, extra[0]]).float()
    g32 = torch.cat([g, extra[1]]).float()
    target = tr.critic.to_raw(torch.cat([c, extra[2]]), torch.cat([s, extra[0]]),
                              torch.cat([g, extra[1]])).float()
    lcs, las = [], []
    with torch.no_grad():
        for _ in range(epochs):
            perm = torch.randperm(m_all, generator=replay)
            for k in range(0, m_all, 16):
                idx = perm[k:k + 16]
                bs, bg = s32[idx], g32[idx]
                lcs.append(float(((tr.critic.raw(bs, bg) - target[idx]) ** 2).mean()))
                m = tr.actor(bs, bg, generator=replay)
                mp = m.double().numpy()
                v1 = tr.critic(bs, m)
                v2 = tr.critic(m, bg)
                las.append(float((v1**2 + v2**2).mean()) + 2.0)  # eq. (6) + the term
                assert np.all(np.isfinite(mp))
    assert len(lcs) == steps
    lc, la = tr.update(s, g, c)
    assert lc == pytest.approx(np.mean(lcs), rel=1e-6)
    assert la == pytest.approx(np.mean(las), rel=1e-6)
    assert tr.updates == steps and tr.skipped_steps == 0


def test_update_skips_and_names_non_finite_gradients(tmp_path: Path, caplog) -> None:
    """A NaN in the critic: its gradient and then the actor's are NaN; both steps are
    skipped, counted and logged with the network's name."""
    tr = _trainer(tmp_path, epochs=1)
    tr.terms = []
    s, g, c, _ = tr.collect()
    with torch.no_grad():
        next(tr.critic.parameters()).fill_(float("nan"))
    with caplog.at_level(logging.WARNING, logger="learn.midpoint.trainer"):
        tr.update(s[:10], g[:10], c[:10])
    assert tr.skipped_steps == 2
    text = caplog.text
    assert "non-finite critic gradient" in text and "non-finite actor gradient" in text


@pytest.mark.parametrize(("depth", "scale", "total", "derivative"),
                         [(2, "none", 176, 128), (3, "none", 352, 256),
                          (3, "straight", 608, 256)])
def test_update_with_the_real_terms_counts_what_they_evaluate(tmp_path: Path, monkeypatch,
                                                               depth: int, scale: str,
                                                               total: int,
                                                               derivative: int) -> None:
    """Path energy (8 pairs, depth D: 8 * 2**D differentiated evaluations per actor step,
    twice as many with the straight-path scale, whose extra half is values only) and
    route search (4 pairs, 2 candidates: 4 * 2**D * 3 per collection), 2 epochs of
    ceil(24 / 16) = 2 steps. Depth 2: 48 + 4 * 32 = 176 evaluations, 128 differentiated;
    depth 3: 96 + 4 * 64 = 352 (straight: 96 + 4 * 128 = 608), 256. A spy on the torch
    costs sees exactly as many."""
    seen = [0]
    real = finsler.Metric.path_costs

    def spy(self: finsler.Metric, points: Any, check: Any = None) -> Any:
        if isinstance(points, torch.Tensor):
            seen[0] += points.shape[0] * (points.shape[1] - 1)
        return real(self, points, check=check)

    tr = _trainer(tmp_path, epochs=2, path_energy_weight=1.0, path_energy_pairs=8,
                  route_candidates=2, route_pairs=4, depth=depth, path_energy_scale=scale)
    s, g, c, _ = tr.collect()
    monkeypatch.setattr(finsler.Metric, "path_costs", spy)
    tr.update(s[:24], g[:24], c[:24])
    assert tr.timesteps == total and seen[0] == total
    assert tr.timesteps_derivative == derivative and tr.updates == 4


def test_route_search_targets_the_pairs_a_stitched_path_shortens(tmp_path: Path) -> None:
    """Against a direct computation: the searched pairs are the next draws of the run's
    generator; a pair is kept iff its cheapest stitched path ``s -> m -> g`` (actor's
    depth-(D-1) paths) costs below 0.99 of the actor's own depth-D path, and its target is
    that cheapest candidate."""
    tr = _trainer(tmp_path, depth=2)
    term = RouteSearch(weight=1.0, candidates=6, pairs=24)
    rng = copy.deepcopy(tr.np_rng)
    assert term.prepare(tr) == 24 * 4 * 7
    dom = tr.metric.domain
    e = torch.as_tensor(dom.sample(48, rng).reshape(24, 2, 2), dtype=torch.float32)
    m = torch.as_tensor(dom.sample(24 * 6, rng), dtype=torch.float32).reshape(24, 6, 2)

    def mean(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return tr.actor(a, b, deterministic=True)

    def length(pts: torch.Tensor) -> np.ndarray:
        p = pts.double().numpy()
        return np.linalg.norm(np.diff(p, axis=1), axis=2).sum(1)  # Euclidean C

    with torch.no_grad():
        own = length(build_tree(e[:, 0], e[:, 1], 2, mean))
        s_rep = e[:, 0, None].expand(24, 6, 2).reshape(-1, 2)
        g_rep = e[:, 1, None].expand(24, 6, 2).reshape(-1, 2)
        alt = (length(build_tree(s_rep, m.reshape(-1, 2), 1, mean))
               + length(build_tree(m.reshape(-1, 2), g_rep, 1, mean))).reshape(24, 6)
    keep = alt.min(1) < 0.99 * own
    assert 0 < keep.sum() < 24  # both cases present
    assert term.target is not None
    ts, tg, tm = term.target
    assert torch.equal(ts, e[keep, 0]) and torch.equal(tg, e[keep, 1])
    assert torch.equal(tm, m[np.flatnonzero(keep), alt.argmin(1)[keep]])
    # a pair where no candidate helps: no target at all
    far = RouteSearch(weight=1.0, candidates=1, pairs=1)
    tr.np_rng = np.random.default_rng(0)
    dom_pts = iter([np.array([[0.0, 0.0], [0.1, 0.0]]), np.array([[0.9, 0.9]])])
    tr.metric = _FixedSamples(tr.metric, dom_pts)
    far.prepare(tr)
    assert far.target is None


def _actor_path_segments(tr: Trainer, rng: Any) -> np.ndarray:
    """Segment lengths ``(5, 4)`` of the actor's depth-2 paths between the 5 pairs the
    path-energy term draws from ``rng`` (a copy of the trainer's generator)."""
    ends = tr.metric.domain.sample(10, rng).reshape(5, 2, 2)
    e = torch.as_tensor(ends, dtype=torch.float32)
    with torch.no_grad():
        pts = build_tree(e[:, 0], e[:, 1], 2,
                         lambda a, b: tr.actor(a, b, deterministic=True)).double().numpy()
    return np.linalg.norm(np.diff(pts, axis=1), axis=2)


def test_path_energy_step_is_the_weighted_mean_energy(tmp_path: Path) -> None:
    """Euclidean, depth 2: the energy of a path of 4 segments is 4 * sum of the squared
    segment lengths; the step's loss is the weight times its mean over the pairs."""
    tr = _trainer(tmp_path, depth=2)
    term = PathEnergy(weight=3.0, pairs=5)
    rng = copy.deepcopy(tr.np_rng)
    out = term.step(tr)
    seg = _actor_path_segments(tr, rng)
    energy = 4 * (seg**2).sum(1)
    assert float(out.loss.detach()) == pytest.approx(3.0 * energy.mean(), rel=1e-5)
    assert out.evaluations == out.derivative == 5 * 4


@pytest.mark.parametrize("power", [3.0, 4.0, 8.0])
def test_path_energy_power_is_the_power_mean_of_the_segments(tmp_path: Path,
                                                             power: float) -> None:
    """``path_energy_power = p``: each pair's term is ``n**2 M_p(C)**2`` with ``M_p`` the
    power mean of its segment lengths (computed here in numpy from the same path); at
    least the plain energy ``n sum C**2`` (power means grow with p), with the schedule
    ``lr`` scaled by the learning-rate factor, and the same count of evaluations."""
    tr = _trainer(tmp_path, depth=2)
    tr.lr = tr.cfg.lr * 0.25
    term = PathEnergy(weight=3.0, pairs=5, power=power, schedule="lr")
    rng = copy.deepcopy(tr.np_rng)
    out = term.step(tr)
    seg = _actor_path_segments(tr, rng)
    mean_p = np.mean(seg**power, axis=1) ** (1 / power)
    energy = 16 * mean_p**2
    assert np.all(energy >= 4 * (seg**2).sum(1) * (1 - 1e-12))
    assert float(out.loss.detach()) == pytest.approx(0.25 * 3.0 * energy.mean(), rel=1e-5)
    assert out.evaluations == out.derivative == 5 * 4


def test_path_energy_power_equal_segments_give_the_squared_length() -> None:
    """Whatever p, a path of equal segment costs L/n has energy L**2 (same minimisers as
    the plain energy); p = 2 is ``n sum C**2`` bit for bit; a zero path has a finite
    gradient."""
    from learn.midpoint.losses import _p_energy
    c = torch.full((3, 64), 0.05, dtype=torch.float64)
    for p in (1.5, 2.0, 4.0, 16.0, 64.0):
        assert torch.allclose(_p_energy(c, p), torch.full((3,), 3.2**2, dtype=torch.float64))
    r = torch.rand(4, 32, dtype=torch.float64)
    assert torch.equal(_p_energy(r, 2.0), 32 * (r**2).sum(1))
    z = torch.zeros(2, 8, dtype=torch.float64, requires_grad=True)
    _p_energy(z, 4.0).sum().backward()
    assert torch.isfinite(z.grad).all()


@pytest.mark.parametrize("bad", [{"path_energy_power": 1.0}, {"path_energy_power": True},
                                 {"path_energy_power": float("nan")},
                                 {"path_energy_power": 100.0},
                                 {"path_energy_schedule": "cosine"}])
def test_path_energy_options_are_checked(bad: dict) -> None:
    name = next(iter(bad))
    with pytest.raises(finsler.InputError, match=name):
        learn.default_config("euclidean", **bad)
