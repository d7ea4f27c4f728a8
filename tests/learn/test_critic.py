"""A run's critic, loaded back (learn.load_critic), and how far a critic is off the cost
of a policy's own sub-paths by level (learn.critic_level_errors)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import finsler
import learn
from learn.storage import BEST_FILE, LATEST_FILE, load_checkpoint


def _cost(metric: finsler.Metric):
    return lambda a, b: torch.tensor(metric.cost(a.numpy(), b.numpy()))


def test_level_errors_of_the_true_cost_against_hand_sums() -> None:
    """With C itself as the 'critic', the deepest level (single segments) is exact and each
    upper sub-pair's error is C(ends) / (sum of C over its segments) - 1, summed by hand."""
    m = finsler.get_metric("matsumoto")
    rng = np.random.default_rng(3)
    pts = m.domain.sample(6 * 9, rng).reshape(6, 9, 2)  # a zig-zag: far from geodesic
    errs = learn.critic_level_errors(m, pts, _cost(m))
    assert [e.shape for e in errs] == [(6,), (12,), (24,), (48,)]
    np.testing.assert_allclose(errs[3], 0.0, atol=1e-12)
    seg = m.path_costs(pts)
    for k in (0, 4):
        direct = m.cost(pts[k, 0], pts[k, 8]) / seg[k].sum() - 1
        assert errs[0][k] == pytest.approx(direct, rel=1e-12)
        halves = [m.cost(pts[k, 4 * i], pts[k, 4 * i + 4]) / seg[k, 4 * i:4 * i + 4].sum() - 1
                  for i in (0, 1)]
        np.testing.assert_allclose(errs[1][2 * k:2 * k + 2], halves, rtol=1e-12)
    assert np.all(errs[0] < 0)  # a straight chord is shorter than a zig-zag (convex metric)


@pytest.mark.parametrize("shape", [(4, 6, 2), (4, 2), (4, 1, 2)])
def test_level_errors_reject_paths_that_are_not_trees(shape) -> None:
    m = finsler.get_metric("matsumoto")
    with pytest.raises(finsler.InputError, match="2\\*\\*D"):
        learn.critic_level_errors(m, np.zeros(shape), _cost(m))


def test_level_errors_reject_zero_segments() -> None:
    m = finsler.get_metric("matsumoto")
    pts = np.zeros((1, 3, 2))
    with pytest.raises(finsler.InputError, match="zero cost"):
        learn.critic_level_errors(m, pts, _cost(m))


def test_load_critic_returns_the_trained_critic(tmp_path) -> None:
    """The loaded critic holds the checkpoint's weights (best and latest), estimates
    Euclidean distances (closed form) far better than an untrained one, and its level
    errors on the run's own paths are small; exported and shipped policies keep no critic."""
    cfg = learn.default_config("euclidean", timesteps=60_000, collection_size=1024,
                               minibatch_size=256, epochs=2, eval_every=5, depth=3)
    run = tmp_path / "run"
    learn.train_run(cfg, run, progress=False)
    for ck, name in (("best", BEST_FILE), ("latest", LATEST_FILE)):
        critic = learn.load_critic(run, checkpoint=ck)
        saved = load_checkpoint(run / name)["critic"]
        assert not critic.training
        for k, v in critic.state_dict().items():
            assert torch.equal(v, saved[k])
    m = finsler.get_metric("euclidean")
    pairs = finsler.sample_pairs(m, 400, seed=9)
    s, g = (torch.as_tensor(pairs[:, i], dtype=torch.float32) for i in (0, 1))
    exact = np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=1)
    with torch.no_grad():
        trained = critic(s, g).numpy()
        fresh = learn.midpoint.policy.build_critic(cfg)(s, g).numpy()
    err_trained = np.mean(np.abs(trained / exact - 1))
    err_fresh = np.mean(np.abs(fresh / exact - 1))
    assert err_trained < 0.1 and err_trained < 0.2 * err_fresh, (err_trained, err_fresh)

    pol = learn.load_policy(run, checkpoint="latest")
    paths = pol.generate(pairs[:, 0], pairs[:, 1])
    errs = learn.critic_level_errors(m, paths, critic.double())
    assert len(errs) == 4 and all(np.mean(np.abs(e)) < 0.1 for e in errs)

    learn.export_policy(run, tmp_path / "exported")
    with pytest.raises(finsler.InputError, match="no critic"):
        learn.load_critic(tmp_path / "exported")
    with pytest.raises(finsler.InputError, match="does not exist"):
        learn.load_critic("matsumoto")
