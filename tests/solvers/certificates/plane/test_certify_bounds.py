"""The bound code of :mod:`solvers.certify` (in :mod:`solvers.certificates.plane.bounds`; issue 22,
mutation testing): the corrections, the interval enclosures of the Hessians (one direction
or a group), the box / triangle test, the lowered values, the per-point / per-triangle
caches and their tightening on demand, each against an independent reference (CasADi
evaluation at sampled points, brute-force geometry, hand-computed numbers). Fast: every
test is well under a second, so that mutation runs can afford them."""

from __future__ import annotations

import importlib

import casadi as ca
import numpy as np
import pytest

import finsler
from finsler import InputError
from finsler.enclosures.intervals import Interval
from solvers.certificates.plane.mesh import _Mesh

from tests.helpers.metrics.certify_bounds import Ridge, Singular, Tilt
from tests.helpers.metrics.singular import Cone
from tests.helpers.tick_clock import TickClock

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation

# the module of the bound code (``solvers.certify`` the attribute is a function)
cm = importlib.import_module("solvers.certificates.plane.bounds")
EPS = np.finfo(float).eps


def _hessians(m: finsler.Metric) -> tuple[ca.Function, ca.Function]:
    """Reference ``(z, v) -> lambda_max(Hess_z F)`` pieces: ``Hess_z F`` and ``Hess_v F``
    as CasADi functions (the VM, not the lowered numpy code certify uses)."""
    x, v = ca.SX.sym("x", 2), ca.SX.sym("v", 2)
    f = m.F_sx(x, v)
    return (ca.Function("hx", [x, v], [ca.hessian(f, x)[0]]),
            ca.Function("hv", [x, v], [ca.hessian(f, v)[0]]))


def _lam_max(hx: ca.Function, z: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.array(hx.map(z.shape[0])(z.T, v.T)).T.reshape(-1, 2, 2)
    return np.linalg.eigvalsh(out)[:, -1]


def _chord_q(hv: ca.Function, z: np.ndarray, u: np.ndarray, d: np.ndarray) -> np.ndarray:
    out = np.array(hv.map(z.shape[0])(z.T, u.T)).T.reshape(-1, 2, 2)
    return np.einsum("ni,nij,nj->n", d, out, d)


def _boxes(n: int, half: float, radius: float, seed: int, k: int = 64
           ) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    r = radius * np.sqrt(rng.uniform(0, 1, n))
    a = rng.uniform(0, 2 * np.pi, n)
    c = np.stack([r * np.cos(a), r * np.sin(a)], 1)
    h = half * rng.uniform(0.5, 1.0, (n, 2))
    ang = 2 * np.pi * np.arange(k) / k
    dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
    kidx = rng.integers(0, k, n)
    return c - h, c + h, dirs[kidx], dirs[(kidx + 1) % k], rng


# ---- _corrections ----------------------------------------------------------------------
def test_corrections_are_the_formula_inflated_by_a_hair() -> None:
    hz = np.array([[1.0, 2.0, 3.0, 4.0], [0.0, 0.0, 0.0, 0.0]])
    ht = np.array([[0.0, 0.0, 16.0, 8.0], [0.0, 24.0, 0.0, 0.0]])
    r2 = np.array([0.5, 2.0])
    # Hz R**2 / 2 + max(Ht_{k-1}, Ht_k) / 8, k-1 taken cyclically within each triangle
    exact = np.array([[0.25 + 1.0, 0.5 + 0.0, 0.75 + 2.0, 1.0 + 2.0],
                      [0.0, 3.0, 3.0, 0.0]])
    corr = cm._corrections(hz, ht, r2)
    assert corr.shape == (2, 4)
    assert np.all(corr >= exact)
    assert np.allclose(corr, exact * (1 + 1e-12), rtol=1e-15, atol=0.0)
    assert np.all(corr[exact > 0] > exact[exact > 0])  # strictly inflated


# ---- _lam_max_upper ----------------------------------------------------------------------
def test_lam_max_upper_bounds_every_matrix_in_the_box_and_is_tight_at_points() -> None:
    rng = np.random.default_rng(0)
    n = 400
    lo = rng.normal(size=(n, 3))
    hi = lo + rng.uniform(0, 1, (n, 3)) * (rng.uniform(0, 1, (n, 1)) < 0.8)
    h = [Interval(lo[:, j], hi[:, j]) for j in range(3)]
    up = cm._lam_max_upper(h)
    assert up.shape == (n,)
    worst = np.full(n, -np.inf)
    for _ in range(40):
        t = rng.uniform(0, 1, (n, 3))
        t[:, :] = np.where(rng.uniform(0, 1, (n, 3)) < 0.3, np.round(t), t)  # box corners
        e = lo + t * (hi - lo)
        mats = np.stack([np.stack([e[:, 0], e[:, 1]], 1), np.stack([e[:, 1], e[:, 2]], 1)], 1)
        lam = np.linalg.eigvalsh(mats)[:, -1]
        assert np.all(lam <= up + 1e-12 * (1 + np.abs(up)))
        worst = np.maximum(worst, lam)
    # the worst matrix (H11, H22 at their top, |H12| at its largest) is attained: tight
    a, c = hi[:, 0], hi[:, 2]
    b = np.maximum(np.abs(lo[:, 1]), np.abs(hi[:, 1]))
    exact = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b**2)
    assert np.all(up >= exact)
    assert np.allclose(up, exact, rtol=1e-13, atol=1e-13)
    assert np.all(worst <= exact + 1e-12)


def test_lam_max_upper_of_point_matrices_is_their_eigenvalue() -> None:
    m = np.array([[[2.0, -3.0], [-3.0, -1.0]], [[0.0, 0.0], [0.0, -5.0]],
                  [[1.0, 4.0], [4.0, 1.0]]])
    h = [Interval(m[:, 0, 0]), Interval(m[:, 0, 1]), Interval(m[:, 1, 1])]
    up = cm._lam_max_upper(h)
    lam = np.linalg.eigvalsh(m)[:, -1]
    assert np.all(up >= lam) and np.allclose(up, lam, rtol=1e-14, atol=1e-14)


# ---- _centered -------------------------------------------------------------------------
def test_centered_is_the_mean_value_form() -> None:
    # f(x, y) = x * y on [1, 2] x [3, 5] around (1.5, 4): f(c) = 6, slopes [3, 5], [1, 2]
    out = cm._centered(Interval(np.array([6.0])),
                       [Interval(np.array([3.0]), np.array([5.0])),
                        Interval(np.array([1.0]), np.array([2.0]))],
                       [Interval(np.array([-0.5]), np.array([0.5])),
                        Interval(np.array([-1.0]), np.array([1.0]))])
    # 6 + [-2.5, 2.5] + [-2, 2]
    assert out.lo[0] <= 1.5 and out.lo[0] == pytest.approx(1.5, rel=1e-14)
    assert out.hi[0] >= 10.5 and out.hi[0] == pytest.approx(10.5, rel=1e-14)
    # a centre off the middle: f(c) + [1, 2] * [0, 0.5] = 3 + [0, 1]
    out = cm._centered(Interval(np.array([3.0])), [Interval(np.array([1.0]), np.array([2.0]))],
                       [Interval(np.array([0.0]), np.array([0.5]))])
    assert out.lo[0] == pytest.approx(3.0, rel=1e-14) and out.lo[0] <= 3.0
    assert out.hi[0] == pytest.approx(4.0, rel=1e-14) and out.hi[0] >= 4.0
    with pytest.raises(ValueError):
        cm._centered(Interval(np.array([0.0])), [Interval(np.array([1.0]))], [])


# ---- _bounds_on_boxes --------------------------------------------------------------------
@pytest.mark.parametrize(("name", "radius"), [("poincare", 0.7), ("matsumoto", 0.8),
                                              ("randers", 0.7)])
def test_bounds_on_boxes_hold_at_sampled_points(name: str, radius: float) -> None:
    m = finsler.get_metric(name)
    lo, hi, v, w, rng = _boxes(60, 0.05, radius, seed=1)
    hz, ht = cm._bounds_on_boxes(m, lo, hi, v, w)
    assert hz.shape == ht.shape == (60,)
    assert np.all(hz >= 0) and np.all(ht >= 0)
    # an infinite enclosure is allowed (certify then splits the box), a wrong one is not
    assert np.mean(np.isfinite(hz) & np.isfinite(ht)) > 0.9
    hx, hv = _hessians(m)
    if name == "randers":  # Hess_z F = 0: the bounds are 0 up to rounding, not inflated
        hz_c = cm._bounds_on_boxes(m, lo, hi, v, w, with_centre=True)[2]
        assert np.all(hz < 1e-100) and np.all(hz_c < 1e-100)
    seen_z, seen_t = np.zeros(60), np.zeros(60)
    for j in range(12):
        t = rng.uniform(0, 1, (60, 2))
        if j < 4:  # the box's corners
            t = np.array([[0, 0], [1, 1], [0, 1], [1, 0]], float)[j][None].repeat(60, 0)
        z = lo + t * (hi - lo)
        s = rng.uniform(0, 1, (60, 1)) if j >= 2 else np.full((60, 1), float(j))
        u = (1 - s) * v + s * w
        lam = _lam_max(hx, z, v)
        q = _chord_q(hv, z, u, w - v)
        assert np.all(lam <= hz * (1 + 1e-12) + 1e-12), name
        assert np.all(q <= ht * (1 + 1e-12) + 1e-12), name
        seen_z, seen_t = np.maximum(seen_z, lam), np.maximum(seen_t, q)
    # and tight: small boxes, typically within a factor 1.6 of the sampled maxima
    for seen, bound in ((seen_z, hz), (seen_t, ht)):
        ok = (bound > 1e-6) & np.isfinite(bound) & (seen > 0)
        if np.any(ok):  # (Randers: Hess_z F = 0)
            if name != "matsumoto":  # (steep near its rim: the median only)
                factor = {"poincare": 1.6, "randers": 8.0}[name]
                assert np.all(bound[ok] <= factor * seen[ok] + 1e-9), name
            assert np.median(bound[ok] / seen[ok]) < (5.0 if name == "matsumoto" else 2.0)


@pytest.mark.parametrize("name", ["poincare", "matsumoto"])
def test_bounds_on_tiny_boxes_approach_the_centre_values(name: str) -> None:
    """Tiny boxes: the mean-value form is tight to O(h); the centre values are exactly the
    point values at the box's centre and the chord's midpoint."""
    m = finsler.get_metric(name)
    lo, hi, v, w, _ = _boxes(40, 1e-4, 0.6, seed=2, k=4096)
    hz, ht, hz_c, ht_c = cm._bounds_on_boxes(m, lo, hi, v, w, with_centre=True)
    hx, hv = _hessians(m)
    c = 0.5 * (lo + hi)
    lam_c = _lam_max(hx, c, v)
    q_c = _chord_q(hv, c, 0.5 * (v + w), w - v)
    assert np.all(lam_c > 0) and np.mean(q_c > 0) > 0.8
    q_c = np.maximum(q_c, 0.0)  # the bounds are >= 0
    assert np.all(hz_c >= lam_c * (1 - 1e-12)) and np.allclose(hz_c, lam_c, rtol=1e-9)
    assert np.all(ht_c >= q_c * (1 - 1e-12))
    assert np.allclose(ht_c, q_c, rtol=1e-9, atol=1e-12)
    # the box's bounds are above the centre's and within 1 % of them
    assert np.all(hz >= hz_c) and np.all(hz <= 1.01 * hz_c)
    pos = ht_c > 1e-3
    assert np.all(ht >= ht_c) and np.all(ht[pos] <= 1.1 * ht_c[pos])


def test_bounds_on_boxes_are_tighter_than_the_natural_extension_alone() -> None:
    """The mean-value form matters on the Poincare disk near the rim: the natural interval
    extension of Hess_z F over a box there is loose, the bound is within 10 % of the
    sampled maximum."""
    m = finsler.get_metric("poincare")
    c = np.array([[0.8, 0.0], [0.0, -0.75], [0.55, 0.55]])
    lo, hi = c - 0.01, c + 0.01
    v = np.array([[1.0, 0.0], [0.0, 1.0], [np.sqrt(0.5), np.sqrt(0.5)]])
    rot = np.array([[np.cos(0.1), np.sin(0.1)], [-np.sin(0.1), np.cos(0.1)]])
    w = v @ rot
    hz, ht = cm._bounds_on_boxes(m, lo, hi, v, w)
    hx, hv = _hessians(m)
    grid = np.linspace(0, 1, 9)
    seen_z = np.zeros(3)
    seen_t = np.zeros(3)
    for a in grid:
        for b in grid:
            z = lo + np.array([a, b]) * (hi - lo)
            seen_z = np.maximum(seen_z, _lam_max(hx, z, v))
            u = (1 - a) * v + a * w
            seen_t = np.maximum(seen_t, _chord_q(hv, z, u, w - v))
    assert np.all(hz >= seen_z) and np.all(hz <= 1.1 * seen_z)
    assert np.all(ht >= seen_t) and np.all(ht <= 1.2 * seen_t)


def test_bounds_on_boxes_infinite_where_one_enclosure_is() -> None:
    m = Cone()
    lo = np.array([[-0.1, -0.1], [0.3, 0.3]])
    hi = np.array([[0.1, 0.1], [0.4, 0.4]])
    v = np.array([[1.0, 0.0], [1.0, 0.0]])
    w = np.array([[np.cos(0.1), np.sin(0.1)]] * 2)
    hz, ht = cm._bounds_on_boxes(m, lo, hi, v, w)
    # the box around the origin: Hess_z F unbounded, so both are infinite (certify splits)
    assert hz[0] == np.inf and ht[0] == np.inf
    assert np.isfinite(hz[1]) and np.isfinite(ht[1])
    # away from it: F = (1 + |x|) |v|, Hess_z |x| = (I - x x'/|x|^2) / |x|: lam_max 1/|x|
    hx, _ = _hessians(m)
    z = np.array([[0.3, 0.3], [0.4, 0.4], [0.3, 0.4], [0.4, 0.3]])
    assert hz[1] >= _lam_max(hx, z, v[[1] * 4]).max()
    assert hz[1] <= 2.0 / (0.3 * np.sqrt(2))


# ---- _box_meets_triangle -------------------------------------------------------------------
def _segments_cross(p: np.ndarray, q: np.ndarray, r: np.ndarray, s: np.ndarray) -> bool:
    def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
        return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    def on(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
        return bool(min(a[0], b[0]) <= c[0] <= max(a[0], b[0])
                    and min(a[1], b[1]) <= c[1] <= max(a[1], b[1]))

    d1, d2, d3, d4 = orient(r, s, p), orient(r, s, q), orient(p, q, r), orient(p, q, s)
    if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
        return True
    return ((d1 == 0 and on(r, s, p)) or (d2 == 0 and on(r, s, q))
            or (d3 == 0 and on(p, q, r)) or (d4 == 0 and on(p, q, s)))


def _in_triangle(t: np.ndarray, p: np.ndarray) -> bool:
    s = [(t[(i + 1) % 3, 0] - t[i, 0]) * (p[1] - t[i, 1])
         - (t[(i + 1) % 3, 1] - t[i, 1]) * (p[0] - t[i, 0]) for i in range(3)]
    return bool(all(x >= 0 for x in s) or all(x <= 0 for x in s))


def _meets_brute(lo: np.ndarray, hi: np.ndarray, tri: np.ndarray) -> bool:
    """Closed box and closed triangle meet: a vertex of one inside the other, or two edges
    cross (exact on small integers)."""
    box = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
    if any(np.all(lo <= p) and np.all(p <= hi) for p in tri):
        return True
    if any(_in_triangle(tri, p) for p in box):
        return True
    return any(_segments_cross(box[i], box[(i + 1) % 4], tri[j], tri[(j + 1) % 3])
               for i in range(4) for j in range(3))


@pytest.mark.parametrize("scale", [1.0, 1 / 64])
def test_box_meets_triangle_agrees_with_brute_force_geometry(scale: float) -> None:
    """Small integers (and the same over 64: exact binary fractions, so that the brute
    force stays exact, with areas below 1 as in a mesh)."""
    rng = np.random.default_rng(5)
    n = 1500
    lo = rng.integers(-6, 6, (n, 2)).astype(float)
    hi = lo + rng.integers(0, 5, (n, 2))
    tri = rng.integers(-8, 8, (n, 3, 2)).astype(float)
    lo, hi, tri = lo * scale, hi * scale, tri * scale
    area = ((tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1])
            - (tri[:, 1, 1] - tri[:, 0, 1]) * (tri[:, 2, 0] - tri[:, 0, 0]))
    keep = area != 0
    lo, hi, tri = lo[keep], hi[keep], tri[keep]
    got = cm._box_meets_triangle(lo, hi, tri)
    want = np.array([_meets_brute(lo[i], hi[i], tri[i]) for i in range(len(lo))])
    assert got.dtype == bool and got.shape == want.shape
    assert np.array_equal(got, want), np.flatnonzero(got != want)[:5]
    assert 0.2 < want.mean() < 0.8  # both answers well represented


def test_box_meets_triangle_touching_counts() -> None:
    tri = np.array([[[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]]] * 6)
    lo = np.array([[2.0, -1.0],   # touches the vertex (2, 0) with its top-left corner
                   [1.0, 1.0],    # touches the hypotenuse at (1, 1) with its corner
                   [-1.0, 2.0],   # touches the vertex (0, 2) with its bottom edge
                   [1.0, 1.0001],  # just beyond the hypotenuse
                   [-3.0, -3.0],  # just below-left, corner (-1e-9, -1e-9)
                   [2.0001, -1.0]])  # just right of the vertex (2, 0)
    hi = np.array([[3.0, 0.0], [2.0, 2.0], [1.0, 3.0], [2.0, 2.0], [-1e-9, -1e-9],
                   [3.0, 0.0]])
    assert cm._box_meets_triangle(lo, hi, tri).tolist() == [True, True, True, False, False,
                                                           False]
    # either orientation of the triangle
    assert cm._box_meets_triangle(lo, hi, tri[:, ::-1]).tolist() == [True, True, True, False,
                                                                    False, False]


# ---- _eval_values ------------------------------------------------------------------------
def test_eval_values_are_lowered_by_16_ulp_and_chunked() -> None:
    m = finsler.get_metric("euclidean")
    v = np.array([[3.0, 4.0], [0.0, -2.0], [6.0, 8.0], [-1.0, 0.0], [0.0, 0.5]] * 3)
    x = np.zeros_like(v)
    exact = np.linalg.norm(v, axis=1)
    want = exact - exact * 16 * EPS
    for chunk in (200_000, 4, 1):
        out = cm._eval_values(m, x, v, chunk=chunk)
        assert out.shape == (15,)
        assert np.array_equal(out, want), chunk
    # a metric with x-dependence, against its own numpy F
    mp = finsler.get_metric("poincare")
    rng = np.random.default_rng(0)
    xx = rng.uniform(-0.5, 0.5, (7, 2))
    vv = rng.normal(size=(7, 2))
    ref = np.asarray(mp.F(xx, vv), float).reshape(-1)
    out = cm._eval_values(mp, xx, vv, chunk=3)
    assert np.all(out < ref) and np.allclose(out, ref * (1 - 16 * EPS), rtol=4 * EPS, atol=0)


@pytest.mark.parametrize("kind", ["invalid", "divide", "over"])
def test_eval_values_refuse_non_finite_values(kind: str) -> None:
    """The clear error, whatever the caller's numpy error state (the floating-point error
    itself is silenced: under ``np.errstate(all="raise")`` it would otherwise escape as a
    FloatingPointError)."""
    m = Singular(kind)
    x = np.array([[0.0, 0.0], [-2.0, 0.0]])
    v = np.array([[1.0, 0.0], [1.0, 0.0]])
    msg = (r"^singular-bounds-test: F is not finite on the mesh \(the polygon covering the "
           r"domain reaches a singularity of F\?\)$")
    with np.errstate(all="raise"), pytest.raises(InputError, match=msg):
        cm._eval_values(m, x, v)
    out = cm._eval_values(m, x[:1], v[:1])
    assert out[0] == {"invalid": 1.0, "divide": 0.5, "over": 1.0}[kind] * (1.0 - 16 * EPS)


# ---- _PointData ----------------------------------------------------------------------------

def test_point_data_time_is_summed_over_the_calls_that_compute(monkeypatch) -> None:
    monkeypatch.setattr(cm, "time", TickClock())
    data = cm._PointData(finsler.get_metric("poincare"), 4)
    data.rows(np.array([[0.1, 0.2]]))
    assert data.seconds == 1.0
    data.rows(np.array([[0.1, 0.2]]))  # nothing new: not timed
    assert data.seconds == 1.0
    data.rows(np.array([[0.3, 0.2], [0.1, 0.2]]))
    assert data.seconds == 2.0
    tri = np.array([[[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]])
    data.triangle_bounds(tri, np.ones((1, 4)), np.array([1e-4]))
    assert data.seconds == 3.0
    data.triangle_bounds(tri, np.ones((1, 4)), np.array([1e-4]))
    assert data.seconds == 3.0


def test_point_data_triangles_are_keyed_by_all_their_coordinates() -> None:
    """Two triangles with the same x coordinates are different triangles."""
    m = finsler.get_metric("poincare")
    data = cm._PointData(m, 8)
    a = np.array([[0.0, 0.0], [0.2, 0.0], [0.0, 0.2]])
    b = a + np.array([0.0, 0.5])
    hz, _ = data.triangle_bounds(np.stack([a, b]), np.ones((2, 8)), np.full(2, 1e-4))
    assert len(data.tri_index) == 2 and np.all(hz[1] > hz[0])
    hz_b, _ = data.triangle_bounds(b[None], np.ones((1, 8)), np.full(1, 1e-4))
    assert np.array_equal(hz_b[0], hz[1])


def test_point_data_rows_cache_values_per_point() -> None:
    m = finsler.get_metric("poincare")
    data = cm._PointData(m, 8)
    ang = 2 * np.pi * np.arange(8) / 8
    assert np.allclose(data.dirs, np.stack([np.cos(ang), np.sin(ang)], 1), rtol=0, atol=1e-15)
    assert data.F.shape == (0, 8) and data.Hz.shape == (0, 8) and data.Ht.shape == (0, 8)
    assert data.seconds == 0.0 and data.index == {} and data.tri_index == {}
    pts = np.array([[0.1, 0.2], [-0.3, 0.0], [0.1, 0.2], [0.0, 0.4]])
    rows = data.rows(pts)
    assert rows.tolist() == [0, 1, 0, 2] and rows.dtype == np.int64
    assert data.F.shape == (3, 8) and data.seconds > 0
    for i, p in enumerate(pts[[0, 1, 3]]):
        ref = np.asarray(m.F(np.repeat(p[None], 8, 0), data.dirs), float).reshape(-1)
        assert np.all(data.F[i] < ref) and np.allclose(data.F[i], ref, rtol=1e-13)
    # known points are not evaluated again; new ones get the next rows
    before = data.F.copy()
    rows = data.rows(np.array([[0.0, 0.4], [0.5, 0.0], [0.1, 0.2]]))
    assert rows.tolist() == [2, 3, 0]
    assert np.array_equal(data.F[:3], before)
    assert data.F.shape == (4, 8)
    assert np.allclose(data.F[3], np.asarray(m.F(np.repeat([[0.5, 0.0]], 8, 0), data.dirs),
                                              float).reshape(-1), rtol=1e-13)


def _triangle_samples(tri: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
    lam = np.vstack([np.eye(3), rng.dirichlet(np.ones(3), n)])
    return lam @ tri


def _assert_above_sampled_hessians(m: finsler.Metric, corners: np.ndarray, dirs: np.ndarray,
                                   hz: np.ndarray, ht: np.ndarray, seed: int, n: int) -> None:
    """``hz[t, j]`` above ``lambda_max(Hess_z F(z, v_j))`` and ``ht[t, j]`` above the chord
    second derivatives from ``v_j`` to ``v_{j+1}``, at ``n`` sampled points of each
    triangle ``corners[t]`` (and random points of each chord)."""
    hx, hv = _hessians(m)
    rng = np.random.default_rng(seed)
    k = dirs.shape[0]
    for t in range(corners.shape[0]):
        z = _triangle_samples(corners[t], rng, n)
        for j in range(k):
            v = np.repeat(dirs[j][None], len(z), 0)
            w = np.repeat(dirs[(j + 1) % k][None], len(z), 0)
            s = rng.uniform(0, 1, (len(z), 1))
            assert _lam_max(hx, z, v).max() <= hz[t, j] * (1 + 1e-12)
            assert _chord_q(hv, z, (1 - s) * v + s * w, w - v).max() <= ht[t, j] * (1 + 1e-12)


def test_point_data_triangle_bounds_hold_inside_and_are_cached() -> None:
    m = finsler.get_metric("poincare")
    k = 16
    data = cm._PointData(m, k)
    corners = np.array([[[0.1, 0.0], [0.3, 0.05], [0.15, 0.2]],
                        [[-0.5, -0.5], [-0.3, -0.55], [-0.45, -0.3]]])
    f = np.array([np.asarray(m.F(np.repeat(c, k, 0), np.tile(data.dirs, (3, 1))),
                             float).reshape(3, k).min(0) for c in corners])
    r2 = np.array([1e-4, 2e-4])  # small: the corrections stay below the split threshold
    hz, ht = data.triangle_bounds(corners, f, r2)
    assert hz.shape == ht.shape == (2, k) and np.all(np.isfinite(hz)) and np.all(hz >= 0)
    assert data.seconds > 0 and len(data.tri_index) == 2
    # the same triangles, vertices permuted, in another order: looked up, not recomputed
    data.Hz[:] += 1.0  # (a recomputation would not see this)
    hz2, ht2 = data.triangle_bounds(corners[::-1][:, [2, 0, 1]], f[::-1], r2[::-1])
    assert np.array_equal(hz2, hz[::-1] + 1.0) and np.array_equal(ht2, ht[::-1])
    assert len(data.tri_index) == 2 and data.Hz.shape == (2, k)
    data.Hz[:] -= 1.0
    # sound: above the sampled Hessians over each triangle (and its chords)
    _assert_above_sampled_hessians(m, corners, data.dirs, hz, ht, seed=1, n=30)
    # and equal to the bounds on the triangles' bounding boxes (no split: corrections small)
    for t in range(2):
        bz, bt = cm._bounds_on_boxes(m, np.repeat(corners[t].min(0)[None], k, 0),
                                     np.repeat(corners[t].max(0)[None], k, 0), data.dirs,
                                     np.roll(data.dirs, -1, axis=0))
        assert np.array_equal(hz[t], bz) and np.array_equal(ht[t], bt)


def _split_reference(m: finsler.Metric, dirs: np.ndarray, items: list[tuple], depth: int
                     ) -> list[tuple[float, float]]:
    """Bounds of elements ``(lo, hi, tri, j, fmin, r2)`` by the documented rule, box by box
    (brute-force geometry), the boxes of one level evaluated together."""
    if not items:
        return []
    k = dirs.shape[0]
    j = np.array([it[3] for it in items])
    hz, ht, hz_c, ht_c = (np.broadcast_to(a, (len(items),)) for a in cm._bounds_on_boxes(
        m, np.array([it[0] for it in items]), np.array([it[1] for it in items]), dirs[j],
        dirs[(j + 1) % k], with_centre=True))
    out: list[tuple[float, float]] = []
    children: list[tuple] = []
    owner: list[int] = []
    for i, (lo, hi, tri, jj, fmin, r2) in enumerate(items):
        out.append((float(hz[i]), float(ht[i])))
        if depth >= cm.SPLIT_DEPTH:
            continue
        large = not (0.5 * hz[i] * r2 + ht[i] / 8.0 <= cm.SPLIT_FRACTION * fmin)
        over = not (hz[i] <= cm.SPLIT_OVERESTIMATE * hz_c[i] + 1e-12 * fmin
                    and ht[i] <= cm.SPLIT_OVERESTIMATE * ht_c[i] + 1e-12 * fmin)
        if not (large and over):
            continue
        out[i] = (-np.inf, -np.inf)
        mid = 0.5 * (lo + hi)
        for xs in ((lo[0], mid[0]), (mid[0], hi[0])):
            for ys in ((lo[1], mid[1]), (mid[1], hi[1])):
                sl, sh = np.array([xs[0], ys[0]]), np.array([xs[1], ys[1]])
                if _meets_brute(sl, sh, tri):
                    children.append((sl, sh, tri, jj, fmin, r2))
                    owner.append(i)
    for i, (a, b) in zip(owner, _split_reference(m, dirs, children, depth + 1), strict=True):
        out[i] = (max(out[i][0], a), max(out[i][1], b))
    return out


def test_point_data_splits_loose_boxes_by_the_documented_rule() -> None:
    """A triangle whose bounding box reaches towards the Poincare rim (corner (0.6, 0.6))
    far from the triangle: the enclosures over the box are loose, the corrections large, so
    the boxes are split (2 levels) into sub-boxes that meet the triangle; the bounds drop
    and stay above the sampled Hessians."""
    m = finsler.get_metric("poincare")
    k = 8
    data = cm._PointData(m, k)
    tri = np.array([[0.0, 0.0], [0.6, 0.0], [0.0, 0.6]])
    fmin = np.asarray(m.F(np.repeat(tri, k, 0), np.tile(data.dirs, (3, 1))),
                      float).reshape(3, k).min(0)
    r2 = 0.2
    hz, ht = data.triangle_bounds(tri[None], fmin[None], np.array([r2]))
    bz, bt = cm._bounds_on_boxes(m, np.repeat(tri.min(0)[None], k, 0),
                                 np.repeat(tri.max(0)[None], k, 0), data.dirs,
                                 np.roll(data.dirs, -1, axis=0))
    assert np.all(hz[0] <= bz) and np.all(ht[0] <= bt)
    assert np.all(hz[0] < 0.8 * bz)  # split, and it pays
    want = _split_reference(m, data.dirs, [(tri.min(0), tri.max(0), tri, j, fmin[j], r2)
                                           for j in range(k)], 0)
    assert [(hz[0, j], ht[0, j]) for j in range(k)] == want
    hx, hv = _hessians(m)
    rng = np.random.default_rng(2)
    z = _triangle_samples(tri, rng, 200)
    for j in range(k):
        v = np.repeat(data.dirs[j][None], len(z), 0)
        w = np.repeat(data.dirs[(j + 1) % k][None], len(z), 0)
        s = rng.uniform(0, 1, (len(z), 1))
        assert _lam_max(hx, z, v).max() <= hz[0, j] * (1 + 1e-12)
        assert _chord_q(hv, z, (1 - s) * v + s * w, w - v).max() <= ht[0, j] * (1 + 1e-12)


@pytest.mark.parametrize("metric", [finsler.get_metric("poincare"), Cone(), Ridge(),
                                    Tilt()], ids=["poincare", "cone", "ridge", "tilt"])
def test_split_decisions_follow_the_documented_rule(metric: finsler.Metric) -> None:
    """Elements on both sides of each test of the rule: corrections small or large against
    F (``fmin`` and ``r2`` from tiny to huge), enclosures tight or loose (the cone: Hz loose
    and Ht tight; the ridge: Hz tight and Ht loose; the tilt: Hz 0 and Ht tight, where the
    ``1e-12 F`` allowance decides), each bound compared with the rule applied box by
    box."""
    k = 256  # short chords: Ht tight where F(x, .) varies little over the box
    data = cm._PointData(metric, k)
    tris = {"near": np.array([[0.1, 0.1], [0.3, 0.1], [0.1, 0.3]]),
            "mid": np.array([[0.15, 0.15], [0.45, 0.15], [0.15, 0.45]]),
            "wide": np.array([[0.05, 0.0], [0.6, 0.05], [0.0, 0.6]])}
    lo, hi, tri, kidx, fmin, r2 = [], [], [], [], [], []
    for j, (t, f, r) in enumerate([(t, f, r) for t in tris.values()
                                   for f, r in ((1e-13, 1e-6), (1e3, 1e3), (1.0, 1e-6))]):
        lo.append(t.min(0))
        hi.append(t.max(0))
        tri.append(t)
        kidx.append(3 * j % k)
        fmin.append(f)
        r2.append(r)
    # and at the threshold of "large": just below / above it, with the Ht term a good part
    for t in tris.values():
        j = 1
        hz, ht = cm._bounds_on_boxes(metric, t.min(0)[None], t.max(0)[None], data.dirs[[j]],
                                     data.dirs[[j + 1]])
        if not (np.isfinite(hz[0]) and np.isfinite(ht[0]) and ht[0] > 0):
            continue
        r = 0.25 * ht[0] / max(hz[0], 1e-300)  # the Hz term is as large as Ht / 8 / 2
        for ratio in (0.9, 1.1):
            lo.append(t.min(0))
            hi.append(t.max(0))
            tri.append(t)
            kidx.append(j)
            r2.append(r)
            fmin.append((0.5 * hz[0] * r + ht[0] / 8.0) / (cm.SPLIT_FRACTION * ratio))
    lo, hi, tri = np.array(lo), np.array(hi), np.array(tri)
    kidx, fmin, r2 = np.array(kidx), np.array(fmin), np.array(r2)
    hz, ht = data._split_bounds(lo, hi, tri, kidx, fmin, r2, 0)
    want = _split_reference(metric, data.dirs, list(zip(lo, hi, tri, kidx, fmin, r2,
                                                        strict=True)), 0)
    assert list(zip(hz, ht, strict=True)) == want
    whole = cm._bounds_on_boxes(metric, lo, hi, data.dirs[kidx], data.dirs[(kidx + 1) % k])
    split = (hz != whole[0]) | (ht != whole[1])
    if isinstance(metric, Tilt):  # both enclosures tight: nothing is split
        assert split.sum() == 0
    else:
        assert 0 < split.sum() < len(lo)  # both kinds present


@pytest.mark.parametrize("group", [1, 2])
def test_triangle_bounds_evaluate_each_element_once_whatever_the_chunk(monkeypatch,
                                                                        group: int) -> None:
    m = finsler.get_metric("poincare")
    rows = [0]
    real = cm._bounds_on_dir_boxes

    def counted(metric, lo, hi, db, with_centre=False):
        rows[0] += lo.shape[0]
        return real(metric, lo, hi, db, with_centre=with_centre)

    monkeypatch.setattr(cm, "_bounds_on_dir_boxes", counted)
    corners = np.array([[[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]],
                        [[0.2, 0.2], [0.3, 0.2], [0.2, 0.3]]])
    ref = None
    for chunk in (32768, 5, 1):
        data = cm._PointData(m, 32, group)
        rows[0] = 0
        out = data.triangle_bounds(corners, np.full((2, 32), 1e3), np.full(2, 1e-4), chunk=chunk)
        # no split (small corrections): 2 triangles x 32 / group
        assert rows[0] == 64 // group, chunk
        if ref is None:
            ref = out
        assert np.array_equal(out[0], ref[0]) and np.array_equal(out[1], ref[1])
        # tightening: each (triangle, direction) once, only where grouped
        rows[0] = 0
        data.tighten(np.array([0, 0, 1, 0]), np.array([3, 3, 5, 4]), np.full(4, 1e3),
                     chunk=chunk)
        assert rows[0] == (0 if group == 1 else 3), chunk
        rows[0] = 0
        data.tighten(np.array([0, 1]), np.array([3, 5]), np.full(2, 1e3), chunk=chunk)
        assert rows[0] == 0


# ---- _row_bounds -------------------------------------------------------------------------
def test_row_bounds_are_values_minus_corrections() -> None:
    m = finsler.get_metric("poincare")
    pts = np.array([[0.0, 0.0], [0.3, 0.0], [0.0, 0.3], [0.3, 0.3], [-0.2, 0.1]])
    msh = _Mesh(pts)
    data = cm._PointData(m, 8)
    b, corr = cm._row_bounds(msh, data)
    t = msh.n_tri
    assert b.shape == (t, 3, 8) and corr.shape == (t, 8)
    f = np.stack([np.asarray(m.F(np.repeat(pts[msh.tri[:, i]], 8, 0),
                                 np.tile(data.dirs, (t, 1))), float).reshape(t, 8)
                  for i in range(3)], 1)
    hz, ht = data.triangle_bounds(pts[msh.tri], f.min(axis=1), msh.r2)
    want = cm._corrections(hz, ht, msh.r2)
    assert np.array_equal(corr, want) and np.all(corr > 0)
    assert np.all(b < f) and np.allclose(b, f - corr[:, None, :], rtol=1e-13, atol=0)


# ---- groups of directions, tightened on demand ----------------------------------------------
def test_direction_group_spans_at_most_the_group_arc() -> None:
    assert [cm.direction_group(k) for k in (8, 128, 200, 256, 512, 1024)] == [1, 1, 1, 2, 4, 8]
    for k in (96, 384, 600, 768):
        g = cm.direction_group(k)
        assert k % g == 0 and (g == 1 or g * 2 * np.pi / k <= cm.GROUP_ARC * (1 + 1e-12))
        assert not any(k % h == 0 and h * 2 * np.pi / k <= cm.GROUP_ARC for h in
                       range(g + 1, k + 1))


@pytest.mark.parametrize("name", ["matsumoto", "poincare"])
def test_group_bounds_hold_for_every_direction_and_chord_of_the_group(name: str) -> None:
    """One enclosure per triangle and group of 4 directions (arcs of 11 degrees at 128): a
    proven bound for each of the group's directions and chords, checked against the sampled
    Hessians of every direction; above the direction-by-direction bounds (looser), and
    tightening gives exactly the smaller of the two."""
    m = finsler.get_metric(name)
    k, group = 128, 4
    loose = cm._PointData(m, k, group)
    single = cm._PointData(m, k)
    corners = np.array([[[0.1, 0.0], [0.25, 0.05], [0.12, 0.18]],
                        [[-0.45, -0.3], [-0.3, -0.4], [-0.35, -0.2]]])
    f = np.full((2, k), 1e3)  # no split: the enclosures over the bounding boxes
    r2 = np.array([1e-4, 2e-4])
    hz, ht = loose.triangle_bounds(corners, f, r2)
    hz1, ht1 = single.triangle_bounds(corners, f, r2)
    assert np.all(np.isfinite(hz)) and np.all(np.isfinite(ht))
    # constant over each group, and mostly looser than one direction at a time (not
    # everywhere: the mean-value form of a group is centred elsewhere)
    assert np.all(hz.reshape(2, -1, group) == hz[:, ::group, None])
    assert np.mean(hz > hz1) > 0.5 and np.mean(ht > ht1) > 0.5
    _assert_above_sampled_hessians(m, corners, loose.dirs, hz, ht, seed=3, n=20)
    # tightening every element: the smaller of the group's and the direction's own bound
    rows = np.repeat([0, 1], k)
    kk = np.tile(np.arange(k), 2)
    changed = loose.tighten(rows, kk, f.reshape(-1))
    assert changed.all() and loose.tight.all()
    assert np.array_equal(loose.Hz, np.minimum(hz, hz1))
    assert np.array_equal(loose.Ht, np.minimum(ht, ht1))


def test_row_bounds_tighten_in_place_the_rows_asked_for_and_the_chord_before() -> None:
    """``_RowBounds.tighten`` bounds (triangle, direction) and (triangle, direction - 1)
    direction by direction (a row's correction takes both chords' Ht) and rewrites ``b``
    and ``corr`` of those triangles in place: the arrays the LP holds see the change."""
    m = finsler.get_metric("matsumoto")
    pts = np.array([[0.0, 0.0], [0.3, 0.0], [0.0, 0.3], [0.3, 0.3], [-0.2, 0.1]])
    msh = _Mesh(pts)
    k = 256
    data = cm._PointData(m, k, 2)
    rb = cm._RowBounds(msh, data)
    b_view, corr_view = rb.b, rb.corr
    b0, corr0 = rb.b.copy(), rb.corr.copy()
    rb.tighten(np.array([1]), np.array([10]))
    assert rb.b is b_view and rb.corr is corr_view
    assert data.tight[rb.trows[1], [9, 10]].all() and data.tight.sum() == 2
    want = cm._corrections(data.Hz[rb.trows], data.Ht[rb.trows], msh.r2)
    assert np.array_equal(rb.corr, want)
    assert np.array_equal(rb.b, rb.f - want[:, None, :])
    # only triangle 1 changed, and only where its bounds did (rows 9-11: Hz_10, Ht_9, Ht_10)
    diff = np.flatnonzero(np.any(rb.corr != corr0, axis=0))
    assert set(diff) <= {9, 10, 11} and diff.size > 0
    assert np.array_equal(np.delete(rb.b, 1, axis=0), np.delete(b0, 1, axis=0))
    assert np.all(rb.corr <= corr0) and np.all(rb.b >= b0)
