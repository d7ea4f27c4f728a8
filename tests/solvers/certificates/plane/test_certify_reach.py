"""The region certify's rows need (solvers.certificates.plane.reach, issue 46 item 4): the proven
speed floor is below every sampled value of F on unit vectors, and a pruned triangle holds
no point of the ellipse |z - x| + |y - z| <= reach (checked on sampled points)."""

from __future__ import annotations

import numpy as np
import pytest

import finsler
from solvers.certificates.plane.mesh import _Mesh, _outline
from solvers.certificates.plane.reach import _speed_floor, reachable_triangles, speed_floor


@pytest.mark.parametrize("name", ["matsumoto", "poincare", "randers", "euclidean"])
def test_speed_floor_is_below_every_sampled_value_and_useful(name: str) -> None:
    m = finsler.get_metric(name)
    poly = _outline(m)
    floor = speed_floor(m, poly)
    rng = np.random.default_rng(5)
    z = rng.uniform(poly.min(0), poly.max(0), (400_000, 2))
    z = z[m.domain.contains(z, tol=0.0)]
    a = rng.uniform(0.0, 2 * np.pi, z.shape[0])
    f = m.F(z, np.stack([np.cos(a), np.sin(a)], 1), check=False)
    assert floor <= f.min()
    assert floor >= 0.9 * f.min()  # useful: within 10 % of the sampled minimum
    assert speed_floor(m, poly) == floor  # cached in the metric


def test_speed_floor_is_zero_where_an_enclosure_is_not_finite() -> None:
    m = finsler.get_metric("poincare")  # F = 2|v| / (1 - |z|**2): infinite at |z| = 1
    poly = 1.5 * _outline(m)  # the polygon reaches beyond the unit circle
    assert _speed_floor(m, poly) == 0.0


def test_pruned_triangles_hold_no_point_of_the_ellipse() -> None:
    rng = np.random.default_rng(7)
    pts = rng.uniform(-1.0, 1.0, (400, 2))
    s, g = np.array([-0.3, 0.1]), np.array([0.4, -0.2])
    reach = 1.1 * float(np.linalg.norm(g - s))
    mesh = _Mesh(np.concatenate([s[None], g[None], pts]))
    corners = mesh.points[mesh.tri]
    keep = reachable_triangles(corners, s, g, reach)
    assert 0 < keep.sum() < keep.size
    # sample points inside every triangle (barycentric), and the ellipse's own points
    lam = rng.dirichlet(np.ones(3), 200)
    inner = np.einsum("sk,tki->tsi", lam, corners)  # (T, 200, 2)
    total = (np.linalg.norm(inner - s, axis=2) + np.linalg.norm(inner - g, axis=2))
    assert np.all(total[~keep] > reach)  # no pruned triangle meets the ellipse
    assert np.all(keep[np.any(total <= reach, axis=1)])  # every one that does is kept
    # a triangle the segment crosses is kept; infinite reach keeps all
    assert keep[mesh.locate(0.5 * (s + g)[None])[0]]
    assert reachable_triangles(corners, s, g, np.inf).all()


def test_region_drops_triangles_and_certify_still_contains_the_exact_distance() -> None:
    m = finsler.get_metric("poincare")
    from solvers import MeshSpec, certify

    s, g = np.array([-0.3, 0.2]), np.array([0.1, 0.3])
    exact = float(m.distance(s, g)[0])
    spec = MeshSpec(h_path=0.1, h_far=0.3, directions=32, target_gap=2e-2, max_rounds=3)
    r = certify(m, s, g, spec)
    assert r.lower <= exact <= r.upper
    floor, reach = r.mesh["speed_floor"], r.mesh["reach"]
    assert 0 < floor <= 2.0 and reach == pytest.approx(r.upper / floor)
    assert r.gap <= 2e-2
