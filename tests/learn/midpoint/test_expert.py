"""Expert iteration (learn.expert): the search's midpoint-tree targets by hand, the term's
count of evaluations of C against a spy, targets nearer the true midpoints than the policy
it improves (Euclidean plane: the midpoint is (a + b) / 2), checkpointed state (a resumed
run equals an uninterrupted one: tests/learn/midpoint/test_learn.py), config checks."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import finsler
import learn
from learn import Trainer
from learn.midpoint.expert import SearchImitation, search_spec, tree_targets
from learn.midpoint.policy import generate_paths


def _small(**over: object) -> learn.TrainConfig:
    base = dict(timesteps=60_000, collection_size=1024, minibatch_size=256, epochs=2,
                eval_every=5, depth=3)
    base.update(over)
    return learn.default_config("euclidean", **base)


def test_tree_targets_by_hand() -> None:
    """One path of 5 points (D = 2) with segment costs 1, 2, 3, 4: the root pair
    (p0, p4) has midpoint p2 and cost 10; level 1: (p0, p2) -> p1 cost 3, (p2, p4) -> p3
    cost 7."""
    p = torch.tensor([[[0.0, 0.0], [1.0, 0.5], [2.0, 0.0], [3.0, -0.5], [4.0, 0.0]]],
                     dtype=torch.float64)
    c = torch.tensor([[1.0, 2.0, 3.0, 4.0]], dtype=torch.float64)
    a, b, m, cost = tree_targets(p, c)
    assert torch.equal(a, p[0, [0, 0, 2]])
    assert torch.equal(b, p[0, [4, 2, 4]])
    assert torch.equal(m, p[0, [2, 1, 3]])
    assert torch.equal(cost, torch.tensor([10.0, 3.0, 7.0], dtype=torch.float64))
    a1, b1, m1, c1 = tree_targets(p, c, levels=1)
    assert torch.equal(a1, p[0, [0]]) and torch.equal(b1, p[0, [4]])
    assert torch.equal(m1, p[0, [2]]) and c1.tolist() == [10.0]
    # two paths: 2 * (2**2 - 1) triples
    assert tree_targets(p.repeat(2, 1, 1), c.repeat(2, 1))[0].shape == (6, 2)
    with pytest.raises(ValueError, match="2\\*\\*D \\+ 1"):
        tree_targets(p[:, :4], c[:, :3])


def _bent_trainer(run_dir) -> Trainer:
    """A Euclidean trainer whose actor's midpoints are (s + g) / 2 pushed 0.2 along y."""
    cfg = _small(depth=3, eval_pairs=10)
    tr = Trainer(cfg, run_dir, progress=False)
    with torch.no_grad():
        tr.actor.net[-1].weight.zero_()
        tr.actor.net[-1].bias.zero_()
        tr.actor.net[-1].bias[1] = 0.2
    return tr


@pytest.mark.parametrize("kind", ["local", "full"])
def test_term_counts_every_evaluation_and_targets_beat_the_policy(tmp_path, monkeypatch,
                                                                  kind) -> None:
    tr = _bent_trainer(tmp_path)
    seen = [0]
    real = finsler.Metric.path_costs

    def spy(self, points, check=None):
        shape = points.shape
        seen[0] += (int(np.prod(shape[:-2])) if len(shape) > 2 else 1) * (shape[-2] - 1)
        return real(self, points, check=check)

    monkeypatch.setattr(finsler.Metric, "path_costs", spy)
    term = SearchImitation(weight=1.0, pairs=12, every=1, spec=search_spec(kind))
    made = term.prepare(tr)
    assert made == seen[0] > 12 * 2**3  # the search's evaluations and the final path costs
    a, b, m, c = term._targets()
    assert a.shape == (12 * 7, 2)
    # every target's cost is the cost of a real path between its ends: >= the distance
    dist = (b.double() - a.double()).norm(dim=1)
    assert (c >= dist * (1 - 1e-6)).all()
    # the searched midpoints are nearer the true ones than the bent policy's own
    with torch.no_grad():
        own = tr.actor(a, b, deterministic=True)
    truth = 0.5 * (a + b)
    err_t = ((m - truth).norm(dim=1) / dist.float()).mean()
    err_p = ((own - truth).norm(dim=1) / dist.float()).mean()
    assert err_t < 0.9 * err_p, (float(err_t), float(err_p))
    # and the searched paths (level 0 of the targets) are never longer than the policy's
    own_paths = generate_paths(tr.actor, tr.metric, a[:12].double(), b[:12].double(), 3)
    own_cost = torch.as_tensor(np.array(tr.metric.path_costs(own_paths.numpy()))).sum(1)
    assert (c[:12] <= own_cost * (1 + 1e-9)).all() and c[:12].mean() < 0.99 * own_cost.mean()
    # the term's loss pulls the actor towards them: one gradient step lowers it
    tr.gen.manual_seed(0)
    out = term.step(tr)
    assert out.loss is not None and out.evaluations == 0
    opt = torch.optim.SGD(tr.actor.parameters(), lr=1e-4)
    before = float(out.loss.detach())
    out.loss.backward()
    opt.step()
    tr.gen.manual_seed(0)  # the same minibatch
    after = float(term.step(tr).loss.detach())
    assert after < before
    # critic data: the sub-pairs and their searched costs, float64
    s, g, cc = term.critic_data(tr)
    assert s.dtype == g.dtype == cc.dtype == torch.float64 and cc.shape == (12 * 7,)


def test_term_rounds_follow_every_and_keep(tmp_path) -> None:
    tr = _bent_trainer(tmp_path)
    term = SearchImitation(weight=1.0, pairs=4, every=2, spec=search_spec("local"), keep=2)
    counts = [term.prepare(tr) for _ in range(6)]
    assert [c > 0 for c in counts] == [True, False, True, False, True, False]
    assert len(term.buffer) == 2  # the last two rounds
    st = term.state()
    other = SearchImitation(weight=1.0, pairs=4, every=2, spec=search_spec("local"), keep=2)
    other.load(st, "cpu")
    assert other.calls == 6 and all(
        torch.equal(x, y) for u, v in zip(other.buffer, term.buffer, strict=True)
        for x, y in zip(u, v, strict=True))


_EXPERT = {"expert_weight": 1.0, "expert_pairs": 8, "expert_every": 2, "expert_keep": 2}


def test_expert_run_counts_the_search_and_stays_model_free(tmp_path) -> None:
    """The same run with and without the term: the all-inclusive count grows by the
    term's evaluations, the paper's count does not, no derivative of C is taken."""
    plain = learn.train_run(_small(timesteps=3000, epochs=1, eval_every=1), tmp_path / "p",
                            progress=False)
    cfg = _small(timesteps=3000, epochs=1, eval_every=1, **_EXPERT)
    res = learn.train_run(cfg, tmp_path / "e", progress=False)
    doc = learn.storage.read_json(tmp_path / "e" / "config.json")
    assert doc["config"]["expert_weight"] == 1.0 and doc["model_free"] is True
    assert doc["uses_derivative_of_C"] == [] and "search_imitation" in str(doc["actor_terms"])
    assert [r["timesteps_derivative"] for r in res.history] == [0] * len(res.history)
    ts = [r["timesteps"] for r in res.history]
    paper = [r["timesteps_paper"] for r in res.history]
    assert paper[:2] == [r["timesteps_paper"] for r in plain.history][:2]
    # iteration 1 searched (8 pairs, depth 3): at least their 8 * 8 path costs on top
    assert ts[1] >= paper[1] + 8 * 8
    assert ts[-1] >= cfg.timesteps


@pytest.mark.parametrize(("over", "match"), [
    ({"expert_weight": -1.0}, "expert_weight"),
    ({"expert_weight": float("nan")}, "expert_weight"),
    ({"expert_pairs": 0}, "expert_pairs"),
    ({"expert_every": 0}, "expert_every"),
    ({"expert_keep": 0}, "expert_keep"),
    ({"expert_levels": -1}, "expert_levels"),
    ({"expert_search": "global"}, "expert_search"),
])
def test_bad_expert_options_are_named(over, match) -> None:
    with pytest.raises(finsler.InputError, match=match):
        _small(**over)
