"""solvers.newton.block_tridiagonal against independent references, FAST (the mutation-testing
selection of the module, see docs/guides/mutation-testing.md): numpy's dense solve of the
assembled matrix, numpy's eigenvalues for definiteness, and the Gershgorin shift of the
modified Cholesky computed here by hand, for both elimination orders, block sizes 1, 2, 3,
every padding of cyclic reduction, numpy and torch."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from solvers.newton.backends import backend_for
from solvers.newton.block_tridiagonal import (
    TAU_FACTOR,
    THOMAS_MAX_BLOCKS,
    THOMAS_MAX_BLOCKS_WIDE,
    block_tridiagonal_solve,
    elimination_for,
    sum_,
)

from tests.helpers.linalg import dense

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation

NP = backend_for(None)


def fields(a: np.ndarray, o: np.ndarray, r: np.ndarray, convert=lambda v: v):
    """(B, M, d, d), (B, M, d, d), (B, M, d) -> the structure-of-arrays fields."""
    d = a.shape[-1]
    diag = [[convert(np.ascontiguousarray(a[..., i, k])) for k in range(d)] for i in range(d)]
    off = [[convert(np.ascontiguousarray(o[..., i, k])) for k in range(d)] for i in range(d)]
    return diag, off, [convert(np.ascontiguousarray(r[..., i])) for i in range(d)]


def system(b: int, m: int, d: int, seed: int, coupling: float = 0.5):
    """Random definite-diagonal systems (the couplings may still make some indefinite)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(b, m, d, d))
    a = a @ np.swapaxes(a, -1, -2) + 3.0 * np.eye(d)
    o = rng.normal(size=(b, m, d, d)) * coupling
    o[:, m - 1] = rng.normal(size=(b, d, d)) * 100.0  # ignored: must not matter
    r = rng.normal(size=(b, m, d))
    return a, o, r


def gershgorin_shift(block: np.ndarray, scale: float) -> float:
    """The modified Cholesky's shift of one pivot block, by hand: TAU_FACTOR times the
    magnitude of Gershgorin's lower bound of its eigenvalues, plus 1e-6 * scale."""
    rows = np.diag(block) - (np.abs(block).sum(1) - np.abs(np.diag(block)))
    return 2.0 * abs(rows.min()) + 1e-6 * scale


def solve(a, o, r, method, scale=None, local=False, ops=NP, convert=lambda v: v):
    diag, off, rhs = fields(a, o, r, convert)
    sc = None if scale is None else convert(np.asarray(scale, dtype=float).reshape(-1, 1))
    x, ok = block_tridiagonal_solve(ops, diag, off, rhs, scale=sc, local=local, method=method)
    return np.stack([ops.to_numpy(xi) for xi in x], -1), ops.to_numpy(ok)


def test_the_constants_and_the_choice_of_elimination() -> None:
    assert TAU_FACTOR == 2.0
    assert (THOMAS_MAX_BLOCKS, THOMAS_MAX_BLOCKS_WIDE) == (64, 256)
    assert elimination_for(1, 1) == elimination_for(64, 2) == "thomas"
    assert elimination_for(65, 2) == elimination_for(65, 1) == "cyclic"
    assert elimination_for(65, 3) == elimination_for(256, 7) == "thomas"
    assert elimination_for(257, 3) == "cyclic"
    assert sum_(iter([1, 2, 3])) == 6 and sum_([np.ones(2)]).tolist() == [1.0, 1.0]


@pytest.mark.parametrize("m", [1, 2, 3, 4, 5, 6, 7, 8, 9, 16])
@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("method", ["thomas", "cyclic", "auto"])
def test_definite_systems_match_the_dense_solve(m: int, d: int, method: str) -> None:
    """Every padding of cyclic reduction (M = 1 ... 16), block sizes 1-3, a batch of 3
    systems: numpy's dense solve to 1e-12, every system reported definite."""
    a, o, r = system(3, m, d, seed=10 * m + d, coupling=0.3)
    x, ok = solve(a, o, r, method)
    assert x.shape == (3, m, d) and ok.shape == (3,)
    for k in range(3):
        h = dense(a[k], o[k])
        assert np.linalg.eigvalsh(h).min() > 0
        ref = np.linalg.solve(h, r[k].reshape(-1))
        np.testing.assert_allclose(x[k].reshape(-1), ref, rtol=0,
                                   atol=1e-12 * np.abs(ref).max())
    assert ok.all()


@pytest.mark.parametrize("m", [1, 2, 5, 8])
@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("method", ["thomas", "cyclic"])
def test_indefinite_systems_are_reported_and_the_others_still_solved(m: int, d: int,
                                                                     method: str) -> None:
    """A system made indefinite (one block shifted down) is reported not definite; the
    definite systems beside it in the batch are solved exactly."""
    a, o, r = system(3, m, d, seed=7 * m + d, coupling=0.3)
    a[1, m // 2] -= 40.0 * np.eye(d)
    x, ok = solve(a, o, r, method)
    for k in range(3):
        h = dense(a[k], o[k])
        definite = np.linalg.eigvalsh(h).min() > 0
        assert bool(ok[k]) == definite
        if definite:
            ref = np.linalg.solve(h, r[k].reshape(-1))
            np.testing.assert_allclose(x[k].reshape(-1), ref, rtol=0,
                                       atol=1e-12 * np.abs(ref).max())
    assert not ok[1] and ok[0] and ok[2]


@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("method", ["thomas", "cyclic"])
@pytest.mark.parametrize("scale", [None, 1.0, 7.0])
@pytest.mark.parametrize(("m", "j"), [(5, 0), (5, 1), (5, 2), (1, 0), (3, 1)])
def test_local_shifts_exactly_the_indefinite_pivot_by_gershgorin(d: int, method: str,
                                                                  scale, m: int, j: int) -> None:
    """``local``: the one indefinite block ``j``, with all couplings around it zero (so
    it is a pivot as given in either elimination order: at the first level of cyclic
    reduction for an even ``j``, deeper for an odd one, the last level for ``M = 1``), is
    shifted by TAU_FACTOR * |Gershgorin bound| + 1e-6 * scale times I, nothing else: the
    solution is the dense solve of H + tau I on that block, and the system is reported
    definite."""
    a, o, r = system(2, m, d, seed=d + 3, coupling=0.3)
    o[:, j] = 0.0
    if j:
        o[:, j - 1] = 0.0
    rng = np.random.default_rng(d)
    q = rng.normal(size=(d, d))
    blk = 0.5 * (q + q.T) + np.diag(np.arange(d) + 1.0)
    blk[0, 0] = -2.5  # indefinite
    assert np.linalg.eigvalsh(blk).min() < 0
    a[0, j] = blk
    x, ok = solve(a, o, r, method, scale=None if scale is None else [scale] * 2, local=True)
    assert ok.all()
    tau = gershgorin_shift(blk, 1.0 if scale is None else scale)
    h = dense(a[0], o[0])
    h[j * d:(j + 1) * d, j * d:(j + 1) * d] += tau * np.eye(d)
    ref = np.linalg.solve(h, r[0].reshape(-1))
    np.testing.assert_allclose(x[0].reshape(-1), ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    ref1 = np.linalg.solve(dense(a[1], o[1]), r[1].reshape(-1))
    np.testing.assert_allclose(x[1].reshape(-1), ref1, rtol=0,
                               atol=1e-12 * np.abs(ref1).max())


@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("method", ["thomas", "cyclic"])
@pytest.mark.parametrize("size", [1.0, 1e-3])
def test_local_leaves_definite_systems_alone(d: int, method: str, size: float) -> None:
    """Definite systems (also of small entries, ``size`` 1e-3: definiteness is not
    "entries above 1") are solved as without ``local`` and reported definite."""
    a, o, r = system(2, 6, d, seed=30 + d, coupling=0.3)
    a, o = a * size, o * size
    x, ok = solve(a, o, r, method, local=True)
    x0, ok0 = solve(a, o, r, method, local=False)
    assert ok.all() and ok0.all()
    np.testing.assert_array_equal(x, x0)
    ref = np.linalg.solve(dense(a[0], o[0]), r[0].reshape(-1))
    np.testing.assert_allclose(x[0].reshape(-1), ref, rtol=0, atol=1e-11 * np.abs(ref).max())


@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("method", ["thomas", "cyclic"])
def test_the_definiteness_threshold_is_relative_to_scale(d: int, method: str) -> None:
    """A pivot of 1e-12 * scale counts as positive, one of 1e-14 * scale does not (the
    threshold is 1e-13 * scale), for scale 1 and 1e6; one block, diagonal (the first
    pivot small), or with a coupling that leaves the last pivot (det / p) small."""
    for scale in (1.0, 1e6):
        for (tiny, definite), coupled in itertools.product(((1e-12, True), (1e-14, False)),
                                                            (False, True)):
            if coupled and d == 1:
                continue
            blk = np.eye(d) * scale
            if coupled:  # [[s, q], [q, s]] with s^2 - q^2 = tiny s^2: last pivot tiny s
                blk[0, 1] = blk[1, 0] = scale * np.sqrt(1.0 - tiny)
                blk[2:, :2] = blk[:2, 2:] = 0.0
                blk = blk[[*range(1, d), 0]][:, [*range(1, d), 0]] if d > 2 else blk
            else:
                blk[0, 0] = tiny * scale
            a = blk[None, None].copy()
            o = np.zeros_like(a)
            r = np.ones((1, 1, d))
            _, ok = solve(a, o, r, method, scale=[scale])
            assert bool(ok[0]) is definite, (scale, tiny)


@pytest.mark.parametrize("method", ["thomas", "cyclic"])
def test_a_negative_first_pivot_is_not_definite_even_with_a_positive_determinant(
        method: str) -> None:
    """diag(-1, -1) has a positive determinant but is not definite; diag(-1, 2) and a
    2 x 2 block with determinant 0 are not definite either."""
    for blk in (np.diag([-1.0, -1.0]), np.diag([-1.0, 2.0]), np.array([[1.0, 1.0],
                                                                       [1.0, 1.0]])):
        _, ok = solve(blk[None, None], np.zeros((1, 1, 2, 2)), np.ones((1, 1, 2)), method)
        assert not ok[0]


@pytest.mark.parametrize("method", ["thomas", "cyclic"])
@pytest.mark.parametrize("d", [2, 3])
def test_torch_matches_numpy(method: str, d: int) -> None:
    torch = pytest.importorskip("torch")
    ops = backend_for("cpu")
    a, o, r = system(2, 5, d, seed=40 + d, coupling=0.3)
    a[1, 2] -= 40.0 * np.eye(d)
    x, ok = solve(a, o, r, method, ops=ops, convert=torch.tensor)
    xn, okn = solve(a, o, r, method)
    assert ok.tolist() == okn.tolist() == [True, False]
    np.testing.assert_allclose(x[0], xn[0], rtol=0, atol=1e-12)
    a[1, 0] = -np.eye(d)
    xl, okl = solve(a, o, r, method, local=True, ops=ops, convert=torch.tensor)
    xln, okln = solve(a, o, r, method, local=True)
    assert okl.all() and okln.all()
    np.testing.assert_allclose(xl, xln, rtol=0, atol=1e-10)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("method", ["thomas", "cyclic"])
def test_each_order_shifts_its_own_schur_complement(d: int, method: str) -> None:
    """Three blocks, the middle one indefinite, coupled to both neighbours: block Thomas
    meets the pivot S = A1 - B0^T A0^-1 B0, cyclic reduction (blocks 0 and 2 first)
    S' = S - B1 A2^-1 B1^T; each shifts its own pivot by its Gershgorin bound (the last
    pivot stays definite: A2 is large), so the two orders give different, each exactly
    predicted, solutions of (H + tau I on block 1) x = r."""
    rng = np.random.default_rng(50 + d)
    a = np.stack([np.eye(d) * 4.0, np.diag(np.r_[-2.5, np.ones(d - 1)]), np.eye(d) * 60.0])
    o = rng.normal(size=(3, d, d))
    o[2] = 0.0
    r = rng.normal(size=(3, d))
    s = a[1] - o[0].T @ np.linalg.solve(a[0], o[0])
    if method == "cyclic":
        s = s - o[1] @ np.linalg.solve(a[2], o[1].T)
    assert np.linalg.eigvalsh(s).min() < 0
    tau = gershgorin_shift(0.5 * (s + s.T), 1.0)
    h = dense(a, o)
    h[d:2 * d, d:2 * d] += tau * np.eye(d)
    ref = np.linalg.solve(h, r.reshape(-1))
    x, ok = solve(a[None], o[None], r[None], method, local=True)
    assert ok.all()
    np.testing.assert_allclose(x[0].reshape(-1), ref, rtol=0, atol=1e-10 * np.abs(ref).max())
