"""Tests of the Seq baseline (learn.seq): the environment of eqs. (57) and (14) against
hand-computed steps, the batched VecEnv against SB3's DummyVecEnv, the all-inclusive count
against a count of every row handed to F, the evaluation's success rule, and tiny PPO runs
(contract files, determinism, exact resume, config errors)."""

from __future__ import annotations

import csv
import io
import warnings

import numpy as np
import pytest
import torch

import finsler
from finsler import InputError
from learn import train_run
from learn.seq import (
    WALL_COLUMNS,
    ZERO_ACTION_REWARD,
    GeodesicEnv,
    GeodesicVecEnv,
    SeqConfig,
    SeqTrainer,
    default_seq_config,
    evaluate_seq,
    load_seq_policy,
)
from learn.storage import LATEST_FILE, load_checkpoint, read_json, read_metrics

torch.set_num_threads(1)


# ----------------------------------------------------------------------------------------
# the environment
# ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["euclidean", "matsumoto", "carlike"])
def test_env_passes_gymnasium_and_sb3_checkers(name: str) -> None:
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        check_env(GeodesicEnv(name), skip_render_check=True)
        sb3_check_env(GeodesicEnv(name), warn=True)


def _minkowski_F(v: np.ndarray) -> float:
    """F of finsler's default Minkowski norm, written out by hand."""
    a11, a12, a22, b1, b2 = 1.0, 0.3, 2.0, 0.4, -0.2
    return float(np.sqrt(a11 * v[0] ** 2 + 2 * a12 * v[0] * v[1] + a22 * v[1] ** 2)
                 + b1 * v[0] + b2 * v[1])


def _randers_F(v: np.ndarray) -> float:
    """Zermelo travel time with wind (0.5, 0.2), the textbook formula."""
    w = np.array([0.5, 0.2])
    lam = 1.0 - w @ w
    return float((np.sqrt(lam * (v @ v) + (w @ v) ** 2) - w @ v) / lam)


@pytest.mark.parametrize("name,F", [("euclidean", lambda v: float(np.hypot(*v))),
                                    ("minkowski", _minkowski_F), ("randers", _randers_F)])
def test_steps_and_rewards_equal_hand_computed_values(name: str, F) -> None:
    env = GeodesicEnv(name, depth=3)
    eps = env.eps
    s, g = np.array([0.8, -0.5]), np.array([-0.6, 0.7])
    obs, _ = env.reset(seed=0, options={"start": s, "goal": g})
    np.testing.assert_array_equal(obs, np.concatenate([s, g]).astype(np.float32))
    # the third action leaves the box [-1, 1]^2 (projection = clipping); the fourth is tiny;
    # SB3 hands float32 actions, the step uses their float64 value
    actions = [np.array([-0.3, 0.9], np.float32), np.array([1.0, -1.0], np.float32),
               np.array([1.0, 0.05], np.float32), np.array([1e-30, -2e-30]),
               np.array([-0.7, 0.2], np.float32)]
    p = s.copy()
    for a in actions:
        v = a.astype(np.float64)
        unprojected = p + eps / F(v) * v  # eq. (57); F does not depend on the point here
        q = np.clip(unprojected, -1.0, 1.0)
        r = F(g - p) - F(g - q) - eps  # eq. (14) with F(g, .) = F(.)
        _, reward, terminated, truncated, info = env.step(a)
        np.testing.assert_allclose(env.point, q, rtol=0, atol=1e-14)
        np.testing.assert_allclose(reward, r, rtol=0, atol=1e-13)
        assert terminated == (F(g - q) < eps)  # C(q, g) = F(g - q) for constant metrics
        assert not truncated and info["evaluations"] == 3
        if np.all(unprojected == q):  # unprojected steps cost eps
            assert F(q - p) == pytest.approx(eps, rel=1e-14)
        p = q
    assert env.env_steps == 5 and env.evaluations == 1 + 5 * 3


def test_zero_action_stays_gives_minus_100_and_truncation_comes_at_step_n() -> None:
    env = GeodesicEnv("matsumoto", depth=2)  # n = 4 steps
    env.reset(seed=1)
    p0, before = env.point, env.evaluations
    for t in range(1, 5):
        _, reward, terminated, truncated, info = env.step(np.zeros(2, np.float32))
        assert reward == ZERO_ACTION_REWARD and not terminated
        assert truncated == (t == 4)
        np.testing.assert_array_equal(env.point, p0)
        assert info["evaluations"] == 0
    assert env.evaluations == before and env.env_steps == 4


def test_time_limit_terminate_ends_episodes_like_the_authors_gym_code() -> None:
    """``time_limit="terminate"``: the n-th step is a termination (no bootstrap) in the single
    env, and the batched env reports no ``TimeLimit.truncated`` (so SB3 does not bootstrap),
    like a DummyVecEnv of such single envs."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    env = GeodesicEnv("matsumoto", depth=2, time_limit="terminate")
    env.reset(seed=1)
    for t in range(1, 5):
        _, _, terminated, truncated, info = env.step(np.zeros(2, np.float32))
        assert terminated == (t == 4) and not truncated and not info["is_success"]
    n = 2
    batched = GeodesicVecEnv("matsumoto", n, depth=2, time_limit="terminate")
    default = GeodesicVecEnv("matsumoto", n, depth=2)
    dummy = DummyVecEnv([lambda: GeodesicEnv("matsumoto", depth=2, time_limit="terminate")
                         for _ in range(n)])
    for e in (batched, default, dummy):
        e.seed(3)
        e.reset()
    zero = np.zeros((n, 2), np.float32)
    for t in range(1, 5):
        _, _, d1, i1 = batched.step(zero)
        _, _, d2, i2 = default.step(zero)
        _, _, d3, i3 = dummy.step(zero)
        assert list(d1) == list(d2) == list(d3) == [t == 4] * n
        assert [i["TimeLimit.truncated"] for i in i1] == [False] * n
        assert [i["TimeLimit.truncated"] for i in i2] == [t == 4] * n
        assert [i.get("TimeLimit.truncated", False) for i in i3] == [False] * n


def test_success_terminates_at_the_right_step_and_rewards_telescope() -> None:
    env = GeodesicEnv("euclidean", depth=3)  # eps 0.2, n = 8
    env.reset(options={"start": [-0.5, 0.0], "goal": [0.45, 0.0]})
    total, steps = 0.0, 0
    while True:
        _, r, terminated, truncated, info = env.step(np.array([1.0, 0.0], np.float32))
        total += r
        steps += 1
        if terminated or truncated:
            break
    # distance 0.95 in steps of 0.2: C(p_3, g) = 0.35, C(p_4, g) = 0.15 < eps
    assert terminated and info["is_success"] and steps == 4
    np.testing.assert_allclose(env.point, [0.3, 0.0], atol=1e-15)
    # the sum of eq. (14) telescopes: F(g, g - s) - F(g, g - p_4) - 4 eps
    assert total == pytest.approx(0.95 - 0.15 - 4 * 0.2, abs=1e-12)


def test_solved_pairs_are_redrawn_and_every_evaluation_is_counted(monkeypatch) -> None:
    """Count every row handed to the metric (F and C) and compare with the env counters."""
    rows = {"n": 0}
    orig_F, orig_cost = finsler.Metric.F, finsler.Metric.cost

    def F(self, x, v, check=None):
        rows["n"] += np.asarray(x).reshape(-1, self.dim).shape[0]
        return orig_F(self, x, v, check=check)

    def cost(self, x, y, check=None):
        rows["n"] += np.asarray(x).reshape(-1, self.dim).shape[0]
        return orig_cost(self, x, y, check=check)

    monkeypatch.setattr(finsler.Metric, "F", F)
    monkeypatch.setattr(finsler.Metric, "cost", cost)
    # huge eps: about 30% of uniform pairs on [-1, 1]^2 are already solved and redrawn
    env = GeodesicEnv("euclidean", eps=0.9, depth=2)
    rng = np.random.default_rng(0)
    hand = 0
    for ep in range(30):
        _, info = env.reset(seed=ep)
        assert env.metric.cost(env.point, env.goal) >= 0.9
        rows["n"] -= 1  # that check was ours
        assert info["evaluations"] % 2 == 0
        hand += info["evaluations"]
        for _ in range(4):
            a = np.zeros(2) if rng.uniform() < 0.3 else rng.uniform(-1, 1, 2)
            _, _, term, trunc, info = env.step(a.astype(np.float32))
            hand += 3 if np.any(a != 0) else 0
            if term or trunc:
                break
    assert env.evaluations == rows["n"] == hand
    assert env.evaluations > 2 * 30  # some pairs were redrawn

    rows["n"] = 0
    venv = GeodesicVecEnv("euclidean", 5, eps=0.9, depth=2)
    venv.seed(3)
    venv.reset()
    for _ in range(12):
        a = rng.uniform(-1, 1, (5, 2))
        a[rng.uniform(size=5) < 0.3] = 0.0
        venv.step(a.astype(np.float32))
    assert venv.evaluations == rows["n"] and venv.env_steps == 60


def test_batched_vecenv_equals_dummy_vecenv_of_single_envs() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    n = 3
    dummy = DummyVecEnv([lambda: GeodesicEnv("matsumoto", depth=3) for _ in range(n)])
    batched = GeodesicVecEnv("matsumoto", n, depth=3)
    dummy.seed(7)
    batched.seed(7)
    np.testing.assert_array_equal(dummy.reset(), batched.reset())
    rng = np.random.default_rng(1)
    episodes = 0
    for _ in range(40):
        a = rng.uniform(-1.2, 1.2, (n, 2))
        a[rng.uniform(size=n) < 0.1] = 0.0
        a = np.clip(a, -1, 1).astype(np.float32)
        o1, r1, d1, i1 = dummy.step(a)
        o2, r2, d2, i2 = batched.step(a)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        for x, y in zip(i1, i2):
            assert x["is_success"] == y["is_success"]
            assert x["TimeLimit.truncated"] == y["TimeLimit.truncated"]
            assert ("terminal_observation" in x) == ("terminal_observation" in y)
            if "terminal_observation" in x:
                np.testing.assert_array_equal(x["terminal_observation"],
                                              y["terminal_observation"])
        episodes += int(d1.sum())
    assert episodes >= n  # auto-resets were exercised
    assert batched.evaluations == sum(e.evaluations for e in dummy.envs)
    assert batched.env_steps == sum(e.env_steps for e in dummy.envs) == 40 * n


# ----------------------------------------------------------------------------------------
# evaluation: paths and the success rule
# ----------------------------------------------------------------------------------------
def _towards_goal(obs: np.ndarray) -> np.ndarray:
    obs = obs.astype(np.float64)
    return obs[:, 2:] - obs[:, :2]


def test_evaluation_paths_end_at_the_goal_and_success_needs_n_segments() -> None:
    m = finsler.get_metric("euclidean")  # eps 0.2
    pairs = np.array([
        [[-0.5, 0.0], [0.25, 0.0]],  # 0.75: reached after 3 steps -> 4 segments: success
        [[-0.5, 0.0], [0.4, 0.0]],  # 0.9: reached after 4 = n steps -> 5 segments: fail
        [[0.0, 0.0], [0.1, 0.0]],  # already within eps: the path s, g, g, ...
        [[-1.0, -1.0], [1.0, 1.0]],  # 2.83: never reached
    ])
    res, paths = evaluate_seq(_towards_goal, m, pairs, 0.2, depth=2)  # n = 4
    assert paths.shape == (4, 5, 2)
    np.testing.assert_array_equal(paths[:, 0], pairs[:, 0])
    np.testing.assert_array_equal(paths[:, -1], pairs[:, 1])
    np.testing.assert_allclose(paths[0, :4, 0], [-0.5, -0.3, -0.1, 0.1], atol=1e-15)
    np.testing.assert_array_equal(paths[2, 1:], np.repeat(pairs[2, 1:], 4, axis=0))
    assert res.success.tolist() == [True, False, True, False]
    assert res.reached.tolist() == [True, True, True, False]  # the paper's episode success
    assert res.steps.tolist() == [3, 4, 0, 4]
    # the second pair's path is p_0..p_3, g: last segment 0.3 > eps
    assert res.max_segment_cost[1] == pytest.approx(0.3, abs=1e-12)
    # steps of cost eps: the tolerance accepts rounding, the strict test may not
    costs = m.path_costs(paths[:1])[0]
    assert np.all(np.abs(costs[:3] - 0.2) < 1e-15) and costs[3] < 0.2
    assert res.strict_success[0] == bool(np.all(costs <= 0.2))
    assert res.success_rate == 0.5 and res.reached_rate == 0.75


def test_projection_that_raises_a_segment_above_eps_fails_honestly() -> None:
    """Minkowski norm, eps 0.3: from the wall x = -1, the direction (-1, 1) costs eps, but
    clipping its x-part leaves (0, 0.316), which costs 0.384 > eps (b = (0.4, -0.2) made
    the removed part cheap). The goal is reached (the paper's episode success), yet the
    path is no solution of the section 5.1 task."""
    m = finsler.get_metric("minkowski")
    pairs = np.array([[[-1.0, -0.5], [-1.0, 0.9]]])

    def up_left(obs: np.ndarray) -> np.ndarray:
        return np.tile([-1.0, 1.0], (obs.shape[0], 1))

    res, paths = evaluate_seq(up_left, m, pairs, 0.3, depth=3)
    costs = m.path_costs(paths)[0]
    assert costs[0] == pytest.approx(np.sqrt(2) * 0.3 / 0.949 - 0.2 * 0.3 / 0.949, rel=1e-3)
    assert costs[0] > 0.3 * (1 + 1e-6)
    assert res.reached[0] and not res.success[0]


# ----------------------------------------------------------------------------------------
# training runs
# ----------------------------------------------------------------------------------------
def _tiny(**over) -> SeqConfig:
    base = dict(timesteps=3_000, eval_every=900, eval_pairs=20, n_envs=4, n_steps=64,
                batch_size=64, n_epochs=2)
    base.update(over)
    return default_seq_config("euclidean", **base)


def _rows_without_wall(path) -> list[dict]:
    text = (path / "metrics.csv").read_text()
    return [{k: v for k, v in r.items() if k not in WALL_COLUMNS}
            for r in csv.DictReader(io.StringIO(text))]


def test_tiny_run_writes_the_contract_files_and_selects_on_validation(tmp_path) -> None:
    cfg = _tiny()
    res = train_run(cfg, tmp_path / "r", progress=False)
    run = tmp_path / "r"
    for f in ("config.json", "metrics.csv", "checkpoint_latest.pt", "checkpoint_best.pt",
              "result.json"):
        assert (run / f).is_file(), f
    doc = read_json(run / "config.json")
    assert doc["model_free"] is True and doc["uses_derivative_of_C"] == []
    for k in ("env", "method", "seed", "timesteps", "minutes", "device", "n_envs"):
        assert k in doc["config"]
    assert doc["config"]["method"] == "seq" and doc["metric"]["name"] == "euclidean"
    rows = read_metrics(run / "metrics.csv")
    for col in ("iteration", "timesteps", "timesteps_paper", "timesteps_derivative",
                "wall_seconds", "success_rate", "mean_length", "mean_max_segment_cost"):
        assert col in rows[0]
    # 3 evaluations per step plus resets: the all-inclusive count exceeds the paper's
    for r in rows[1:]:
        assert 3 * r["timesteps_paper"] <= r["timesteps"] <= 3 * r["timesteps_paper"] + (
            2 * 4 * r["timesteps_paper"])
        assert r["timesteps_derivative"] == 0
        assert r["timesteps_paper"] == 256 * r["iteration"]
    assert rows[-1]["timesteps"] >= cfg.timesteps > rows[-1]["timesteps"] - 7 * 256
    result = read_json(run / "result.json")
    assert result["stopped_by"] == "timesteps" and result["timesteps"] == res.timesteps
    # the best checkpoint holds the best validation row and reproduces it
    best_row = max(rows, key=lambda r: (r["success_rate"], -r["mean_max_segment_cost"]))
    assert res.best["success_rate"] == best_row["success_rate"]
    pol = load_seq_policy(run, checkpoint="best")
    ev = pol.evaluate(finsler.validation_pairs(pol.metric, 20))
    assert ev.success_rate == best_row["success_rate"]
    assert ev.mean_max_segment_cost == pytest.approx(best_row["mean_max_segment_cost"],
                                                     abs=1e-7)
    paths = pol.generate(np.zeros((2, 2)), np.full((2, 2), 0.5))
    assert paths.shape == (2, 17, 2) and np.all(paths[:, -1] == 0.5)
    assert load_seq_policy(run, checkpoint="latest").checkpoint == "checkpoint_latest.pt"
    with pytest.raises(InputError, match="not empty"):
        train_run(cfg, run, progress=False)


def test_same_seed_same_metrics_different_seed_different(tmp_path) -> None:
    cfg = _tiny(timesteps=1_800)
    train_run(cfg, tmp_path / "a", progress=False)
    train_run(cfg, tmp_path / "b", progress=False)
    train_run(cfg.replace(seed=1), tmp_path / "c", progress=False)
    a, b, c = (_rows_without_wall(tmp_path / x) for x in "abc")
    assert a == b and len(a) >= 2
    assert a != c


def test_resume_continues_exactly_like_an_uninterrupted_run(tmp_path, monkeypatch) -> None:
    cfg = _tiny(timesteps=2_400, eval_every=700)
    train_run(cfg, tmp_path / "full", progress=False)

    calls = {"n": 0}
    orig = SeqTrainer.train_rollout

    def crashing(self):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("simulated crash")
        return orig(self)

    monkeypatch.setattr(SeqTrainer, "train_rollout", crashing)
    with pytest.raises(RuntimeError, match="simulated crash"):
        train_run(cfg, tmp_path / "crash", progress=False)
    monkeypatch.setattr(SeqTrainer, "train_rollout", orig)
    before = _rows_without_wall(tmp_path / "crash")
    assert not (tmp_path / "crash" / "result.json").exists()
    train_run(cfg, tmp_path / "crash", resume=True, progress=False)
    after = _rows_without_wall(tmp_path / "crash")
    assert after[: len(before)] == before and len(after) > len(before)
    assert int(after[-1]["timesteps"]) > int(before[-1]["timesteps"])
    assert after == _rows_without_wall(tmp_path / "full")
    a = load_checkpoint(tmp_path / "full" / LATEST_FILE)
    b = load_checkpoint(tmp_path / "crash" / LATEST_FILE)
    for k in a["policy"]:
        assert torch.equal(a["policy"][k], b["policy"][k]), k
    assert a["counters"]["timesteps"] == b["counters"]["timesteps"]
    # resuming with another training setting is refused
    with pytest.raises(InputError, match="lr"):
        train_run(cfg.replace(lr=1e-4), tmp_path / "crash", resume=True, progress=False)


@pytest.mark.parametrize("over,match", [
    ({"timesteps": 0}, "timesteps"),
    ({"lr": 0.0}, "lr"),
    ({"lr": "0.1"}, "lr"),
    ({"batch_size": 4096}, "batch_size"),
    ({"gamma": 1.5}, "gamma"),
    ({"n_envs": 0}, "n_envs"),
    ({"n_steps": -1}, "n_steps"),
    ({"eval_every": 0}, "eval_every"),
    ({"eval_pairs": 0}, "eval_pairs"),
    ({"minutes": -1.0}, "minutes"),
    ({"device": "tpu"}, "device"),
    ({"activation": "sigmoid"}, "activation"),
    ({"hidden": (64, 0)}, "hidden"),
    ({"eps": 0.0}, "eps"),
    ({"depth": 0}, "depth"),
    ({"method": "midpoint"}, "method"),
    ({"clip_range": 0.0}, "clip_range"),
    ({"gae_lambda": 2.0}, "gae_lambda"),
    ({"ent_coef": -1.0}, "ent_coef"),
    ({"reject_solved": 1}, "reject_solved"),
    ({"time_limit": "bootstrap"}, "time_limit"),
    ({"no_such_field": 1}, "no_such_field"),
])
def test_bad_config_values_raise_input_error_naming_the_field(over, match) -> None:
    with pytest.raises(InputError, match=match):
        default_seq_config("matsumoto", **over)


def test_config_round_trip_and_unknown_keys() -> None:
    cfg = default_seq_config("carlike", seed=3)
    assert cfg.timesteps == 80_000_000 and cfg.n_envs * cfg.n_steps == 2048
    assert default_seq_config("matsumoto").timesteps == 20_000_000
    assert SeqConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(InputError, match="bogus"):
        SeqConfig.from_dict({**cfg.to_dict(), "bogus": 1})
    with pytest.raises(finsler.UnknownMetricError):
        default_seq_config("no-such-env")
    assert default_seq_config("matsumoto", n_envs=1).n_steps == 2048  # the paper's SB3 setup
