"""Fast focused tests of validation/testing/regions.py (mutation testing of
the property suite). No CasADi, no solve: small duck-typed metrics (a real ``Disk`` or
``Box`` domain and a numpy ``F``) whose invalid regions, scans and fundamental tensors are
known by hand; every sample set is recomputed independently from the same seeded
generator, and every sentence is written out in full."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import pytest

from finsler import Box, Disk
from validation.testing import regions as R

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


class Fake:
    """A metric by duck typing: ``domain``, ``dim`` and ``F(x, v, check=False)``."""

    def __init__(self, domain, f=None, hessian=None):
        self.domain = domain
        self.dim = domain.dim
        self._f = f if f is not None else (lambda x, v: np.linalg.norm(v, axis=-1))
        self._h = hessian
        self.calls = []

    def F(self, x, v, check=True):
        assert check is False
        x, v = np.asarray(x), np.asarray(v)
        assert x.shape == v.shape and x.shape[-1] == self.dim, (x.shape, v.shape)
        self.calls.append((x.shape, v.shape))
        return self._f(np.asarray(x, float), np.asarray(v, float))

    def lowered_hessian(self, xs, dirs):
        # a lowered CasADi function takes float64 points, one per direction
        assert xs.dtype == np.float64 and xs.shape == dirs.shape, (xs.dtype, xs.shape)
        return (self._h(np.asarray(xs), np.asarray(dirs)),)


@dataclass(frozen=True)
class SloppyDisk(Disk):
    """A unit disk whose projection lands ``slack`` (relative) outside it."""

    slack: float = 0.0

    def project(self, x):
        return np.asarray(Disk.project(self, x)) * (1.0 + self.slack)


# ----------------------------------------------------------------------------------------
# centre, box around, boundary points
# ----------------------------------------------------------------------------------------
def test_centre_of_disk_and_boxes_with_infinite_sides():
    np.testing.assert_array_equal(R._centre(Fake(Disk(2.0, (1.0, -3.0)))), [1.0, -3.0])
    c = R._centre(Fake(Disk(2.0, (1, -3))))  # integer centre: float64 all the same
    assert c.dtype == np.float64 and c.tolist() == [1.0, -3.0]
    np.testing.assert_array_equal(R._centre(Fake(Box((0.0, 2.0), (4.0, 6.0)))), [2.0, 4.0])
    # an infinite side counts as 0 on its own side
    np.testing.assert_array_equal(R._centre(Fake(Box((-math.inf, 0.0), (5.0, 2.0)))),
                                  [2.5, 1.0])
    np.testing.assert_array_equal(R._centre(Fake(Box((1.0, 0.0), (math.inf, 2.0)))),
                                  [0.5, 1.0])


def test_box_around_pads_a_fifth_and_bounds_infinite_sides_by_ten():
    lo, hi = R._box_around(Fake(Box((0.0, 0.0), (1.0, 2.0))))
    np.testing.assert_allclose(lo, [-0.2, -0.4], rtol=0, atol=1e-15)
    np.testing.assert_allclose(hi, [1.2, 2.4], rtol=0, atol=1e-15)
    lo, hi = R._box_around(Fake(Box((-math.inf, 0.0), (3.0, math.inf))))
    np.testing.assert_allclose(lo, [-10.0 - 2.6, 0.0 - 2.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(hi, [3.0 + 2.6, 10.0 + 2.0], rtol=0, atol=1e-12)


def _reference_boundary_disk(n, seed):
    """boundary_points of the unit disk recomputed: 8 n uniform draws in [-1.4, 1.4]^2
    (the bounding box padded by a fifth of its width, 0.4, on each side), those of norm > 1
    (the first n) scaled onto the circle."""
    rng = np.random.default_rng(seed)
    p = rng.uniform([-1.4, -1.4], [1.4, 1.4], size=(8 * n, 2))
    out = p[p[:, 0] ** 2 + p[:, 1] ** 2 > 1.0][:n]
    return out / np.hypot(out[:, 0], out[:, 1])[:, None]


@pytest.mark.parametrize("n", [1, 7, 40])
def test_boundary_points_of_the_disk(n):
    got = R.boundary_points(Fake(Disk()), n, np.random.default_rng(5))
    assert got.shape == (n, 2)
    np.testing.assert_allclose(np.hypot(got[:, 0], got[:, 1]), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(got, _reference_boundary_disk(n, 5), rtol=0, atol=1e-15)


def test_boundary_points_from_exactly_eight_n_draws():
    """1-D box [0, 1]: draws in [-0.2, 1.2], the first n of those outside [0, 1] clipped;
    for some seeds none of the 8 n draws is outside (fewer points, not more draws)."""
    fewer = 0
    for seed in range(300):
        got = R.boundary_points(Fake(Box((0.0,), (1.0,))), 1, np.random.default_rng(seed))
        p = np.random.default_rng(seed).uniform(-0.2, 1.2, size=(8, 1))
        want = np.clip(p[(p < 0.0) | (p > 1.0)][:1], 0.0, 1.0).reshape(-1, 1)
        np.testing.assert_array_equal(got, want)
        fewer += len(want) == 0
    assert fewer > 0


def test_boundary_points_of_a_box_and_none():
    got = R.boundary_points(Fake(Box((0.0, 0.0), (1.0, 1.0))), 30, np.random.default_rng(2))
    assert got.shape == (30, 2)
    assert np.all((got >= 0.0) & (got <= 1.0))
    on_side = np.isclose(got, 0.0, atol=0) | np.isclose(got, 1.0, atol=0)
    assert np.all(on_side.any(axis=1))
    none = R.boundary_points(Fake(Box((0.0,), (1.0,))), 0, np.random.default_rng(2))
    assert none.shape == (0, 1)


# ----------------------------------------------------------------------------------------
# DomainScan and scan_domain
# ----------------------------------------------------------------------------------------
def test_domain_scan_bad_values_and_what():
    v = np.array([[1.0, np.nan], [0.0, 2.0], [0.0, 0.0], [3.0, 4.0], [-1.0, np.nan],
                  [5.0, 6.0]])
    s = R.DomainScan(np.zeros((6, 1)), np.array([[1.0], [-1.0]]), v, 4)
    np.testing.assert_array_equal(s.bad_values, [[False, True], [True, False],
                                                 [True, True], [False, False],
                                                 [True, True], [False, False]])
    np.testing.assert_array_equal(s.bad, [True, True, True, False, True, False])
    assert s.what() == "zero or NaN or negative"  # 3 zeros, 2 NaN, 1 negative
    inf = R.DomainScan(np.zeros((2, 1)), np.eye(1), np.array([[np.inf], [np.inf]]), 2)
    assert inf.what() == "infinite"
    ok = R.DomainScan(np.zeros((1, 1)), np.eye(1), np.array([[1.0]]), 1)
    assert ok.what() == "invalid" and not ok.bad.any()


def _nan_beyond(r):
    def f(x, v):
        return np.linalg.norm(v, axis=-1) * np.where(np.linalg.norm(x, axis=-1) <= r,
                                                     1.0 + x[:, 0] ** 2, np.nan)
    return f


def test_scan_domain_points_directions_and_values():
    m = Fake(Disk(), _nan_beyond(0.5))
    scan = R.scan_domain(m, seed=3, inside=50, boundary=20)
    rng = np.random.default_rng([3, 48])
    inside = Disk().sample(50, rng)
    boundary = R.boundary_points(Fake(Disk()), 20, rng)
    np.testing.assert_array_equal(scan.points, np.concatenate([inside, boundary, [[0, 0]]]))
    assert scan.inside == 50
    np.testing.assert_array_equal(scan.directions, [[1, 0], [0, 1], [-1, 0], [0, -1]])
    r = np.hypot(scan.points[:, 0], scan.points[:, 1])
    want = np.where(r <= 0.5, 1.0 + scan.points[:, 0] ** 2, np.nan)
    np.testing.assert_array_equal(scan.values, np.repeat(want[:, None], 4, axis=1))
    np.testing.assert_array_equal(scan.bad, r > 0.5)
    assert m.calls == [((71 * 4, 2), (71 * 4, 2))]  # one batched call


def test_scan_domain_default_sizes_and_seed():
    m = Fake(Disk(0.5, (1.0, 1.0)))
    scan = R.scan_domain(m)
    assert len(scan.points) == 2048 + 512 + 1 and scan.inside == 2048
    np.testing.assert_array_equal(scan.points[:2048],
                                  Disk(0.5, (1.0, 1.0)).sample(2048,
                                                               np.random.default_rng([0, 48])))
    np.testing.assert_array_equal(scan.points[-1], [1.0, 1.0])
    assert R.INSIDE_SAMPLES == 2048 and R.BOUNDARY_SAMPLES == 512


def test_scan_domain_drops_points_outside_and_keeps_the_boundary():
    # a box: projections land exactly on the faces and are kept (tolerance 1e-9)
    m = Fake(Box((0.0, 0.0), (1.0, 1.0)))
    scan = R.scan_domain(m, seed=1, inside=10, boundary=10)
    assert len(scan.points) == 21
    assert np.all(m.domain.contains(scan.points, tol=0.0))


def test_scan_domain_keeps_points_within_1e9_of_the_domain():
    # projections 1e-10 outside are kept, 1e-6 outside dropped (the inside draws and the
    # centre are kept either way)
    near = R.scan_domain(Fake(SloppyDisk(slack=1e-10)), seed=1, inside=30, boundary=10)
    assert len(near.points) == 41
    far = R.scan_domain(Fake(SloppyDisk(slack=1e-6)), seed=1, inside=30, boundary=10)
    assert len(far.points) == 31
    np.testing.assert_array_equal(far.points[:30], near.points[:30])


def test_scan_domain_and_direction_scan_values_are_float64():
    def ints(x, v):
        return np.ones(len(x), dtype=np.int64)

    scan = R.scan_domain(Fake(Disk(), ints), inside=5, boundary=2)
    assert scan.values.dtype == np.float64
    _, _, f = R.directions_scan(Fake(Disk(), ints), points=5, directions=3)
    assert f.dtype == np.float64


def test_scan_domain_point_by_point_when_the_batch_raises():
    def f(x, v):
        if x.ndim == 2:
            raise ValueError("no batches")
        if x[0] > 0.0:
            raise ZeroDivisionError("x0 > 0")
        return float(np.linalg.norm(v)) * 2.0

    m = Fake(Box((-1.0, -1.0), (1.0, 1.0)), f)
    scan = R.scan_domain(m, seed=4, inside=12, boundary=6)
    want = np.where(scan.points[:, 0] > 0.0, np.nan, 2.0)
    np.testing.assert_array_equal(scan.values, np.repeat(want[:, None], 4, axis=1))
    assert math.isnan(R._one(m, np.array([0.5, 0.0]), np.array([1.0, 0.0])))
    assert R._one(m, np.array([-0.5, 0.0]), np.array([0.0, 3.0])) == 6.0

    def g(x, v):
        if x.ndim == 2:
            raise ArithmeticError("no batches")
        raise ValueError("never")

    scan = R.scan_domain(Fake(Box((-1.0,), (1.0,)), g), inside=3, boundary=2)
    assert np.isnan(scan.values).all() and scan.values.shape == (6, 2)


def test_scan_domain_silences_floating_point_warnings():
    def f(x, v):
        return np.sqrt(0.25 - np.sum(x * x, axis=-1)) * np.linalg.norm(v, axis=-1)

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scan = R.scan_domain(Fake(Disk(), f), seed=2, inside=40, boundary=10)
        _, _, fd = R.directions_scan(Fake(Disk(), f), seed=2, points=40, directions=4)
    assert scan.bad.any() and np.isnan(fd).any()


# ----------------------------------------------------------------------------------------
# features and describe_region
# ----------------------------------------------------------------------------------------
def test_features_names_and_values():
    x = np.array([[0.3, -0.4], [1.5, 0.0]])
    feats = R._features(Fake(Disk()), x)
    assert [n for n, _ in feats] == ["|x|", "|x0|", "|x1|", "x0", "-x0", "x1", "-x1"]
    want = [[0.5, 1.5], [0.3, 1.5], [0.4, 0.0], [0.3, 1.5], [-0.3, -1.5], [-0.4, 0.0],
            [0.4, -0.0]]
    for (_, got), w in zip(feats, want, strict=True):
        np.testing.assert_allclose(got, w, rtol=0, atol=1e-15)
    off = R._features(Fake(Disk(1.0, (1.0, 0.0))), x)
    assert [n for n, _ in off][:3] == ["|x - (1, 0)|", "|x0 - 1|", "|x1|"]
    np.testing.assert_allclose(off[0][1], [math.hypot(0.7, 0.4), 0.5], rtol=0, atol=1e-15)
    np.testing.assert_allclose(off[1][1], [0.7, 0.5], rtol=0, atol=1e-15)
    one = R._features(Fake(Box((-1.0,), (1.0,))), np.array([[0.5]]))
    assert [n for n, _ in one] == ["|x0|", "x0", "-x0"]
    two = R._features(Fake(Box((0.0, 0.0), (2.0, 4.0))), np.array([[1.0, 2.0]]))
    assert [n for n, _ in two][:3] == ["|x - (1, 2)|", "|x0 - 1|", "|x1 - 2|"]
    assert R._tuple(np.array([0.123456, -2.0])) == "(0.1235, -2)"


def test_describe_region_by_distance_from_the_centre():
    x = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, -0.8], [0.95, 0.0], [0.0, 1.0]])
    bad = np.array([False, False, False, True, True])
    assert R.describe_region(Fake(Disk()), x, bad, "NaN") == (
        "F is NaN for |x| > 0.875 (2 of 5 sampled points; valid up to 0.8, invalid from "
        "0.95)")


def test_describe_region_by_a_coordinate_downwards():
    x = np.array([[0.0, 0.0], [0.9, 0.0], [-0.4, 0.3], [-0.8, 0.0], [0.2, 0.1],
                  [-0.9, 0.5]])
    bad = np.array([False, False, False, True, False, True])
    assert R.describe_region(Fake(Box((-1.0, -1.0), (1.0, 1.0))), x, bad, "negative") == (
        "F is negative for x0 < -0.6 (2 of 6 sampled points; valid up to -0.4, invalid "
        "from -0.8)")


def test_describe_region_by_a_coordinate_upwards():
    x = np.array([[0.0, -0.9], [0.0, 0.0], [0.9, 0.2], [0.0, 0.5], [-0.9, 0.6]])
    bad = np.array([False, False, False, True, True])
    assert R.describe_region(Fake(Box((-1.0, -1.0), (1.0, 1.0))), x, bad, "zero") == (
        "F is zero for x1 > 0.35 (2 of 5 sampled points; valid up to 0.2, invalid from 0.5)")


def test_describe_region_everywhere_and_nowhere():
    x = np.array([[0.0, 0.0], [0.6, 0.6], [1.0, 0.0], [0.5, 0.5], [0.0, 1.0]])
    m = Fake(Box((-1.0, -1.0), (1.0, 1.0)))
    assert R.describe_region(m, x, np.ones(5, bool), "NaN") == (
        "F is NaN at every one of the 5 sampled points")
    bad = np.array([False, True, False, True, False])
    assert R.describe_region(m, x, bad, "NaN") == (
        "F is NaN at 2 of 5 sampled points (40.0%), in no region a threshold on |x| or one "
        "coordinate describes; the nearest to the domain's centre is x = (0.5, 0.5)")
    # the nearest to an off-origin centre
    c = Fake(Box((0.0, 0.0), (2.0, 2.0)))
    y = x + 1.0
    assert R.describe_region(c, y, bad, "NaN").endswith("the nearest to the domain's centre "
                                                        "is x = (1.5, 1.5)")
    # nearest to the centre (1, 1), not to its mirror image
    z = np.array([[1.0, 1.0], [0.2, 0.4], [0.0, 1.0], [2.0, 1.0], [1.9, 1.0], [1.0, 0.0],
                  [1.0, 2.0]])
    bad = np.array([False, True, False, False, True, False, False])
    assert R.describe_region(c, z, bad, "NaN") == (
        "F is NaN at 2 of 7 sampled points (28.6%), in no region a threshold on |x| or one "
        "coordinate describes; the nearest to the domain's centre is x = (1.9, 1)")


# ----------------------------------------------------------------------------------------
# directions, direction scan, weakest direction, share
# ----------------------------------------------------------------------------------------
def test_unit_directions():
    np.testing.assert_allclose(R.unit_directions(2, 4), [[1, 0], [0, 1], [-1, 0], [0, -1]],
                               rtol=0, atol=1e-15)
    d = R.unit_directions(3, 5, seed=7)
    g = np.random.default_rng(7).normal(size=(5, 3))
    np.testing.assert_allclose(d, g / np.linalg.norm(g, axis=1)[:, None], rtol=0, atol=1e-15)
    np.testing.assert_allclose(R.unit_directions(3, 2), R.unit_directions(3, 2, seed=0))


def test_directions_scan_values_and_defaults():
    def f(x, v):
        return np.abs(v[:, 0]) + 2.0 * np.abs(v[:, 1]) * (1.0 + x[:, 0])

    m = Fake(Box((0.0, 0.0), (1.0, 1.0)), f)
    x, dirs, got = R.directions_scan(m, seed=6, points=9, directions=8)
    np.testing.assert_array_equal(x, m.domain.sample(9, np.random.default_rng([6, 48, 1])))
    np.testing.assert_allclose(dirs, R.unit_directions(2, 8, 6), rtol=0, atol=0)
    want = (np.abs(dirs[None, :, 0]) + 2.0 * np.abs(dirs[None, :, 1]) * (1.0 + x[:, None, 0]))
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
    _, d3, _ = R.directions_scan(Fake(Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))), seed=5,
                                 points=4, directions=6)
    np.testing.assert_allclose(d3, R.unit_directions(3, 6, 5), rtol=0, atol=0)
    assert not np.allclose(d3, R.unit_directions(3, 6, 0))
    x, dirs, got = R.directions_scan(Fake(Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))))
    assert x.shape == (1024, 3) and dirs.shape == (32, 3) and got.shape == (1024, 32)
    np.testing.assert_allclose(dirs, R.unit_directions(3, 32, 0), rtol=0, atol=0)
    np.testing.assert_array_equal(x, Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)).sample(
        1024, np.random.default_rng([0, 48, 1])))


def _tensor(xs, dirs):
    """Fundamental tensors (column-major flattened, as CasADi) [[2, 0.3], [-0.3, 1.5 +
    cos a]] at direction angle a: the symmetric part's smallest eigenvalue is 0.5 at a = pi,
    eigenvector (0, 1); an antisymmetric part that only a missing symmetrisation sees."""
    a = np.arctan2(dirs[:, 1], dirs[:, 0])
    k = len(dirs)
    h = np.zeros((k, 2, 2))
    h[:, 0, 0] = 2.0
    h[:, 1, 1] = 1.5 + np.cos(a) + 0.1 * xs[:, 0]
    h[:, 0, 1] = 0.3
    h[:, 1, 0] = -0.3
    return h.transpose(0, 2, 1).reshape(k, 4)


def test_weakest_direction():
    m = Fake(Disk(), hessian=_tensor)
    v, lam, w = R.weakest_direction(m, np.array([0.0, 0.0]))
    np.testing.assert_allclose(v, [-1.0, 0.0], rtol=0, atol=1e-12)
    assert lam == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_allclose(np.abs(w), [0.0, 1.0], rtol=0, atol=1e-12)
    v, lam, _ = R.weakest_direction(m, np.array([0.5, 0.0]), n_directions=6)
    # directions at 0, 60, ..., 300 degrees: 180 is among them
    np.testing.assert_allclose(v, [-1.0, 0.0], rtol=0, atol=1e-12)
    assert lam == pytest.approx(0.55, abs=1e-12)
    v, lam, _ = R.weakest_direction(m, [0, 0], n_directions=4)  # integers: as floats
    assert lam == pytest.approx(0.5, abs=1e-12)
    # the default 64 directions: angle pi is the 33rd
    calls = []
    R.weakest_direction(Fake(Disk(), hessian=lambda xs, d: calls.append(len(d))
                             or _tensor(xs, d)), np.zeros(2))
    assert calls == [64]


def test_weakest_direction_where_the_tensor_bends_along_a_diagonal():
    def h(xs, dirs):
        k = len(dirs)
        a = np.arctan2(dirs[:, 1], dirs[:, 0])
        # [[1, c], [c, 1]] with c = 0.5 cos(a): eigenvalues 1 -+ |c|; smallest 0.5 at a = 0
        c = 0.5 * np.cos(a)
        return np.stack([np.ones(k), c, c, np.ones(k)], 1)

    v, lam, w = R.weakest_direction(Fake(Disk(), hessian=h), np.zeros(2), n_directions=8)
    np.testing.assert_allclose(v, [1.0, 0.0], rtol=0, atol=1e-12)
    assert lam == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_allclose(np.abs(w), [math.sqrt(0.5)] * 2, rtol=0, atol=1e-12)
    assert w[0] * w[1] < 0  # the eigenvector of 1 - c: (1, -1)


def test_share():
    assert R.share(np.array([True, False, False, False])) == "25.0% (1 of 4)"
    assert R.share(np.array([True] * 98 + [False] * 3998)) == "2.4% (98 of 4096)"
