"""Tests of the midpoint actor-critic: targets by hand, determinism, learning on the
Euclidean plane against true midpoints, exact resume, run-directory errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

import finsler
import learn
from learn import Trainer
from learn.midpoint.losses import PathEnergy, RouteSearch
from learn.midpoint.policy import build_actor, generate_paths
from learn.midpoint.trainer import actor_loss, paper_depth


# ----------------------------------------------------------------------------------------
# trees and targets, by hand
# ----------------------------------------------------------------------------------------
def _hand_tree() -> torch.Tensor:
    """One depth-2 tree on a horizontal line of the Euclidean plane:
    p_{2,*} = 0, 0.1, 0.3, 0.6, 1.0 (leaf costs 0.1, 0.2, 0.3, 0.4)."""
    x = torch.tensor([0.0, 0.1, 0.3, 0.6, 1.0], dtype=torch.float64) - 0.5
    return torch.stack([x, torch.full_like(x, 0.25)], -1)[None]


def test_build_tree_inserts_midpoints_level_by_level() -> None:
    calls = []

    def mean(s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        calls.append(s.shape[0])
        return 0.5 * (s + g)

    s = torch.tensor([[0.0], [10.0]], dtype=torch.float64)
    g = torch.tensor([[4.0], [2.0]], dtype=torch.float64)
    pts = learn.build_tree(s, g, 2, mean)
    assert pts.shape == (2, 5, 1)
    assert pts[0, :, 0].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert pts[1, :, 0].tolist() == [10.0, 8.0, 6.0, 4.0, 2.0]
    assert calls == [2, 4]  # one batched call per level
    s1, g1 = learn.level_pairs(pts, 1)
    assert s1[0, :, 0].tolist() == [0.0, 2.0] and g1[0, :, 0].tolist() == [2.0, 4.0]


def test_monte_carlo_targets_of_a_hand_built_depth2_tree() -> None:
    m = finsler.get_metric("euclidean")
    pts = _hand_tree()
    leaf = m.cost(pts[0, :-1], pts[0, 1:])[None]
    targets = learn.mc_targets(leaf)
    # by hand: level 2 = leaf costs, level 1 = 0.1 + 0.2, 0.3 + 0.4, level 0 = 1.0
    np.testing.assert_allclose(targets[2].numpy(), [[0.1, 0.2, 0.3, 0.4]], atol=1e-15)
    np.testing.assert_allclose(targets[1].numpy(), [[0.3, 0.7]], atol=1e-15)
    np.testing.assert_allclose(targets[0].numpy(), [[1.0]], atol=1e-15)


def test_td_lambda_targets_of_a_hand_built_depth2_tree() -> None:
    leaf = torch.tensor([[1.0, 2.0, 3.0, 4.0]], dtype=torch.float64)
    values = [
        torch.tensor([[100.0]], dtype=torch.float64),  # unused (root has no parent)
        torch.tensor([[2.5, 8.0]], dtype=torch.float64),
        torch.tensor([[0.5, 1.5, 2.5, 3.5]], dtype=torch.float64),
    ]
    t = learn.td_lambda_targets(leaf, values, 0.5)
    # eq. (8) by hand with lambda = 1/2:
    # c_{1,0} = .5 (0.5 + 1.5) + .5 (1 + 2) = 2.5 ; c_{1,1} = .5 (2.5 + 3.5) + .5 (3 + 4) = 6.5
    # c_{0,0} = .5 (2.5 + 8.0) + .5 (2.5 + 6.5) = 9.75
    assert t[2].tolist() == [[1.0, 2.0, 3.0, 4.0]]
    assert t[1].tolist() == [[2.5, 6.5]]
    assert t[0].tolist() == [[9.75]]
    # lambda = 0: pure bootstrap from the children's values; lambda = 1: Monte Carlo
    t0 = learn.td_lambda_targets(leaf, values, 0.0)
    assert t0[1].tolist() == [[2.0, 6.0]] and t0[0].tolist() == [[10.5]]
    t1 = learn.td_lambda_targets(leaf, values, 1.0)
    for a, b in zip(t1, learn.mc_targets(leaf)):
        assert torch.equal(a, b)


def test_trainer_collect_uses_td_targets_of_its_own_critic(run_dirs) -> None:
    cfg = learn.default_config("euclidean", depth=2, targets="td", td_lambda=0.3,
                               collection_size=7, zero_pairs=False)
    tr = Trainer(cfg, run_dirs(), progress=False)
    s, g, c, ts = tr.collect()
    assert ts == 4 and s.shape == (7, 2)  # one tree: 1 + 2 + 4 pairs, 4 evaluations of C
    # the collected pairs are ordered level 0, level 1, level 2
    v = tr.critic(s.float(), g.float()).double()
    leaf = (g[3:] - s[3:]).norm(dim=1)
    c1 = 0.7 * torch.stack([v[3] + v[4], v[5] + v[6]]) + 0.3 * torch.stack(
        [leaf[0] + leaf[1], leaf[2] + leaf[3]])
    c0 = 0.7 * (v[1] + v[2]) + 0.3 * (c1[0] + c1[1])
    torch.testing.assert_close(c, torch.cat([c0[None], c1, leaf]), rtol=1e-6, atol=1e-6)
    assert torch.equal(s[1], s[0]) and torch.equal(g[2], g[0]) and torch.equal(g[1], s[2])


def _exact_midpoint_actor(tr: Trainer) -> None:
    """Zero the residual actor's output layer: its mean is then exactly (s + g) / 2."""
    with torch.no_grad():
        tr.actor.net[-1].weight.zero_()
        tr.actor.net[-1].bias.zero_()


def test_path_energy_of_exact_midpoints_is_squared_distance(run_dirs) -> None:
    """On the Euclidean plane the recursive exact midpoints give n equal segments of
    length L / n, so n * sum C**2 = L**2; the pairs are fresh draws from the run's RNG."""
    cfg = learn.default_config("euclidean", depth=3, path_energy_weight=1.0,
                               path_energy_pairs=5)
    tr = Trainer(cfg, run_dirs(), progress=False)
    _exact_midpoint_actor(tr)
    term = PathEnergy(weight=1.0, pairs=5)
    state = tr.np_rng.bit_generator.state
    e = term.energy(tr)
    rng = np.random.default_rng()
    rng.bit_generator.state = state
    ends = tr.metric.domain.sample(10, rng).reshape(5, 2, 2)
    want = np.sum((ends[:, 1] - ends[:, 0]) ** 2, axis=1)
    np.testing.assert_allclose(e.detach().numpy(), want, rtol=1e-5)
    # a perturbed actor has a larger energy and a gradient that points back
    with torch.no_grad():
        tr.actor.net[-1].bias[:2] = 0.05
    tr.np_rng.bit_generator.state = state
    e2 = term.energy(tr)
    assert (e2.detach().numpy() > want).all()
    e2.mean().backward()
    assert tr.actor.net[-1].bias.grad[:2].abs().min() > 0


def test_scale_free_path_energy_is_one_for_exact_midpoints(run_dirs) -> None:
    """``path_energy_scale="straight"`` divides by the straight path's energy: on the
    Euclidean plane exact midpoints give exactly 1 per pair whatever the pair's size, a
    perturbed actor more than 1 with a gradient, and a step counts the straight paths'
    evaluations of C (values only) beside the tree's."""
    cfg = learn.default_config("euclidean", depth=3, path_energy_weight=1.0,
                               path_energy_pairs=6, path_energy_scale="straight")
    tr = Trainer(cfg, run_dirs(), progress=False)
    _exact_midpoint_actor(tr)
    term = PathEnergy(weight=1.0, pairs=6, scale="straight")
    np.testing.assert_allclose(term.energy(tr).detach().numpy(), np.ones(6), rtol=1e-5)
    with torch.no_grad():
        tr.actor.net[-1].bias[:2] = 0.05
    e2 = term.energy(tr)
    assert (e2.detach().numpy() > 1.0).all()
    e2.mean().backward()
    assert tr.actor.net[-1].bias.grad[:2].abs().min() > 0
    out = term.step(tr)
    assert out.evaluations == 2 * 6 * 8 and out.derivative == 6 * 8
    with pytest.raises(finsler.InputError, match="path_energy_scale"):
        learn.default_config("euclidean", path_energy_scale="log")


def test_path_energy_term_alone_learns_euclidean_midpoints(tmp_path) -> None:
    """The energy term is a training signal of its own: weighted 10x, it dominates the
    actor's gradient, and a 4e4-timestep run must bring midpoints within 0.02 of
    (s + g) / 2 (the untrained actor is off by ~0.1)."""
    cfg = learn.default_config("euclidean", depth=2, timesteps=40_000, collection_size=1024,
                               minibatch_size=256, epochs=1, eval_every=1000,
                               path_energy_weight=10.0, path_energy_pairs=32)
    pairs = finsler.sample_pairs(finsler.get_metric("euclidean"), 300, seed=5)
    learn.train_run(cfg, tmp_path / "run", progress=False)
    pol = learn.load_policy(tmp_path / "run", checkpoint="latest")
    err = np.linalg.norm(pol.midpoint(pairs[:, 0], pairs[:, 1])
                         - 0.5 * (pairs[:, 0] + pairs[:, 1]), axis=1)
    assert err.mean() < 0.02, err.mean()


def test_exploration_floor_scales_with_the_pair_distance() -> None:
    m = finsler.get_metric("matsumoto")
    cfg = learn.default_config("matsumoto", explore_std=0.1, log_std_min=-10.0,
                               init_log_std=-10.0)
    actor = build_actor(cfg, m)
    s = torch.tensor([[0.0, 0.0], [0.1, 0.1], [-0.5, 0.2]])
    g = torch.tensor([[0.6, 0.8], [0.1, 0.1], [-0.5, 0.25]])
    mean, std = actor.distribution(s, g)
    gap = (g - s).norm(dim=1)
    # the learned std is about exp(-10) = 4.5e-5 (the coincident pair keeps it)
    torch.testing.assert_close(std, (0.1 * gap)[:, None].expand(3, 2), rtol=1e-6, atol=1e-4)
    assert std[0].min() > 0.09 and std[1].max() < 1e-4
    # the mean (evaluation) is the same with and without the floor
    plain = build_actor(cfg.replace(explore_std=0.0), m)
    plain.load_state_dict(actor.state_dict())
    torch.testing.assert_close(plain.distribution(s, g)[0], mean)
    assert plain.distribution(s, g)[1].max() < 1e-4


def test_relative_actor_offset_and_std_are_multiples_of_the_pair_length() -> None:
    """``actor_relative``: with a constant network output (mu, log_std) the mean is
    (s + g) / 2 + span * r * mu and the std span * r * exp(log_std), r the pair's length
    in normalised coordinates (span = the domain's half-widths): closed forms, for pairs
    at every scale; a zero pair keeps mean = s and a ~0 std, with a finite gradient."""
    m = finsler.get_metric("carlike")  # box domain with unequal sides: span is not 1
    cfg = learn.default_config("carlike", actor_relative=True)
    actor = build_actor(cfg, m)
    with torch.no_grad():
        actor.net[-1].weight.zero_()
        actor.net[-1].bias.copy_(torch.tensor([0.1, -0.2, 0.3, -1.0, -2.0, -3.0]))
    span = actor.scaler.span
    s = torch.tensor([[0.1, 0.2, 0.3], [0.1, 0.2, 0.3], [-0.4, 0.5, -0.2], [0.3, 0.3, 0.3]])
    g = torch.tensor([[0.5, -0.1, 0.9], [0.104, 0.197, 0.306], [0.2, 0.5, 0.1],
                      [0.3, 0.3, 0.3]])
    mean, std = actor.distribution(s, g)
    r = ((g - s) / span).norm(dim=1, keepdim=True)
    torch.testing.assert_close(mean, 0.5 * (s + g) + span * r * torch.tensor([0.1, -0.2, 0.3]))
    torch.testing.assert_close(std, span * r * torch.exp(torch.tensor([-1.0, -2.0, -3.0])))
    # a pair 100x shorter (same centre and direction) has a 100x smaller offset
    off = mean - 0.5 * (s + g)
    torch.testing.assert_close(off[1] / off[0], (r[1] / r[0]).expand(3), rtol=1e-4, atol=0)
    assert torch.allclose(mean[3], s[3]) and std[3].max() < 1e-5
    # the network sees centre, direction and length: n_in = 2 dim + 1
    assert actor.net[0].in_features == 7 and build_actor(
        cfg.replace(actor_relative=False), m).net[0].in_features == 6
    # gradients through coincident points (the path-energy term) are finite
    pts = s.clone().requires_grad_(True)
    actor(pts, pts.detach().clone().requires_grad_(True), deterministic=True).sum().backward()
    assert torch.isfinite(pts.grad).all()


def test_relative_actor_policy_saves_and_loads(tmp_path) -> None:
    """A run with ``actor_relative`` trains, and the policy loaded from its directory
    predicts the trainer's own midpoints (the field is in config.json; older runs without
    it load as absolute residual actors)."""
    cfg = learn.default_config("euclidean", depth=2, timesteps=20_000, collection_size=1024,
                               minibatch_size=256, eval_every=1000, actor_relative=True)
    tr = Trainer(cfg, tmp_path / "run", progress=False)
    tr.run()
    pol = learn.load_policy(tmp_path / "run", checkpoint="latest")
    assert pol.actor.relative and pol.config.actor_relative
    pairs = finsler.sample_pairs(tr.metric, 50, seed=3)
    own = learn.Policy(tr.actor, cfg).midpoint(pairs[:, 0], pairs[:, 1])
    np.testing.assert_array_equal(pol.midpoint(pairs[:, 0], pairs[:, 1]), own)
    d = cfg.to_dict()
    d.pop("actor_relative")
    assert learn.TrainConfig.from_dict(d).actor_relative is False


def test_multi_head_actor_policy_is_the_best_scored_head() -> None:
    """``actor_heads``: with a constant network output, :meth:`Actor.candidates` gives each
    head's Gaussian by the same closed form as one head (relative actor: offset and std
    multiples of the pair's length), and the policy's mean and sample are the head with
    the largest score, per pair; one head keeps the single-head layout (no score)."""
    m = finsler.get_metric("carlike")
    cfg = learn.default_config("carlike", actor_relative=True, actor_heads=3)
    actor = build_actor(cfg, m)
    assert actor.net[-1].out_features == 3 * 6 + 3
    mus = torch.tensor([[0.1, -0.2, 0.3], [-0.3, 0.0, 0.2], [0.0, 0.4, -0.1]])
    log_stds = torch.tensor([[-1.0, -2.0, -3.0], [-2.0, -2.0, -2.0], [-4.0, -1.0, -1.5]])
    span = actor.scaler.span
    s = torch.tensor([[0.1, 0.2, 0.3], [-0.4, 0.5, -0.2]])
    g = torch.tensor([[0.5, -0.1, 0.9], [0.2, 0.5, 0.1]])
    r = ((g - s) / span).norm(dim=1, keepdim=True)
    for best in range(3):
        scores = torch.full((3,), -1.0)
        scores[best] = 2.0
        with torch.no_grad():
            actor.net[-1].weight.zero_()
            actor.net[-1].bias.copy_(torch.cat([torch.cat([mus, log_stds], 1).reshape(-1),
                                                scores]))
        mean, std, sc = actor.candidates(s, g)
        assert mean.shape == std.shape == (2, 3, 3) and sc.shape == (2, 3)
        for k in range(3):
            torch.testing.assert_close(mean[:, k], 0.5 * (s + g) + span * r * mus[k])
            torch.testing.assert_close(std[:, k], span * r * torch.exp(log_stds[k]))
        m_pol, s_pol = actor.distribution(s, g)
        torch.testing.assert_close(m_pol, mean[:, best])
        torch.testing.assert_close(s_pol, std[:, best])
        torch.testing.assert_close(actor(s, g, deterministic=True), m.domain.project(
            mean[:, best]))
    one = build_actor(cfg.replace(actor_heads=1), m)
    assert one.net[-1].out_features == 6 and one.candidates(s, g)[2] is None


def test_multi_head_actor_starts_its_heads_apart() -> None:
    """The heads start at distinct offsets, so that they can descend into different
    basins: PyTorch's initialisation of the same network, plus 0.25 along +x, -x, +y, -y
    for heads 1-4 (head 0 and the stds and scores untouched); one head is PyTorch's
    initialisation alone."""
    from learn.mlp import mlp

    m = finsler.get_metric("matsumoto")
    cfg = learn.default_config("matsumoto", actor_heads=5)
    for heads, n_out in ((5, 5 * 4 + 5), (1, 4)):
        torch.manual_seed(0)
        actor = build_actor(cfg.replace(actor_heads=heads), m)
        torch.manual_seed(0)
        ref = mlp(actor.net[0].in_features, n_out, cfg.hidden, cfg.activation)
        shift = (actor.net[-1].bias - ref[-1].bias).detach()
        want = torch.zeros(n_out)
        if heads == 5:
            want[[4, 8, 13, 17]] = torch.tensor([0.25, -0.25, 0.25, -0.25])
        torch.testing.assert_close(shift, want, rtol=0, atol=1e-7)
        torch.testing.assert_close(actor.net[-1].weight, ref[-1].weight, rtol=0, atol=0)


def _distance_critic(tr: Trainer) -> None:
    """Replace the critic with the exact Euclidean distance (``critic(s, g)``)."""
    tr.critic = lambda a, b: (b - a).norm(dim=-1)  # type: ignore[assignment]


def test_multi_head_actor_loss_scores_the_head_the_critic_rates_best(run_dirs) -> None:
    """With the exact Euclidean distance as critic and two heads, one exactly at the
    midpoint and one offset: the scores' gradient raises the midpoint head's score and
    lowers the other's, the midpoint head (the winner) gets no mean gradient (its loss is
    at its minimum), and the loser's mean gradient scales with ``actor_head_share``: the
    same at share 1 as a head trained alone, 1/20 of it at 0.05."""
    grads = {}
    for share in (1.0, 0.05):
        cfg = learn.default_config("euclidean", depth=2, actor_heads=2,
                                   actor_head_share=share, actor_head_weight=1.0,
                                   log_std_min=-20.0)
        tr = Trainer(cfg, run_dirs(), progress=False)
        with torch.no_grad():
            last = tr.actor.net[-1]
            last.weight.zero_()
            last.bias.zero_()
            last.bias[2:4] = -20.0  # head 0: mean (s + g) / 2, std ~0
            last.bias[4] = 0.1  # head 1: offset along x
            last.bias[6:8] = -20.0
        _distance_critic(tr)
        s = torch.tensor([[-0.5, 0.2], [0.3, -0.4], [0.0, 0.0]])
        g = torch.tensor([[0.5, -0.1], [-0.2, 0.6], [0.1, 0.7]])
        tr.actor.zero_grad()
        tr._actor_loss(s, g).backward()
        b = last.bias.grad.clone()
        assert b[8] < 0 < b[9]  # descent raises score 0 (the winner), lowers score 1
        torch.testing.assert_close(b[0:2], torch.zeros(2), atol=1e-5, rtol=0)
        assert b[4].abs() > 1e-3
        grads[share] = b[4:6]
    torch.testing.assert_close(grads[0.05], 0.05 * grads[1.0], rtol=1e-5, atol=1e-8)


def test_multi_head_policy_saves_and_loads(tmp_path) -> None:
    """A run with ``actor_heads`` trains, and the policy loaded from its directory
    predicts the trainer's own midpoints; a config.json without the field loads as one
    head; impossible values are refused by name."""
    cfg = learn.default_config("euclidean", depth=2, timesteps=20_000, collection_size=1024,
                               minibatch_size=256, eval_every=1000, actor_relative=True,
                               actor_heads=2)
    tr = Trainer(cfg, tmp_path / "run", progress=False)
    tr.run()
    pol = learn.load_policy(tmp_path / "run", checkpoint="latest")
    assert pol.actor.heads == 2 and pol.config.actor_heads == 2
    pairs = finsler.sample_pairs(tr.metric, 50, seed=3)
    own = learn.Policy(tr.actor, cfg).midpoint(pairs[:, 0], pairs[:, 1])
    np.testing.assert_array_equal(pol.midpoint(pairs[:, 0], pairs[:, 1]), own)
    d = cfg.to_dict()
    for k in ("actor_heads", "actor_head_weight", "actor_head_share"):
        d.pop(k)
    assert learn.TrainConfig.from_dict(d).actor_heads == 1
    for field, bad in (("actor_heads", 0), ("actor_heads", 2.5), ("actor_heads", True),
                       ("actor_head_weight", -1.0), ("actor_head_weight", float("nan")),
                       ("actor_head_share", 1.5)):
        with pytest.raises(finsler.InputError, match=field):
            learn.default_config("euclidean", **{field: bad})


def test_actor_pairs_join_the_actor_minibatch_without_evaluating_c(run_dirs, monkeypatch) -> None:
    """``actor_pairs``: the actor loss is the method's loss over the minibatch followed by
    ``actor_pairs`` fresh uniform pairs drawn from the run's numpy generator (recomputed
    here with actor_pairs off on the concatenated batch, the same noise), and an update
    with them evaluates C nowhere (every evaluation would be counted in timesteps)."""
    cfg = learn.default_config("euclidean", depth=2, actor_pairs=7, actor_relative=True)
    tr = Trainer(cfg, run_dirs(), progress=False)
    _distance_critic(tr)
    s = torch.tensor([[-0.5, 0.2], [0.3, -0.4], [0.0, 0.0]])
    g = torch.tensor([[0.5, -0.1], [-0.2, 0.6], [0.0, 0.0]])
    np_state, torch_state = tr.np_rng.bit_generator.state, tr.gen.get_state()
    loss = tr._actor_loss(s, g)
    after = tr.np_rng.bit_generator.state
    ref_rng = np.random.default_rng()
    ref_rng.bit_generator.state = np_state
    ends = torch.as_tensor(tr.metric.domain.sample(14, ref_rng).reshape(7, 2, 2),
                           dtype=torch.float32)
    assert ref_rng.bit_generator.state == after
    tr.gen.set_state(torch_state)
    tr.cfg = cfg.replace(actor_pairs=0)
    ref = tr._actor_loss(torch.cat([s, ends[:, 0]]), torch.cat([g, ends[:, 1]]))
    torch.testing.assert_close(loss, ref, rtol=0, atol=0)
    tr.cfg = cfg
    # an update with the pairs: C is never evaluated, timesteps stay what they were
    s64, g64, c64, _ = tr.collect()
    tr.critic = Trainer(cfg, run_dirs(), progress=False).critic

    def no_cost(*_: object) -> None:
        raise AssertionError("C evaluated by an actor_pairs update")

    monkeypatch.setattr(type(tr.metric), "cost", no_cost)
    monkeypatch.setattr(type(tr.metric), "path_costs", no_cost)
    before = tr.timesteps
    tr.update(s64, g64, c64)
    assert tr.timesteps == before
    for bad in (-1, 2.5, True):
        with pytest.raises(finsler.InputError, match="actor_pairs"):
            learn.default_config("euclidean", actor_pairs=bad)


def test_critic_hidden_sizes_the_critic_alone(tmp_path) -> None:
    """``critic_hidden`` gives the critic its own layer widths (the actor keeps
    ``hidden``); such a run resumes from its checkpoint; a config.json without the field
    loads with the critic as wide as the actor; impossible widths are refused by name."""
    cfg = learn.default_config("euclidean", depth=2, hidden=(16, 16), critic_hidden=(24, 8),
                               timesteps=8_000, collection_size=1024, minibatch_size=256,
                               eval_every=2)
    tr = Trainer(cfg, tmp_path / "run", progress=False)
    widths = [m.out_features for m in tr.critic.net if isinstance(m, torch.nn.Linear)]
    assert widths == [24, 8, 1]
    assert [m.out_features for m in tr.actor.net
            if isinstance(m, torch.nn.Linear)][:2] == [16, 16]
    tr.run()
    resumed = Trainer(cfg, tmp_path / "run", resume=True, progress=False)
    for a, b in zip(resumed.critic.parameters(), tr.critic.parameters(), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    d = cfg.to_dict()
    d.pop("critic_hidden")
    assert learn.TrainConfig.from_dict(d).critic_hidden is None
    for bad in ((0, 8), (), "wide"):
        with pytest.raises(finsler.InputError, match="critic_hidden"):
            learn.default_config("euclidean", critic_hidden=bad)


def test_relative_critic_is_length_times_exp_of_its_output() -> None:
    """``critic_transform=relative``: with a constant network output z the critic is
    ``r * exp(z)``, r the pair's coordinate length in normalised coordinates (the
    domain's half-widths, here by hand), symmetric under the swap when ``symmetric``,
    0 at a zero pair; ``to_raw`` inverts ``forward``."""
    m = finsler.get_metric("carlike")  # a box with unequal half-widths
    lo, hi = m.domain.bounds()
    half = torch.as_tensor(0.5 * (hi - lo), dtype=torch.float32)
    for symmetric in (False, True):
        critic = learn.Critic(m, hidden=(8,), normalize_inputs=True, transform="relative",
                              symmetric=symmetric)
        with torch.no_grad():
            critic.net[-1].weight.zero_()
            critic.net[-1].bias.fill_(0.3)
        pairs = torch.as_tensor(finsler.sample_pairs(m, 20, seed=1), dtype=torch.float32)
        s, g = pairs[:, 0], pairs[:, 1]
        r = (((g - s) / half) ** 2).sum(-1).sqrt()
        torch.testing.assert_close(critic(s, g), r * math.exp(0.3), rtol=1e-5, atol=0)
        torch.testing.assert_close(critic(g, s), critic(s, g), rtol=1e-5, atol=0)
        assert float(critic(s, s).detach().abs().max()) < 1e-5
        c = torch.rand(20) + 0.1
        torch.testing.assert_close(critic.to_raw(c, s, g), torch.log(c / r), rtol=1e-5,
                                   atol=1e-6)
    # with an input-dependent output, forward and to_raw are inverse of each other
    critic = learn.Critic(m, hidden=(8,), normalize_inputs=True, transform="relative")
    torch.testing.assert_close(critic.to_raw(critic(s, g), s, g), critic.raw(s, g),
                               rtol=1e-5, atol=1e-5)


def test_relative_critic_skips_zero_pairs_and_learns_a_distance(run_dirs) -> None:
    """The relative critic's loss is the mean squared error of log(c / r) over the
    pairs with a cost (zero pairs: log 0, no target; an update stays finite; a NaN cost is
    not dropped but skips the step), and on the
    Euclidean plane critic steps on exact distances fit them to within 1% on pairs not
    trained on."""
    cfg = learn.default_config("euclidean", depth=2, critic_transform="relative", epochs=1,
                               minibatch_size=4096)
    tr = Trainer(cfg, run_dirs(), progress=False)
    rng = np.random.default_rng(0)
    pts = torch.as_tensor(tr.metric.domain.sample(2048, rng), dtype=torch.float64)
    s, g = pts[:1024], pts[1024:]
    s, g = torch.cat([s, g[:100]]), torch.cat([g, g[:100]])  # 100 zero pairs
    c = (g - s).norm(dim=-1)
    with torch.no_grad():
        z = tr.critic.raw(s.float(), g.float())
        want = ((z - tr.critic.to_raw(c, s, g).float())[c > 0] ** 2).mean()
    lc, _ = tr.update(s, g, c)
    assert math.isfinite(lc)
    assert lc == pytest.approx(float(want), rel=1e-6)
    # a NaN cost is not a zero pair: it reaches the loss and the critic's step is skipped
    bad = c.clone()
    bad[0] = float("nan")
    tr.update(s, g, bad)
    assert tr.skipped_steps == 1
    cfg = cfg.replace(minibatch_size=256, epochs=40)
    tr = Trainer(cfg, run_dirs(), progress=False)
    tr.update(s, g, c)
    test = torch.as_tensor(tr.metric.domain.sample(400, rng), dtype=torch.float32)
    a, b = test[:200], test[200:]
    with torch.no_grad():
        rel = (tr.critic(a, b) / (b - a).norm(dim=-1) - 1).abs()
    assert float(rel.max()) < 0.01


def test_route_search_returns_only_real_improvements(run_dirs) -> None:
    cfg = learn.default_config("euclidean", depth=3, route_candidates=16, route_pairs=40)
    tr = Trainer(cfg, run_dirs(), progress=False)
    _exact_midpoint_actor(tr)
    term = RouteSearch(candidates=16, pairs=40, weight=1.0)
    # straight, evenly split paths are optimal: no candidate can be 1% cheaper
    assert term.prepare(tr) == 40 * 2**3 * (1 + 16)  # evaluations of C it made
    assert term.target is None
    # a bent actor (every midpoint pushed 0.3 along y): stitched routes can win
    with torch.no_grad():
        tr.actor.net[-1].bias[1] = 0.3
    term.prepare(tr)
    found = term.target
    assert found is not None and 0 < found[0].shape[0] <= 40
    m = tr.metric

    def cost(a: torch.Tensor, b: torch.Tensor, depth: int) -> np.ndarray:
        paths = generate_paths(tr.actor, m, a.double(), b.double(), depth).numpy()
        return m.path_costs(paths).sum(1)

    s, g, mid = found
    own = cost(s, g, 3)
    via = cost(s, mid, 2) + cost(mid, g, 2)
    assert (via < 0.99 * own).all()


def test_paper_depth_schedule() -> None:
    # T = 127 * 10 timesteps, D = 6: c_d = 11 trees per depth, depths 0..6
    assert [paper_depth(c, 1270, 6) for c in (0, 10, 11, 21, 22, 65, 66, 76, 77, 10**6)] == [
        0, 0, 1, 1, 2, 5, 6, 6, 6, 6]


@pytest.mark.parametrize("method", ["midpoint", "inter", "two-to-one"])
def test_actor_losses(method: str) -> None:
    a = torch.tensor([1.0, 2.0])
    b = torch.tensor([3.0, 0.5])
    want = {"midpoint": a**2 + b**2, "inter": a + b, "two-to-one": a**2 + 2 * b**2}[method]
    assert torch.equal(actor_loss(method, a, b), want)


def test_midpoint_loss_power_is_eq6_at_2_and_the_power_mean_otherwise() -> None:
    """``actor_loss_power``: eq. (6) itself at p = 2; otherwise ``2**(1-2/p) (a**p +
    b**p)**(2/p)``, equal to eq. (6) for an even split, with its minimiser over the split
    of a fixed length at the even split and an uneven split costing about p - 1 times
    more than at p = 2 (against a longer route, which costs the same)."""
    from learn.midpoint.losses import ACTOR_LOSSES, actor_loss_of

    assert actor_loss_of("midpoint", 2.0) is ACTOR_LOSSES["midpoint"]
    a = torch.tensor([1.0, 2.0, 0.0, 5.0], dtype=torch.float64)
    b = torch.tensor([3.0, 0.5, 0.0, 5.0], dtype=torch.float64)
    for p in (3.0, 4.0, 8.0):
        want = 2 ** (1 - 2 / p) * (a**p + b**p) ** (2 / p)
        torch.testing.assert_close(actor_loss_of("midpoint", p)(a, b), want, rtol=1e-12,
                                   atol=1e-100)  # 0 at a = b = 0, up to 1e-200
    d, x = 2.0, torch.tensor(1e-3, dtype=torch.float64)
    h = torch.tensor(d / 2, dtype=torch.float64)
    even = {p: actor_loss_of("midpoint", p)(h, h) for p in (2.0, 4.0)}
    assert float(even[2.0]) == d**2 / 2
    assert float(even[4.0]) == pytest.approx(d**2 / 2, rel=1e-14)
    uneven = {p: float(actor_loss_of("midpoint", p)(d / 2 + x, d / 2 - x) - even[p])
              for p in (2.0, 4.0)}
    assert uneven[4.0] / uneven[2.0] == pytest.approx(3.0, rel=1e-3)
    longer = {p: float(actor_loss_of("midpoint", p)(d / 2 + x, d / 2 + x) - even[p])
              for p in (2.0, 4.0)}
    assert longer[4.0] == pytest.approx(longer[2.0], rel=1e-12)
    t = torch.linspace(0.05, 0.95, 181, dtype=torch.float64)
    assert float(t[actor_loss_of("midpoint", 4.0)(t * d, (1 - t) * d).argmin()]) == \
        pytest.approx(0.5)
    z = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    actor_loss_of("midpoint", 4.0)(z, z.detach()).sum().backward()
    assert torch.isfinite(z.grad).all()


@pytest.mark.parametrize("bad", [dict(actor_loss_power=1.0), dict(actor_loss_power=True),
                                 dict(actor_loss_power=float("nan")),
                                 dict(actor_loss_power=65.0),
                                 dict(actor_loss_power=4.0, method="inter")])
def test_actor_loss_power_rejects_impossible_values(bad: dict) -> None:
    with pytest.raises(finsler.InputError, match="actor_loss_power"):
        learn.TrainConfig(env="matsumoto", **bad)


# ----------------------------------------------------------------------------------------
# determinism, learning, resume
# ----------------------------------------------------------------------------------------
@pytest.fixture
def run_dirs(tmp_path_factory):
    """Fresh run directories under pytest's temporary root (cleaned by pytest, never left
    in the system's temp folder): ``run_dirs()`` makes one."""
    return lambda: tmp_path_factory.mktemp("run")


def _small(**over: object) -> learn.TrainConfig:
    base = dict(timesteps=60_000, collection_size=1024, minibatch_size=256, epochs=2,
                eval_every=5, depth=3)
    base.update(over)
    return learn.default_config("euclidean", **base)


# the Matsumoto defaults' additions (fused Adam, path energy, one pass) plus route search
_EXTRAS = {"fused_adam": True, "path_energy_weight": 1.0, "path_energy_pairs": 8,
           "epochs": 1, "route_candidates": 4, "route_pairs": 16}


@pytest.mark.parametrize("extras", [{}, _EXTRAS])
def test_same_seed_same_midpoints_different_seed_different(tmp_path, extras) -> None:
    pairs = finsler.default_pairs(finsler.get_metric("euclidean"), 20)
    mids = []
    for k, seed in enumerate((3, 3, 4)):
        out = tmp_path / f"run{k}"
        learn.train_run(_small(seed=seed, timesteps=6_000, **extras), out, progress=False)
        mids.append(learn.load_policy(out).midpoint(pairs[:, 0], pairs[:, 1]))
    assert np.array_equal(mids[0], mids[1])
    assert not np.allclose(mids[0], mids[2])


def test_short_euclidean_training_learns_true_midpoints(tmp_path) -> None:
    """Independent check: on the Euclidean plane the midpoint is (s + g) / 2 and the
    distance |g - s|. The untrained actor (random init) is off by ~0.1 on average; after
    a 1e5-timestep run (depth-2 trees) the mean midpoint error must be below 0.02 (box
    side 2, mean pair distance ~1) and the critic within 10% of the true distance."""
    cfg = learn.default_config("euclidean", depth=2, timesteps=100_000, collection_size=1024,
                               minibatch_size=256, epochs=2, eval_every=1000,
                               path_energy_weight=0.0)  # Algorithm 1 alone
    m = finsler.get_metric("euclidean")
    pairs = finsler.sample_pairs(m, 500, seed=11)
    truth = 0.5 * (pairs[:, 0] + pairs[:, 1])
    tr = Trainer(cfg, tmp_path / "run", progress=False)
    err0 = np.linalg.norm(learn.Policy(tr.actor, cfg).midpoint(pairs[:, 0], pairs[:, 1])
                          - truth, axis=1)
    tr.run()
    pol = learn.load_policy(tmp_path / "run", checkpoint="latest")
    err = np.linalg.norm(pol.midpoint(pairs[:, 0], pairs[:, 1]) - truth, axis=1)
    assert err0.mean() > 0.08
    assert err.mean() < 0.02, err.mean()
    assert np.quantile(err, 0.95) < 0.05
    dist = np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=1)
    with torch.no_grad():
        v = tr.critic(torch.as_tensor(pairs[:, 0]).float(),
                      torch.as_tensor(pairs[:, 1]).float()).double().numpy()
    rel = np.abs(v - dist) / dist
    assert np.median(rel) < 0.1, np.median(rel)


# expert iteration (learn.expert): its rounds, replay buffer and call count are checkpointed
_EXPERT = {"expert_weight": 1.0, "expert_pairs": 8, "expert_every": 2, "expert_keep": 2}


@pytest.mark.parametrize("extras", [{}, _EXTRAS, _EXPERT])
def test_resume_equals_uninterrupted(tmp_path, monkeypatch, extras) -> None:
    cfg = _small(timesteps=12_000, eval_every=3, **extras)
    full = learn.train_run(cfg, tmp_path / "full", progress=False)

    calls = [0]
    real_update = Trainer.update

    def crashing_update(self, *a):
        calls[0] += 1
        if calls[0] == 8:  # crash between checkpoints (iterations 6 and 9)
            raise RuntimeError("simulated crash")
        return real_update(self, *a)

    monkeypatch.setattr(Trainer, "update", crashing_update)
    with pytest.raises(RuntimeError, match="simulated crash"):
        learn.train_run(cfg, tmp_path / "crash", progress=False)
    monkeypatch.setattr(Trainer, "update", real_update)
    with pytest.raises(finsler.InputError, match="--resume"):
        learn.train_run(cfg, tmp_path / "crash", progress=False)
    resumed = learn.train_run(cfg, tmp_path / "crash", resume=True, progress=False)

    a = learn.storage.load_checkpoint(tmp_path / "full" / learn.storage.LATEST_FILE)
    b = learn.storage.load_checkpoint(tmp_path / "crash" / learn.storage.LATEST_FILE)
    for net in ("actor", "critic"):
        for k in a[net]:
            assert torch.equal(a[net][k], b[net][k]), (net, k)
    assert a["counters"]["timesteps"] == b["counters"]["timesteps"] == full.timesteps
    keys = ("iteration", "timesteps", "success_rate", "mean_length", "critic_loss",
            "actor_loss")
    def clean(v):  # losses are NaN before the first update
        return None if isinstance(v, float) and np.isnan(v) else v

    rows_a = [{k: clean(r[k]) for k in keys} for r in full.history]
    rows_b = [{k: clean(r[k]) for k in keys} for r in resumed.history]
    assert rows_a == rows_b
    assert len(rows_a) > 3


# the polish after the budget (TrainConfig.polish_steps): the critic only
_POLISH = {"polish_steps": 40, "polish_eval_every": 15, "polish_pairs": 16}


def _weights(run: Path) -> dict:
    return learn.storage.load_checkpoint(run / learn.storage.LATEST_FILE)["actor"]


def test_polish_makes_no_evaluation_of_c_and_a_resumed_run_polishes_as_a_new_one(
        tmp_path, monkeypatch) -> None:
    cfg = _small(timesteps=6_000, eval_every=2)
    plain = learn.train_run(cfg, tmp_path / "plain", progress=False)
    calls = [0]
    real = finsler.Metric.path_costs

    def spy(self, points, check=None):
        calls[0] += 1
        return real(self, points, check=check)

    # a new run with the polish, and the finished plain run resumed with it
    new = learn.train_run(cfg.replace(**_POLISH), tmp_path / "new", progress=False)
    monkeypatch.setattr(finsler.Metric, "path_costs", spy)
    resumed = learn.train_run(cfg.replace(**_POLISH), tmp_path / "plain", resume=True,
                          progress=False)
    monkeypatch.setattr(finsler.Metric, "path_costs", real)
    # no evaluation of C to learn: the budget's count is unchanged, and C was called only
    # by the validation rows (one batched call each: 15, 30, 40 polish steps)
    assert new.timesteps == resumed.timesteps == plain.timesteps
    assert calls[0] == 3
    polish_rows = [r for r in resumed.history if r["iteration"] > plain.history[-1]["iteration"]]
    assert [r["iteration"] - plain.history[-1]["iteration"] for r in polish_rows] == [15, 30, 40]
    assert all(r["lr"] == 1e-4 and r["timesteps"] == plain.timesteps for r in polish_rows)
    assert learn.storage.read_json(tmp_path / "plain" / "result.json")["polish_steps"] == 40
    # the polish changed the actor, and the resumed run equals the new one bit for bit
    a, b = _weights(tmp_path / "new"), _weights(tmp_path / "plain")
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert [r["success_rate"] for r in new.history] == [r["success_rate"]
                                                       for r in resumed.history]
    # config.json of the resumed run records the polish it made
    doc = learn.storage.read_json(tmp_path / "plain" / "config.json")
    assert doc["config"]["polish_steps"] == 40


def test_polish_moves_an_undertrained_actor_towards_the_true_midpoints(tmp_path) -> None:
    """Independent check on the Euclidean plane (midpoint (s + g) / 2, distance |g - s|):
    after a short run whose actor lags its critic, 60 polish steps (critic frozen, no
    evaluation of C) bring the midpoints nearer the true ones and the paths nearer the
    straight line (measured: relative midpoint error 0.151 -> 0.125, length ratio 1.50 ->
    1.39). The critic is the same with and without the polish."""
    cfg = learn.default_config("euclidean", timesteps=3_000, collection_size=1024,
                               minibatch_size=256, epochs=2, eval_every=5, depth=3)
    runs = {}
    for name, over in (("plain", {}), ("polished", dict(polish_steps=60, polish_lr=1e-3))):
        runs[name] = Trainer(cfg.replace(**over), tmp_path / name, progress=False)
        runs[name].run()
    m = runs["plain"].metric
    e = finsler.sample_pairs(m, 500, 5)
    dist = np.linalg.norm(e[:, 1] - e[:, 0], axis=1)
    err, ratio = {}, {}
    for name, tr in runs.items():
        pol = learn.Policy(tr.actor, tr.cfg)
        err[name] = (np.linalg.norm(pol.midpoint(e[:, 0], e[:, 1])
                                    - 0.5 * (e[:, 0] + e[:, 1]), axis=1) / dist).mean()
        ratio[name] = (m.path_costs(pol.generate(e[:, 0], e[:, 1])).sum(1) / dist).mean()
    assert err["polished"] < 0.92 * err["plain"], err
    assert ratio["polished"] < ratio["plain"] - 0.05, ratio
    for a, b in zip(runs["plain"].critic.state_dict().values(),
                    runs["polished"].critic.state_dict().values()):
        assert torch.equal(a, b)


def test_polish_settings_are_fixed_once_the_polish_began(tmp_path) -> None:
    cfg = _small(timesteps=3_000, **_POLISH)
    learn.train_run(cfg, tmp_path / "r", progress=False)
    with pytest.raises(finsler.InputError, match=r"polish_lr.*only polish_steps"):
        learn.train_run(cfg.replace(polish_lr=1e-3), tmp_path / "r", resume=True, progress=False)
    more = learn.train_run(cfg.replace(polish_steps=50), tmp_path / "r", resume=True,
                       progress=False)
    assert more.history[-1]["iteration"] - more.history[-2]["iteration"] == 5


def test_select_eps_keeps_the_checkpoint_best_at_the_tighter_tolerance(tmp_path) -> None:
    cfg = _small(timesteps=12_000, eval_every=1)
    tight = 0.6 * cfg.eval_eps
    learn.train_run(cfg.replace(select_eps=tight), tmp_path / "r", progress=False)
    rows = learn.storage.read_metrics(tmp_path / "r" / "metrics.csv")
    assert len(rows) > 5 and all("success_rate_select" in r for r in rows)
    # the rule: success at select_eps, then at eps, then the lowest mean largest segment
    want = max(rows, key=lambda r: (r["success_rate_select"], r["success_rate"],
                                    -r["mean_max_segment_cost"]))
    best = learn.storage.load_checkpoint(tmp_path / "r" / learn.storage.BEST_FILE)["eval"]
    assert best["selection_success"] == want["success_rate_select"]
    assert best["timesteps"] == want["timesteps"]
    # and the recorded figure is the policy's: recomputed from its paths
    pol = learn.load_policy(tmp_path / "r")
    pairs = finsler.validation_pairs(pol.metric, cfg.eval_pairs)
    costs = pol.metric.path_costs(pol.generate(pairs[:, 0], pairs[:, 1]))
    assert (costs.max(1) <= tight).mean() == pytest.approx(best["selection_success"])
    doc = learn.storage.read_json(tmp_path / "r" / "config.json")
    assert "select_eps" in doc["selection"] and doc["beyond_paper"]["select_eps"]["used"] == tight
    with pytest.raises(finsler.InputError, match="select_eps"):
        learn.train_run(cfg.replace(select_eps=None), tmp_path / "r", resume=True, progress=False)


def test_resume_refuses_changed_settings(tmp_path) -> None:
    cfg = _small(timesteps=5_000)
    learn.train_run(cfg, tmp_path / "r", progress=False)
    with pytest.raises(finsler.InputError, match="lr"):
        learn.train_run(cfg.replace(lr=0.5), tmp_path / "r", resume=True, progress=False)


# ----------------------------------------------------------------------------------------
# configuration and loading errors
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("over", "match"),
    [
        (dict(method="sideways"), "method"),
        (dict(targets="q"), "targets"),
        (dict(epochs=0), "epochs"),
        (dict(lr=-1.0), "lr"),
        (dict(td_lambda=1.5), "td_lambda"),
        (dict(device="tpu"), "device"),
        (dict(path_energy_weight=-1.0), "path_energy_weight"),
        (dict(path_energy_weight=float("nan")), "path_energy_weight"),
        (dict(path_energy_pairs=0), "path_energy_pairs"),
        (dict(polish_steps=-1), "polish_steps"),
        (dict(polish_steps=2.5), "polish_steps"),
        (dict(polish_pairs=0), "polish_pairs"),
        (dict(polish_eval_every=0), "polish_eval_every"),
        (dict(polish_lr=0.0), "polish_lr"),
        (dict(polish_lr=float("inf")), "polish_lr"),
        (dict(select_eps=0.0), "select_eps"),
        (dict(select_eps=float("nan")), "select_eps"),
        (dict(select_eps=-1.0), "select_eps"),
        (dict(select_eps=True), "select_eps"),
    ],
)
def test_config_rejects_impossible_options(over: dict, match: str) -> None:
    with pytest.raises(finsler.InputError, match=match):
        learn.default_config("matsumoto", **over)


def test_config_rejects_symmetric_critic_for_irreversible_metric() -> None:
    with pytest.raises(finsler.InputError, match="reversible"):
        learn.default_config("matsumoto", symmetric_critic=True)
    with pytest.raises(finsler.UnknownMetricError):
        learn.default_config("klein-bottle")


def test_cuda_request_without_cuda_is_a_clear_error() -> None:
    if torch.cuda.is_available():
        pytest.skip("CUDA present")
    with pytest.raises(finsler.InputError, match="CUDA is not available"):
        learn.resolve_device("cuda")


def _count_torch_costs(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """A spy on Metric.path_costs: ``[n]``, n = the torch evaluations of C made so far."""
    seen = [0]
    real = finsler.Metric.path_costs

    def spy(self, points, check=None):
        if isinstance(points, torch.Tensor):
            seen[0] += points.shape[0] * (points.shape[1] - 1)
        return real(self, points, check=check)

    monkeypatch.setattr(finsler.Metric, "path_costs", spy)
    return seen


def test_all_inclusive_count_equals_a_hand_count(tmp_path, monkeypatch) -> None:
    """Euclidean, depth 3, collections of 1024 pairs: a tree gives 15 + 9 = 24 pairs, so
    ceil(1024 / 24) = 43 trees = 1032 pairs = 5 minibatches of 256 (one epoch). Per
    iteration: trees 43 * 8 = 344 evaluations of C (the paper's count); path energy
    5 steps * 8 pairs * 8 segments = 320 (differentiated); route search
    16 pairs * 8 * (1 + 4 candidates) = 640. The budget 3000 binds the all-inclusive count:
    3 iterations, 3 * 1304 = 3912. Every torch evaluation of C is also counted by a spy."""
    seen = _count_torch_costs(monkeypatch)
    cfg = _small(timesteps=3000, epochs=1, eval_every=1, path_energy_weight=1.0,
                 path_energy_pairs=8, route_candidates=4, route_pairs=16)
    res = learn.train_run(cfg, tmp_path / "r", progress=False)
    rows = res.history
    assert [r["timesteps"] for r in rows] == [0, 1304, 2608, 3912]
    assert [r["timesteps_paper"] for r in rows] == [0, 344, 688, 1032]
    assert [r["timesteps_derivative"] for r in rows] == [0, 320, 640, 960]
    assert seen[0] == 3912
    assert not cfg.model_free and learn.paper_config("matsumoto").model_free
    doc = learn.storage.read_json(tmp_path / "r" / "config.json")
    assert doc["model_free"] is False and doc["uses_derivative_of_C"] == ["path_energy"]
    result = learn.storage.read_json(tmp_path / "r" / "result.json")
    assert result["timesteps"] == 3912 and result["stopped_by"] == "timesteps"


def test_hand_count_with_two_epochs_counts_the_terms_in_every_epoch(tmp_path,
                                                                     monkeypatch) -> None:
    """As above with epochs=2: the collection (trees 344, route search 640, made once per
    iteration) is counted once, the path-energy term at each of its 2 x 5 steps:
    10 * 8 pairs * 8 segments = 640. Per iteration 344 + 640 + 640 = 1624; the budget
    3000 stops after 2 iterations at 3248. A count made in the first epoch only (320)
    would give 1304 per iteration; the spy sees every torch evaluation of C."""
    seen = _count_torch_costs(monkeypatch)
    cfg = _small(timesteps=3000, epochs=2, eval_every=1, path_energy_weight=1.0,
                 path_energy_pairs=8, route_candidates=4, route_pairs=16)
    res = learn.train_run(cfg, tmp_path / "r", progress=False)
    rows = res.history
    assert [r["timesteps"] for r in rows] == [0, 1624, 3248]
    assert [r["timesteps_paper"] for r in rows] == [0, 344, 688]
    assert [r["timesteps_derivative"] for r in rows] == [0, 640, 1280]
    assert seen[0] == 3248


def test_best_checkpoint_is_chosen_on_the_validation_set(tmp_path, monkeypatch) -> None:
    """Training never touches the default evaluation set; checkpoint_best's recorded
    success is the success of that checkpoint on the validation pairs."""
    def forbidden(*a, **k):
        raise AssertionError("training used the default evaluation set")

    monkeypatch.setattr(finsler, "default_pairs", forbidden)
    cfg = _small(timesteps=8_000, eval_every=1, eval_pairs=30)
    res = learn.train_run(cfg, tmp_path / "r", progress=False)
    monkeypatch.undo()
    m = finsler.get_metric("euclidean")
    val = finsler.validation_pairs(m, 30)
    assert not np.allclose(val, finsler.default_pairs(m, 30))
    best = learn.load_policy(tmp_path / "r", checkpoint="best")
    ev = best.evaluate(val)
    assert ev.success_rate == res.best["success_rate"]
    assert ev.mean_max_segment_cost == pytest.approx(res.best["mean_max_segment_cost"],
                                                     rel=1e-6)
    assert res.best["success_rate"] == max(r["success_rate"] for r in res.history)


def test_config_json_records_versions_and_beyond_paper_choices(tmp_path) -> None:
    import json

    learn.train_run(_small(timesteps=2_000), tmp_path / "r", progress=False)
    doc = json.loads((tmp_path / "r" / "config.json").read_text())
    assert set(doc["versions"]) == {"python", "torch", "numpy", "casadi"}
    assert doc["config"]["seed"] == 0 and doc["task"] == {"depth": 3, "eps": 0.2,
                                                          "segments": 8}
    assert doc["beyond_paper"]["critic_transform"] == {"used": "log1p", "paper": "none"}
    assert "lr" in doc["beyond_paper"]
    assert learn.beyond_paper(learn.paper_config("matsumoto")) == {}


def test_load_policy_errors(tmp_path) -> None:
    with pytest.raises(finsler.InputError, match="does not exist"):
        learn.load_policy(tmp_path / "nowhere")
    learn.train_run(_small(timesteps=2_000), tmp_path / "r", progress=False)
    pol = learn.load_policy(tmp_path / "r")
    with pytest.raises(finsler.DomainError):
        pol.generate(np.array([[3.0, 0.0]]), np.array([[0.0, 0.0]]))
    with pytest.raises(finsler.InputError, match="shape"):
        pol.evaluate(np.zeros((4, 2, 3)))
    for f in ("checkpoint_best.pt", "checkpoint_latest.pt"):
        (tmp_path / "r" / f).write_bytes(b"not a checkpoint")
    with pytest.raises(learn.CorruptFileError, match="corrupt"):
        learn.load_policy(tmp_path / "r")


def test_generate_shapes_and_endpoints(tmp_path) -> None:
    learn.train_run(_small(timesteps=2_000), tmp_path / "r", progress=False)
    pol = learn.load_policy(tmp_path / "r")
    pairs = finsler.default_pairs(pol.metric, 7)
    paths = pol.generate(pairs[:, 0], pairs[:, 1])
    assert paths.shape == (7, 2**3 + 1, 2) and paths.dtype == np.float64
    assert np.array_equal(paths[:, 0], pairs[:, 0]) and np.array_equal(paths[:, -1], pairs[:, 1])
    assert pol.generate(pairs[:, 0], pairs[:, 1], depth=5).shape == (7, 33, 2)
    # the midpoint is the actor's mean at (s, g), projected into the domain (computed here
    # from the network directly, not through the tree code)
    with torch.no_grad():
        mean = pol.actor.distribution(torch.as_tensor(pairs[:, 0]).float(),
                                      torch.as_tensor(pairs[:, 1]).float())[0]
    want = pol.metric.domain.project(mean.double()).numpy()
    np.testing.assert_allclose(pol.midpoint(pairs[:, 0], pairs[:, 1]), want, rtol=0,
                               atol=1e-7)


def test_path_energy_gradient_is_finite_where_points_coincide() -> None:
    # two consecutive points projected onto the same boundary point: C = 0 there and its
    # derivative through sqrt is 0/0; the energy's costs equal path_costs and the gradient
    # is finite (one such NaN ended a 4e8-evaluation car-like run at 3.7e8)
    from learn.midpoint.losses import _path_costs_safe

    m = finsler.get_metric("carlike")
    pts = torch.tensor([[[0.0, 0.0, 0.0], [0.3, 0.1, 0.2], [0.3, 0.1, 0.2], [0.6, 0.2, 0.1]]],
                       dtype=torch.float64, requires_grad=True)
    naive = m.path_costs(pts)
    (naive**2).sum().backward()
    assert not torch.isfinite(pts.grad).all()  # the failure this guards against
    pts.grad = None
    c = _path_costs_safe(m, pts)
    assert torch.equal(c.detach(), naive.detach())
    (c**2).sum().backward()
    assert torch.isfinite(pts.grad).all()
    # the same gradient as the path without the repeated point
    q = pts.detach()[:, [0, 1, 3]].clone().requires_grad_(True)
    (m.path_costs(q) ** 2).sum().backward()
    torch.testing.assert_close(pts.grad[:, 0], q.grad[:, 0])
    torch.testing.assert_close(pts.grad[:, 1] + pts.grad[:, 2], q.grad[:, 1])


def test_non_finite_gradient_skips_the_step_and_is_counted(tmp_path) -> None:
    cfg = learn.default_config("euclidean", depth=2, collection_size=64, minibatch_size=32)
    tr = Trainer(cfg, tmp_path / "run", progress=False)
    before = [p.detach().clone() for p in tr.actor.parameters()]
    for p in tr.actor.parameters():
        p.grad = torch.zeros_like(p)
    next(tr.actor.parameters()).grad[0] = float("nan")
    tr._step_if_finite(tr.opt_actor, tr.actor, "actor")
    assert tr.skipped_steps == 1
    assert all(torch.equal(a, b) for a, b in zip(before, tr.actor.parameters()))
    assert all(torch.isfinite(p).all() for p in tr.actor.parameters())
    # a finite gradient steps as usual
    for p in tr.actor.parameters():
        p.grad = torch.ones_like(p)
    tr._step_if_finite(tr.opt_actor, tr.actor, "actor")
    assert tr.skipped_steps == 1
    assert not all(torch.equal(a, b) for a, b in zip(before, tr.actor.parameters()))


def test_inter_and_two_to_one_variants_build_where_the_defaults_set_a_loss_power() -> None:
    """Panda's defaults use eq. (6) with p = 8; the sweep's eq. (17) / (18) variants, which
    have no power, still build (with p = 2) and keep the other model-free defaults."""
    from learn.registry import get_method

    variants = get_method("midpoint").variants
    assert learn.default_config("panda-pole").actor_loss_power == 8.0
    for name in ("inter", "two-to-one"):
        cfg = variants[name].make("panda-pole")
        assert (cfg.method, cfg.actor_loss_power) == (name, 2.0)
        assert cfg.symmetric_critic and cfg.path_energy_weight == 0.0
    assert variants["midpoint-free"].make("panda-pole").actor_loss_power == 8.0
