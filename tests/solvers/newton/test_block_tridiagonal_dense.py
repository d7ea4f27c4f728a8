"""block_tridiagonal_solve_dense (dense stacks) against numpy's dense solve of the assembled
system (an independent reference) and against the structure-of-arrays cyclic reduction
(the same pivot shifts where a block is not definite)."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.newton.backends import _NUMPY_OPS
from solvers.newton.block_tridiagonal import block_tridiagonal_solve, block_tridiagonal_solve_dense

from tests.helpers.linalg import dense


def _system(rng, b, m, d, shift):
    a = rng.normal(size=(b, m, d, d))
    diag = a @ np.swapaxes(a, -1, -2) + shift * np.eye(d)
    off = 0.3 * rng.normal(size=(b, m, d, d))
    rhs = rng.normal(size=(b, m, d))
    scale = np.abs(np.trace(diag, axis1=2, axis2=3)).mean(1) / d
    return diag, off, rhs, scale


@pytest.mark.parametrize(("m", "d"), [(1, 3), (2, 3), (7, 3), (10, 2), (31, 3), (40, 4)])
def test_dense_solves_definite_systems(m, d):
    rng = np.random.default_rng(m * 10 + d)
    diag, off, rhs, scale = _system(rng, 3, m, d, 2.0 + 2.0 * m ** 0)
    diag = diag + 3.0 * np.eye(d)  # diagonally dominant enough: definite
    x, ok = block_tridiagonal_solve_dense(diag, off, rhs, scale)
    assert ok.all()
    for k in range(3):
        ref = np.linalg.solve(dense(diag[k], off[k]), rhs[k].ravel())
        np.testing.assert_allclose(x[k].ravel(), ref, rtol=1e-10, atol=1e-12)


def _fields_solve(diag, off, rhs, scale, local):
    """The same systems through the fields solve (one array per block entry), the reference."""
    d = diag.shape[-1]
    return block_tridiagonal_solve(
        _NUMPY_OPS, [[np.ascontiguousarray(diag[..., i, j]) for j in range(d)]
                     for i in range(d)],
        [[np.ascontiguousarray(off[..., i, j]) for j in range(d)] for i in range(d)],
        [np.ascontiguousarray(rhs[..., i]) for i in range(d)], scale[:, None], local=local,
        method="cyclic")


@pytest.mark.parametrize("m", [5, 63, 100])
def test_dense_matches_fields_where_blocks_are_shifted(m):
    rng = np.random.default_rng(m)
    d = 3
    diag, off, rhs, scale = _system(rng, 4, m, d, -1.5)
    x, ok = block_tridiagonal_solve_dense(diag, off, rhs, scale, local=True)
    ref, ok_ref = _fields_solve(diag, off, rhs, scale, local=True)
    ref = np.stack(ref, -1)
    np.testing.assert_array_equal(ok, ok_ref)
    np.testing.assert_allclose(x, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    # without the shift the systems that are not definite are reported, as on fields
    _, ok_plain = block_tridiagonal_solve_dense(diag, off, rhs, scale, local=False)
    _, ok_fields = _fields_solve(diag, off, rhs, scale, local=False)
    assert not ok_plain.any()  # every system had blocks to shift: the shift is exercised
    np.testing.assert_array_equal(ok_plain, ok_fields)
