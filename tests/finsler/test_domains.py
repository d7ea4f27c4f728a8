"""Domains: uniform sampling (statistical tests), projection, constraints; bad input."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch
from scipy import stats

import finsler
from finsler import Box, Disk, DomainError, InputError, Product


def test_disk_sampling_is_uniform() -> None:
    """Under the uniform law on a disk of radius R, (r/R)^2 and the angle are U(0, 1)."""
    d = Disk(radius=2.0, center=(0.5, -1.0))
    x = d.sample(20000, np.random.default_rng(0))
    rel = x - np.array([0.5, -1.0])
    r2 = np.sum(rel**2, axis=1) / 4.0
    ang = (np.arctan2(rel[:, 1], rel[:, 0]) + np.pi) / (2 * np.pi)
    assert stats.kstest(r2, "uniform").pvalue > 0.01
    assert stats.kstest(ang, "uniform").pvalue > 0.01
    # and a non-uniform law (radius uniform) is rejected by the same test
    bad = np.random.default_rng(0).uniform(size=20000) ** 2
    assert stats.kstest(bad, "uniform").pvalue < 1e-6
    assert np.all(d.contains(x))


def test_box_and_product_sampling_is_uniform() -> None:
    m = finsler.get_metric("carlike")
    x = m.domain.sample(20000, np.random.default_rng(1))
    theta = (x[:, 2] + np.pi) / (2 * np.pi)
    assert stats.kstest(theta, "uniform").pvalue > 0.01
    assert stats.kstest(np.sum(x[:, :2] ** 2, axis=1), "uniform").pvalue > 0.01
    # the two factors are independent
    assert abs(stats.spearmanr(theta, x[:, 0]).statistic) < 0.03
    p = finsler.get_metric("panda-pole")
    q = p.domain.sample(20000, np.random.default_rng(2))
    lo, hi = p.domain.bounds()
    for j in range(7):
        assert stats.kstest((q[:, j] - lo[j]) / (hi[j] - lo[j]), "uniform").pvalue > 0.001


def test_sampling_is_deterministic_for_a_seed() -> None:
    m = finsler.get_metric("matsumoto")
    a = m.domain.sample(10, np.random.default_rng(5))
    b = m.domain.sample(10, np.random.default_rng(5))
    assert np.array_equal(a, b)


def test_sample_pairs_draws_from_a_generator_in_place() -> None:
    """A training run's fresh pairs: ``sample_pairs`` with a Generator draws the same
    points, and advances the stream by as much, as the domain's own sampler on a twin
    generator; with an integer seed it starts a fresh stream each time."""
    m = finsler.get_metric("panda-pole")
    a, b = np.random.default_rng(11), np.random.default_rng(11)
    for k in (1, 5, 64):
        got = finsler.sample_pairs(m, k, a)
        want = m.domain.sample(2 * k, b).reshape(k, 2, m.dim)
        np.testing.assert_array_equal(got, want)
    assert a.random() == b.random()
    np.testing.assert_array_equal(finsler.sample_pairs(m, 3, 7), finsler.sample_pairs(m, 3, 7))
    with pytest.raises(InputError, match="positive integer"):
        finsler.sample_pairs(m, 0, a)


@pytest.mark.parametrize("name", ["matsumoto", "carlike", "panda-pole", "euclidean", "poincare"])
def test_projection_idempotent_inside_and_nearest(name: str) -> None:
    m = finsler.get_metric(name)
    rng = np.random.default_rng(3)
    lo, hi = m.domain.bounds()
    span = hi - lo
    x = rng.uniform(lo - span, hi + span, size=(500, m.dim))
    p = m.domain.project(x)
    assert np.all(m.domain.contains(p, tol=1e-12))
    assert np.allclose(m.domain.project(p), p, atol=1e-15)
    inside = m.domain.contains(x)
    assert np.array_equal(p[inside], x[inside])
    # nearest point: no sampled domain point is closer than the projection
    cand = m.domain.sample(4000, rng)
    dist_p = np.linalg.norm(p - x, axis=1)
    dist_c = np.linalg.norm(cand[None] - x[:50, None], axis=2).min(axis=1)
    assert np.all(dist_p[:50] <= dist_c + 1e-12)
    # torch path: same values, differentiable
    xt = torch.tensor(x, requires_grad=True)
    pt = m.domain.project(xt)
    assert np.allclose(pt.detach().numpy(), p, atol=1e-14)
    pt.sum().backward()
    assert torch.isfinite(xt.grad).all()


def test_disk_projection_gradient_is_tangential() -> None:
    d = Disk(radius=1.0)
    x = torch.tensor([[2.0, 0.0]], dtype=torch.float64, requires_grad=True)
    d.project(x)[0, 1].backward()  # d(project_y)/dx at (2, 0) = (0, R/|x|)
    assert np.allclose(x.grad.numpy(), [[0.0, 0.5]])


def test_constraints_for_ipopt() -> None:
    m = finsler.get_metric("carlike")
    x = ca.SX.sym("x", 3)
    cons = m.domain.constraints_sx(x)
    assert len(cons) == 1
    g = ca.Function("g", [x], [cons[0][0]])
    assert float(g([0.3, 0.4, 1.0])) == pytest.approx(0.25)
    assert cons[0][2] == pytest.approx(1.0)
    lo, hi = m.domain.bounds()
    assert np.allclose(lo, [-1, -1, -np.pi]) and np.allclose(hi, [1, 1, np.pi])
    assert finsler.get_metric("panda-pole").domain.constraints_sx(ca.SX.sym("q", 7)) == []


def test_domain_check_errors() -> None:
    m = finsler.get_metric("matsumoto")
    with pytest.raises(DomainError, match="outside the domain"):
        m.domain.check(np.array([[0.9, 0.9]]))
    with pytest.raises(InputError, match="shape"):
        m.domain.check(np.zeros((3, 3)))
    with pytest.raises(InputError, match="NaN or inf"):
        m.domain.check(np.array([[np.nan, 0.0]]))


def test_bad_domain_construction() -> None:
    with pytest.raises(InputError):
        Disk(radius=-1.0)
    with pytest.raises(InputError):
        Box((0.0, 1.0), (1.0, 0.0))
    with pytest.raises(InputError):
        Product(())
    with pytest.raises(InputError):
        Disk().sample(-3, np.random.default_rng(0))


def test_an_unbounded_box_refuses_to_be_sampled_by_name() -> None:
    """Uniform points of an unbounded box do not exist: a clear error naming the box, not
    numpy's OverflowError (found through `geodesics check` on such a metric); a bounded box
    still draws inside its bounds."""
    box = finsler.Box((-1.0, -np.inf), (1.0, np.inf))
    with pytest.raises(finsler.InputError, match=r"unbounded box \[-1, 1\] x \[-inf, inf\]"):
        box.sample(3, np.random.default_rng(0))
    pts = finsler.Box((-1.0, 2.0), (1.0, 3.0)).sample(50, np.random.default_rng(0))
    assert pts.shape == (50, 2) and np.all((pts[:, 0] >= -1) & (pts[:, 0] <= 1))
    assert np.all((pts[:, 1] >= 2) & (pts[:, 1] <= 3))


def test_pair_i_of_a_seed_depends_on_k_where_the_domain_draws_in_blocks() -> None:
    """What ``sample_pairs``' docstring says: a prefix of a larger set is the smaller set on
    a box (Randers), not on a disk (Matsumoto), which draws all radii, then all angles."""
    box = finsler.get_metric("randers")
    disk = finsler.get_metric("matsumoto")
    np.testing.assert_array_equal(finsler.sample_pairs(box, 20, 7)[:9],
                                  finsler.sample_pairs(box, 9, 7))
    assert not np.array_equal(finsler.sample_pairs(disk, 20, 7)[:9],
                              finsler.sample_pairs(disk, 9, 7))
