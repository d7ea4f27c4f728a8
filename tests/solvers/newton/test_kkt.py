"""The KKT residual of the reformulated (slack) problem reported for metrics whose F is not
smooth (solvers.newton.kkt): against IPOPT's own Lagrangian gradient at its solutions,
against finite differences of the energy where F is differentiable, large at perturbed
paths, and the residual the results carry."""

from __future__ import annotations

import numpy as np
import pytest

import finsler
import solvers
from solvers import SeedPlan
from solvers.inputs import domain_scale
from solvers.newton.energy import energy_residual
from solvers.newton.kkt import kkt_residual, optimality_residual, uses_kkt
from solvers.seeding.plans import seed_batch
from solvers.transcription import energy_nlp

N = 16


@pytest.fixture(scope="module")
def carlike() -> finsler.Metric:
    return finsler.get_metric("carlike")


@pytest.fixture(scope="module")
def ipopt_solutions(carlike: finsler.Metric) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """IPOPT's car-like solutions from the seed plan's curves at ``N`` segments: (points,
    IPOPT's own largest Lagrangian-gradient entry relative to the objective, the
    seed)."""
    m = carlike
    pairs = finsler.sample_pairs(m, 2, 777)
    _, curves = seed_batch(m, pairs[:, 0], pairs[:, 1], N,
                           SeedPlan(bulges=(0.15, 0.3, 0.45, 0.6, 0.8), random=4))
    seeds = curves.reshape(-1, N + 1, m.dim)[::3]
    nlp = energy_nlp(m, N)
    grad = nlp.solver.get_function("nlp_grad")
    out = []
    for seed in seeds:
        s, g = seed[0], seed[-1]
        z0 = nlp.points_to_z(seed)
        p = np.concatenate([s, g])
        pp = np.concatenate([p, [1.0 / float(nlp._energy(z0, p))]])
        r = nlp.solver(x0=np.clip(z0, nlp.lbx, nlp.ubx), p=pp, lbx=nlp.lbx, ubx=nlp.ubx,
                       lbg=nlp.lbg, ubg=nlp.ubg)
        if not nlp.solver.stats()["success"]:
            continue
        x = np.asarray(r["x"]).ravel()
        # IPOPT's KKT: grad f + J^T lam_g + lam_x = 0 (objective normalised to ~1)
        lag = np.asarray(grad(x, pp, 1.0, r["lam_g"])[2]).ravel() + np.asarray(
            r["lam_x"]).ravel()
        out.append((nlp.z_to_points(x, s, g), float(np.max(np.abs(lag)) / float(r["f"])),
                    seed))
    assert len(out) >= 6
    return out


def test_kkt_small_where_ipopt_is_optimal(carlike, ipopt_solutions) -> None:
    """At IPOPT's solutions (its own Lagrangian gradient ~0, an independent computation
    with IPOPT's multipliers) the KKT residual is small, while the energy's gradient is
    not an optimality measure: on some of them (kinks, reversing without turning) it is
    of order 1."""
    m = carlike
    # the solutions where IPOPT's own Lagrangian gradient is tight (most: ~1e-13)
    tight = [p for p, k, _ in ipopt_solutions if k <= 1e-9]
    assert len(tight) >= 6
    pts = np.stack(tight)
    ours = kkt_residual(m, pts, domain_scale(m))
    assert np.all(ours <= 1e-4), ours
    assert np.median(ours) <= 1e-6
    grad = energy_residual(m, pts, domain_scale(m))
    assert np.max(grad) >= 1e-2  # the old measure flags optima: it is no measure there


def test_kkt_large_at_perturbed_paths(carlike, ipopt_solutions) -> None:
    m = carlike
    rng = np.random.default_rng(5)
    pts = np.stack([p for p, _, _ in ipopt_solutions])
    moved = pts.copy()
    moved[:, 1:-1] += 1e-3 * rng.standard_normal(moved[:, 1:-1].shape)
    moved = np.asarray(m.domain.project(moved.reshape(-1, m.dim))).reshape(pts.shape)
    assert np.all(kkt_residual(m, moved, domain_scale(m)) >= 1e-2)
    # the seeds (not optimal) too
    seeds = np.stack([s for _, _, s in ipopt_solutions])
    assert np.all(kkt_residual(m, seeds, domain_scale(m)) >= 1e-2)


def _energy(m: finsler.Metric, p: np.ndarray) -> float:
    return float(np.sum(m.path_costs(p[None], check=False)[0] ** 2))


def test_kkt_equals_finite_differences_where_differentiable(carlike) -> None:
    """A path inside the domain with no segment at a kink (v_th away from 0) and no
    active domain constraint: the Lagrangian's gradient is the energy's gradient, so the
    residual equals the finite-difference gradient's largest entry times the domain size
    over the energy; some segments have a positive excess (active slack constraints)."""
    m = carlike
    t = np.linspace(0.0, 1.0, N + 1)[:, None]
    for seed in range(100):  # a path whose every segment is clearly off the kinks
        rng = np.random.default_rng(seed)
        p = np.array([-0.4, -0.2, 0.3]) + t * np.array([0.7, 0.5, 1.2])
        p[1:-1] += 0.02 * rng.standard_normal((N - 1, 3))
        v = np.diff(p, axis=0)
        u = v[:, 0] * np.cos(p[:-1, 2]) + v[:, 1] * np.sin(p[:-1, 2])
        excess = m.r_min * np.abs(v[:, 2]) - u
        if (np.all(np.abs(v[:, 2]) > 1e-3) and np.all(np.abs(excess) > 1e-3)
                and np.any(excess > 0) and np.any(excess < 0)):
            break
    else:
        raise AssertionError("no test path found")
    h = 1e-6
    g = np.zeros((N - 1, 3))
    for j in range(1, N):
        for i in range(3):
            a, b = p.copy(), p.copy()
            a[j, i] += h
            b[j, i] -= h
            g[j - 1, i] = (_energy(m, a) - _energy(m, b)) / (2 * h)
    want = np.max(np.abs(g)) * domain_scale(m) / _energy(m, p)
    got = kkt_residual(m, p[None], domain_scale(m))[0]
    assert got == pytest.approx(want, rel=1e-6)


def test_dispatch_by_hook(carlike) -> None:
    """Metrics choose their residual by what they provide: car-like (not smooth, with
    ``smooth_square_sx``) the KKT residual, a smooth metric the energy's gradient."""
    assert uses_kkt(carlike)
    m = finsler.get_metric("matsumoto")
    assert not uses_kkt(m)
    pts = np.stack([np.linspace([-0.5, 0.1], [0.6, -0.2], N + 1)])
    pts[:, 1:-1, 1] += 0.05
    assert optimality_residual(m, pts, 1.6)[0] == energy_residual(m, pts, 1.6)[0]


def test_results_carry_the_kkt_residual(carlike) -> None:
    m = carlike
    s, g = finsler.sample_pairs(m, 1, 4242)[0]
    r = solvers.solve_geodesic(m, s, g, segments=N)
    assert r.status.converged
    assert r.residual == pytest.approx(kkt_residual(m, r.points[None], domain_scale(m))[0])
    assert r.residual <= 1e-4
