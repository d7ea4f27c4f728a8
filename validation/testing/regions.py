"""Where in the domain a property of ``F`` stops holding, from samples: the points the
``domain`` property scans (the whole declared domain, its boundary included), a sentence
naming the region where ``F`` is not finite and positive ("F is NaN for |x| > 0.9"), and
the direction at a point where the fundamental tensor is not positive definite.

Samples are seeded (``numpy`` generators from the check's seed): the same seed gives the
same points and the same sentences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from finsler import Disk, Metric

__all__ = ["DomainScan", "boundary_points", "describe_region", "directions_scan",
           "scan_domain", "share", "unit_directions", "weakest_direction"]

#: Points of the domain scan: uniform inside, and on the boundary (projections onto the
#: domain of points drawn around it).
INSIDE_SAMPLES = 2048
BOUNDARY_SAMPLES = 512


def _centre(m: Metric) -> np.ndarray:
    d = m.domain
    if isinstance(d, Disk):
        return np.asarray(d.center, float)
    lo, hi = d.bounds()
    lo = np.where(np.isfinite(lo), lo, 0.0)
    hi = np.where(np.isfinite(hi), hi, 0.0)
    return 0.5 * (lo + hi)


def _box_around(m: Metric) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = m.domain.bounds()
    lo = np.where(np.isfinite(lo), lo, -10.0)
    hi = np.where(np.isfinite(hi), hi, 10.0)
    pad = 0.2 * (hi - lo)
    return lo - pad, hi + pad


def boundary_points(m: Metric, n: int, rng: np.random.Generator) -> np.ndarray:
    """About ``n`` points of the domain's boundary ``(k, dim)``: points drawn uniformly in
    its bounding box enlarged by 20% that lie outside the domain, projected onto it (the
    box's corners and faces, the disk's circle)."""
    lo, hi = _box_around(m)
    p = rng.uniform(lo, hi, size=(8 * n, m.dim))
    out = p[~m.domain.contains(p, tol=0.0)][:n]
    if len(out) == 0:
        return np.zeros((0, m.dim))
    return np.asarray(m.domain.project(out), float)


@dataclass(frozen=True)
class DomainScan:
    """``F`` at ``points`` ``(N, dim)`` of the domain (``inside`` of them drawn uniformly,
    the rest on the boundary) along the ``2 dim`` signed coordinate directions:
    ``values`` ``(N, 2 dim)``; ``bad`` ``(N,)``: a value is not finite or not ``> 0``."""

    points: np.ndarray
    directions: np.ndarray
    values: np.ndarray
    inside: int

    @property
    def bad_values(self) -> np.ndarray:
        v = self.values
        return ~np.isfinite(v) | ~(v > 0)

    @property
    def bad(self) -> np.ndarray:
        return self.bad_values.any(axis=1)

    def what(self) -> str:
        """What ``F`` is at the bad samples: ``NaN``, ``infinite``, ``negative``, ``zero``
        (the kinds found, most frequent first)."""
        v = self.values[self.bad_values]
        kinds = {"NaN": int(np.isnan(v).sum()), "infinite": int(np.isinf(v).sum()),
                 "negative": int((v < 0).sum()), "zero": int((v == 0).sum())}
        found = sorted((k for k in kinds if kinds[k]), key=lambda k: -kinds[k])
        return " or ".join(found) or "invalid"


def scan_domain(m: Metric, seed: int = 0, inside: int = INSIDE_SAMPLES,
                boundary: int = BOUNDARY_SAMPLES) -> DomainScan:
    """``F`` over the whole declared domain (`DomainScan`), seeded. Floating-point
    warnings are silenced: invalid values are what the scan looks for."""
    rng = np.random.default_rng([int(seed), 48])
    pts = np.concatenate([m.domain.sample(inside, rng), boundary_points(m, boundary, rng),
                          _centre(m)[None]])
    pts = pts[m.domain.contains(pts, tol=1e-9)]
    eye = np.eye(m.dim)
    dirs = np.concatenate([eye, -eye])
    xs = np.repeat(pts, len(dirs), axis=0)
    vs = np.tile(dirs, (len(pts), 1))
    with np.errstate(all="ignore"):
        try:
            f = np.asarray(m.F(xs, vs, check=False), float).reshape(len(pts), len(dirs))
        except (ArithmeticError, ValueError):  # evaluate point by point to see where
            f = np.array([[_one(m, x, v) for v in dirs] for x in pts])
    return DomainScan(pts, dirs, f, inside)


def _one(m: Metric, x: np.ndarray, v: np.ndarray) -> float:
    try:
        return float(m.F(x, v, check=False))
    except (ArithmeticError, ValueError):
        return math.nan


def _features(m: Metric, x: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Named functions of the points whose thresholds can describe a region: the distance
    from the domain's centre, then each coordinate's distance from the centre, then each
    coordinate upwards and downwards."""
    c = _centre(m)
    name = "|x|" if not np.any(c) else f"|x - {_tuple(c)}|"
    feats = []
    if isinstance(m.domain, Disk) or m.dim > 1:
        feats.append((name, np.linalg.norm(x - c, axis=1)))
    for k in range(m.dim):
        coord = f"x{k}"
        feats.append((f"|{coord}|" if c[k] == 0 else f"|{coord} - {c[k]:.4g}|",
                      np.abs(x[:, k] - c[k])))
    for k in range(m.dim):
        feats.append((f"x{k}", x[:, k]))
        feats.append((f"-x{k}", -x[:, k]))
    return feats


def _tuple(c: np.ndarray) -> str:
    return "(" + ", ".join(f"{a:.4g}" for a in c) + ")"


def describe_region(m: Metric, x: np.ndarray, bad: np.ndarray, what: str) -> str:
    """A sentence saying where among the points ``x`` ``(N, dim)`` the samples flagged
    ``bad`` lie: a threshold on the distance from the domain's centre or on one
    coordinate that separates them from the others ("F is NaN for |x| > 0.9"), else the
    share of the samples and the bad one nearest the centre."""
    n, k = len(x), int(bad.sum())
    if k == n:
        return f"F is {what} at every one of the {n} sampled points"
    for name, f in _features(m, x):
        top, low = float(np.max(f[~bad])), float(np.min(f[bad]))
        if low > top:
            t = 0.5 * (top + low)
            if name.startswith("-"):
                return (f"F is {what} for {name[1:]} < {-t:.3g} ({k} of {n} sampled points; "
                        f"valid up to {-top:.4g}, invalid from {-low:.4g})")
            return (f"F is {what} for {name} > {t:.3g} ({k} of {n} sampled points; valid up "
                    f"to {top:.4g}, invalid from {low:.4g})")
    r = np.linalg.norm(x - _centre(m), axis=1)
    j = int(np.flatnonzero(bad)[np.argmin(r[bad])])
    return (f"F is {what} at {k} of {n} sampled points ({100.0 * k / n:.1f}%), in no "
            f"region a threshold on |x| or one coordinate describes; the nearest to the "
            f"domain's centre is x = {_tuple(x[j])}")


def unit_directions(dim: int, n: int, seed: int = 0) -> np.ndarray:
    """``n`` unit directions ``(n, dim)``: evenly spaced on the circle in 2-D (as
    `finsler.Metric.convexity` takes them), uniformly random (seeded) otherwise."""
    if dim == 2:
        a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        return np.stack([np.cos(a), np.sin(a)], 1)
    g = np.random.default_rng(seed).normal(size=(n, dim))
    return g / np.linalg.norm(g, axis=1, keepdims=True)


def directions_scan(m: Metric, seed: int = 0, points: int = 1024, directions: int = 32
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``F`` at ``points`` uniform points of the domain ``(N, dim)`` along ``directions``
    unit directions ``(K, dim)`` -> ``(x, dirs, F (N, K))`` (seeded; warnings silenced:
    invalid values are what it looks for)."""
    x = m.domain.sample(points, np.random.default_rng([int(seed), 48, 1]))
    dirs = unit_directions(m.dim, directions, seed)
    with np.errstate(all="ignore"):
        f = np.asarray(m.F(np.repeat(x, len(dirs), axis=0), np.tile(dirs, (len(x), 1)),
                           check=False), float).reshape(len(x), len(dirs))
    return x, dirs, f


def weakest_direction(m: Metric, x: np.ndarray, n_directions: int = 64
                      ) -> tuple[np.ndarray, float, np.ndarray]:
    """At a point ``x`` ``(dim,)``: the unit direction ``v`` (of ``n_directions``, as
    `finsler.Metric.convexity` samples them) where the fundamental tensor
    ``Hess_v F**2 / 2`` has its smallest eigenvalue, that eigenvalue, and its eigenvector
    ``w`` (the direction in which ``F(x, .)`` bends the wrong way near ``v``)."""
    dirs = unit_directions(m.dim, n_directions)
    xs = np.repeat(np.asarray(x, float).reshape(1, -1), len(dirs), axis=0)
    (h,) = m.lowered_hessian(xs, dirs)
    h = np.asarray(h).reshape(-1, m.dim, m.dim).transpose(0, 2, 1)
    lam, vec = np.linalg.eigh(0.5 * (h + h.transpose(0, 2, 1)))
    k = int(np.argmin(lam[:, 0]))
    return dirs[k], float(lam[k, 0]), vec[k, :, 0]


def share(bad: np.ndarray) -> str:
    """``"2.4% (98 of 4096)"``."""
    return f"{100.0 * float(np.mean(bad)):.1f}% ({int(np.sum(bad))} of {len(bad)})"
