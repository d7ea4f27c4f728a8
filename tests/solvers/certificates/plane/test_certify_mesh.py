"""solvers.certificates.plane.mesh against independent references, FAST (the mutation-testing
selection of the module, see docs/guides/mutation-testing.md): exact geometry of the outline, brute
force distances and point-in-polygon tests, the lattice's defining formula, P2 gradients
exact on quadratics, circumradii from the circumcentre, barycentric point location, and a
zigzag worked out by hand on a metric whose unit ball is not convex."""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from finsler import Box, Disk, InputError
from solvers.certificates.plane.mesh import (
    _distance_to_path,
    _hex_lattice,
    _initial_points,
    _inside_polygon,
    _Mesh,
    _outline,
    _spacing,
    _zigzag,
)

#: every test here is in the fast focused selection of mutation runs
pytestmark = pytest.mark.mutation


@dataclass(frozen=True)
class Spec:
    h_path: float = 0.05
    corridor: float = 0.1
    grade: float = 0.6
    h_far: float = 0.25


def signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_outline_of_a_box_is_its_corners_counter_clockwise() -> None:
    poly = _outline(SimpleNamespace(domain=Box((-1.0, -2.0), (3.0, 0.5)), name="b"))
    assert poly.dtype == np.float64
    np.testing.assert_array_equal(poly, [[-1, -2], [3, -2], [3, 0.5], [-1, 0.5]])
    assert signed_area(poly) == pytest.approx(4 * 2.5)
    ints = _outline(SimpleNamespace(domain=Box((-1, -2), (3, 1)), name="b"))
    assert ints.dtype == np.float64  # integer corners still give float coordinates


def test_outline_of_a_disk_is_a_circumscribed_64_gon() -> None:
    c, r = np.array([0.3, -0.2]), 0.7
    poly = _outline(SimpleNamespace(domain=Disk(radius=r, center=(0.3, -0.2)), name="d"))
    assert poly.shape == (64, 2)
    np.testing.assert_allclose(np.linalg.norm(poly - c, axis=1), r / math.cos(math.pi / 64),
                               rtol=1e-14)
    mids = 0.5 * (poly + np.roll(poly, -1, axis=0))  # the edges touch the circle
    np.testing.assert_allclose(np.linalg.norm(mids - c, axis=1), r, rtol=1e-13)
    assert signed_area(poly) > 0  # counter-clockwise
    ang = np.arctan2(poly[:, 1] - c[1], poly[:, 0] - c[0])
    np.testing.assert_allclose(np.mod(ang, 2 * np.pi), 2 * np.pi * (np.arange(64) + 0.5) / 64,
                               atol=1e-13)


def test_outline_refuses_other_domains() -> None:
    dom = SimpleNamespace(describe=lambda: "a strange set")
    with pytest.raises(InputError, match=r"2-D box or disk.*m1 has a strange set"):
        _outline(SimpleNamespace(domain=dom, name="m1"))


def test_inside_polygon_is_the_distance_to_the_boundary() -> None:
    """A square and a triangle: inside with margin exactly when the distance to every
    edge's line (inward) is at least the margin, computed point by point."""
    rng = np.random.default_rng(1)
    pts = rng.uniform(-1.5, 1.5, size=(400, 2))
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    for margin in (0.0, 0.2, -0.1):
        ref = np.minimum(1 - np.abs(pts[:, 0]), 1 - np.abs(pts[:, 1])) >= margin
        np.testing.assert_array_equal(_inside_polygon(pts, square, margin), ref)
    tri = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]])  # hypotenuse x + 2y = 2
    d_hyp = (2 - pts[:, 0] - 2 * pts[:, 1]) / math.sqrt(5)
    ref = np.minimum(np.minimum(pts[:, 0], pts[:, 1]), d_hyp) >= 0.1
    np.testing.assert_array_equal(_inside_polygon(pts, tri, 0.1), ref)


def _brute_distance(p: np.ndarray, path: np.ndarray) -> float:
    best = math.inf
    for i in range(len(path) - 1):
        a, b = path[i], path[i + 1]
        e = b - a
        ee = float(e @ e)
        t = 0.0 if ee == 0 else min(1.0, max(0.0, float((p - a) @ e) / ee))
        best = min(best, float(np.linalg.norm(p - (a + t * e))))
    return best


@pytest.mark.parametrize("chunk", [4096, 7, 1])
def test_distance_to_path_is_the_brute_force_distance(chunk: int) -> None:
    """Short segments (|e|**2 < 1) and a repeated point; points drawn afresh for each
    chunk size (so no array of an earlier call can be met again in fresh memory)."""
    rng = np.random.default_rng(2 + chunk)
    path = 0.3 * np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 1.0], [-0.5, 0.2]])
    pts = rng.uniform(-0.3, 0.6, size=(50 + chunk % 5, 2))
    got = _distance_to_path(pts, path, chunk=chunk)
    ref = [_brute_distance(p, path) for p in pts]
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-15)
    # beyond both ends of a single segment: the distance to the end point
    seg = np.array([[0.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(_distance_to_path(np.array([[-3.0, 4.0], [4.0, 4.0],
                                                           [0.5, -2.0]]), seg), [5.0, 5.0, 2.0])


def test_spacing_formula() -> None:
    spec = Spec(h_path=0.05, corridor=0.1, grade=0.6, h_far=0.25)
    d = np.array([0.0, 0.1, 0.2, 0.3, 0.5, 10.0])
    ref = [min(0.25, 0.05 + 0.6 * max(x - 0.1, 0.0)) for x in d]
    np.testing.assert_allclose(_spacing(d, spec), ref, rtol=1e-15)


@pytest.mark.parametrize("h", [0.3, 0.17])
def test_hex_lattice_covers_the_box_and_nests(h: float) -> None:
    lo, hi = np.array([-0.7, -0.4]), np.array([0.9, 0.6])
    pts = _hex_lattice(lo, hi, h)
    dy = h * math.sqrt(3) / 2
    jj = pts[:, 1] / dy
    ii = pts[:, 0] / h - 0.5 * jj
    np.testing.assert_allclose(jj, np.round(jj), atol=1e-9)  # on the lattice
    np.testing.assert_allclose(ii, np.round(ii), atol=1e-9)
    assert np.all((pts >= lo - h - 1e-12) & (pts <= hi + h + 1e-12))
    assert len({tuple(p) for p in np.round(pts, 9)}) == len(pts)  # no duplicates
    # every point of the box has a lattice point within h / sqrt(3)
    rng = np.random.default_rng(3)
    probe = rng.uniform(lo, hi, size=(300, 2))
    near = np.min(np.linalg.norm(probe[:, None] - pts[None], axis=2), axis=1)
    assert near.max() <= h / math.sqrt(3) + 1e-12
    # the complete lattice within [lo - h, hi + h]: count its points by the formula
    j_all = np.arange(math.floor((lo[1] - h) / dy) - 2, math.ceil((hi[1] + h) / dy) + 3)
    count = 0
    for j in j_all:
        y = j * dy
        if lo[1] - h <= y <= hi[1] + h:
            i = np.arange(math.floor((lo[0] - h) / h - 0.5 * j) - 2,
                          math.ceil((hi[0] + h) / h - 0.5 * j) + 3)
            x = h * (i + 0.5 * j)
            count += int(np.sum((x >= lo[0] - h) & (x <= hi[0] + h)))
    assert len(pts) == count
    coarse = _hex_lattice(lo, hi, 2 * h)
    fine = {tuple(p) for p in np.round(pts, 9)}
    inside = coarse[np.all((coarse >= lo - h) & (coarse <= hi + h), axis=1)]
    assert all(tuple(p) in fine for p in np.round(inside, 9))


def test_initial_points_are_graded_inside_and_start_with_the_ends() -> None:
    """The square [-1, 1]^2 (test of the rest below) and the ends on lattice points of
    the finest level (the lattice's own copies of them must be left out)."""
    spec = Spec(h_path=0.05, corridor=0.1, grade=0.6, h_far=0.25)
    poly = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    s, g = np.array([-0.5, 0.0]), np.array([0.5, 0.0])
    path = np.stack([np.linspace(s[0], g[0], 9), np.linspace(s[1], g[1], 9)], 1)
    pts = _initial_points(poly, path, s, g, spec)
    np.testing.assert_array_equal(pts[0], s)
    np.testing.assert_array_equal(pts[1], g)
    rest = pts[2:]
    assert np.all(np.abs(rest) <= 1.0 + 1e-12)  # inside the polygon or on its edges
    for e in (s, g):  # nothing else within 0.4 h_path of the ends
        assert np.linalg.norm(rest - e, axis=1).min() > 0.4 * spec.h_path
    # boundary: every edge sampled, gaps at most the local spacing (h_far far away)
    on_edge = np.isclose(np.abs(rest).max(axis=1), 1.0)
    for corner in poly:
        assert np.min(np.linalg.norm(rest - corner, axis=1)) < 1e-12
    bnd = rest[on_edge]
    for side in (bnd[np.isclose(bnd[:, 1], -1.0)][:, 0], bnd[np.isclose(bnd[:, 0], 1.0)][:, 1]):
        gaps = np.diff(np.sort(side))
        assert gaps.max() <= spec.h_far + 1e-9 and gaps.min() >= 0.05 - 1e-9
    # interior: near the path the spacing is h_path, far away it is h_far
    dist = _distance_to_path(rest, path)
    nn = np.sort(np.linalg.norm(rest[:, None] - rest[None], axis=2), axis=1)[:, 1]
    inner = ~on_edge
    near = inner & (dist < 0.08)
    far = inner & (dist > 0.6)
    assert near.sum() > 30 and far.sum() > 5
    np.testing.assert_allclose(np.median(nn[near]), spec.h_path, rtol=0.05)
    np.testing.assert_allclose(np.median(nn[far]), spec.h_far, rtol=0.25)
    assert nn[inner].min() >= 0.4 * spec.h_path
    # the points of the h_path lattice that are not on the 2 h_path one (lattice indices
    # i, j not both even) are exactly those where the spacing asks for h_path
    h, dy = spec.h_path, spec.h_path * math.sqrt(3) / 2
    jj = np.round(rest[:, 1] / dy)
    ii = np.round(rest[:, 0] / h - 0.5 * jj)
    on_lattice = inner & np.isclose(rest[:, 1], jj * dy) & np.isclose(rest[:, 0],
                                                                       h * (ii + 0.5 * jj))
    finest = on_lattice & ((ii % 2 != 0) | (jj % 2 != 0))
    assert finest.sum() > 30
    assert np.all(_spacing(dist[finest], spec) <= spec.h_path * (1 + 1e-9))
    lat = _hex_lattice(poly.min(0), poly.max(0), h)
    lat = lat[_inside_polygon(lat, poly, 0.3 * h)]
    lat = lat[(_spacing(_distance_to_path(lat, path), spec) <= h)
              & (np.linalg.norm(lat - s, axis=1) > 0.4 * h)
              & (np.linalg.norm(lat - g, axis=1) > 0.4 * h)]
    kept = {tuple(p) for p in np.round(rest, 9)}
    assert all(tuple(p) in kept for p in np.round(lat, 9))
    # the first level's points keep 0.3 h from the polygon, every level nests in it
    assert np.all(np.abs(rest[inner & (nn < 0.06)]).max(axis=1) <= 1.0 - 0.3 * 0.05 + 1e-12)


def test_initial_points_boundary_of_a_shifted_polygon() -> None:
    """A polygon away from the origin: every edge sampled from its corner on, consecutive
    boundary points at least h_path and at most the local spacing (+ h_path / 2, the
    candidates' distance) apart."""
    spec = Spec(h_path=0.1, corridor=0.1, grade=0.6, h_far=0.2)
    poly = np.array([[1.0, 2.0], [2.5, 2.0], [2.5, 3.0], [1.0, 3.0]])
    s, g = np.array([1.5, 2.5]), np.array([2.0, 2.5])
    pts = _initial_points(poly, np.stack([s, g]), s, g, spec)[2:]
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        e = (b - a) / np.linalg.norm(b - a)
        off = pts - a
        on = np.abs(off[:, 0] * e[1] - off[:, 1] * e[0]) < 1e-12
        t = np.sort(off[on] @ e)
        t = t[(t > -1e-12) & (t < np.linalg.norm(b - a) + 1e-12)]
        assert t[0] == pytest.approx(0.0, abs=1e-12) and t[-1] == pytest.approx(
            np.linalg.norm(b - a), abs=1e-12)
        gaps = np.diff(t)
        # the candidates are at most h_path / 2 apart: a gap exceeds the spacing by less
        assert gaps.max() <= spec.h_far + 0.5 * spec.h_path + 1e-9
        assert gaps[:-1].min() >= spec.h_path - 1e-9  # the last gap ends at a corner


def test_initial_points_with_equal_spacings_are_one_lattice() -> None:
    spec = Spec(h_path=0.2, corridor=0.1, grade=0.6, h_far=0.2)
    poly = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    s, g = np.array([-0.5, 0.0]), np.array([0.5, 0.0])
    pts = _initial_points(poly, poly[[0, 2]], s, g, spec)
    rest = pts[2:]
    lat = _hex_lattice(poly.min(0), poly.max(0), 0.2)
    lat = lat[_inside_polygon(lat, poly, 0.06)]
    lat = lat[(np.linalg.norm(lat - s, axis=1) > 0.08) & (np.linalg.norm(lat - g, axis=1) > 0.08)]
    inner = rest[np.abs(rest).max(axis=1) < 1 - 1e-12]
    assert {tuple(p) for p in np.round(inner, 9)} == {tuple(p) for p in np.round(lat, 9)}


def _mesh_points() -> np.ndarray:
    rng = np.random.default_rng(5)
    corners = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return np.concatenate([corners, rng.uniform(0.05, 0.95, size=(30, 2))])


def test_p2_gradients_are_exact_for_quadratics() -> None:
    """P2 interpolation reproduces a quadratic: the gradients at every triangle's
    vertices, from the values at vertices and edge midpoints, are the exact ones."""
    mesh = _Mesh(_mesh_points())
    xy = np.concatenate([mesh.points, mesh.midpoints])
    assert mesh.n_dofs == xy.shape[0] == mesh.points.shape[0] + mesh.edges.shape[0]

    def q(p):
        return 1.5 * p[:, 0] ** 2 - 0.7 * p[:, 0] * p[:, 1] + 2.2 * p[:, 1] ** 2 \
            + 0.3 * p[:, 0] - 1.1 * p[:, 1] + 0.4

    def grad_q(p):
        return np.stack([3.0 * p[:, 0] - 0.7 * p[:, 1] + 0.3,
                         -0.7 * p[:, 0] + 4.4 * p[:, 1] - 1.1], -1)

    g = mesh.gradients(q(xy))
    assert g.shape == (mesh.n_tri, 3, 2)
    ref = grad_q(mesh.points[mesh.tri].reshape(-1, 2)).reshape(mesh.n_tri, 3, 2)
    np.testing.assert_allclose(g, ref, atol=1e-9)
    # every edge is once in the list, its midpoint the middle of its end points
    e = np.sort(np.concatenate([mesh.tri[:, [0, 1]], mesh.tri[:, [1, 2]], mesh.tri[:, [2, 0]]]),
                axis=1)
    assert {tuple(x) for x in e} == {tuple(x) for x in mesh.edges}
    np.testing.assert_allclose(mesh.midpoints, 0.5 * (mesh.points[mesh.edges[:, 0]]
                                                      + mesh.points[mesh.edges[:, 1]]))
    # dofs 3-5 of a triangle are the edges (0 1), (1 2), (2 0)
    nv = mesh.points.shape[0]
    for t in range(mesh.n_tri):
        for k, (i, j) in enumerate([(0, 1), (1, 2), (2, 0)]):
            edge = mesh.edges[mesh.dofs[t, 3 + k] - nv]
            assert sorted(edge) == sorted([mesh.tri[t, i], mesh.tri[t, j]])


def test_circumradii_and_centroids() -> None:
    mesh = _Mesh(_mesh_points())
    z = mesh.points[mesh.tri]
    for t in range(mesh.n_tri):
        a, b, c = z[t]
        m = 2 * np.array([b - a, c - a])
        centre = a + np.linalg.solve(m, [b @ b - a @ a - 2 * a @ (b - a),
                                         c @ c - a @ a - 2 * a @ (c - a)])
        r = np.linalg.norm(centre - a)
        assert np.linalg.norm(centre - b) == pytest.approx(r, rel=1e-9)
        assert mesh.r2[t] == pytest.approx(r * r, rel=1e-9)
    np.testing.assert_allclose(mesh.centroids, z.mean(axis=1))


def test_locate_by_barycentric_coordinates_and_refine() -> None:
    mesh = _Mesh(_mesh_points())
    rng = np.random.default_rng(6)
    pts = np.concatenate([rng.uniform(0, 1, size=(60, 2)), [[2.0, 2.0], [-0.1, 0.5]]])
    rows = mesh.locate(pts)
    assert list(rows[-2:]) == [-1, -1]
    for p, t in zip(pts[:-2], rows[:-2]):
        a, b, c = mesh.points[mesh.tri[t]]
        lam = np.linalg.solve(np.array([b - a, c - a]).T, p - a)
        assert lam.min() >= -1e-12 and lam.sum() <= 1 + 1e-12
    marked = np.array([0, 3])
    new = mesh.refine(marked)
    nv = mesh.points.shape[0]
    np.testing.assert_array_equal(new[:nv], mesh.points)
    want = {tuple(np.round(0.5 * (mesh.points[mesh.tri[t, i]] + mesh.points[mesh.tri[t, j]]), 12))
            for t in marked for i, j in [(0, 1), (1, 2), (2, 0)]}
    got = [tuple(np.round(p, 12)) for p in new[nv:]]
    assert len(got) == len(set(got)) == len(want) and set(got) == want


def test_slivers_are_dropped_and_located_as_none() -> None:
    """Collinear points on the bottom edge make Delaunay slivers of zero area only when
    cocircular ties arise; a grid has none, so every simplex is kept in order."""
    g = np.stack(np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4)), -1).reshape(-1, 2)
    g = g + np.random.default_rng(7).normal(scale=1e-3, size=g.shape)
    mesh = _Mesh(g)
    assert mesh.n_tri == mesh.delaunay.simplices.shape[0]
    np.testing.assert_array_equal(mesh.simplex_row, np.arange(mesh.n_tri))
    u = mesh.points[mesh.tri[:, 1]] - mesh.points[mesh.tri[:, 0]]
    w = mesh.points[mesh.tri[:, 2]] - mesh.points[mesh.tri[:, 0]]
    area = 0.5 * np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
    assert area.sum() == pytest.approx(float(np.prod(np.ptp(g, axis=0))), rel=0.05)


def test_a_region_keeps_exactly_the_triangles_it_marks() -> None:
    """``region`` (certify's reachable triangles) gets the Delaunay corners and drops the
    others: their rows, their edges' unknowns and their points' location."""
    g = np.stack(np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5)), -1).reshape(-1, 2)
    g = g + np.random.default_rng(8).normal(scale=1e-3, size=g.shape)
    full = _Mesh(g)
    seen = []

    def left_half(corners: np.ndarray) -> np.ndarray:
        seen.append(corners.copy())
        return corners.mean(axis=1)[:, 0] < 0.5

    mesh = _Mesh(g, left_half)
    np.testing.assert_array_equal(seen[0], g[full.delaunay.simplices])
    keep = g[full.tri].mean(axis=1)[:, 0] < 0.5
    assert 0 < keep.sum() < keep.size
    np.testing.assert_array_equal(mesh.tri, full.tri[keep])
    np.testing.assert_array_equal(mesh.simplex_row[keep], np.arange(keep.sum()))
    assert np.all(mesh.simplex_row[~keep] == -1)
    assert mesh.edges.shape[0] < full.edges.shape[0]
    assert mesh.n_dofs == g.shape[0] + mesh.edges.shape[0]
    right = full.centroids[~keep]
    assert np.all(mesh.locate(right) == -1)
    assert np.all(mesh.locate(full.centroids[keep]) == np.arange(keep.sum()))


def test_a_mesh_of_too_few_points_is_refused() -> None:
    with pytest.raises(InputError, match="mesh of 2 points cannot be triangulated"):
        _Mesh(np.array([[0.0, 0.0], [1.0, 0.0]]))
    with pytest.raises(InputError, match="mesh of 3 points cannot be triangulated"):
        _Mesh(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))


def test_zero_area_slivers_are_dropped_and_near_slivers_kept(monkeypatch) -> None:
    """Delaunay's simplices with two extra triangles made up here: one of zero area (three
    vertices on a diagonal, not along an axis: dropped, and a point located in it
    reported as in no triangle) and one of area2 1.3e-14 (relative ~4e-14 of the
    largest: kept, the threshold is 1e-14 relative)."""

    import scipy.spatial

    real = scipy.spatial.Delaunay
    # 5 = (0.3, 0.3), 6 = (0.5, 0.6), 7 = 2 * 6 - 5 off the line 5-6 by ~4e-14
    # (all shifted by (0.25, 0.75): no vertex at the origin, so the area's formula must
    # use differences of coordinates)
    pts = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0],
                    [0.3, 0.3], [0.5, 0.6], [0.7 - 3e-14, 0.9 + 2e-14]]) + np.array([0.25, 0.75])

    class Fake:
        def __init__(self, points):
            self.inner = real(points)
            # 0, 5, 3 lie on the square's diagonal: zero area (to rounding)
            self.simplices = np.concatenate([self.inner.simplices, [[0, 5, 3], [5, 6, 7]]])

        def find_simplex(self, q):
            out = self.inner.find_simplex(q)
            out[np.all(q == [-5.0, -5.0], axis=1)] = len(self.simplices) - 2
            out[np.all(q == [-6.0, -6.0], axis=1)] = len(self.simplices) - 1
            return out

    monkeypatch.setattr(scipy.spatial, "Delaunay", Fake)
    mesh = _Mesh(pts)
    n = len(mesh.delaunay.inner.simplices)
    assert mesh.n_tri == n + 1  # the zero-area one dropped, the thin one kept
    np.testing.assert_array_equal(mesh.tri[-1], [5, 6, 7])
    np.testing.assert_array_equal(mesh.simplex_row, [*range(n), -1, n])
    np.testing.assert_array_equal(mesh.locate(np.array([[-5.0, -5.0], [-6.0, -6.0],
                                                        [9.0, 9.0]])), [-1, n, -1])
    assert np.all(np.isfinite(mesh.r2))


class _Lobes:
    """F(x, v) = |v| (1 + c(x) cos 4 theta), c = 0.5 for x_0 < 0.5 (cheap along the
    diagonals, 0.5 |v|, dear along the axes, 1.5 |v|: a unit ball that is not convex),
    c = 0 beyond (Euclidean). Domain: a large box. The zigzag must evaluate F at the
    segments' midpoints, without input checks (the points are the solver's own)."""

    domain = Box((-10.0, -10.0), (10.0, 10.0))
    cut = 0.5

    def F(self, x, v, check=True):
        assert check is False
        x, v = np.asarray(x, float), np.asarray(v, float)
        assert x.shape == v.shape
        c = np.where(x[:, 0] < self.cut, 0.5, 0.0)
        return np.hypot(v[:, 0], v[:, 1]) * (1 + c * np.cos(4 * np.arctan2(v[:, 1], v[:, 0])))


class _Euclid:
    domain = Box((-10.0, -10.0), (10.0, 10.0))

    @staticmethod
    def F(x, v, check=True):
        assert check is False
        return np.hypot(np.asarray(v)[:, 0], np.asarray(v)[:, 1])


def test_zigzag_replaces_a_dear_segment_by_diagonal_teeth() -> None:
    """(0,0) -> (0.4,0) along an axis costs 1.5 |v| (midpoint where c = 0.5); along the two
    diagonals (8 directions) sqrt(2) * 0.5 |v| = 0.71 |v|: the zigzag (0,0) (.1,.1)
    (.2,0) (.3,.1) (.4,0) with 2 teeth. A zero-length segment, a segment whose midpoint
    is Euclidean (x_0 >= 0.5: no cheaper combination) and a cheap diagonal segment are
    kept as they are."""
    pts = np.array([[0.0, 0.0], [0.4, 0.0], [0.4, 0.0], [1.4, 0.0], [2.0, 0.6],
                    [1.0, 0.6], [0.0, 0.6], [-0.5, 0.1]])
    zig = _zigzag(_Lobes(), pts, 8)
    # (1.0, 0.6) -> (0.0, 0.6): midpoint x_0 = 0.5, Euclidean: kept; (0.0, 0.6) ->
    # (-0.5, 0.1) is a diagonal: kept; (1.4, 0) -> (2, .6) and (2, .6) -> (1, .6): kept
    want = [[0, 0], [0.1, 0.1], [0.2, 0], [0.3, 0.1], [0.4, 0], [0.4, 0], [1.4, 0], [2, 0.6],
            [1.0, 0.6], [0.0, 0.6], [-0.5, 0.1]]
    np.testing.assert_allclose(zig, want, atol=1e-12)
    zig3 = _zigzag(_Lobes(), pts[:2], 8, teeth=3)
    assert zig3.shape == (7, 2)
    np.testing.assert_allclose(zig3, [[0, 0], [0.4 / 6, 0.4 / 6], [0.4 / 3, 0],
                                      [0.2, 0.4 / 6], [0.8 / 3, 0], [2 / 3 * 0.5, 0.4 / 6],
                                      [0.4, 0]], atol=1e-12)
    length = float(np.sum(_Lobes().F(zig3[:-1], np.diff(zig3, axis=0), check=False)))
    assert length == pytest.approx(math.sqrt(2) * 0.5 * 0.4, rel=1e-12)
    assert _zigzag(_Euclid(), pts, 8) is None  # a norm: no cheaper combination
    assert _zigzag(_Lobes(), np.array([[0.0, 0.0], [0.3, 0.3]]), 8) is None
    # downwards: teeth along the diagonals of the lower half, 225 degrees first (of two
    # equally cheap pairs, the first sampled direction leads)
    up = _zigzag(_Lobes(), np.array([[0.0, 0.0], [0.0, -0.4]]), 8)
    np.testing.assert_allclose(up, [[0, 0], [-0.1, -0.1], [0, -0.2], [-0.1, -0.3], [0, -0.4]],
                               atol=1e-12)
    # with 4 directions no pair is cheaper than the axis itself (the axes are sampled)
    assert _zigzag(_Lobes(), pts[:2], 4) is None


def test_zigzag_is_projected_into_the_domain_and_keeps_the_ends() -> None:
    class Small(_Lobes):
        domain = Box((-1.0, -0.1), (1.0, 0.1))
        cut = 1.0

    zig = _zigzag(Small(), np.array([[-0.5, 0.0], [0.5, 0.0]]), 8)
    np.testing.assert_allclose(zig, [[-0.5, 0], [-0.25, 0.1], [0, 0], [0.25, 0.1], [0.5, 0]],
                               atol=1e-12)  # (-.25, .25) projected to (-.25, .1)
    zig = _zigzag(Small(), np.array([[-1.5, 0.0], [0.5, 0.0]]), 8)
    np.testing.assert_array_equal(zig[[0, -1]], [[-1.5, 0.0], [0.5, 0.0]])  # ends kept
    np.testing.assert_allclose(zig[1], [-1.0, 0.1], atol=1e-12)
