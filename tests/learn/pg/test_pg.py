"""The PG baseline (section 5.2, eqs. 15-16, appendix B.3): loss, policies, generation,
accounting, run directories, determinism, resume, config validation."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
import torch

import finsler
from finsler import InputError
from learn import pg, train_run
from learn.pg import (
    DepthPolicy,
    PGConfig,
    PGTrainer,
    c_tau,
    cycle_depth,
    default_pg_config,
    gaussian_entropy,
    gaussian_log_prob,
    generate_pg_paths,
    load_pg_policy,
    pair_baseline,
    pg_loss,
    sample_training_paths,
    schedule_total,
)
from learn.storage import read_json, read_metrics

torch.set_num_threads(1)

WALL = {"wall_seconds", "evaluations_per_second", "cycles_per_second"}
CONTRACT = ["iteration", "timesteps", "timesteps_paper", "timesteps_derivative", "wall_seconds",
            "success_rate", "mean_length", "mean_max_segment_cost", "depth",
            "success_rate_task_depth"]


def tiny(**kw):
    """Matsumoto with 3 policies and a schedule of 2 + 3 + 3 cycles, 2 pairs x 3 samples."""
    base = dict(depth=3, cycles_first=2, cycles_other=3, pairs_per_cycle=2, samples_per_pair=3,
                eval_every=2, eval_pairs=10, seed=3)
    base.update(kw)
    return default_pg_config("matsumoto", **base)


# -- objective and estimator ------------------------------------------------------------
def test_c_tau_and_baseline_by_hand():
    seg = torch.tensor([[1.0, 2.0, 3.0, 4.0], [0.5, 0.5, 1.0, 0.0]], dtype=torch.float64)
    # (1 + 2)^2 + (3 + 4)^2 = 58; (0.5 + 0.5)^2 + (1 + 0)^2 = 2
    assert c_tau(seg).tolist() == [58.0, 2.0]
    assert c_tau(torch.tensor([[2.0, 3.0]])).tolist() == [13.0]
    costs = torch.tensor([[1.0, 2.0, 6.0], [0.0, 0.0, 3.0]])
    assert pair_baseline(costs).tolist() == [3.0, 1.0]
    with pytest.raises(InputError):
        c_tau(torch.ones(2, 3))


def test_loss_on_fixed_batch_equals_hand_computation():
    ratio = torch.tensor([1.5, 0.5, 0.5, 1.1], dtype=torch.float64)
    old = torch.tensor([0.3, -1.0, 2.0, 0.0], dtype=torch.float64)
    logp = old + torch.log(ratio)
    adv = torch.tensor([2.0, -1.0, 2.0, -4.0], dtype=torch.float64)
    ent = torch.tensor([1.0, 2.0, 3.0, 4.0], dtype=torch.float64)
    # r A = [3, -0.5, 1, -4.4]; clip(r, 0.8, 1.2) A = [2.4, -0.8, 1.6, -4.4]
    # max -> [3, -0.5, 1.6, -4.4], mean -0.075; entropy mean 2.5, coefficient 0.5
    loss, parts = pg_loss(logp, old, adv, ent, clip=0.2, entropy_coef=0.5)
    assert float(loss) == pytest.approx(-0.075 - 1.25, abs=1e-12)
    assert parts["surrogate"] == pytest.approx(-0.075, abs=1e-12)
    assert parts["entropy"] == pytest.approx(2.5)
    assert parts["clipped_fraction"] == pytest.approx(0.75)
    # the authors' code: max(r A, 1.2 A) -> [3, -0.5, 2.4, -4.4], mean 0.125
    loss2, _ = pg_loss(logp, old, adv, ent, clip=0.2, entropy_coef=0.5, surrogate="sgt-pg-code")
    assert float(loss2) == pytest.approx(0.125 - 1.25, abs=1e-12)


def test_gradient_at_ratio_one_is_eq16():
    """At r = 1 (one epoch per cycle), d loss / d log pi_i = A_i / N: eq. (16)."""
    logp = torch.tensor([0.1, -0.2, 0.7], dtype=torch.float64, requires_grad=True)
    adv = torch.tensor([1.5, -0.5, -1.0], dtype=torch.float64)
    std = torch.tensor([[0.5, 2.0]] * 3, dtype=torch.float64, requires_grad=True)
    loss, _ = pg_loss(logp, logp.detach(), adv, gaussian_entropy(std), 0.2, 1.0)
    loss.backward()
    assert torch.allclose(logp.grad, adv / 3)
    # entropy bonus: d(-mean entropy)/d std = -1 / (N std)
    assert torch.allclose(std.grad, -1.0 / (3 * std.detach()))


def test_gaussian_log_prob_and_entropy_match_torch():
    g = torch.Generator().manual_seed(0)
    mean = torch.randn(5, 3, generator=g, dtype=torch.float64)
    std = torch.rand(5, 3, generator=g, dtype=torch.float64) + 0.1
    x = torch.randn(5, 3, generator=g, dtype=torch.float64)
    ref = torch.distributions.Normal(mean, std)
    assert torch.allclose(gaussian_log_prob(x, mean, std), ref.log_prob(x).sum(-1))
    assert torch.allclose(gaussian_entropy(std), ref.entropy().sum(-1))


# -- policies and generation --------------------------------------------------------------
def test_std_and_mean_follow_the_paper():
    metric = finsler.get_metric("matsumoto")
    pol = DepthPolicy(metric, base_std=0.05)
    m = torch.tensor([0.1, -0.2])
    sigma = torch.tensor([0.0, 1.5])
    c = torch.tensor([0.3, -2.0])
    with torch.no_grad():
        pol.net[-1].weight.zero_()
        pol.net[-1].bias.copy_(torch.cat([m, sigma]))
        pol.c.copy_(c)
    s = torch.tensor([[0.2, 0.1], [-0.5, 0.0]], dtype=torch.float64)
    goal = torch.tensor([[-0.4, 0.9], [-0.5, 0.0]], dtype=torch.float64)
    with torch.no_grad():
        mean, std = pol.distribution(s, goal)
    sp = [math.log1p(math.exp(float(v))) for v in sigma]
    sc = [math.log1p(math.exp(float(v))) for v in c]
    for k in range(2):
        gap = math.hypot(*(goal[k] - s[k]).tolist())
        for i in range(2):
            assert float(mean[k, i]) == pytest.approx(0.5 * float(s[k, i] + goal[k, i])
                                                      + float(m[i]), abs=1e-7)
            assert float(std[k, i]) == pytest.approx(sp[i] + (0.05 + sc[i]) * gap, rel=1e-6)
    assert mean.dtype == torch.float64


def _policies(metric, n, seed=0):
    torch.manual_seed(seed)
    return [DepthPolicy(metric) for _ in range(n)]


def _mean(pol, metric, s, g):
    return metric.domain.project(pol.distribution(s, g)[0])


def test_generation_composes_top_policy_then_lower_means():
    metric = finsler.get_metric("matsumoto")
    pols = _policies(metric, 3)
    s = torch.tensor([[0.5, -0.3], [-0.7, 0.1]], dtype=torch.float64)
    g = torch.tensor([[-0.6, 0.6], [0.8, -0.2]], dtype=torch.float64)
    with torch.no_grad():
        # depth 3 by hand: pi_3, then pi_2 on both halves, then pi_1 on the quarters
        m4 = _mean(pols[2], metric, s, g)
        m2, m6 = _mean(pols[1], metric, s, m4), _mean(pols[1], metric, m4, g)
        pts = [s, m2, m4, m6, g]
        full = [s]
        for a, b in itertools.pairwise(pts):
            full += [_mean(pols[0], metric, a, b), b]
        ref = torch.stack(full, 1)
        out = generate_pg_paths(pols, metric, s, g, 3)
        assert torch.allclose(out, ref, atol=1e-12)
        # depth 2 uses pi_2 first (not pi_3)
        out2 = generate_pg_paths(pols, metric, s, g, 2)
        mm = _mean(pols[1], metric, s, g)
        ref2 = torch.stack([s, _mean(pols[0], metric, s, mm), mm,
                            _mean(pols[0], metric, mm, g), g], 1)
        assert torch.allclose(out2, ref2, atol=1e-12)


def test_training_paths_sample_pi_d_and_fill_with_lower_means():
    metric = finsler.get_metric("matsumoto")
    pols = _policies(metric, 3, seed=1)
    s = torch.tensor([[0.5, -0.3], [-0.7, 0.1]], dtype=torch.float64)
    g = torch.tensor([[-0.6, 0.6], [0.8, -0.2]], dtype=torch.float64)
    gen = torch.Generator().manual_seed(7)
    raw, paths = sample_training_paths(pols, metric, s, g, 3, 4, gen)
    assert raw.shape == (2, 4, 2) and paths.shape == (8, 9, 2)
    with torch.no_grad():
        mean, std = pols[2].distribution(s, g)
        noise = torch.randn((2, 4, 2), generator=torch.Generator().manual_seed(7),
                            dtype=torch.float64)
        assert torch.allclose(raw, mean[:, None] + std[:, None] * noise)
        mid = metric.domain.project(raw.reshape(-1, 2))
        ss, gg = s.repeat_interleave(4, 0), g.repeat_interleave(4, 0)
        # sampled midpoint from pi_3, then pi_2's means on the halves, pi_1's on the quarters
        q1, q3 = _mean(pols[1], metric, ss, mid), _mean(pols[1], metric, mid, gg)
        pts = [ss, q1, mid, q3, gg]
        ref = [ss]
        for a, b in itertools.pairwise(pts):
            ref += [_mean(pols[0], metric, a, b), b]
        assert torch.allclose(paths, torch.stack(ref, 1), atol=1e-12)


# -- schedule and accounting --------------------------------------------------------------
def test_paper_schedule_totals():
    assert default_pg_config("matsumoto").timesteps == 20_613_600
    assert default_pg_config("carlike").timesteps == 82_591_200
    cfg = default_pg_config("panda-pole")
    assert (cfg.cycles_first, cfg.cycles_other, cfg.timesteps) == (1077, 1077, 20_032_200)
    c = tiny()
    assert [cycle_depth(c, i) for i in range(10)] == [1, 1, 2, 2, 2, 3, 3, 3, 3, 3]


def test_accounting_equals_hand_count(tmp_path, monkeypatch):
    cfg = tiny()
    # 2 pairs x 3 samples = 6 paths per cycle: 2 cycles x 2 + 3 x 4 + 3 x 8 segments each
    hand = 6 * (2 * 2 + 3 * 4 + 3 * 8)
    assert schedule_total(cfg) == hand == cfg.timesteps
    counted = {"n": 0}
    cls = type(cfg.metric)
    orig = cls.cost

    def counting(self, x, y, check=None):
        if isinstance(x, torch.Tensor):  # training costs (validation runs on numpy)
            counted["n"] += x.shape[0]
        return orig(self, x, y, check=check)

    monkeypatch.setattr(cls, "cost", counting)
    res = train_run(cfg, tmp_path / "run", progress=False)
    assert res.timesteps == hand == counted["n"]
    final = read_metrics(tmp_path / "run" / "metrics.csv")[-1]
    assert final["timesteps"] == final["timesteps_paper"] == hand
    assert final["timesteps_derivative"] == 0
    assert res.iterations == 8
    # a budget that does not fit the next cycle stops before it
    res2 = train_run(cfg.replace(timesteps=6 * (2 * 2 + 4) + 5), tmp_path / "run2",
                    progress=False)
    assert res2.timesteps == 6 * (2 * 2 + 4) and res2.iterations == 3


# -- run directories ------------------------------------------------------------------------
def _rows(path):
    """Metrics rows without the wall-clock columns, NaN (no loss yet) as None."""
    return [{k: None if isinstance(v, float) and math.isnan(v) else v
             for k, v in r.items() if k not in WALL} for r in read_metrics(path)]


def test_tiny_run_contract_selection_and_determinism(tmp_path):
    cfg = tiny()
    res = train_run(cfg, tmp_path / "a", progress=False)
    run = tmp_path / "a"
    for name in ("config.json", "metrics.csv", "checkpoint_latest.pt", "checkpoint_best.pt",
                 "result.json"):
        assert (run / name).is_file(), name
    doc = read_json(run / "config.json")
    for key in ("env", "method", "seed", "timesteps", "minutes", "device"):
        assert key in doc["config"]
    assert doc["config"]["method"] == "pg" and doc["model_free"] is True
    assert doc["uses_derivative_of_C"] == [] and "versions" in doc and "metric" in doc
    rows = read_metrics(run / "metrics.csv")
    assert all(c in rows[0] for c in CONTRACT)
    # evaluated every 2 cycles and at each level's last cycle (2, 5), plus the last (8)
    assert [r["iteration"] for r in rows] == [0, 2, 4, 5, 6, 8]
    assert [r["depth"] for r in rows] == [1, 1, 2, 2, 3, 3]
    result = read_json(run / "result.json")
    assert result["stopped_by"] == "timesteps" and result["timesteps"] == cfg.timesteps
    assert result["final"]["iteration"] == 8

    # the logged numbers are the validation set's, at depth D and at the task's depth
    val = finsler.validation_pairs(cfg.metric, cfg.eval_pairs)
    latest = load_pg_policy(run, checkpoint="latest")
    ev = latest.evaluate(val, depth=3)
    assert rows[-1]["success_rate_task_depth"] == ev.success_rate
    assert rows[-1]["mean_length_task_depth"] == pytest.approx(ev.mean_length, abs=1e-7)
    ev_default = latest.evaluate(depth=3)
    assert ev_default.mean_length != pytest.approx(ev.mean_length, abs=1e-7)
    row4 = next(r for r in rows if r["iteration"] == 4)
    assert row4["depth"] == 2  # measured at the trained depth (not checked numerically here)
    best = load_pg_policy(run)
    evb = best.evaluate(val)
    assert evb.depth == 3
    assert evb.mean_max_segment_cost == pytest.approx(res.best["mean_max_segment_cost"])
    task_keys = [(r["success_rate_task_depth"], -r["mean_max_segment_cost_task_depth"])
                 for r in rows]
    assert (evb.success_rate, -round(evb.mean_max_segment_cost, 8)) == max(task_keys)
    paths = best.generate(val[:4, 0], val[:4, 1])
    assert paths.shape == (4, 9, 2) and paths.dtype == np.float64
    assert np.allclose(paths[:, 0], val[:4, 0]) and np.allclose(paths[:, -1], val[:4, 1])

    # same seed, same rows (wall-clock columns aside); another seed differs
    train_run(cfg, tmp_path / "b", progress=False)
    assert _rows(run / "metrics.csv") == _rows(tmp_path / "b" / "metrics.csv")
    train_run(cfg.replace(seed=4), tmp_path / "c", progress=False)
    assert _rows(run / "metrics.csv") != _rows(tmp_path / "c" / "metrics.csv")
    # a non-empty directory is refused without resume
    with pytest.raises(InputError, match="not empty"):
        train_run(cfg, run, progress=False)


def test_resume_after_interruption_equals_uninterrupted(tmp_path, monkeypatch):
    cfg = tiny(eval_every=3)
    train_run(cfg, tmp_path / "full", progress=False)

    orig = PGTrainer.cycle

    def interrupted(self):
        if self.iteration == 4:  # mid level 2, one cycle after the checkpoint at 3
            raise KeyboardInterrupt
        return orig(self)

    monkeypatch.setattr(PGTrainer, "cycle", interrupted)
    with pytest.raises(KeyboardInterrupt):
        train_run(cfg, tmp_path / "cut", progress=False)
    assert not (tmp_path / "cut" / "result.json").exists()
    monkeypatch.setattr(PGTrainer, "cycle", orig)
    train_run(cfg, tmp_path / "cut", resume=True, progress=False)

    assert _rows(tmp_path / "full" / "metrics.csv") == _rows(tmp_path / "cut" / "metrics.csv")
    a = load_pg_policy(tmp_path / "full", checkpoint="latest").policies.state_dict()
    b = load_pg_policy(tmp_path / "cut", checkpoint="latest").policies.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    ra, rb = (read_json(tmp_path / d / "result.json") for d in ("full", "cut"))
    assert ra["timesteps"] == rb["timesteps"] and ra["best"]["iteration"] == rb["best"][
        "iteration"]
    # resuming with different settings is refused, naming the field
    with pytest.raises(InputError, match="lr"):
        train_run(cfg.replace(lr=1e-3), tmp_path / "cut", resume=True, progress=False)


def test_only_the_trained_policy_changes(tmp_path):
    cfg = tiny(cycles_first=1, cycles_other=2, restore_level_best=False, init_from_lower=False)
    tr = PGTrainer(cfg, tmp_path / "r", progress=False)
    tr._t0 = 0.0
    tr._enter_level(2)
    before = [{k: v.clone() for k, v in p.state_dict().items()} for p in tr.policies]
    tr.cycle()
    after = [p.state_dict() for p in tr.policies]
    changed = [any(not torch.equal(before[i][k], after[i][k]) for k in after[i])
               for i in range(3)]
    assert changed == [False, True, False]


# -- configuration ------------------------------------------------------------------------
@pytest.mark.parametrize("field,value", [
    ("lr", 0.0), ("lr", "x"), ("clip", 1.5), ("clip", 0.0), ("samples_per_pair", 1),
    ("pairs_per_cycle", 0), ("hidden", ()), ("hidden", (64, 0)), ("activation", "sigmoid"),
    ("method", "seq"), ("epochs", 0), ("entropy_coef", -1.0), ("minutes", 0.0),
    ("timesteps", 0), ("eps", -1.0), ("seed", -1), ("depth", 0), ("eval_every", 0),
    ("eval_pairs", 0), ("cycles_first", 0), ("cycles_other", 0), ("threads", 0),
    ("objective", "cube"), ("surrogate", "trpo"), ("device", "tpu"), ("base_std", 0.0),
    ("init_from_lower", 1), ("pairs_per_cycle", True), ("init_c", math.nan),
])
def test_bad_config_values_raise_naming_the_field(field, value):
    with pytest.raises(InputError, match=field):
        default_pg_config("matsumoto", **{field: value})


def test_config_round_trip_and_unknown_keys():
    cfg = tiny(hidden=(32, 16))
    d = json.loads(json.dumps(cfg.to_dict()))
    assert PGConfig.from_dict(d) == cfg
    with pytest.raises(InputError, match="bogus"):
        PGConfig.from_dict({**d, "bogus": 1})
    with pytest.raises(InputError, match="environment"):
        default_pg_config("nowhere")
    with pytest.raises(InputError):
        PGTrainer(object(), "/nonexistent", progress=False)  # type: ignore[arg-type]


def test_policy_rejects_bad_depth(tmp_path):
    cfg = tiny(cycles_first=1, cycles_other=1)
    train_run(cfg, tmp_path / "r", progress=False)
    pol = load_pg_policy(tmp_path / "r")
    with pytest.raises(InputError, match="depth"):
        pol.generate([[0.0, 0.0]], [[0.5, 0.5]], depth=4)
    assert pol.generate([[0.0, 0.0]], [[0.5, 0.5]], depth=0).shape == (1, 2, 2)
    assert pol.evaluate(depth=1).depth == 1
    with pytest.raises(InputError, match="checkpoint"):
        load_pg_policy(tmp_path / "r", checkpoint="first")
    assert pg.PGPolicy.__name__ in repr(pol)


def test_level_change_restores_best_and_starts_from_lower(tmp_path):
    cfg = tiny(cycles_first=4, eval_every=1)
    tr = PGTrainer(cfg, tmp_path / "r", progress=False)
    tr._t0 = 0.0
    tr._log_and_checkpoint()
    for _ in range(4):
        tr.cycle()
        tr._log_and_checkpoint()
    keys = [(r["success_rate"], -r["mean_max_segment_cost"]) for r in tr.history]
    best_at = tr.history[max(range(len(keys)), key=keys.__getitem__)]["iteration"]
    assert tr.level_best["iteration"] == best_at
    kept = {k: v.clone() for k, v in tr.level_best["state"].items()}
    tr._enter_level(2)
    a, b = tr.policies[0].state_dict(), tr.policies[1].state_dict()
    assert all(torch.equal(a[k], kept[k]) for k in kept)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert tr.level == 2 and tr.level_best is None
