"""Symmetric block-tridiagonal linear systems, vectorised over many systems at once: the
Hessian solves of the batched Newton method (`solvers.newton.energy`).

Fields of small blocks are kept "structure of arrays": a vector field is a list of ``d``
arrays, a matrix field a ``d x d`` list of arrays, every array ``(B, M)`` (``B`` systems
of ``M`` blocks), so every block operation is a few elementwise array operations on a
backend (`solvers.newton.backends`). `block_tridiagonal_solve` factorises by block
Thomas elimination (short systems; blocks larger than 2 x 2 as dense ``(B, d, d)``
stacks, LAPACK's Cholesky where every block is definite) or block cyclic reduction (long
ones: ``log2 M`` levels), optionally shifting pivot blocks that are not positive definite
(a block-wise modified Cholesky).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from solvers.newton.backends import _NUMPY_OPS

__all__ = ["TAU_FACTOR", "THOMAS_MAX_BLOCKS", "THOMAS_MAX_BLOCKS_WIDE", "THOMAS_ROWS_MAX", "Mat",
           "Vec", "all_rows", "block_tridiagonal_solve",
           "block_tridiagonal_solve_dense", "elimination_for", "sum_"]

Vec = list
Mat = list

#: A block that is not positive definite is shifted by TAU_FACTOR times (a bound of) its
#: most negative eigenvalue: its curvature mirrored, the step there gradient-like.
TAU_FACTOR = 2.0


def _mmul(a: Mat, b: Mat) -> Mat:
    d, k = len(a), len(b[0])
    return [[sum_(a[i][j] * b[j][c] for j in range(len(b))) for c in range(k)]
            for i in range(d)]


def _mvec(a: Mat, v: Vec) -> Vec:
    return [sum_(a[i][j] * v[j] for j in range(len(v))) for i in range(len(a))]


def sum_(terms: Any) -> Any:
    it = iter(terms)
    out = next(it)
    for t in it:
        out = out + t
    return out


def _mT(a: Mat) -> Mat:
    return [[a[j][i] for j in range(len(a))] for i in range(len(a[0]))]


def _msub(a: Mat, b: Mat) -> Mat:
    return [[x - y for x, y in zip(ra, rb)] for ra, rb in zip(a, b)]


def _vsub(a: Vec, b: Vec) -> Vec:
    return [x - y for x, y in zip(a, b)]


def _msl(a: Mat, sl: Any) -> Mat:
    return [[None if x is None else x[:, sl] for x in row] for row in a]


def _vsl(a: Vec, sl: Any) -> Vec:
    return [x[:, sl] for x in a]


def _chol(ops: Any, a: Mat, scale: Any, local: bool) -> tuple[Mat, Any]:
    """Cholesky factors of a field of symmetric blocks -> (lower factors, definite
    ``(B, M)``). ``scale`` ``(B, 1)``: the problem's mean Hessian diagonal. A pivot that is
    not positive (relative to ``1e-13 * scale``) makes its block not definite; with
    ``local`` such a block is then shifted by ``tau I``, ``tau`` from Gershgorin's bound of
    its smallest eigenvalue (the modified Cholesky of Gill and Murray, block by block: only
    the blocks that need it), so every block factorises. Failed pivots are replaced by 1
    so the arithmetic stays finite."""
    low, ok = _chol_plain(ops, a, scale)
    if not local:
        return low, ok
    bad = ~ok
    if not bool(bad.any()):
        return low, ok
    d = len(a)
    low_eig = None
    for i in range(d):
        r = a[i][i] - sum_(ops.abs(a[i][k]) for k in range(d) if k != i) if d > 1 else a[i][i]
        low_eig = r if low_eig is None else ops.where(r < low_eig, r, low_eig)
    floor = 1e-6 * scale
    tau = ops.where(bad, ops.abs(low_eig) * TAU_FACTOR + floor, 0.0)
    shifted = [[a[i][k] + tau if i == k else a[i][k] for k in range(d)] for i in range(d)]
    return _chol_plain(ops, shifted, scale)


def _chol_plain(ops: Any, a: Mat, scale: Any) -> tuple[Mat, Any]:
    d = len(a)
    low: Mat = [[None] * d for _ in range(d)]
    ok = None
    tiny = 1e-13 * scale
    for j in range(d):
        s = a[j][j]
        for k in range(j):
            s = s - low[j][k] * low[j][k]
        good = s > tiny
        ok = good if ok is None else ok & good
        piv = ops.sqrt(ops.where(good, s, 1.0))
        low[j][j] = piv
        inv = 1.0 / piv
        for i in range(j + 1, d):
            t = a[i][j]
            for k in range(j):
                t = t - low[i][k] * low[j][k]
            low[i][j] = t * inv
    return low, ok


def _chol_solve(low: Mat, rhs: Any) -> Any:
    """Solve ``L L^T x = rhs`` for a field of factors and a vector field (list) or a matrix
    field (list of lists, one column per inner entry)."""
    if isinstance(rhs[0], list):
        cols = [_chol_solve(low, [row[c] for row in rhs]) for c in range(len(rhs[0]))]
        return [[cols[c][i] for c in range(len(cols))] for i in range(len(rhs))]
    d = len(low)
    y: list[Any] = [None] * d
    for i in range(d):
        t = rhs[i]
        for k in range(i):
            t = t - low[i][k] * y[k]
        y[i] = t / low[i][i]
    x: list[Any] = [None] * d
    for i in reversed(range(d)):
        t = y[i]
        for k in range(i + 1, d):
            t = t - low[k][i] * x[k]
        x[i] = t / low[i][i]
    return x


#: Systems of at most this many blocks are solved in order (block Thomas: ``M`` steps on
#: long vectors), longer ones by cyclic reduction (``log2 M`` levels); by the size alone,
#: so a problem's arithmetic does not depend on the batch it is in (measured with
#: ``benchmarks/solver_speed.py --metrics none --linear``: 3400 problems x 31 blocks 10 vs
#: 23 ms, 200 x 63 7.3 vs 5.9 ms, 100 x 255 30 vs 11 ms, 4 x 4095 382 vs 9.5 ms).
THOMAS_MAX_BLOCKS = 64
#: The same for blocks larger than 2 x 2 (the dense-block Thomas elimination: 7 x 7, 6
#: systems of 255 blocks 11 vs 27 ms, of 1023 blocks 43 vs 48 ms).
THOMAS_MAX_BLOCKS_WIDE = 256


def elimination_for(m: int, d: int) -> str:
    """``"thomas"`` or ``"cyclic"``: the elimination order ``method="auto"`` takes for
    systems of ``m`` blocks of size ``d x d`` (by the size alone)."""
    return "thomas" if m <= (THOMAS_MAX_BLOCKS if d <= 2 else THOMAS_MAX_BLOCKS_WIDE) \
        else "cyclic"


def block_tridiagonal_solve(ops: Any, diag: Mat, off: Mat, rhs: Vec, scale: Any = None,
                            local: bool = False, method: str = "auto") -> tuple[Vec, Any]:
    """Solve symmetric block-tridiagonal systems ``H x = rhs`` by block cyclic reduction.

    Fields (structure of arrays, every entry ``(B, M)``): ``diag`` the ``d x d`` diagonal
    blocks, ``off`` the blocks coupling unknowns ``j`` and ``j + 1`` (column ``M - 1`` is
    ignored), ``rhs`` the ``d`` right-hand sides. Returns (solution field, positive definite
    ``(B,)``).

    Odd-even reduction eliminates the even-indexed unknowns of every level at once, so a
    system of ``M`` blocks takes ``log2 M`` levels of vectorised block operations. It is
    block Gaussian elimination in an odd-even order: a system is positive definite
    exactly when every pivot block met is. With ``local`` a pivot block that is not
    definite is shifted (`_chol`): that solves ``(H + E) x = rhs`` with ``E`` block
    diagonal, non-zero only where ``H`` needed it, and positive definite.
    """
    b, m = rhs[0].shape
    d = len(rhs)
    if scale is None:
        scale = ops.full((b, 1), 1.0)
    if method == "auto":
        method = elimination_for(m, d)
    with np.errstate(all="ignore"):  # a system that is not definite may overflow: reported
        if method == "thomas":
            return _thomas(ops, diag, off, rhs, scale, local)
        return _cyclic_padded(ops, diag, off, rhs, scale, local, b, m, d)


def _cyclic_padded(ops: Any, diag: Mat, off: Mat, rhs: Vec, scale: Any, local: bool, b: int,
                   m: int, d: int) -> tuple[Vec, Any]:
    size = 1
    while size < m:
        size = 2 * size + 1
    pad = size - m
    if pad:
        one, zero = ops.full((b, pad), 1.0), ops.zeros((b, pad))
        diag = [[ops.cat([diag[i][k], one if i == k else zero], 1) for k in range(d)]
                for i in range(d)]
        rhs = [ops.cat([r, zero], 1) for r in rhs]
    zc = ops.zeros((b, pad + 1))
    off = [[ops.cat([off[i][k][:, : m - 1], zc], 1) for k in range(d)] for i in range(d)]
    x, ok = _cyclic_reduction(ops, diag, off, rhs, scale, local)
    return [xi[:, :m] for xi in x], ok


def _inv_sym(ops: Any, a: Mat, scale: Any, local: bool) -> tuple[Mat, Any]:
    """Inverses of a field of symmetric 2 x 2 blocks (every entry ``(K,)``) -> (inverses,
    definite). With ``local``, blocks that are not positive definite are first shifted by
    ``tau I`` (Gershgorin bound; see `_chol`)."""
    p, q, r = a[0][0], a[0][1], a[1][1]
    det = p * r - q * q
    tiny = 1e-13 * scale
    ok = (p > tiny) & (det > tiny * ops.abs(r))
    if local:
        low_eig = ops.where(p < r, p, r) - ops.abs(q)
        tau = ops.where(ok, 0.0, ops.abs(low_eig) * TAU_FACTOR + 1e-6 * scale)
        p, r = p + tau, r + tau
        det = p * r - q * q
        ok = (p > 0) & (det > 0)
    inv = 1.0 / ops.where(ok, det, 1.0)
    off = -q * inv
    return [[r * inv, off], [off, p * inv]], ok


def _chol_dense(ops: Any, a: Any, tiny: Any) -> tuple[Any, Any]:
    """Cholesky factors of dense symmetric blocks ``(K, d, d)`` -> (lower factors,
    definite ``(K,)``): the pivots of `_chol_plain` (not positive relative to
    ``tiny`` ``(K,)``: not definite, replaced by 1), one column at a time over all blocks."""
    d = a.shape[-1]
    low = a * 0.0
    ok = None
    for j in range(d):
        s = a[:, j, j] - (low[:, j, :j] * low[:, j, :j]).sum(-1)
        good = s > tiny
        ok = good if ok is None else ok & good
        piv = ops.sqrt(ops.where(good, s, 1.0))
        low[:, j, j] = piv
        if j + 1 < d:
            t = a[:, j + 1:, j] - (low[:, j + 1:, :j] * low[:, j, None, :j]).sum(-1)
            low[:, j + 1:, j] = t / piv[:, None]
    return low, ok


def _inv_dense(ops: Any, a: Any, scale: Any, local: bool) -> tuple[Any, Any]:
    """Inverses of dense symmetric blocks ``(K, d, d)`` -> (inverses, definite ``(K,)``),
    by the Cholesky factor; with ``local`` the blocks that are not positive definite are
    shifted by ``tau I`` first, ``tau`` from Gershgorin's bound of the smallest eigenvalue
    (as `_chol`). Every block by the same arithmetic, whatever the others are: a
    block's inverse never depends on the stack it is in (LAPACK where the whole stack was
    definite, pivot by pivot otherwise, sent one car-like path to another basin when a
    pair was solved beside others). Pivot by pivot is also the faster one from ~1000
    3 x 3 blocks on (0.87 against 1.5 ms; 1.1x slower at 100)."""
    d = a.shape[-1]
    low, ok = _chol_dense(ops, a, 1e-13 * scale)
    if local and not bool(ok.all()):
        diag = a.diagonal(0, -2, -1)
        rest = ops.abs(a).sum(-1) - ops.abs(diag)
        low_eig = (diag - rest).min(-1)  # numpy: the minima; torch: (values, indices)
        low_eig = getattr(low_eig, "values", low_eig)
        tau = ops.where(ok, 0.0, ops.abs(low_eig) * TAU_FACTOR + 1e-6 * scale)
        shifted = a * 1.0
        for i in range(d):
            shifted[:, i, i] = a[:, i, i] + tau
        low, ok = _chol_dense(ops, shifted, 1e-13 * scale)
    # L^{-1} row by row (forward substitution on the identity), then L^{-T} L^{-1}
    inv_l = a * 0.0
    for i in range(d):
        row = -(low[:, i, :i, None] * inv_l[:, :i, :]).sum(1)
        row[:, i] = row[:, i] + 1.0
        inv_l[:, i, :] = row / low[:, i, i, None]
    return inv_l.mT @ inv_l, ok


def _thomas(ops: Any, a: Mat, off: Mat, r: Vec, scale: Any, local: bool) -> tuple[Vec, Any]:
    """Block LDL^T elimination in order (the block Thomas algorithm): ``M`` sequential
    steps, each a few batched ``d x d`` matrix products over the ``B`` systems (the blocks
    as dense ``(M, B, d, d)`` arrays; element by element the Python overhead of a 7 x 7
    block was most of a one-pair Panda solve). Cheaper than cyclic reduction when ``M`` is
    small against ``B``."""
    d = len(r)
    if d == 2:
        return _thomas2(ops, a, off, r, scale, local)
    m = r[0].shape[1]
    sc = scale[:, 0]

    def dense(field: Mat) -> Any:  # d x d field of (B, M) -> (M, B, d, d)
        return ops.stack([ops.stack([x.T for x in row], -1) for row in field], -2)

    col, ocol = dense(a), dense(off)
    rcol = ops.stack([x.T for x in r], -1)[..., None]  # (M, B, d, 1)
    gs: list[Any] = []
    zs: list[Any] = []
    ok = None
    s_blk, y = col[0], rcol[0]
    for j in range(m):
        inv, good = _inv_dense(ops, s_blk, sc, local)
        ok = good if ok is None else ok & good
        zs.append(inv @ y)
        if j == m - 1:
            break
        o = ocol[j]
        g = inv @ o
        gs.append(g)
        nxt = col[j + 1] - o.mT @ g
        s_blk = 0.5 * (nxt + nxt.mT)
        y = rcol[j + 1] - g.mT @ y
    x_cols: list[Any] = [None] * m
    x_cols[m - 1] = zs[m - 1]
    for j in range(m - 2, -1, -1):
        x_cols[j] = zs[j] - gs[j] @ x_cols[j + 1]
    x = ops.stack(x_cols, 1)[..., 0]  # (B, M, d)
    return [ops.contiguous(x[..., i]) for i in range(d)], ok


def _thomas2(ops: Any, a: Mat, off: Mat, r: Vec, scale: Any, local: bool
             ) -> tuple[Vec, Any]:
    """`_thomas` written out for 2 x 2 blocks (the 2-D metrics: the common case,
    where the generic loops' Python overhead is a third of the solve). The same
    arithmetic as `_inv_sym` and the generic elimination, entry by entry; the pivot
    blocks are inverted in closed form, and only where one of them is not definite (rare)
    does `_inv_sym` shift them block by block (a step is ~45 array operations on
    ``B`` entries instead of ~70)."""
    m = r[0].shape[1]
    if ops.name == "numpy" and r[0].shape[0] <= THOMAS_ROWS_MAX:
        return _thomas2_rows(a, off, r, scale, local)
    sc = scale[:, 0]
    tiny = 1e-13 * sc
    d00, d01, d11 = (ops.contiguous(x.T) for x in (a[0][0], a[0][1], a[1][1]))
    o00, o01, o10, o11 = (ops.contiguous(x.T) for x in (off[0][0], off[0][1], off[1][0],
                                                         off[1][1]))
    r0, r1 = ops.contiguous(r[0].T), ops.contiguous(r[1].T)
    p, q, w = d00[0], d01[0], d11[0]
    y0, y1 = r0[0], r1[0]
    gs, zs = [], []
    ok = None
    for j in range(m):
        det = p * w - q * q
        good = (p > tiny) & (det > tiny * ops.abs(w))
        if bool(good.all()):
            inv = 1.0 / det
            i00, i01, i11 = w * inv, -q * inv, p * inv
            ok = good if ok is None else ok
        else:  # a pivot block that is not definite: reported, or (local) shifted by
            # _inv_sym on those blocks alone (where tau = 0 it computes the same as here)
            inv = 1.0 / ops.where(good, det, 1.0)
            i00, i01, i11 = w * inv, -q * inv, p * inv
            if local:
                k = ops.index(np.flatnonzero(ops.to_numpy(~good)))
                (b00, b01), (_, b11) = (res := _inv_sym(ops, [[p[k], q[k]], [q[k], w[k]]],
                                                        sc[k], local))[0]
                i00[k], i01[k], i11[k] = b00, b01, b11
                good = good.clone() if hasattr(good, "clone") else good.copy()
                good[k] = res[1]
            ok = good if ok is None else ok & good
        zs.append((i00 * y0 + i01 * y1, i01 * y0 + i11 * y1))
        if j == m - 1:
            break
        g, p, q, w, y0, y1 = _eliminate2((i00, i01, i11), (o00[j], o01[j], o10[j], o11[j]),
                                         (d00[j + 1], d01[j + 1], d11[j + 1]),
                                         (r0[j + 1], r1[j + 1]), y0, y1)
        gs.append(g)
    x0, x1 = _back_substitute2(zs, gs, [None] * m, [None] * m)
    return [ops.stack_cols(x0), ops.stack_cols(x1)], ok


def _eliminate2(inv: tuple, off: tuple, nxt: tuple, rhs: tuple, y0: Any, y1: Any
                ) -> tuple[tuple, Any, Any, Any, Any, Any]:
    """One forward step of the 2 x 2 block elimination, on arrays (a batch) or on Python
    floats (one system) alike: ``G = P^-1 A`` from the pivot's inverse ``inv = (i00, i01,
    i11)`` and the off-diagonal block ``off = (a00, a01, a10, a11)``, the next pivot
    ``D' - A^T G`` (symmetric: ``(p, q, w)``) and right side ``r' - G^T y``. The same
    operations in the same order on both paths, so they agree bit for bit."""
    i00, i01, i11 = inv
    a00, a01, a10, a11 = off
    g00 = i00 * a00 + i01 * a10
    g01 = i00 * a01 + i01 * a11
    g10 = i01 * a00 + i11 * a10
    g11 = i01 * a01 + i11 * a11
    p = nxt[0] - (a00 * g00 + a10 * g10)
    q = nxt[1] - (a00 * g01 + a10 * g11)
    w = nxt[2] - (a01 * g01 + a11 * g11)
    return ((g00, g01, g10, g11), p, q, w, rhs[0] - (g00 * y0 + g10 * y1),
            rhs[1] - (g01 * y0 + g11 * y1))


def _back_substitute2(zs: list, gs: list, x0: list, x1: list) -> tuple[list, list]:
    """The back substitution ``x_j = z_j - G_j x_{j+1}`` of the 2 x 2 elimination into the
    lists ``x0``, ``x1`` (length ``m``; arrays or Python floats alike)."""
    m = len(zs)
    x0[m - 1], x1[m - 1] = zs[m - 1]
    for j in range(m - 2, -1, -1):
        g00, g01, g10, g11 = gs[j]
        x0[j] = zs[j][0] - (g00 * x0[j + 1] + g01 * x1[j + 1])
        x1[j] = zs[j][1] - (g10 * x0[j + 1] + g11 * x1[j + 1])
    return x0, x1


#: Up to this many systems of 2 x 2 blocks (numpy), `_thomas2` runs system by system
#: on Python floats (`_thomas2_rows`): the same IEEE operations in the same order, so
#: bitwise the same solutions, without the ~1 us per array operation that makes the
#: vectorised elimination cost about the same for 1 system as for 20 (63 blocks: ~0.08
#: ms per system against ~1.3 ms per call; the last iterations of a batched Newton solve
#: run a handful of problems).
THOMAS_ROWS_MAX = 16


def _thomas2_rows(a: Mat, off: Mat, r: Vec, scale: Any, local: bool) -> tuple[Vec, Any]:
    """`_thomas2` on numpy arrays, one system at a time in Python floats (a few
    systems): every operation is the vectorised one's (`_inv_sym` where a pivot
    block is not definite), element by element, so the results are identical."""
    d00, d01, d11 = a[0][0].tolist(), a[0][1].tolist(), a[1][1].tolist()
    o00, o01, o10, o11 = (x.tolist() for x in (off[0][0], off[0][1], off[1][0], off[1][1]))
    r0, r1 = r[0].tolist(), r[1].tolist()
    scs = scale[:, 0].tolist()
    b, m = r[0].shape
    x0s, x1s, oks = [], [], []
    for k in range(b):
        sc, e00, e01, e11 = scs[k], d00[k], d01[k], d11[k]
        f00, f01, f10, f11, s0, s1 = o00[k], o01[k], o10[k], o11[k], r0[k], r1[k]
        tiny = 1e-13 * sc
        p, q, w, y0, y1 = e00[0], e01[0], e11[0], s0[0], s1[0]
        gs, zs = [], []
        ok = True
        for j in range(m):
            det = p * w - q * q
            good = p > tiny and det > tiny * abs(w)
            if not good and local:  # _inv_sym's shift, tau = 0 where the block is definite
                low_eig = (p if p < w else w) - abs(q)
                tau = abs(low_eig) * TAU_FACTOR + 1e-6 * sc
                p, w = p + tau, w + tau
                det = p * w - q * q
                good = p > 0 and det > 0
            ok = ok and good
            inv = 1.0 / (det if good else 1.0)
            i00, i01, i11 = w * inv, -q * inv, p * inv
            zs.append((i00 * y0 + i01 * y1, i01 * y0 + i11 * y1))
            if j == m - 1:
                break
            g, p, q, w, y0, y1 = _eliminate2((i00, i01, i11), (f00[j], f01[j], f10[j], f11[j]),
                                             (e00[j + 1], e01[j + 1], e11[j + 1]),
                                             (s0[j + 1], s1[j + 1]), y0, y1)
            gs.append(g)
        x0, x1 = _back_substitute2(zs, gs, [0.0] * m, [0.0] * m)
        x0s.append(x0)
        x1s.append(x1)
        oks.append(ok)
    shape = (b, m)
    return ([np.array(x0s, dtype=np.float64).reshape(shape),
             np.array(x1s, dtype=np.float64).reshape(shape)], np.array(oks, dtype=bool))


def all_rows(ops: Any, ok: Any) -> Any:
    return ok.all(1) if hasattr(ok, "detach") else np.all(ok, 1)


def _cyclic_reduction(ops: Any, a: Mat, off: Mat, r: Vec, scale: Any, local: bool
                      ) -> tuple[Vec, Any]:
    m = r[0].shape[1]
    if m == 1:
        low, ok = _chol(ops, a, scale, local)
        return _chol_solve(low, r), all_rows(ops, ok)
    ev, od = slice(0, None, 2), slice(1, None, 2)
    low, ok_e = _chol(ops, _msl(a, ev), scale, local)  # pivots of the even unknowns
    low_l, low_r = _msl(low, slice(0, -1)), _msl(low, slice(1, None))
    left, right, nxt = _msl(off, slice(0, m - 1, 2)), _msl(off, od), _msl(off, slice(2, None, 2))
    r_e = _vsl(r, ev)
    w_l = _chol_solve(low_l, left)  # A_{k-1}^{-1} B_{k-1}
    w_r = _chol_solve(low_r, _mT(right))  # A_{k+1}^{-1} B_k^T
    v_l = _chol_solve(low_l, _vsl(r_e, slice(0, -1)))
    v_r = _chol_solve(low_r, _vsl(r_e, slice(1, None)))
    left_t = _mT(left)
    a2 = _msub(_msub(_msl(a, od), _mmul(left_t, w_l)), _mmul(right, w_r))
    off2 = [[-x for x in row] for row in _mmul(_mT(w_r), nxt)]
    r2 = _vsub(_vsub(_vsl(r, od), _mvec(left_t, v_l)), _mvec(right, v_r))
    xk, ok_k = _cyclic_reduction(ops, a2, off2, r2, scale, local)
    b = r[0].shape[0]
    zero = ops.zeros((b, 1))
    xpad = [ops.cat([zero, x, zero], 1) for x in xk]
    prev = [[ops.cat([zero, x[:, od]], 1) for x in row] for row in off]
    cur = _msl(off, ev)
    rhs_e = _vsub(_vsub(r_e, _mvec(_mT(prev), _vsl(xpad, slice(0, -1)))),
                  _mvec(cur, _vsl(xpad, slice(1, None))))
    xe = _chol_solve(low, rhs_e)
    x = []
    for i in range(len(r)):
        xi = ops.zeros((b, m))
        xi[:, ev] = xe[i]
        xi[:, od] = xk[i]
        x.append(xi)
    return x, all_rows(ops, ok_e) & ok_k



def block_tridiagonal_solve_dense(diag: np.ndarray, off: np.ndarray, rhs: np.ndarray,
                                  scale: np.ndarray, local: bool = False
                                  ) -> tuple[np.ndarray, np.ndarray]:
    """`block_tridiagonal_solve` by cyclic reduction on dense stacks (numpy): ``diag``
    and ``off`` ``(B, M, d, d)`` (``off[:, j]`` the block of rows ``j``, columns ``j + 1``;
    ``off[:, M - 1]`` ignored), ``rhs`` ``(B, M, d)``, ``scale`` ``(B,)``. The same
    elimination order and pivot shifts as the structure-of-arrays cyclic reduction
    (`_inv_dense`: Gershgorin's bound, as `_chol`), equal to rounding, every
    block operation one batched matrix product: fewer array operations (a level ~15
    instead of ~400), each on more data, so faster for a few systems and slower for many.
    Returns (solution ``(B, M, d)``, definite ``(B,)``)."""
    b, m, d = rhs.shape
    size = 1
    while size < m:
        size = 2 * size + 1
    dg = np.zeros((b, size, d, d))
    dg[:, :m] = diag
    dg[:, m:] = np.eye(d)
    of = np.zeros((b, size, d, d))
    of[:, :m - 1] = off[:, :m - 1]
    r = np.zeros((b, size, d))
    r[:, :m] = rhs
    with np.errstate(all="ignore"):
        x, ok = _cyclic_dense(dg, of, r, np.asarray(scale, dtype=np.float64), local)
    return x[:, :m], ok


def _inv_blocks(a: np.ndarray, scale: np.ndarray, local: bool) -> tuple[np.ndarray, np.ndarray]:
    b, k, d, _ = a.shape
    inv, ok = _inv_dense(_NUMPY_OPS, a.reshape(b * k, d, d), np.repeat(scale, k), local)
    return inv.reshape(b, k, d, d), ok.reshape(b, k)


def _cyclic_dense(a: np.ndarray, off: np.ndarray, r: np.ndarray, scale: np.ndarray,
                  local: bool) -> tuple[np.ndarray, np.ndarray]:
    m = r.shape[1]
    if m == 1:
        inv, ok = _inv_blocks(a, scale, local)
        return (inv @ r[..., None])[..., 0], ok.all(1)
    inv, ok_e = _inv_blocks(a[:, ::2], scale, local)  # pivots of the even unknowns
    inv_l, inv_r = inv[:, :-1], inv[:, 1:]
    left, right, nxt = off[:, 0:m - 1:2], off[:, 1::2], off[:, 2::2]
    r_e = r[:, ::2]
    w_l = inv_l @ left  # A_{k-1}^{-1} B_{k-1}
    w_r = inv_r @ np.swapaxes(right, -1, -2)  # A_{k+1}^{-1} B_k^T
    v_l = inv_l @ r_e[:, :-1, :, None]
    v_r = inv_r @ r_e[:, 1:, :, None]
    left_t = np.swapaxes(left, -1, -2)
    a2 = a[:, 1::2] - left_t @ w_l - right @ w_r
    off2 = -(np.swapaxes(w_r, -1, -2) @ nxt)
    r2 = r[:, 1::2] - (left_t @ v_l)[..., 0] - (right @ v_r)[..., 0]
    xk, ok_k = _cyclic_dense(a2, off2, r2, scale, local)
    b, _, d = r.shape
    xpad = np.zeros((b, xk.shape[1] + 2, d))
    xpad[:, 1:-1] = xk
    prev = np.concatenate([np.zeros((b, 1, d, d)), off[:, 1::2]], 1)
    rhs_e = (r_e - (np.swapaxes(prev, -1, -2) @ xpad[:, :-1, :, None])[..., 0]
             - (off[:, ::2] @ xpad[:, 1:, :, None])[..., 0])
    x = np.empty_like(r)
    x[:, ::2] = (inv @ rhs_e[..., None])[..., 0]
    x[:, 1::2] = xk
    return x, ok_e.all(1) & ok_k
