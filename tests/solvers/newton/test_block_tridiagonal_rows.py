"""The 2 x 2 block Thomas elimination on both of its paths (solvers.newton.block_tridiagonal:
the vectorised ``_thomas2`` and, for at most ``THOMAS_ROWS_MAX`` numpy systems, the one
system at a time ``_thomas2_rows``), FAST: against numpy's dense solve of the assembled
matrix, the Gershgorin shift of an indefinite pivot (and Schur complement) computed here
by hand, and against each other bit for bit (the same IEEE operations in the same order:
a batch's answers do not depend on how many systems it holds)."""

from __future__ import annotations

import numpy as np
import pytest

import solvers.newton.block_tridiagonal as bt
from solvers.newton.backends import backend_for
from solvers.newton.block_tridiagonal import THOMAS_ROWS_MAX, block_tridiagonal_solve

from tests.helpers.linalg import dense

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation

NP = backend_for(None)


def system(b: int, m: int, seed: int, coupling: float = 0.3):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(b, m, 2, 2))
    a = a @ np.swapaxes(a, -1, -2) + 3.0 * np.eye(2)
    o = rng.normal(size=(b, m, 2, 2)) * coupling
    o[:, m - 1] = rng.normal(size=(b, 2, 2)) * 100.0  # ignored: must not matter
    return a, o, rng.normal(size=(b, m, 2))


def solve(a, o, r, scale=None, local=False, ops=NP, convert=lambda v: v):
    diag = [[convert(np.ascontiguousarray(a[..., i, k])) for k in range(2)] for i in range(2)]
    off = [[convert(np.ascontiguousarray(o[..., i, k])) for k in range(2)] for i in range(2)]
    rhs = [convert(np.ascontiguousarray(r[..., i])) for i in range(2)]
    sc = None if scale is None else convert(np.asarray(scale, dtype=float).reshape(-1, 1))
    with np.errstate(all="ignore"):
        x, ok = block_tridiagonal_solve(ops, diag, off, rhs, scale=sc, local=local,
                                        method="thomas")
    return np.stack([ops.to_numpy(xi) for xi in x], -1), ops.to_numpy(ok)


def shift(block: np.ndarray, scale: float) -> float:
    """Gershgorin's shift of a 2 x 2 pivot, by hand: 2 |min(p, r) - |q|| + 1e-6 scale."""
    return 2.0 * abs(min(block[0, 0], block[1, 1]) - abs(block[0, 1])) + 1e-6 * scale


@pytest.fixture(params=["rows", "vector"])
def path(request, monkeypatch):
    """Every system through one path: ``rows`` (any batch size) or ``vector`` (none)."""
    monkeypatch.setattr(bt, "THOMAS_ROWS_MAX", 10**9 if request.param == "rows" else 0)
    return request.param


def test_the_batch_size_that_takes_the_rows_path(monkeypatch) -> None:
    assert THOMAS_ROWS_MAX == 16
    calls = []
    real = bt._thomas2_rows
    monkeypatch.setattr(bt, "_thomas2_rows", lambda *a: calls.append(1) or real(*a))
    for b, want in ((1, 1), (THOMAS_ROWS_MAX, 1), (THOMAS_ROWS_MAX + 1, 0)):
        calls.clear()
        solve(*system(b, 4, seed=b))
        assert len(calls) == want, b
    torch = pytest.importorskip("torch")
    calls.clear()
    a, o, r = system(3, 4, seed=5)
    x, _ = solve(a, o, r, ops=backend_for("cpu"), convert=torch.tensor)
    assert not calls  # torch tensors stay on their device: the vectorised path
    np.testing.assert_allclose(x, solve(a, o, r)[0], rtol=0, atol=1e-13)


@pytest.mark.parametrize("b", [1, 4, 20])
@pytest.mark.parametrize("m", [1, 2, 3, 7, 63])
@pytest.mark.parametrize("local", [False, True])
def test_definite_systems_match_the_dense_solve(path, b: int, m: int, local: bool) -> None:
    a, o, r = system(b, m, seed=100 * b + m)
    x, ok = solve(a, o, r, scale=np.full(b, 2.5), local=local)
    assert x.shape == (b, m, 2) and ok.shape == (b,) and ok.dtype == bool and ok.all()
    for k in range(b):
        h = dense(a[k], o[k])
        assert np.linalg.eigvalsh(h).min() > 0
        ref = np.linalg.solve(h, r[k].reshape(-1))
        np.testing.assert_allclose(x[k].reshape(-1), ref, rtol=0,
                                   atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("m", [1, 2, 6])
def test_indefinite_systems_are_reported_and_the_others_solved(path, m: int) -> None:
    a, o, r = system(5, m, seed=m)
    a[1, m // 2] -= 40.0 * np.eye(2)
    a[3, m - 1] = np.nan
    x, ok = solve(a, o, r)
    assert ok.tolist() == [True, False, True, False, True]
    for k in (0, 2, 4):
        ref = np.linalg.solve(dense(a[k], o[k]), r[k].reshape(-1))
        np.testing.assert_allclose(x[k].reshape(-1), ref, rtol=0,
                                   atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("scale", [1.0, 7.0])
@pytest.mark.parametrize(("m", "j"), [(1, 0), (4, 0), (4, 2), (4, 3)])
def test_local_shifts_the_indefinite_pivot_by_gershgorin(path, scale, m: int, j: int) -> None:
    """Block ``j`` indefinite with its couplings zero (it is its own pivot): solved with
    that block shifted by the shift computed here, every other block as given; a system
    beside it that needs nothing is solved exactly, both reported definite."""
    a, o, r = system(2, m, seed=3 * m + j)
    a[0, j] = np.array([[-1.5, 0.7], [0.7, 0.4]])
    o[0, j] = 0.0
    if j:
        o[0, j - 1] = 0.0
    x, ok = solve(a, o, r, scale=[scale, scale], local=True)
    assert ok.all()
    fixed = a[0].copy()
    fixed[j] += shift(a[0, j], scale) * np.eye(2)
    for k, blocks in ((0, fixed), (1, a[1])):
        ref = np.linalg.solve(dense(blocks, o[k]), r[k].reshape(-1))
        np.testing.assert_allclose(x[k].reshape(-1), ref, rtol=0,
                                   atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("coupling", [0.2, 0.5, 1.5])
def test_local_shifts_an_indefinite_schur_complement(path, coupling: float) -> None:
    """Three coupled blocks: the second pivot ``S = A1 - B0^T A0^-1 B0`` (not ``A1``)
    is shifted where it is not definite, so the solve is that of ``H + tau I`` on block 1,
    tau from ``S``'s Gershgorin bound."""
    a = np.array([[[2.0, 0.3], [0.3, 1.0]], [[0.5, 0.2], [0.2, 0.6]], [[3.0, 0.1], [0.1, 2.0]]])
    o = np.array([[[coupling, 0.4], [-0.3, coupling]], [[0.2, 0.1], [0.0, 0.3]],
                  [[9.0, 9.0], [9.0, 9.0]]])
    r = np.array([[1.0, -2.0], [0.5, 0.25], [-1.0, 3.0]])
    s = a[1] - o[0].T @ np.linalg.inv(a[0]) @ o[0]
    good = s[0, 0] > 1e-13 and np.linalg.det(s) > 1e-13 * abs(s[1, 1])
    x, ok = solve(a[None], o[None], r[None], scale=[1.0], local=True)
    fixed = a.copy()
    if not good:
        fixed[1] += shift(s, 1.0) * np.eye(2)
    assert bool(good) == (coupling == 0.2) and ok[0]
    ref = np.linalg.solve(dense(fixed, o), r.reshape(-1))
    np.testing.assert_allclose(x[0].reshape(-1), ref, rtol=0, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("b", [1, 3, 16])
@pytest.mark.parametrize("m", [1, 2, 5, 63])
@pytest.mark.parametrize("local", [False, True])
def test_the_two_paths_agree_bit_for_bit(monkeypatch, b: int, m: int, local: bool) -> None:
    """Definite, indefinite (first pivot, later pivots), not finite, and varying scales:
    the rows path returns exactly the vectorised path's solutions and flags."""
    rng = np.random.default_rng(b * 1000 + m)
    a, o, r = system(b, m, seed=b + m)
    a[::2, min(3, m - 1)] -= 5.0 * np.eye(2)
    a[:, 0, 1, 1] = rng.normal(size=b)
    a[b // 2, m - 1, 0, 0] = np.nan
    a[-1, 0, 0, 1] = a[-1, 0, 1, 0] = np.inf if b > 1 else 0.0
    scale = rng.uniform(0.3, 3.0, size=b)
    monkeypatch.setattr(bt, "THOMAS_ROWS_MAX", 0)
    xv, okv = solve(a, o, r, scale=scale, local=local)
    monkeypatch.setattr(bt, "THOMAS_ROWS_MAX", 10**9)
    xr, okr = solve(a, o, r, scale=scale, local=local)
    assert okr.dtype == okv.dtype == bool and okr.tolist() == okv.tolist()
    assert xr.shape == xv.shape == (b, m, 2)
    np.testing.assert_array_equal(xr, xv)
    if local:
        assert okr.sum() >= b - 2  # only the rows with NaN / inf may fail


@pytest.mark.parametrize("scale", [1.0, 3.0])
def test_a_first_pivot_at_the_threshold_is_not_definite(path, scale: float) -> None:
    """``p > 1e-13 * scale`` strictly: a pivot exactly at the threshold is not definite,
    the next float above it is (relative to ``scale``)."""
    tiny = 1e-13 * scale
    for p, want in ((tiny, False), (np.nextafter(tiny, 1.0), True), (-1.0, False)):
        blk = np.array([[[[p, 0.0], [0.0, 1.0]]]])
        _, ok = solve(blk, np.zeros((1, 1, 2, 2)), np.ones((1, 1, 2)), scale=[scale])
        assert bool(ok[0]) is want, p


def test_no_systems_keep_their_shapes(path) -> None:
    a, o, r = system(1, 5, seed=9)
    x, ok = solve(a[:0], o[:0], r[:0], local=True)
    assert x.shape == (0, 5, 2) and x.dtype == np.float64
    assert ok.shape == (0,) and ok.dtype == bool


@pytest.mark.parametrize("local", [False, True])
def test_the_determinant_threshold_scales_with_the_pivots_second_entry(path, local) -> None:
    """``det > 1e-13 * scale * |w|``: with ``w = 100`` a determinant of ~3e-12 (above
    ``1e-13 / |w|``, below ``1e-13 * |w|``) is not definite; ``local`` shifts it by the
    Gershgorin bound computed here."""
    q = np.sqrt(100.0 - 3e-12)
    blk = np.array([[1.0, q], [q, 100.0]])
    det = blk[0, 0] * blk[1, 1] - q * q
    assert 1e-15 < det < 1e-11
    r = np.array([[[1.0, -2.0]]])
    x, ok = solve(blk[None, None], np.zeros((1, 1, 2, 2)), r, scale=[1.0], local=local)
    assert bool(ok[0]) is local
    if local:
        ref = np.linalg.solve(blk + shift(blk, 1.0) * np.eye(2), r[0, 0])
        np.testing.assert_allclose(x[0, 0], ref, rtol=1e-12)


@pytest.mark.parametrize("m", [4, 40])
def test_the_defaults_report_an_indefinite_system_without_shifting(m: int) -> None:
    """Called with neither ``local`` nor ``method`` (the defaults: report, do not shift;
    the elimination chosen by size), an indefinite system is reported, and every definite
    one is solved as numpy solves the assembled matrix."""
    a, o, r = system(3, m, seed=40 + m)
    a[1, m // 2] -= 40.0 * np.eye(2)
    diag = [[np.ascontiguousarray(a[..., i, k]) for k in range(2)] for i in range(2)]
    off = [[np.ascontiguousarray(o[..., i, k]) for k in range(2)] for i in range(2)]
    rhs = [np.ascontiguousarray(r[..., i]) for i in range(2)]
    x, ok = block_tridiagonal_solve(NP, diag, off, rhs)
    assert np.asarray(ok).tolist() == [True, False, True]
    x = np.stack(x, -1)
    for k in (0, 2):
        ref = np.linalg.solve(dense(a[k], o[k]), r[k].reshape(-1))
        np.testing.assert_allclose(x[k].reshape(-1), ref, rtol=0,
                                   atol=1e-11 * np.abs(ref).max())
