"""The batched Newton solver of the discrete energy (solvers.newton.energy, solvers.newton.driver):
block-tridiagonal solves against dense linear algebra, the energy's derivatives against
CasADi's Hessian of the whole energy, closed-form geodesics, the torch device path, the
IPOPT fallback at an active domain constraint, statuses and bad input."""

from __future__ import annotations

from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
import torch

import finsler
import solvers
from finsler import InputError
from solvers.inputs import domain_scale
from solvers.newton.backends import _NUMPY_OPS, backend_for
from solvers.newton.block_tridiagonal import block_tridiagonal_solve
from solvers.newton.driver import _Runner, residuals
from solvers.newton.energy import (
    NewtonOptions,
    _to_field,
    energy_residual,
    energy_terms,
    newton_energy,
)
from solvers.status import NewtonStatus

from tests.helpers.linalg import dense
from tests.helpers.metrics.newton import Bump, Cheaper, Kink, Tilt, WallAbove

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


def _fields(ops, a, o, r, convert):
    d = a.shape[-1]
    diag = [[convert(np.ascontiguousarray(a[..., i, k])) for k in range(d)] for i in range(d)]
    off = [[convert(np.ascontiguousarray(o[..., i, k])) for k in range(d)] for i in range(d)]
    return diag, off, [convert(np.ascontiguousarray(r[..., i])) for i in range(d)]


@pytest.mark.parametrize("shape", [(3, 13, 2), (2, 1, 3), (4, 16, 7), (2, 63, 2), (1, 2, 1),
                                   (5, 9, 3), (2, 100, 2), (2, 255, 7)])
@pytest.mark.parametrize("method", ["thomas", "cyclic"])
@pytest.mark.parametrize("device", [None, "cpu"])
def test_block_tridiagonal_solve_matches_dense(shape, method, device) -> None:
    """Both elimination orders, numpy and torch, any number of blocks (padding to 2**L-1
    in cyclic reduction), block sizes 1-7: the solution of numpy's dense solve to 1e-12,
    and positive definiteness told exactly (an indefinite system is reported)."""
    b, m, d = shape
    rng = np.random.default_rng(sum(shape))
    a = rng.normal(size=(b, m, d, d))
    a = a @ np.swapaxes(a, -1, -2) + 4.0 * np.eye(d)
    o = rng.normal(size=(b, m, d, d)) * 0.6
    a[0, m // 2] -= 30.0 * np.eye(d)  # the first system indefinite
    r = rng.normal(size=(b, m, d))
    ops = backend_for(device)
    convert = (lambda x: x) if device is None else (lambda x: torch.tensor(x))
    x, ok = block_tridiagonal_solve(ops, *_fields(ops, a, o, r, convert), method=method)
    x = np.stack([ops.to_numpy(xi) for xi in x], -1)
    ok = ops.to_numpy(ok)
    for k in range(b):
        h = dense(a[k], o[k])
        assert bool(ok[k]) == bool(np.all(np.linalg.eigvalsh(h) > 0))
        if ok[k]:
            ref = np.linalg.solve(h, r[k].reshape(-1))
            np.testing.assert_allclose(x[k].reshape(-1), ref, rtol=0, atol=1e-12 * np.max(
                np.abs(ref)))


@pytest.mark.parametrize("d", [2, 7])
def test_local_modification_solves_a_definite_neighbour(d) -> None:
    """With ``local`` every system factorises, and the solution solves (H + E) x = r with E
    block diagonal, zero on the blocks that were definite: checked by recovering E (2 x 2
    blocks: their own elimination; 7 x 7: the dense one). A definite system solved in the
    same batch is solved exactly (nothing of it is modified)."""
    rng = np.random.default_rng(3)
    b, m = 2, 9
    a = rng.normal(size=(b, m, d, d))
    a = a @ np.swapaxes(a, -1, -2) + 3.0 * np.eye(d)
    a[0, 4] = np.eye(d) + 0.5 * (np.eye(d, k=1) + np.eye(d, k=-1))
    a[0, 4, 0, 0] = -2.0  # one indefinite block in the first system
    assert np.linalg.eigvalsh(a[0, 4]).min() < 0
    o = rng.normal(size=(b, m, d, d)) * 0.3
    assert np.linalg.eigvalsh(dense(a[1], o[1])).min() > 0
    r = rng.normal(size=(b, m, d))
    x, ok = block_tridiagonal_solve(_NUMPY_OPS, *_fields(_NUMPY_OPS, a, o, r, lambda v: v),
                                    method="thomas", local=True)
    assert ok.all()
    x = np.stack(x, -1)
    resid = (r[0].reshape(-1) - dense(a[0], o[0]) @ x[0].reshape(-1)).reshape(m, d)
    # H x + E x = r: the residual is E x, non-zero only where a block was modified
    nonzero = np.flatnonzero(np.max(np.abs(resid), axis=1) > 1e-10)
    assert nonzero.size >= 1
    assert set(nonzero) <= {3, 4, 5}  # the modified pivot's block (Schur complements near it)
    ref = np.linalg.solve(dense(a[1], o[1]), r[1].reshape(-1))
    np.testing.assert_allclose(x[1].reshape(-1), ref, rtol=0, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("name", ["matsumoto", "randers", "poincare", "panda-pole"])
def test_energy_terms_equal_casadi_hessian_of_the_whole_energy(name) -> None:
    """Gradient and block-tridiagonal Hessian assembled from the segment function equal
    CasADi's gradient and Hessian of the whole discrete energy (one symbolic expression of
    all interior points) to 1e-10 relative."""
    m = finsler.get_metric(name)
    n, d = 5, m.dim
    pair = finsler.sample_pairs(m, 1, seed=11)[0]
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, n + 1)[:, None]
    pts = pair[0] + t * (pair[1] - pair[0])
    pts[1:-1] += 0.02 * rng.normal(size=(n - 1, d))
    pts = np.asarray(m.domain.project(pts))
    X = ca.SX.sym("X", d, n - 1)
    P = [ca.SX(ca.DM(pts[0]))] + [X[:, i] for i in range(n - 1)] + [ca.SX(ca.DM(pts[-1]))]
    e = sum(m.F_sx(P[i], P[i + 1] - P[i]) ** 2 for i in range(n))
    h, g = ca.hessian(e, ca.vec(X))
    fn = ca.Function("e", [X], [e, g, h])
    e_ref, g_ref, h_ref = (np.asarray(v) for v in fn(pts[1:-1].T))
    terms = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, pts[None]))
    assert terms.energy[0] == pytest.approx(float(e_ref.reshape(-1)[0]), rel=1e-12)
    grad = np.stack(terms.grad, -1)[0].reshape(-1)
    np.testing.assert_allclose(grad, g_ref.reshape(-1), rtol=0,
                               atol=1e-10 * np.max(np.abs(g_ref)))
    a = np.stack([np.stack(row, -1) for row in terms.diag], -2)[0]
    o = np.stack([np.stack(row, -1) for row in terms.off], -2)[0]
    np.testing.assert_allclose(dense(a, o), h_ref, rtol=0, atol=1e-10 * np.max(np.abs(h_ref)))


def test_euclidean_newton_reaches_the_straight_line_in_one_step() -> None:
    """Euclidean energy is quadratic: from any bulged path one Newton step gives the
    equally spaced straight line (energy |g - s|**2 / n exactly), residual 0."""
    m = finsler.get_metric("euclidean")
    s, g = np.array([-0.7, 0.2]), np.array([0.5, -0.4])
    n = 32
    t = np.linspace(0, 1, n + 1)[:, None]
    paths = np.stack([s + t * (g - s) + a * np.sin(np.pi * t) * np.array([0.3, 0.4])
                      for a in (0.0, 0.5, -1.0)])
    paths = np.asarray(m.domain.project(paths.reshape(-1, 2))).reshape(paths.shape)
    res = newton_energy(m, paths, scale=2.0)
    assert np.all(res.status == NewtonStatus.CONVERGED) and np.all(res.iterations <= 2)
    np.testing.assert_allclose(res.points, np.broadcast_to(s + t * (g - s), res.points.shape),
                               atol=1e-14)
    np.testing.assert_allclose(res.energy, np.sum((g - s) ** 2) / n, rtol=1e-14)


@pytest.mark.parametrize("name", ["poincare", "randers", "sphere", "minkowski"])
def test_closed_form_distances_and_ipopt_agree(name) -> None:
    """Closed-form metrics: the Newton path (the default) converges (residual <= 1e-10),
    its energy equals IPOPT's to 1e-10, and its length to the exact distance (Randers,
    Minkowski: straight lines, exact at any n; Poincare, sphere: to the O(n^-2) of the
    discretisation: the polyline's eq. (58) length)."""
    m = finsler.get_metric(name)
    pairs = finsler.sample_pairs(m, 4, seed=7)
    res = solvers.solve_batch(m, pairs, 64, workers=1, progress=False)
    exact = m.distance(pairs[:, 0], pairs[:, 1])
    for (s, g), r, d in zip(pairs, res, exact):
        assert r.method == "newton" and r.status is solvers.Status.SUCCESS
        assert r.residual <= 1e-10
        ref = solvers.solve_geodesic(m, s, g, 64, method="ipopt")
        assert r.energy == pytest.approx(ref.energy, rel=1e-10)
        if name in ("randers", "minkowski"):  # x-independent F: C is exact on segments
            assert abs(r.length - d) <= 1e-12 * d
        else:  # the polyline's length bounds d from above, within O(n^-2)
            assert d <= r.length_quadrature + r.length_quadrature_error
            assert r.length_quadrature <= d * (1 + 1e-3)


def test_torch_device_path_equals_numpy() -> None:
    """The same batch on torch tensors (here on the CPU, as it would run on CUDA): the
    same statuses and paths as numpy to 1e-10."""
    m = finsler.get_metric("matsumoto")
    pairs = finsler.sample_pairs(m, 3, seed=2)
    a = solvers.solve_batch(m, pairs, 32, workers=1, progress=False)
    b = solvers.solve_batch(m, pairs, 32, workers=1, progress=False, device="cpu")
    for x, y in zip(a, b):
        assert x.status is y.status and x.method == y.method == "newton"
        np.testing.assert_allclose(x.points, y.points, atol=1e-10)
    with pytest.raises(InputError, match="device"):
        solvers.solve_batch(m, pairs, 32, workers=1, progress=False, device="nonsense")


def test_active_box_bound_projected_newton() -> None:
    """A geodesic pressed against a box's edge (as a Panda path against a joint limit):
    projected Newton holds the coordinates at the bound that the gradient pushes out and
    converges by itself, to IPOPT's energy, with points on the edge and a residual (the
    projected gradient) below 1e-10 where the plain gradient is O(1)."""
    m = Cheaper()
    s, g = np.array([0.9, -0.8]), np.array([0.9, 0.8])
    ref = solvers.solve_geodesic(m, s, g, 16, method="ipopt")
    assert np.max(ref.points[:, 0]) > 1 - 1e-6  # the constraint is active
    r = solvers.solve_geodesic(m, s, g, 16)
    assert r.converged and r.method == "newton" and r.residual <= 1e-10
    assert r.energy == pytest.approx(ref.energy, rel=1e-8)
    assert np.sum(r.points[:, 0] == 1.0) >= 3
    terms = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, r.points[None]), hessian=False)
    assert np.max(np.abs(np.stack(terms.grad, -1))) * 2.0 / r.energy > 1e-3
    assert energy_residual(m, r.points[None], 2.0)[0] <= 1e-8


def test_active_disk_constraint_is_finished_by_ipopt() -> None:
    """The same pressed against the unit disk's rim: the Newton steps keep leaving the
    disk (status BOUNDARY), IPOPT finishes the pair: a converged result named ``ipopt``
    with points on the rim, IPOPT's energy, and a small projected residual."""
    m = Cheaper(disk=True)
    s, g = np.array([0.8, -0.55]), np.array([0.8, 0.55])
    ref = solvers.solve_geodesic(m, s, g, 16, method="ipopt")
    assert np.max(np.linalg.norm(ref.points, axis=1)) > 1 - 1e-6  # the rim is active
    t = np.linspace(0, 1, 17)[:, None]
    alone = newton_energy(m, (s + t * (g - s))[None], scale=2.0)
    assert alone.status[0] == NewtonStatus.BOUNDARY
    r = solvers.solve_geodesic(m, s, g, 16)
    assert r.converged and r.method == "ipopt"
    assert r.energy == pytest.approx(ref.energy, rel=1e-8)
    assert r.residual <= 1e-6
    assert energy_residual(m, r.points[None], 2.0)[0] == pytest.approx(r.residual)


def test_statuses_and_bad_input() -> None:
    m = finsler.get_metric("poincare")
    s, g = np.array([-0.3, 0.1]), np.array([0.4, 0.2])
    t = np.linspace(0, 1, 9)[:, None]
    good = s + t * (g - s)
    bad = good.copy()
    bad[3] = np.nan
    res = newton_energy(m, np.stack([good, bad]), scale=2.0)
    assert res.status[0] == NewtonStatus.CONVERGED
    assert res.status[1] == NewtonStatus.NOT_FINITE
    capped = newton_energy(m, (good + 0.3 * np.sin(np.pi * t) * [0, 1])[None],
                           NewtonOptions(max_iter=1), scale=2.0)
    assert capped.status[0] == NewtonStatus.MAX_ITERATIONS and capped.residual[0] > 1e-10
    with pytest.raises(InputError, match="shape"):
        newton_energy(m, good, scale=2.0)
    with pytest.raises(InputError, match="gtol"):
        NewtonOptions(gtol=0.0)
    with pytest.raises(InputError, match="method"):
        solvers.solve_geodesic(m, s, g, 8, method="bogus")
    # a metric declared not smooth without the smooth_square_sx hook (the car-like metric
    # with the hook withdrawn): no batched method for it (car-like itself opts in through
    # the interior point, tests/solvers/newton/test_interior.py)
    from finsler.hooks import MetricHooks

    class NoHook(finsler.CarLike):
        smooth_square_sx = MetricHooks.smooth_square_sx

    with pytest.raises(InputError, match="smooth"):
        solvers.solve_geodesic(NoHook(), [0.1, 0.1, 0.0], [0.3, 0.2, 0.1], 8, method="newton")


def test_residual_is_small_only_at_a_minimiser() -> None:
    """The reported residual (projected gradient of the energy, relative) is ~1e-12 at a
    converged path and O(1) after moving one point."""
    m = finsler.get_metric("sphere")
    r = solvers.solve_geodesic(m, [-0.5, 0.1], [0.4, 0.3], 16)
    assert r.residual <= 1e-10
    moved = r.points.copy()
    moved[5] += 0.01
    assert energy_residual(m, moved[None], 1.6)[0] > 1e-2


@pytest.mark.parametrize("name, n", [("matsumoto", 32), ("panda-pole", 8)])
def test_batch_results_do_not_depend_on_the_other_pairs(name: str, n: int) -> None:
    """A pair solved alone, or in a batch with others, gives the same path to the last bit
    (every problem has its own steps and tests; drops compare seeds of one pair only; a
    pivot block is inverted by the same arithmetic whatever the other blocks are: with
    LAPACK taken only where the whole stack was definite, Panda's paths differed by up to
    5e-10 between a pair alone and in a batch of four)."""
    m = finsler.get_metric(name)
    pairs = finsler.sample_pairs(m, 4, seed=9)
    batch = solvers.solve_batch(m, pairs, n, workers=1, progress=False, method="newton")
    for (s, g), r in zip(pairs, batch):
        alone = solvers.solve_geodesic(m, s, g, n, method="newton")
        np.testing.assert_array_equal(alone.points, r.points)
        assert alone.best_seed == r.best_seed


# ----------------------------------------------------------------------------------------
# issue 48: tests that can fail on a line search, a seed plan or a residual gone wrong
# ----------------------------------------------------------------------------------------
def _bent_paths(m: finsler.Metric, pairs: np.ndarray, n: int, bump: float) -> np.ndarray:
    """Paths between ``pairs`` bent sideways by a sine (far from the optimum), in the
    domain."""
    t = np.linspace(0.0, 1.0, n + 1)
    d = pairs[:, 1] - pairs[:, 0]
    perp = np.stack([-d[:, 1], d[:, 0]], 1)
    p = (pairs[:, 0, None] + t[None, :, None] * d[:, None]
         + bump * np.sin(3 * np.pi * t)[None, :, None] * perp[:, None])
    p = np.asarray(m.domain.project(p.reshape(-1, 2)), float).reshape(p.shape)
    p[:, 0], p[:, -1] = pairs[:, 0], pairs[:, 1]
    return p


def _worst_armijo_excess(m: finsler.Metric, armijo: float, c: float) -> float:
    """Step a :class:`NewtonState` (line search on ``armijo``) from bent paths and return
    the largest ``(E_new - E_old - c grad E_old . (p_new - p_old)) / E_old`` over every
    iteration and problem, with ``E`` and its gradient from :func:`energy_terms` at the
    paths before and after each step (the sufficient-decrease condition, along the
    projection arc on box domains as Bertsekas's projected Newton states it)."""
    from solvers.newton.energy import NewtonState

    pairs = finsler.sample_pairs(m, 8, seed=5)
    opt = NewtonOptions(armijo=0.25)
    object.__setattr__(opt, "armijo", armijo)  # frozen; the negative controls go below 0
    lo, hi = m.domain.bounds()
    state = NewtonState(m, _bent_paths(m, pairs, 16, 0.3), opt, _NUMPY_OPS,
                        float(np.max(hi - lo)))
    worst, steps = -np.inf, 0
    while state.running and steps < 60:
        ids = state.active.copy()
        before = state.paths(ids)
        state.step()
        after = state.paths(ids)
        steps += 1
        tb = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, before), hessian=False)
        ta = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, after), hessian=False)
        slope = np.sum(np.stack(tb.grad, -1) * (after - before)[:, 1:-1], axis=(1, 2))
        worst = max(worst, float(np.max((ta.energy - tb.energy - c * slope) / tb.energy)))
    return worst


@pytest.mark.parametrize("name", ["matsumoto", "sphere"])
def test_every_newton_step_decreases_the_energy_sufficiently(name: str) -> None:
    """Every accepted step meets the Armijo condition with the configured constant (0.25
    here, stricter than the default 1e-4); the same check on a line search that accepts
    any finite step (the constant forced to -1e300) finds a violation, on these metrics
    where full Newton steps from bent paths overshoot: the test can fail."""
    m = finsler.get_metric(name)
    assert _worst_armijo_excess(m, 0.25, 0.25) <= 1e-14  # round-off ties are accepted
    assert _worst_armijo_excess(m, -1e300, 0.25) > 1e-3


def test_the_global_optimum_comes_from_a_seed_other_than_the_first() -> None:
    """Around the bump, not through it. An independent bound: the minimiser of ``E = sum
    C**2`` over 16 segments has length ``L <= sqrt(16 E) <= sqrt(16 E(detour))`` for any
    path (Cauchy-Schwarz), here a sine detour of amplitude 0.6 (its costs from
    ``metric.cost``). The straight seed alone stays on the x-axis, above that bound; the
    default seed plan (a seed plan that kept only its first seed would not) finds a path
    within it, from a seed other than the straight line."""
    m = Bump()
    s, g = np.array([-0.8, 0.0]), np.array([0.8, 0.0])
    t = np.linspace(0.0, 1.0, 17)
    detour = np.stack([-0.8 + 1.6 * t, 0.6 * np.sin(np.pi * t)], 1)
    bound = float(np.sqrt(16 * np.sum(np.asarray(m.cost(detour[:-1], detour[1:])) ** 2)))
    alone = solvers.solve_geodesic(m, s, g, 16, seeds=solvers.SeedPlan(
        bulges=(), graph=False, coarse=None, own=False))
    assert alone.converged and alone.seeds_tried == 1
    assert np.max(np.abs(alone.points[:, 1])) == 0.0 and alone.length > 1.1 * bound
    best = solvers.solve_geodesic(m, s, g, 16)
    assert best.converged and best.seeds_tried > 1
    assert best.length <= bound and best.best_seed not in ("straight", "")
    assert np.max(np.abs(best.points[:, 1])) > 0.2  # it went around


def test_the_ladder_carries_alternatives_to_the_size_where_they_win() -> None:
    """A ladder from 4 segments to 64: at 4 the best optimum goes above (over the wall,
    which the coarse path steps across), at 64 below. The reference is a second method:
    every seed solved at 64 segments, no ladder. Carrying only the coarse winner
    (``refine_top=1``) ends above, measurably longer; carrying the best 3 (both routes)
    ends on the reference's path. (``drop_rtol=1``: the default 5 % would stop the route
    below at the first level, where it is 10 % above.)"""
    m = WallAbove()
    s, g = np.array([-0.8, 0.0]), np.array([0.8, 0.0])
    base = dict(bulges=(0.5,), graph=False, own=False, random=0)
    coarse = solvers.solve_geodesic(m, s, g, 4, seeds=solvers.SeedPlan(**base, coarse=None))
    assert coarse.converged and coarse.points[:, 1].max() > 0.3  # above at 4 segments
    ref = solvers.solve_geodesic(m, s, g, 64, seeds=solvers.SeedPlan(**base, coarse=None))
    assert ref.converged and ref.points[:, 1].min() < -0.3  # below at 64

    def ladder(top: int) -> solvers.GeodesicResult:
        return solvers.solve_geodesic(m, s, g, 64, seeds=solvers.SeedPlan(
            **base, coarse=4, factor=2, refine_top=top, drop_rtol=1.0))

    one, three = ladder(1), ladder(3)
    assert one.converged and three.converged
    assert one.points[:, 1].max() > 0.3 and one.length > 1.05 * ref.length
    assert three.points[:, 1].min() < -0.3
    assert three.length == pytest.approx(ref.length, rel=1e-8)
    np.testing.assert_allclose(three.points, ref.points, atol=1e-5)


def test_residual_equals_finite_differences_of_the_energy() -> None:
    """The gradient of ``E = sum_i F(p_i, p_{i+1} - p_i)**2`` behind ``energy_residual``
    against central differences of E computed from ``metric.F`` alone (step 1e-6), and the
    residual against ``max |grad| * scale / E`` from those differences (points well inside
    the disk, so the projection changes nothing)."""
    m = finsler.get_metric("sphere")
    rng = np.random.default_rng(48)
    pts = rng.uniform(-0.35, 0.35, size=(9, 2))

    def energy(p: np.ndarray) -> float:
        return float(np.sum(np.asarray(m.F(p[:-1], p[1:] - p[:-1])) ** 2))

    h = 1e-6
    fd = np.zeros((7, 2))
    for i in range(1, 8):
        for k in range(2):
            up, down = pts.copy(), pts.copy()
            up[i, k] += h
            down[i, k] -= h
            fd[i - 1, k] = (energy(up) - energy(down)) / (2 * h)
    terms = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, pts[None]), hessian=False)
    grad = np.stack(terms.grad, -1)[0]
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-8 * np.max(np.abs(fd)))
    want = np.max(np.abs(fd)) * 1.6 / energy(pts)
    assert energy_residual(m, pts[None], 1.6)[0] == pytest.approx(want, rel=1e-6)


# ----------------------------------------------------------------------------------------
# solvers.newton and solvers.batched against independent references, fast: the first-order
# residual of Euclidean paths in closed form (the energy sum |x_j - x_{j-1}|**2 has gradient
# 2 (2 x_j - x_{j-1} - x_{j+1})), its projection at the domain's boundary, and the batch
# driver's dropping of losing rows worked out by hand on a made-up state.
# ----------------------------------------------------------------------------------------


def euclid_residual(pts: np.ndarray, scale: float) -> np.ndarray:
    """|grad E|_inf * scale / E of Euclidean paths (B, n+1, d), every point inside."""
    d = np.diff(pts, axis=1)
    e = np.sum(d * d, axis=(1, 2))
    g = 2.0 * (d[:, :-1] - d[:, 1:])
    return np.max(np.abs(g), axis=(1, 2)) * scale / e


def test_residuals_of_euclidean_paths_in_closed_form() -> None:
    m = finsler.get_metric("euclidean")
    assert domain_scale(m) == 2.0  # the box [-1, 1]^2
    rng = np.random.default_rng(4)
    line = np.linspace([-0.5, -0.2], [0.4, 0.3], 7)
    pts = np.stack([line, line + np.r_[0, 1, 1, 1, 1, 1, 0][:, None] * rng.normal(
        scale=0.05, size=(7, 2)), line + np.r_[0, 0, 0, 1, 0, 0, 0][:, None] * 0.1])
    got = residuals(m, pts)
    ref = euclid_residual(pts, 2.0)
    assert got[0] < 1e-12  # the straight line, evenly spaced: a minimiser
    np.testing.assert_allclose(got[1:], ref[1:], rtol=1e-10)
    np.testing.assert_allclose(energy_residual(m, pts, 3.0), euclid_residual(pts, 3.0),
                               rtol=1e-10, atol=1e-12)
    # two points (no interior point): residual 0 by definition
    np.testing.assert_array_equal(residuals(m, pts[:, [0, -1]]), [0.0, 0.0, 0.0])


def test_the_residual_drops_the_part_of_the_gradient_that_leaves_the_domain() -> None:
    """A path bent to the box's side x_0 = 1: the interior point on the side, pulled back
    inwards by the energy (descent towards the chord) keeps its whole gradient; a path
    through a point on the side that the chord lies beyond (descent pushes outwards)
    loses the outward component there."""
    m = finsler.get_metric("euclidean")
    inwards = np.array([[[0.6, -0.5], [1.0, 0.0], [0.6, 0.5]]])
    np.testing.assert_allclose(residuals(m, inwards), euclid_residual(inwards, 2.0),
                               rtol=1e-10)
    # ends outside the box (x_0 = 1.4 would be the straight line): the middle point at the
    # side, gradient 2 (2 x - a - b) = (-1.6, 0) pushes outwards: projected away -> 0
    outwards = np.array([[[0.6, -0.5], [1.0, 0.0], [0.6, 0.5]]])
    outwards[0, 1, 0] = 1.0
    outwards[0, [0, 2], 0] = 1.2  # descent direction +x_0: leaves the domain
    assert residuals(m, outwards)[0] == pytest.approx(0.0, abs=1e-12)
    # the same path with a sideways bend: only the tangential part (along x_1) remains
    side = outwards.copy()
    side[0, 1, 1] = 0.1
    d = np.diff(side, axis=1)
    e = np.sum(d * d)
    tangential = abs(2.0 * (2 * side[0, 1, 1] - side[0, 0, 1] - side[0, 2, 1]))
    assert residuals(m, side)[0] == pytest.approx(tangential * 2.0 / e, rel=1e-10)


def _state(status, energy, active):
    dropped: list[np.ndarray] = []
    st = SimpleNamespace(status=np.array(status), energy=np.array(energy, float),
                         active=np.array(active, dtype=np.int64),
                         drop=lambda rows: dropped.append(np.array(rows)))
    return st, dropped


C, R = NewtonStatus.CONVERGED, NewtonStatus.MAX_ITERATIONS


def test_drop_losers_stops_rows_above_factor_times_their_pairs_best() -> None:
    """Pairs 0, 1, 2: pair 0's best converged energy 1.0 (row 0; row 1 converged at 3.0 is
    not active), pair 1's 2.0 (row 3), pair 2 none converged. Active rows 2 (pair 0, 1.25),
    4 (pair 1, 2.7), 5 (pair 1, 2.5), 6 (pair 2, 100): with factor 1.3, row 4 (2.7 > 2.6)
    is dropped; row 2 (1.25 <= 1.3), row 5 (2.5 <= 2.6) and row 6 (no converged row in its
    pair) run on."""
    pair = np.array([0, 0, 0, 1, 1, 1, 2])
    st, dropped = _state([C, C, R, C, R, R, R], [1.0, 3.0, 1.25, 2.0, 2.7, 2.5, 100.0],
                         [2, 4, 5, 6])
    _Runner._drop_losers(st, pair, 1.3)
    assert len(dropped) == 1
    np.testing.assert_array_equal(dropped[0], [4])
    st, dropped = _state([C, C, R, C, R, R, R], [1.0, 3.0, 1.25, 2.0, 2.7, 2.5, 100.0],
                         [2, 4, 5, 6])
    _Runner._drop_losers(st, pair, 1.2)  # 1.25 > 1.2, 2.5 > 2.4 too
    np.testing.assert_array_equal(dropped[0], [2, 4, 5])
    st, dropped = _state([C, C, R, C, R, R, R], [1.0, 3.0, 1.3, 2.0, 2.6, 2.5, 100.0],
                         [2, 4, 5, 6])
    _Runner._drop_losers(st, pair, 1.3)  # equal to factor * best: kept (strictly above)
    assert dropped == [] or dropped[0].size == 0


def test_drop_losers_does_nothing_without_a_converged_row_or_an_active_one() -> None:
    pair = np.array([0, 0, 1])
    st, dropped = _state([R, R, R], [1.0, 9.0, 5.0], [0, 1, 2])
    _Runner._drop_losers(st, pair, 1.3)
    assert dropped == []
    st, dropped = _state([C, C, R], [1.0, 9.0, 5.0], [])
    _Runner._drop_losers(st, pair, 1.3)
    assert dropped == []
    st, dropped = _state([C, R, R], [1.0, 9.0, 5.0], [1, 2])  # pair 1: none converged
    _Runner._drop_losers(st, pair, 1.3)
    np.testing.assert_array_equal(dropped[0], [1])


def _bent_line_paths() -> np.ndarray:
    line = np.linspace([-0.5, -0.2], [0.4, 0.3], 6)
    bend = np.r_[0, 1, 1, 1, 1, 0][:, None] * np.array([[0.05, -0.08], [0.1, 0.02],
                                                        [-0.07, 0.04]])[:, None]
    return line[None] + bend


def test_drop_stops_only_running_problems() -> None:
    """Problems dropped before any step keep their starting points and report DROPPED;
    the others converge to the straight line; dropping a converged problem (indices as
    a plain list) leaves it converged."""
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import NewtonOptions, NewtonState

    m = finsler.get_metric("euclidean")
    paths = _bent_line_paths()
    st = NewtonState(m, paths, NewtonOptions(), backend_for(None), 2.0)
    st.drop([0, 2])
    assert list(st.active) == [1]
    while st.running:
        st.step()
    st.drop([1])
    res = st.result()
    assert list(res.status) == [NewtonStatus.DROPPED, NewtonStatus.CONVERGED,
                                NewtonStatus.DROPPED]
    np.testing.assert_array_equal(res.points[[0, 2]], paths[[0, 2]])
    np.testing.assert_allclose(res.points[1], np.linspace([-0.5, -0.2], [0.4, 0.3], 6),
                               atol=1e-9)


def test_newton_energy_takes_nested_lists_and_reports_the_residual_at_scale_one() -> None:
    """``paths`` as nested lists solve as the array does; the residual of a problem
    stopped after one iteration is the closed form's at the default scale 1."""
    from solvers.newton.energy import NewtonOptions, newton_energy

    m = finsler.get_metric("euclidean")
    paths = _bent_line_paths()
    a = newton_energy(m, paths)
    b = newton_energy(m, paths.tolist())
    np.testing.assert_array_equal(a.points, b.points)
    assert list(a.status) == [NewtonStatus.CONVERGED] * 3
    one = newton_energy(m, paths + 0.01 * np.sin(np.arange(6))[None, :, None],
                        NewtonOptions(max_iter=1, line_steps=1, armijo=0.9))
    assert all(one.status != NewtonStatus.CONVERGED)
    np.testing.assert_allclose(one.residual, euclid_residual(one.points, 1.0), rtol=1e-8)


def test_newton_energy_passes_scale_on_and_checks_the_number_of_points() -> None:
    """The residual at scale 2 is the closed form's at 2; three points (one interior
    point) are the fewest accepted, two are refused."""
    from finsler.errors import InputError
    from solvers.newton.energy import NewtonOptions, newton_energy

    m = finsler.get_metric("euclidean")
    paths = _bent_line_paths() + 0.01 * np.sin(np.arange(6))[None, :, None]
    one = newton_energy(m, paths, NewtonOptions(max_iter=1, line_steps=1, armijo=0.9),
                        scale=2.0)
    np.testing.assert_allclose(one.residual, euclid_residual(one.points, 2.0), rtol=1e-8)
    three = newton_energy(m, np.array([[[0.0, 0.0], [0.3, 0.2], [0.4, 0.0]]]))
    assert three.status[0] == NewtonStatus.CONVERGED
    np.testing.assert_allclose(three.points[0, 1], [0.2, 0.0], atol=1e-9)
    with pytest.raises(InputError, match="n >= 2"):
        newton_energy(m, paths[:, [0, -1]])


def test_newton_energy_shifts_only_the_blocks_that_need_it_by_default() -> None:
    """``local=True`` is the default: on Matsumoto paths whose Hessian is not definite
    along the way, the default run is the local=True run to the last bit, and the
    whole-Hessian shift (local=False) takes another course on the third path."""
    from solvers.newton.energy import newton_energy

    m = finsler.get_metric("matsumoto")
    line = np.linspace([-0.2, -0.1], [0.2, 0.15], 9)
    rng = np.random.default_rng(0)
    p = line[None] + np.r_[0, [1] * 7, 0][:, None] * rng.normal(scale=0.08, size=(3, 9, 2))
    default = newton_energy(m, p, scale=2.0)
    local = newton_energy(m, p, scale=2.0, local=True)
    whole = newton_energy(m, p, scale=2.0, local=False)
    np.testing.assert_array_equal(default.points, local.points)
    np.testing.assert_array_equal(default.iterations, local.iterations)
    assert np.abs(whole.points[2] - local.points[2]).max() > 1e-3


def _rows(pair, energy, status):
    from solvers.newton.driver import Rows

    n = len(pair)
    return Rows(np.array(pair), [f"r{i}" for i in range(n)], np.arange(n * 6.0).reshape(
        n, 3, 2), np.array(energy, float), np.array(status, dtype=np.int64),
        np.arange(n, dtype=np.int64), np.full(n, 0.5))


def test_rows_take_keeps_the_results_of_solved_rows_only() -> None:
    from solvers.newton.driver import Rows

    rows = _rows([0, 0, 1], [3.0, 1.0, 2.0], [C, C, R])
    t = rows.take([2, 0])
    assert t.names == ["r2", "r0"] and list(t.pair) == [1, 0]
    np.testing.assert_array_equal(t.points, rows.points[[2, 0]])
    np.testing.assert_array_equal(t.energy, [2.0, 3.0])
    np.testing.assert_array_equal(t.status, [R, C])
    np.testing.assert_array_equal(t.iterations, [2, 0])
    np.testing.assert_array_equal(t.residual, [0.5, 0.5])
    unsolved = Rows(rows.pair, rows.names, rows.points).take([1])
    assert unsolved.names == ["r1"] and len(unsolved.energy) == 0


def test_best_of_picks_per_pair_among_the_marked_rows() -> None:
    """Pair 0: rows 0 (3.0, converged), 1 (1.0, converged), 2 (0.5, not converged); pair 1:
    row 3 (2.0, converged). Among all: 1 and 3; among rows 0, 2, 3: 0 (a converged row
    goes before a lower unconverged one) and 3; among rows 2: 2 and none; among none:
    none; among rows 0 and 1 only: 1 and none."""
    from solvers.newton.driver import _best_of

    rows = _rows([0, 0, 0, 1], [3.0, 1.0, 0.5, 2.0], [C, C, R, C])
    mark = np.array
    assert list(_best_of(rows, 2, mark([True] * 4))) == [1, 3]
    assert list(_best_of(rows, 2, mark([True, False, True, True]))) == [0, 3]
    assert list(_best_of(rows, 2, mark([False, False, True, False]))) == [2, -1]
    assert list(_best_of(rows, 3, mark([False] * 4))) == [-1, -1, -1]
    assert list(_best_of(rows, 2, mark([True, True, False, False]))) == [1, -1]


def test_drop_losers_with_one_active_row() -> None:
    pair = np.array([0, 0])
    st, dropped = _state([C, R], [1.0, 2.0], [1])
    _Runner._drop_losers(st, pair, 1.3)
    np.testing.assert_array_equal(dropped[0], [1])


def test_the_opt_in_newton_covers_smooth_metrics_and_nonsmooth_ones_with_the_hook() -> None:
    from solvers.newton.driver import covers, covers_opt_in

    smooth = finsler.get_metric("euclidean")
    assert covers(smooth) and covers_opt_in(smooth)
    car = finsler.get_metric("carlike")  # not smooth, provides smooth_square_sx
    assert not covers(car) and covers_opt_in(car) == bool(car.provides("smooth_square_sx"))


def test_a_point_just_inside_the_side_pushed_outwards_counts_as_on_it() -> None:
    """The projected residual's step moves the point of the largest gradient entry by
    1e-3 * scale: a point 5e-4 inside the side x_0 = 1, pushed outwards, is projected
    onto the side, so only delta / t = 5e-4 / (1e-3 * scale / gmax) of its outward
    component remains (a quarter at scale 2)."""
    m = finsler.get_metric("euclidean")
    delta = 5e-4
    pts = np.array([[[1.2, -0.5], [1.0 - delta, 0.001], [1.2, 0.5]]])
    d = np.diff(pts, axis=1)
    e = float(np.sum(d * d))
    g = 2.0 * (d[0, 0] - d[0, 1])  # the middle point's gradient: outwards in x_0
    gmax = float(np.max(np.abs(g)))
    assert g[0] < 0 and abs(g[0]) == gmax
    want = max(delta * gmax / (1e-3 * 2.0), abs(g[1])) * 2.0 / e
    assert residuals(m, pts)[0] == pytest.approx(want, rel=1e-9)


def test_value_evaluations_add_up_over_every_line_search() -> None:
    """Every energy-only evaluation (line searches) counts its segments: the total is the
    sum over the calls, counted here from their arguments."""
    from solvers.newton.energy import NewtonOptions, NewtonState, newton_energy

    seen: list[int] = []
    original = NewtonState._energies

    def counting(self, p):
        seen.append(int(p[0].shape[0] * (p[0].shape[1] - 1)))
        return original(self, p)

    m = finsler.get_metric("euclidean")
    mp = pytest.MonkeyPatch()
    mp.setattr(NewtonState, "_energies", counting)
    try:  # Armijo 0.9 refuses the full Newton step of a quadratic: line searches follow
        res = newton_energy(m, _bent_line_paths(), NewtonOptions(max_iter=4, armijo=0.9,
                                                            line_steps=3))
    finally:
        mp.undo()
    assert len(seen) >= 2
    assert res.value_evaluations == sum(seen)


def test_carried_keeps_one_row_per_optimum_within_the_band() -> None:
    """keep 2, band 20 %, tol 1e-6. Pair 0: rows 0 (1.0), 1 (1.05, another path), 2 (1.0 +
    1e-12, the same path as row 0 to 1e-9), 3 (1.5, above the band), all converged: rows 0
    and 1 go up (row 2 is row 0's optimum again). Pair 1, nothing converged: its two
    lowest finite rows 5 (1.8) and 4 (2.0), not 6 (inf). Pair 2: one row of infinite
    energy: none."""
    from solvers.newton.driver import Rows, _carried

    base = np.zeros((3, 2))
    pts = np.stack([base, base + 0.3, base + 1e-9, base - 0.3, base, base + 0.1,
                    base + 0.2, base])
    rows = Rows(np.array([0, 0, 0, 0, 1, 1, 1, 2]), [f"r{i}" for i in range(8)], pts,
                np.array([1.0, 1.05, 1.0 + 1e-12, 1.5, 2.0, 1.8, np.inf, np.inf]),
                np.array([C, C, C, C, R, R, R, R], dtype=np.int64),
                np.zeros(8, dtype=np.int64), np.zeros(8))
    assert list(_carried(rows, 3, 2, 0.2, 1e-6)) == [0, 1, 4, 5]
    assert list(_carried(rows, 3, 3, 0.6, 1e-6)) == [0, 1, 3, 4, 5]  # row 3 in the band
    assert list(_carried(rows, 3, 1, 0.2, 1e-6)) == [0, 5]


# ----------------------------------------------------------------------------------------
# the iteration, step by step, against a dense reference written from the docstring
# ----------------------------------------------------------------------------------------
class _DenseNewton:
    """One problem of :class:`NewtonState` redone with dense linear algebra, from the
    class docstring: the Hessian (assembled densely from :func:`energy_terms`, itself
    checked against CasADi's Hessian of the whole energy in test_newton.py) shifted by
    ``delta * mean diagonal`` (whole-Hessian mode: the smallest of ``last / 3`` or 0, then
    ``delta0``, x8, that Cholesky accepts), the full step first after a full step, else
    the longest acceptable of ``2**-k``; Armijo on energies from ``metric.F`` alone; the
    shift raised x8 (at least ``delta0``) without progress, divided by 3 after progress
    (local mode). Domains that are not boxes (trial points outside are refused)."""

    def __init__(self, m, path, opt, local, scale):
        self.m, self.p, self.opt, self.local, self.scale = m, path.copy(), opt, local, scale
        self.delta, self.full, self.hits, self.it = 0.0, True, 0, 0
        self.n = path.shape[0] - 1
        self.evals, self.values = self.n, 0  # segments with derivatives / values only
        self.status = NewtonStatus.RUNNING
        self.g, self.h = self._derivatives(self.p)
        self.e = self.energy(self.p)
        if self.residual() <= opt.gtol:
            self.status = NewtonStatus.CONVERGED

    def energy(self, p):
        return float(np.sum(np.asarray(self.m.F(p[:-1], p[1:] - p[:-1])) ** 2))

    def _derivatives(self, p):
        from solvers.newton.energy import _NUMPY_OPS, _to_field, energy_terms

        t = energy_terms(self.m, _NUMPY_OPS, _to_field(_NUMPY_OPS, p[None]))
        d, k = p.shape[1], p.shape[0] - 2
        h = np.zeros((k * d, k * d))
        for j in range(k):
            for a in range(d):
                for b in range(d):
                    h[j * d + a, j * d + b] = t.diag[a][b][0, j]
                    if j < k - 1:
                        h[j * d + a, (j + 1) * d + b] = t.off[a][b][0, j]
                        h[(j + 1) * d + b, j * d + a] = t.off[a][b][0, j]
        return np.stack(t.grad, -1)[0].reshape(-1), h

    def residual(self):
        return np.max(np.abs(self.g)) * self.scale / self.e

    @staticmethod
    def definite(a):
        try:
            np.linalg.cholesky(a)
            return True
        except np.linalg.LinAlgError:
            return False

    def step(self):
        opt, n = self.opt, self.g.size
        dsc = float(np.mean(np.abs(np.diag(self.h))))
        if self.local:
            shifted = self.h + self.delta * dsc * np.eye(n)
            assert self.definite(shifted), "the reference covers definite local solves only"
            factored = True
        else:
            delta = self.delta / 3.0 if self.delta > 0 else 0.0
            factored = False
            for _ in range(40):
                shifted = self.h + delta * dsc * np.eye(n)
                if self.definite(shifted):
                    factored = True
                    break
                delta = opt.delta0 if delta == 0 else delta * 8.0
                if delta > opt.delta_max:
                    break
            if factored:
                self.delta = delta
        moved, alpha, left = False, 0.0, False
        if factored:
            s = np.linalg.solve(shifted, -self.g)
            slope = float(self.g @ s)

            def at(a):
                q = self.p.copy()
                q[1:-1] += a * s.reshape(-1, self.p.shape[1])
                return q

            def inside(q):
                return bool(np.all(self.m.domain.contains(q, tol=1e-12 * self.scale)))

            if self.full:
                q = at(1.0)
                if not inside(q):
                    left = True
                else:
                    self.evals += self.n
                    e1 = self.energy(q)
                    if (slope < 0 and e1 <= self.e + opt.armijo * slope) or abs(
                            e1 - self.e) <= 1e-15 * abs(self.e):
                        moved, alpha = True, 1.0
            if not moved and slope < 0:
                left |= not inside(at(1.0))
                self.values += self.n * sum(inside(at(2.0 ** -j)) for j in range(opt.line_steps))
                for j in range(opt.line_steps):
                    q = at(2.0 ** -j)
                    if inside(q) and self.energy(q) <= self.e + opt.armijo * 2.0 ** -j * slope:
                        moved, alpha = True, 2.0 ** -j
                        self.evals += self.n
                        break
            if moved:
                self.p = at(alpha)
                self.g, self.h = self._derivatives(self.p)
                self.e = self.energy(self.p)
        self.it += 1
        self.full = moved and alpha == 1.0
        if factored and not moved:
            self.delta = max(self.delta * 8.0, opt.delta0)
        elif moved and self.local:
            self.delta /= 3.0
        if self.delta < 1e-12:
            self.delta = 0.0
        self.hits = 0 if moved else self.hits + int(left)
        if not factored or self.delta > opt.delta_max:
            self.status = NewtonStatus.STALLED
        elif self.hits >= opt.boundary_hits:
            self.status = NewtonStatus.BOUNDARY
        elif self.it >= opt.max_iter and self.residual() > opt.gtol:
            self.status = NewtonStatus.MAX_ITERATIONS
        elif self.residual() <= opt.gtol:
            self.status = NewtonStatus.CONVERGED
        return moved, alpha, left


def _follow(m, paths, opt, local, scale, delta=0.0):
    """Step a NewtonState and the dense reference side by side; every iteration the
    points, shift, status, iteration count, energy and residual of every problem agree.
    ``delta``: the shift every problem starts with. Returns the (moved, step, left the
    domain) history of every problem."""
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import NewtonState

    st = NewtonState(m, paths, opt, backend_for(None), scale, local)
    refs = [_DenseNewton(m, p, opt, local, scale) for p in paths]
    st.delta[:] = delta
    for r in refs:
        r.delta = delta
    history: list[list[tuple[bool, float, bool]]] = [[] for _ in refs]
    for _ in range(opt.max_iter + 1):
        for b, r in enumerate(refs):
            assert st.status[b] == r.status, (b, st.status[b], r.status, history[b])
            assert st.iterations[b] == r.it
            np.testing.assert_allclose(st.paths()[b], r.p, rtol=0, atol=1e-10)
            assert st.delta[b] == pytest.approx(r.delta, rel=1e-9, abs=0)
            assert st.energy[b] == pytest.approx(r.e, rel=1e-10)
            assert st.residual[b] == pytest.approx(r.residual(), rel=1e-6)
            assert st.hits[b] == r.hits
        assert st.evaluations == sum(r.evals for r in refs)
        assert st.value_evaluations == sum(r.values for r in refs)
        if not st.running:
            break
        st.step()
        for b, r in enumerate(refs):
            if r.status == NewtonStatus.RUNNING:
                history[b].append(r.step())
    assert not st.running
    return history


def _bent(m, count, amp, seed, n=8):
    rng = np.random.default_rng(seed)
    line = np.linspace([-0.3, -0.2], [0.35, 0.25], n + 1)
    bump = np.sin(np.pi * np.linspace(0, 1, n + 1))[None, :, None]
    return line[None] + amp * bump * rng.normal(size=(count, 1, 2)) + np.r_[
        0, [1] * (n - 1), 0][None, :, None] * rng.normal(scale=amp / 4, size=(count, n + 1, 2))


def test_line_search_and_shifts_follow_a_dense_reference_with_a_strict_armijo() -> None:
    """Sphere paths (a disk domain), Armijo 0.45 and three step lengths: full Newton steps
    are refused on the strongly bent paths, shorter steps taken or none (the shift grows
    x8 from delta0, then shrinks /3 after progress); every iteration equals the dense
    reference, and the history shows each kind of step happened."""
    from solvers.newton.energy import NewtonOptions

    m = finsler.get_metric("sphere")
    paths = _bent(m, 5, 0.35, 7)
    opt = NewtonOptions(armijo=0.45, line_steps=3, max_iter=12, gtol=1e-9)
    hist = _follow(m, paths, opt, True, 1.6)
    kinds = {(mv, a) for h in hist for mv, a, _ in h}
    assert (True, 1.0) in kinds and (False, 0.0) in kinds
    assert any(mv and a < 1.0 for mv, a in kinds)


def test_whole_hessian_shift_follows_a_dense_reference_on_indefinite_hessians() -> None:
    """Matsumoto paths whose Hessians are not definite, ``local=False``: the smallest
    shift of the ladder 0, delta0, x8 ... (from last / 3 after a factorisation) that
    makes the dense Hessian positive definite, and every iteration as the reference."""
    from solvers.newton.energy import NewtonOptions

    m = finsler.get_metric("matsumoto")
    paths = _bent(m, 4, 0.15, 4)
    opt = NewtonOptions(armijo=0.3, line_steps=3, max_iter=10, gtol=1e-9)
    refs = [_DenseNewton(m, p, opt, False, 2.0) for p in paths]
    assert sum(not r.definite(r.h) for r in refs) >= 1  # the shift is needed
    hist = _follow(m, paths, opt, False, 2.0)
    assert any(h for h in hist)


@pytest.mark.parametrize("local", [True, False])
@pytest.mark.parametrize("delta_max", [1.0, 1e10])
def test_refused_steps_raise_the_shift_until_progress_or_stall(local, delta_max) -> None:
    """Armijo 0.85 with steps 1 and 1/2: on a nearly quadratic energy Newton steps are
    refused (a quadratic accepts only steps <= 2 (1 - 0.85) = 0.3), so the shift climbs
    x8 until the shifted direction passes (then /3 after progress, local mode), or beyond
    ``delta_max`` = 1, where the problem stops as STALLED; each iteration as the dense
    reference."""
    from solvers.newton.energy import NewtonOptions

    m = finsler.get_metric("sphere")
    opt = NewtonOptions(armijo=0.85, line_steps=2, max_iter=14, gtol=1e-9,
                        delta_max=delta_max)
    hist = _follow(m, _bent(m, 3, 0.1, 5), opt, local, 1.6)
    moved = [[mv for mv, _, _ in h] for h in hist]
    assert all(not h[0] for h in moved)  # the first Newton step is refused everywhere
    assert any(any(h) for h in moved) == (delta_max > 1.0)


@pytest.mark.parametrize(("c", "side", "held"), [(3.0, -1, True), (-1.0, 1, True),
                                                 (0.0, 1, False), (1.0, 1, False)])
def test_a_coordinate_within_bound_eps_of_a_side_pushed_out_is_held(c, side, held) -> None:
    """Projected Newton on a box: the middle point half of ``bound_eps`` (1e-9 * scale)
    inside the side ``x_0 = side``; the energy's gradient there is small (|g| < 1 in the
    first two cases: the sign decides, not the size). Pushed outwards (g > 0 at the left
    side, g < 0 at the right) the coordinate is held: its gradient entry leaves the
    residual and one Newton step leaves it where it is; pulled inwards it is free."""
    from solvers.newton.backends import _NUMPY_OPS, backend_for
    from solvers.newton.energy import NewtonOptions, NewtonState, _to_field, energy_terms

    m, scale = Tilt(c), 2.0
    eps = 1e-9 * scale
    x0 = side * (1.0 - 0.5 * eps)
    p = np.array([[[side * 0.97, -0.3], [x0, 0.0], [side * 0.97, 0.3]]])
    t = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, p), hessian=False)
    g = np.stack(t.grad, -1)[0, 0]
    outwards = g[0] * side < 0
    assert outwards == held and (abs(g[0]) < 1.0 or not held)
    keep = np.array([not held, True])
    want = np.max(np.abs(g[keep])) * scale / t.energy[0]
    st = NewtonState(m, p, NewtonOptions(max_iter=1), backend_for(None), scale)
    assert st.residual[0] == pytest.approx(want, rel=1e-12)
    # the reduced Newton step: held coordinate fixed, the free ones -H_ff^-1 g_f
    h = np.array([[st.terms.diag[i][k][0, 0] for k in range(2)] for i in range(2)])
    step = np.zeros(2)
    step[keep] = -np.linalg.solve(h[np.ix_(keep, keep)], g[keep])
    assert np.all(np.linalg.eigvalsh(h[np.ix_(keep, keep)]) > 0)
    st.step()
    moved = st.paths()[0, 1] - p[0, 1]
    assert (moved[0] == 0.0) == held
    j = int(np.argmax(np.abs(step)))
    alpha = moved[j] / step[j]
    assert min(abs(alpha - 2.0 ** -k) for k in range(4)) < 1e-9
    np.testing.assert_allclose(moved, alpha * step, rtol=1e-9, atol=1e-15)


def test_evaluations_count_every_segment_evaluated() -> None:
    """Three Euclidean paths of 5 segments. Default options: 15 segments with derivatives
    at the start, 15 more for the full Newton step (exact on a quadratic), no value
    evaluation. Armijo 0.9 with steps 1, 1/2, 1/4 refuses every step (a quadratic accepts
    only steps <= 0.2): the first iteration evaluates the full steps' derivatives (15) and
    3 x 15 values, the second only the 45 values (no full step after a refused one)."""
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import NewtonOptions, NewtonState

    m = finsler.get_metric("euclidean")
    st = NewtonState(m, _bent_line_paths(), NewtonOptions(), backend_for(None), 2.0)
    assert (st.evaluations, st.value_evaluations) == (15, 0)
    st.step()
    assert (st.evaluations, st.value_evaluations) == (30, 0)
    assert list(st.status) == [NewtonStatus.CONVERGED] * 3
    res = st.result()
    assert (res.evaluations, res.value_evaluations) == (30, 0)
    assert res.status.dtype == np.int64 and res.iterations.dtype == np.int64
    strict = NewtonState(m, _bent_line_paths(), NewtonOptions(armijo=0.9, line_steps=3),
                         backend_for(None), 2.0)
    strict.step()
    assert (strict.evaluations, strict.value_evaluations) == (30, 45)
    strict.step()
    assert (strict.evaluations, strict.value_evaluations) == (30, 90)
    assert strict.result().value_evaluations == 90
    np.testing.assert_array_equal(strict.paths(), _bent_line_paths())


def test_newton_energy_hands_its_device_to_the_backend(monkeypatch) -> None:
    """``device="cpu"`` runs on the torch backend (the numpy and torch runs agree, see
    test_newton.py, so only the backend asked for tells them apart)."""
    import solvers.newton.energy as newton

    seen: list = []
    real = newton.backend_for

    def spy(device):
        seen.append(device)
        return real(device)

    monkeypatch.setattr(newton, "backend_for", spy)
    m = finsler.get_metric("euclidean")
    res = newton.newton_energy(m, _bent_line_paths(), device="cpu")
    assert seen == ["cpu"] and real("cpu").name == "torch"
    assert list(res.status) == [NewtonStatus.CONVERGED] * 3


def test_dropping_nothing_changes_nothing() -> None:
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import NewtonOptions, NewtonState

    st = NewtonState(finsler.get_metric("euclidean"), _bent_line_paths(), NewtonOptions(),
                     backend_for(None), 2.0)
    st.drop([])
    assert list(st.active) == [0, 1, 2] and st.running


def test_a_full_step_that_leaves_the_disk_then_a_shorter_one_resets_the_hits() -> None:
    """A sphere path near the rim of its disk (radius 0.8), default options: its full
    Newton step leaves the disk, a shorter one is taken (the boundary
    hits start again from 0), as the dense reference does, iteration by iteration."""
    from solvers.newton.energy import NewtonOptions

    m = finsler.get_metric("sphere")
    paths = _bent(m, 3, 0.2, 15)[:1] * 1.7
    assert np.max(np.linalg.norm(paths, axis=-1)) < 0.79
    hist = _follow(m, paths, NewtonOptions(max_iter=12, gtol=1e-9), True, 1.6)
    assert any(mv and left and a < 1.0 for mv, a, left in hist[0])


@pytest.mark.parametrize(("delta0", "delta_max"), [(1e-4, 1e-3), (2e-36, 1e10)])
def test_hessians_the_shift_ladder_cannot_fix_stall(delta0, delta_max) -> None:
    """Whole-Hessian shift on Matsumoto paths, two of them indefinite (they need a shift
    of about 0.12 of the mean diagonal): past ``delta_max`` = 1e-3, or beyond the 40
    shifts tried per iteration (from delta0 = 2e-36 the 40th is 2e-36 * 8**38 = 0.04),
    they stop as STALLED at the first iteration with their shift unchanged; the definite
    ones run on, each as the dense reference."""
    from solvers.newton.energy import NewtonOptions

    m = finsler.get_metric("matsumoto")
    opt = NewtonOptions(armijo=0.3, line_steps=3, max_iter=10, gtol=1e-9, delta0=delta0,
                        delta_max=delta_max)
    hist = _follow(m, _bent(m, 4, 0.15, 4), opt, False, 2.0)
    assert [len(h) for h in hist][1:3] == [1, 1] and len(hist[0]) > 1


@pytest.mark.parametrize("local", [True, False])
def test_the_block_solves_get_each_problems_mean_diagonal_as_scale(monkeypatch, local) -> None:
    """The Hessian's scale handed to the block solve (the size of the local shifts and
    of the pivot tests) is, per problem, the mean of |diagonal entries| of its Hessian
    (Matsumoto paths, two of them indefinite: the whole-Hessian ladder solves again for
    those only, with their own scales)."""
    import solvers.newton.energy as newton
    from solvers.newton.backends import backend_for

    calls: list[np.ndarray] = []
    real = newton.block_tridiagonal_solve

    def spy(ops, diag, off, rhs, scale=None, **kw):
        calls.append(np.asarray(scale, dtype=float).reshape(-1))
        return real(ops, diag, off, rhs, scale, **kw)

    m = finsler.get_metric("matsumoto")
    paths = _bent(m, 4, 0.15, 4)
    st = newton.NewtonState(m, paths, newton.NewtonOptions(), backend_for(None), 2.0, local)
    want = np.array([np.mean(np.abs(np.diag(_DenseNewton(m, p, st.opt, local, 2.0).h)))
                     for p in paths])
    monkeypatch.setattr(newton, "block_tridiagonal_solve", spy)
    st.step()
    np.testing.assert_allclose(calls[0], want, rtol=1e-12)
    if local:
        assert len(calls) == 1
    else:  # the indefinite problems 1 and 2 are solved again, shifted
        assert len(calls) > 1
        np.testing.assert_allclose(calls[1], want[[1, 2]], rtol=1e-12)


@pytest.mark.parametrize("local", [True, False])
def test_a_shift_below_1e_12_of_the_diagonal_is_dropped(local) -> None:
    """Problems starting with a shift of 2.5e-12: after a step it is 2.5e-12 / 3 < 1e-12
    (divided after progress, or before the factorisation in whole-Hessian mode), and a
    shift that small is set to 0, as in the reference."""
    from solvers.newton.energy import NewtonOptions

    m = finsler.get_metric("sphere")
    hist = _follow(m, _bent(m, 3, 0.1, 5), NewtonOptions(max_iter=2, gtol=1e-9), local,
                   1.6, delta=2.5e-12)
    assert all(h[0][0] for h in hist)  # every problem made progress


def test_a_geodesic_pressed_against_the_left_side_stays_in_the_box() -> None:
    """``exp(3 x_0) |v|`` is cheaper to the left: between two points near the side
    ``x_0 = -1`` the geodesic presses against it. Projected Newton from the chord clamps
    trial points at the LOWER bound too: every point stays in the box, several lie on the
    side, and the energy is IPOPT's (the same discrete problem, another method)."""
    import solvers
    from solvers.newton.energy import newton_energy

    m = Tilt(3.0)
    s, g = np.array([-0.9, -0.8]), np.array([-0.9, 0.8])
    ref = solvers.solve_geodesic(m, s, g, 16, method="ipopt")
    assert np.min(ref.points[:, 0]) < -1 + 1e-6  # the side is active
    t = np.linspace(0.0, 1.0, 17)[:, None]
    res = newton_energy(m, (s + t * (g - s))[None], scale=2.0)
    assert res.status[0] == NewtonStatus.CONVERGED
    assert np.min(res.points[0, :, 0]) >= -1.0 and np.sum(res.points[0, :, 0] == -1.0) >= 3
    assert res.energy[0] == pytest.approx(ref.energy, rel=1e-8)


class _CountingRuns:
    """Wraps a lowered program: records the rows of every evaluation."""

    def __init__(self, real):
        self.real, self.rows = real, []

    def run(self, lowering, args):
        self.rows.append(int(args[0][0].shape[0]))
        return self.real.run(lowering, args)


def _counting_metric(c: float) -> tuple[Tilt, _CountingRuns]:
    m = Tilt(c)
    spy = _CountingRuns(m.segment_derivatives)
    m.__dict__["segment_derivatives"] = spy  # the cached property's slot
    return m, spy


@pytest.mark.parametrize("device", [None, "cpu"])
def test_energy_terms_in_chunks_equal_one_evaluation(device) -> None:
    """Five paths of 4 segments with ``chunk=8``: numpy evaluates 8 // 4 = 2 paths at a
    time (2, 2, 1), torch all five at once; the terms equal those of one evaluation of
    everything (the default chunk) to the last bit on numpy."""
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import _to_field, energy_terms

    ops = backend_for(device)
    rng = np.random.default_rng(5)
    paths = np.linspace([-0.5, 0.1], [0.4, -0.2], 5)[None] + 0.05 * rng.normal(size=(5, 5, 2))
    m, spy = _counting_metric(0.7)
    whole = energy_terms(m, ops, _to_field(ops, paths))
    assert spy.rows == [5]
    spy.rows.clear()
    parts = energy_terms(m, ops, _to_field(ops, paths), chunk=8)
    assert spy.rows == ([5] if device else [2, 2, 1])
    flat = lambda t: np.concatenate([np.asarray(ops.to_numpy(a)).reshape(-1) for a in (  # noqa: E731
        t.energy, *t.grad, *(x for r in t.diag for x in r), *(x for r in t.off for x in r))])
    np.testing.assert_array_equal(flat(parts), flat(whole))
    lean = energy_terms(m, ops, _to_field(ops, paths), hessian=False)
    assert lean.diag is None and lean.off is None
    one = lean.take(ops, np.array([3]))
    assert one.diag is None and one.off is None
    np.testing.assert_array_equal(ops.to_numpy(one.energy), ops.to_numpy(whole.energy)[[3]])


def test_newton_state_evaluates_in_chunks_of_its_option() -> None:
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import NewtonOptions, NewtonState

    m, spy = _counting_metric(0.7)
    paths = np.linspace([-0.5, 0.1], [0.4, -0.2], 5)[None] + np.zeros((3, 5, 2))
    paths[:, 1:-1] += 0.03
    NewtonState(m, paths, NewtonOptions(chunk=8), backend_for(None), 2.0)
    assert spy.rows == [2, 1]


def test_newton_options_refuse_wrong_types_with_a_clear_error() -> None:
    from finsler.errors import InputError
    from solvers.newton.energy import NewtonOptions

    for bad in ({"gtol": "1e-10"}, {"armijo": None}):
        with pytest.raises(InputError, match=f"{next(iter(bad))} must be positive and finite"):
            NewtonOptions(**bad)
    for bad in ({"max_iter": 2.5}, {"max_iter": True}, {"line_steps": 10.0}):
        with pytest.raises(InputError, match=f"{next(iter(bad))} must be a positive integer"):
            NewtonOptions(**bad)
    assert NewtonOptions(max_iter=np.int64(3)).max_iter == 3


def test_the_newton_state_shifts_locally_by_default_and_shows_chosen_paths() -> None:
    """A NewtonState made without ``local`` steps as the local one (Matsumoto paths with
    indefinite Hessians, where the whole-Hessian shift steps elsewhere); ``paths(which)``
    gives the problems asked for, in that order."""
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import NewtonOptions, NewtonState

    m = finsler.get_metric("matsumoto")
    paths = _bent(m, 4, 0.15, 4)
    states = [NewtonState(m, paths, NewtonOptions(), backend_for(None), 2.0, *extra)
              for extra in ((), (True,), (False,))]
    for st in states:
        st.step()
    default, local, whole = (st.paths() for st in states)
    np.testing.assert_array_equal(default, local)
    assert np.abs(default - whole).max() > 1e-6
    np.testing.assert_array_equal(states[0].paths([2, 0]), default[[2, 0]])


def test_a_start_with_finite_energy_but_nan_derivatives_is_not_finite() -> None:
    """The second path has an interior point at ``x_0 = 0`` (infinite derivatives, finite
    energy): NOT_FINITE at once, no iteration; the first path (no point at x_0 = 0) runs."""
    from solvers.newton.energy import _NUMPY_OPS, _to_field, energy_terms, newton_energy

    m = Kink()
    a = np.array([[-0.6, 0.1], [-0.3, 0.3], [-0.2, 0.5], [-0.1, 0.2]])
    b = np.array([[-0.6, 0.1], [0.0, 0.3], [0.3, 0.5], [0.5, 0.2]])
    with np.errstate(all="ignore"):
        t = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, b[None]))
    assert np.isfinite(t.energy[0]) and not np.all(np.isfinite(np.stack(t.grad)))
    res = newton_energy(m, np.stack([a, b]), scale=2.0)
    assert res.status[1] == NewtonStatus.NOT_FINITE and res.iterations[1] == 0
    assert res.status[0] != NewtonStatus.NOT_FINITE and res.iterations[0] > 0


def test_constant_terms_of_chunked_evaluations_fill_their_chunk() -> None:
    """Euclidean segments have constant second derivatives (2 and -2: the lowered program
    returns plain numbers, expanded to each chunk's rows): five paths in chunks of 2, 2,
    1 give the closed-form Hessian blocks (4 I on the diagonal, -2 I coupling) and energy
    sum |p_{j+1} - p_j|**2 for every path."""
    from solvers.newton.energy import _NUMPY_OPS, _to_field, energy_terms

    m = finsler.get_metric("euclidean")
    rng = np.random.default_rng(9)
    paths = np.linspace([-0.5, 0.1], [0.4, -0.2], 5)[None] + 0.05 * rng.normal(size=(5, 5, 2))
    t = energy_terms(m, _NUMPY_OPS, _to_field(_NUMPY_OPS, paths), chunk=8)
    np.testing.assert_allclose(t.energy, np.sum(np.diff(paths, axis=1) ** 2, axis=(1, 2)),
                               rtol=1e-14)
    eye = np.eye(2)
    for i in range(2):
        for k in range(2):
            np.testing.assert_array_equal(t.diag[i][k], np.full((5, 3), 4.0 * eye[i, k]))
            want = np.full((5, 3), -2.0 * eye[i, k])
            want[:, -1] = 0.0  # the last column couples nothing
            np.testing.assert_array_equal(t.off[i][k], want)


def test_armijo_on_a_box_measures_the_decrease_along_the_clipped_step() -> None:
    """``exp(0.5 x_0) |v|`` from (-0.98, -0.6) to (-0.98, 0.6), two segments: the Newton
    step of the middle point crosses the side x_0 = -1 and is clipped. Its energy change
    is 0.77 of the model along the clipped displacement (g . (q - p)) but only 0.17 of
    ``slope`` (g . s, the unclipped step): with Armijo 0.5 the projected step is taken
    whole, as the model along the projection arc says."""
    from solvers.newton.backends import backend_for
    from solvers.newton.energy import NewtonOptions, NewtonState

    m = Tilt(0.5)
    p = np.array([[-0.98, -0.6], [-0.98, 0.0], [-0.98, 0.6]])
    opt = NewtonOptions(armijo=0.5)
    r = _DenseNewton(m, p, opt, True, 2.0)
    assert np.all(np.linalg.eigvalsh(r.h) > 0)
    s = np.linalg.solve(r.h, -r.g)
    q = p.copy()
    q[1] = np.clip(p[1] + s, -1.0, 1.0)
    assert q[1, 0] == -1.0 and p[1, 0] + s[0] < -1.0  # clipped
    change = r.energy(q) - r.e
    assert change / (r.g @ (q[1] - p[1])) > 0.5 > change / (r.g @ s)
    st = NewtonState(m, p[None], opt, backend_for(None), 2.0)
    st.step()
    np.testing.assert_allclose(st.paths()[0], q, rtol=0, atol=1e-14)
