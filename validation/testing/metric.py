"""Properties of a metric's ``F(x, v)`` itself (no solver): the domain, finiteness and
positivity, positive 1-homogeneity, the triangle inequality in ``v`` (convexity of the
indicatrix) with the non-convex region mapped, strong convexity (the fundamental tensor),
reversibility as declared, the lowered numpy/torch forms against the symbolic one, and
smoothness where the solver and exp/log need it.

Each ``check_*`` function takes the metric and returns a `PropertyResult`; a
metric that documents where ``F(x, .)`` is not convex (``convex_everywhere = False``) has
that region *mapped* (how much of the domain, how near the centre it comes), and the
claim is tested on its convex part: a region the caller names (``convex_shrink``: the
domain scaled about its centre) or, if none, the convex core found by the map.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from hypothesis import strategies as st

from finsler import Box, Disk, Domain, Metric, Product
from finsler.errors import InputError
from validation import strategies as vs
from validation.testing.engine import (
    FAILED,
    MAPPED,
    SKIPPED,
    PropertyResult,
    Verdict,
    combine,
    fmt,
    search,
    seeded,
)
from validation.testing.regions import (
    describe_region,
    directions_scan,
    scan_domain,
    weakest_direction,
)

__all__ = [
    "ConvexityMap",
    "check_domain",
    "check_finite_positive",
    "check_homogeneity",
    "check_lowered_forms",
    "check_reversibility",
    "check_smoothness",
    "check_strong_convexity",
    "check_subadditivity",
    "convexity_map",
    "domain_scale_of",
    "metric_properties",
    "vectors",
]

#: Relative tolerance of homogeneity, subadditivity and the lowered forms (float64 rounding
#: of a few hundred operations).
RTOL = 1e-12
#: Relative tolerance of reversibility ``F(x, -v) = F(x, v)``.
SYMMETRY_RTOL = 1e-13
#: A metric declared not reversible must show ``|F(x, -v) - F(x, v)| > this * F(x, v)``
#: somewhere.
ASYMMETRY_MIN = 1e-3
#: Relative tolerance of the lowered fundamental tensor against CasADi's.
HESSIAN_RTOL = 1e-10
#: Points of the convexity map.
MAP_SAMPLES = 4096
#: The automatic convex region is this fraction of the convex core found by the map.
CORE_MARGIN = 0.95


def vectors(dim: int, low: float = 1e-3, scale: float = 3.0) -> st.SearchStrategy[np.ndarray]:
    """A tangent vector ``(dim,)``: coordinates in ``[-scale, scale]`` (shrinking towards
    small integers), Euclidean norm at least ``low``."""
    coord = st.floats(-scale, scale, allow_nan=False, allow_infinity=False)
    return (st.lists(coord, min_size=dim, max_size=dim).map(lambda c: np.asarray(c, float))
            .filter(lambda v: float(np.linalg.norm(v)) >= low))


def _points(m: Metric, shrink: float = 1.0) -> st.SearchStrategy[np.ndarray]:
    if shrink < 1.0 and domain_scale_of(m.domain, np.zeros((1, m.dim))) is None:
        raise InputError(f"a convex region (the domain scaled by {shrink:g}) needs a box, "
                         f"disk or product domain; {m.name} has {m.domain.describe()}")
    return vs.points(m, shrink)


def _f(m: Metric, x: np.ndarray, v: np.ndarray) -> float:
    return float(m.F(x, v, check=False))


def _vec(x: np.ndarray) -> list[float]:
    return [float(a) for a in np.asarray(x).reshape(-1)]


# ----------------------------------------------------------------------------------------
# where F(x, .) is convex: the map of the documented region
# ----------------------------------------------------------------------------------------
def domain_scale_of(domain: Domain, x: np.ndarray) -> np.ndarray | None:
    """For points ``x`` ``(N, dim)``: the smallest ``s`` with ``x`` in the domain scaled by
    ``s`` about its centre (as `validation.strategies.points` scales it) -> ``(N,)``;
    None for a domain kind that is not a box, disk or product of them."""
    x = np.asarray(x, float).reshape(-1, domain.dim)
    if isinstance(domain, Box):
        lo, hi = domain.bounds()
        c, r = 0.5 * (lo + hi), 0.5 * (hi - lo)
        return np.max(np.abs(x - c) / r, axis=1)
    if isinstance(domain, Disk):
        return np.linalg.norm(x - np.asarray(domain.center), axis=1) / domain.radius
    if isinstance(domain, Product):
        parts, k = [], 0
        for f in domain.factors:
            s = domain_scale_of(f, x[:, k:k + f.dim])
            if s is None:
                return None
            parts.append(s)
            k += f.dim
        return np.max(np.stack(parts, 1), axis=1)
    return None


@dataclass(frozen=True)
class ConvexityMap:
    """Where ``F(x, .)`` is not strongly convex, from ``samples`` uniform points of the
    domain (seeded): the smallest eigenvalue of the fundamental tensor over 32 directions
    per point (`finsler.Metric.convexity`).

    ``fraction``: share of the points where it is ``< 0``; ``nearest``: the non-convex
    point nearest the domain's centre, and ``nearest_scale`` its scale (1 = the boundary;
    None for a domain kind without a centre); ``core``: the largest scale below which every
    sampled point is convex (1 if none is non-convex)."""

    samples: int
    fraction: float
    min_eigenvalue: float
    nearest: tuple[float, ...] | None
    nearest_scale: float | None
    core: float | None
    worst: tuple[float, ...] | None = None
    """The sampled point with the smallest eigenvalue (None if the map found no point
    with a negative one)."""

    def describe(self) -> str:
        if self.fraction == 0:
            return (f"F(x, .) is strongly convex at all {self.samples} sampled points of the "
                    "domain")
        near = ""
        if self.nearest_scale is not None:
            near = (f"; the non-convex sample nearest the domain's centre is "
                    f"{fmt(self.nearest, 4)}, at {self.nearest_scale:.4f} of the domain's "
                    "size")
        return (f"F(x, .) is not convex on {100 * self.fraction:.1f}% of {self.samples} "
                f"sampled points (smallest eigenvalue of the fundamental tensor "
                f"{self.min_eigenvalue:.3g}){near}")


def convexity_map(metric: Metric, samples: int = MAP_SAMPLES, seed: int = 0) -> ConvexityMap:
    """The `ConvexityMap` of ``metric`` (cached on the metric per samples and seed:
    `finsler.Metric.derived`)."""
    samples, seed = int(samples), int(seed)
    return metric.derived(f"testing.convexity_map.{samples}.{seed}",
                          lambda: _map(metric, samples, seed))


def _map(m: Metric, samples: int, seed: int) -> ConvexityMap:
    x = m.domain.sample(samples, np.random.default_rng([seed, 24]))
    lam = m.convexity(x, n_directions=32)
    bad = lam < 0
    scale = domain_scale_of(m.domain, x)
    nearest = nearest_scale = None
    core: float | None = 1.0
    if bad.any() and scale is not None:
        k = int(np.flatnonzero(bad)[np.argmin(scale[bad])])
        nearest, nearest_scale = tuple(float(a) for a in x[k]), float(scale[k])
        core = nearest_scale
    elif bad.any():
        core = None
    worst = tuple(float(a) for a in x[int(np.argmin(lam))]) if bad.any() else None
    return ConvexityMap(samples, float(bad.mean()), float(lam.min()), nearest, nearest_scale,
                        core, worst)


def convex_region(metric: Metric, convex_shrink: float | None, seed: int = 0
                  ) -> tuple[float | None, str]:
    """The scale of the domain on which a metric not convex everywhere is claimed (and
    tested) to be convex: ``convex_shrink`` if given, else a margin inside the core of the
    convexity map (None if it has none), with a sentence saying which."""
    if convex_shrink is not None:
        s = float(convex_shrink)
        if not 0.0 < s <= 1.0:
            raise InputError(f"convex_shrink must be in (0, 1], got {convex_shrink!r}")
        return s, f"the declared convex region (the domain scaled by {s:.4g})"
    core = convexity_map(metric, seed=seed).core
    if not core:
        return None, "no convex core around the domain's centre"
    s = CORE_MARGIN * core
    return s, f"the convex core found by the map (the domain scaled by {s:.4g})"


def solve_region(metric: Metric, convex_shrink: float | None = None, seed: int = 0) -> float:
    """Where solved distances are checked: the whole domain (1) for a metric convex
    everywhere, else its convex region (`convex_region`; 1 if it has none) -- through
    a non-convex region discrete lengths converge to the distance slower than their stated
    errors say."""
    if metric.convex_everywhere:
        return 1.0
    return convex_region(metric, convex_shrink, seed)[0] or 1.0


def _mapped_search(m: Metric, name: str, claim: str, build: Any, check: Any, describe: Any,
                   examples: int, seed: int, convex_shrink: float | None) -> PropertyResult:
    """A convexity-type property: on a metric convex everywhere a failure is a failure; on
    one that documents non-convexity it must hold on the convex region and its failures
    elsewhere are mapped."""
    rng = seeded(seed, name)
    if m.convex_everywhere:
        return search(name, claim, build(1.0), check, describe, examples=examples, rng=rng)
    region, which = convex_region(m, convex_shrink, seed)
    parts = []
    if region is not None:
        inside = search(name, claim, build(region), check, describe, examples=examples,
                        rng=rng)
        inside.note = (f"Holds on {which} ({inside.tried} examples)." if inside.ok else
                       f"FAILS on {which}, where it must hold. {inside.note}".strip())
        parts.append(inside)
    whole = search(name, claim, build(1.0), check, describe, examples=examples, rng=rng)
    if whole.status == FAILED:
        whole.status = MAPPED
        whole.mapped += 1
        whole.note = (f"On the whole domain it fails (the counterexample): mapped, not an "
                      f"error, since {m.name} documents it ({m.convexity_note}). "
                      f"{convexity_map(m, seed=seed).describe()}.")
    parts.append(whole)
    return combine(name, claim, parts)


# ----------------------------------------------------------------------------------------
# the properties
# ----------------------------------------------------------------------------------------
def check_domain(metric: Metric, *, examples: int = 100, seed: int = 0) -> PropertyResult:
    """What the metric promises about its domain: ``F(x, v)`` is finite and ``> 0`` at
    points sampled over the whole declared domain, its boundary included
    (`scan_domain`: uniform points, projections onto the
    boundary, along the signed coordinate directions), and the projection onto the domain
    lies in it, is idempotent and leaves points of the domain where they are (points
    ``p`` drawn from the domain's bounding box enlarged by 20%). A failure of ``F`` says
    where it stops being valid (a threshold on ``|x|`` or a coordinate, from the samples).
    An ``F`` that fails at the domain's centre is a fault of ``F`` itself, which no smaller
    domain mends: it is left to `check_finite_positive`, and this property checks the
    projection only."""
    m = metric
    name = "domain"
    claim = ("F is finite and > 0 on the whole declared domain (boundary included); "
             "project(p) is in the domain, idempotent, the identity inside")
    t0 = time.perf_counter()
    scan = scan_domain(m, seed)
    bad = scan.bad
    n = len(scan.points)
    where = (f"{n} points ({scan.inside} uniform, {n - scan.inside} on the boundary, the "
             f"centre) along the {len(scan.directions)} signed coordinate directions")
    at_centre = bool(bad[-1])  # the centre is last
    if bad.any() and not at_centre:
        r = np.linalg.norm(scan.points - scan.points[-1], axis=1)
        j = int(np.flatnonzero(bad)[np.argmin(r[bad])])
        i = int(np.flatnonzero(scan.bad_values[j])[0])
        region = describe_region(m, scan.points, bad, scan.what())
        return PropertyResult(
            name, claim, FAILED, tried=n, passed=int((~bad).sum()),
            counterexample={"x": _vec(scan.points[j]), "v": _vec(scan.directions[i])},
            lhs=("F(x, v)", float(scan.values[j, i])), rhs=("0", 0.0), relation=">",
            note=(f"{region}. Sampled {where}; the counterexample is the invalid sample "
                  f"nearest the domain's centre. Fix F there, or declare a smaller domain."),
            seconds=time.perf_counter() - t0)
    lo, hi = m.domain.bounds()
    lo = np.where(np.isfinite(lo), lo, -10.0)
    hi = np.where(np.isfinite(hi), hi, 10.0)
    pad = 0.2 * (hi - lo)
    scale = float(np.max(hi - lo))
    strat = st.tuples(*(st.floats(float(a - p), float(b + p)) for a, b, p in zip(lo, hi, pad))
                      ).map(lambda c: np.asarray(c, float))

    def check(p: np.ndarray) -> Verdict:
        q = np.asarray(m.domain.project(p[None]), float)[0]
        if not bool(m.domain.contains(q[None], tol=1e-9)[0]):
            return Verdict(False, ("project(p)", _vec(q)), ("in the domain", m.domain.describe()),
                           "in", "the projection lies outside the domain")
        qq = np.asarray(m.domain.project(q[None]), float)[0]
        moved = float(np.max(np.abs(qq - q)))
        if moved > 1e-12 * scale:
            return Verdict.compare(("project(project(p))", _vec(qq)), "==",
                                   ("project(p)", _vec(q)), False, "projection not idempotent")
        if bool(m.domain.contains(p[None], tol=0.0)[0]):
            moved = float(np.max(np.abs(q - p)))
            if moved > 1e-12 * scale:
                return Verdict.compare(("project(p)", _vec(q)), "==", ("p", _vec(p)), False,
                                       "a point of the domain is moved by the projection")
        return Verdict(True)

    res = search(name, claim, strat, check, lambda p: {"p": _vec(p)}, examples=examples,
                 rng=seeded(seed, name))
    res.tried += n
    res.passed += n
    about_f = (f"F is {scan.what()} at the domain's centre: a fault of F itself, not of the "
               "domain's extent (property finite-positive)" if at_centre
               else f"F finite and > 0 at all {where}")
    res.note = f"{about_f}. {res.note}".strip()
    res.seconds = time.perf_counter() - t0
    return res


def check_finite_positive(metric: Metric, *, examples: int = 100, seed: int = 0
                          ) -> PropertyResult:
    """``F(x, v)`` is finite and ``> 0`` for every ``x`` of the domain and ``v != 0``."""
    m = metric

    def check(ex: tuple[np.ndarray, np.ndarray]) -> Verdict:
        x, v = ex
        f = _f(m, x, v)
        return Verdict.compare(("F(x, v)", f), ">", ("0", 0.0), math.isfinite(f) and f > 0,
                               "" if math.isfinite(f) else "F is not finite")

    res = search("finite-positive", "F(x, v) is finite and > 0 for v != 0 on the domain",
                 st.tuples(_points(m), vectors(m.dim)), check,
                 lambda ex: {"x": _vec(ex[0]), "v": _vec(ex[1])}, examples=examples,
                 rng=seeded(seed, "finite-positive"))
    # hypothesis favours simple vectors (axes, small integers): sweep the directions too
    x, dirs, f = directions_scan(m, seed)
    bad = ~np.isfinite(f) | ~(f > 0)
    share = (f"F is not finite and > 0 for {100 * float(bad.mean()):.1f}% of {bad.size} "
             f"(point, direction) samples ({len(x)} uniform points x {len(dirs)} unit "
             "directions)")
    if res.status == FAILED:
        res.note = f"{res.note}. {share}.".lstrip(". ")
    elif bad.any():
        i, k = np.unravel_index(int(np.argmin(np.where(np.isfinite(f), f, -np.inf))), f.shape)
        res = PropertyResult(res.name, res.claim, FAILED, tried=res.tried + bad.size,
                             passed=res.passed + int((~bad).sum()),
                             counterexample={"x": _vec(x[i]), "v": _vec(dirs[k])},
                             lhs=("F(x, v)", float(f[i, k])), relation=">", rhs=("0", 0.0),
                             note=f"{share}; the counterexample is the smallest value (not "
                                  "shrunk: the search drew no such direction).",
                             seconds=res.seconds)
    return res


def check_homogeneity(metric: Metric, *, examples: int = 100, seed: int = 0,
                      rtol: float = RTOL) -> PropertyResult:
    """``F(x, lam v) = lam F(x, v)`` for ``lam`` in ``[0.01, 100]`` (relative ``rtol``), and
    ``F(x, 0) = 0``."""
    m = metric
    zero = np.zeros(m.dim)

    def check(ex: tuple[np.ndarray, np.ndarray, float]) -> Verdict:
        x, v, lam = ex
        f0 = _f(m, x, zero)
        if f0 != 0.0:
            return Verdict.compare(("F(x, 0)", f0), "==", ("0", 0.0), False)
        a, b = _f(m, x, lam * v), lam * _f(m, x, v)
        ok = abs(a - b) <= rtol * abs(b) + 1e-300
        return Verdict.compare(("F(x, lam v)", a), "==", ("lam F(x, v)", b), ok,
                               f"relative difference {abs(a - b) / max(abs(b), 1e-300):.3g} "
                               f"(tolerance {rtol:g})")

    return search("homogeneity", "F(x, lam v) = lam F(x, v) for lam > 0, F(x, 0) = 0",
                  st.tuples(_points(m), vectors(m.dim), st.floats(0.01, 100.0)), check,
                  lambda ex: {"x": _vec(ex[0]), "v": _vec(ex[1]), "lam": float(ex[2])},
                  examples=examples, rng=seeded(seed, "homogeneity"))


def check_subadditivity(metric: Metric, *, examples: int = 100, seed: int = 0,
                        convex_shrink: float | None = None, rtol: float = RTOL
                        ) -> PropertyResult:
    """The triangle inequality of ``F(x, .)``: ``F(x, v + w) <= F(x, v) + F(x, w)`` and the
    midpoint form ``F(x, (v + w)/2) <= (F(x, v) + F(x, w))/2`` (both within ``rtol``).
    Where the metric documents non-convexity the failures are mapped (module docstring)."""
    m = metric

    def check(ex: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Verdict:
        x, v, w = ex
        fv, fw = _f(m, x, v), _f(m, x, w)
        tol = rtol * (1.0 + abs(fv) + abs(fw))
        lhs = _f(m, x, v + w)
        if not lhs <= fv + fw + tol:
            return Verdict.compare(("F(x, v + w)", lhs), "<=", ("F(x, v) + F(x, w)", fv + fw),
                                   False, f"excess {lhs - fv - fw:.3g}")
        mid = _f(m, x, 0.5 * (v + w))
        return Verdict.compare(("F(x, (v + w)/2)", mid), "<=",
                               ("(F(x, v) + F(x, w))/2", 0.5 * (fv + fw)),
                               mid <= 0.5 * (fv + fw) + tol)

    return _mapped_search(
        m, "subadditivity", "F(x, v + w) <= F(x, v) + F(x, w) (the indicatrix is convex)",
        lambda s: st.tuples(_points(m, s), vectors(m.dim), vectors(m.dim)), check,
        lambda ex: {"x": _vec(ex[0]), "v": _vec(ex[1]), "w": _vec(ex[2])}, examples, seed,
        convex_shrink)


def _not_smooth(m: Metric, name: str, claim: str, why: str) -> PropertyResult:
    return PropertyResult(name, claim, SKIPPED, note=(
        f"{m.name} is declared not smooth ({m.convexity_note}): {why}"))


def check_strong_convexity(metric: Metric, *, examples: int = 100, seed: int = 0,
                           convex_shrink: float | None = None, directions: int = 64
                           ) -> PropertyResult:
    """The fundamental tensor ``Hess_v F(x, v)**2 / 2`` is positive definite at ``x`` for
    ``directions`` unit directions ``v`` (`finsler.Metric.convexity`): a smooth metric
    is Finsler there. Skipped for metrics declared not smooth. Non-convexity the metric
    documents is mapped."""
    m = metric
    name = "strong-convexity"
    claim = "the fundamental tensor Hess_v F^2/2 is positive definite"
    if not m.smooth:
        return _not_smooth(m, name, claim, "its fundamental tensor is not defined "
                                           "everywhere; convexity is checked by subadditivity")

    def check(x: np.ndarray) -> Verdict:
        lam = float(m.convexity(x[None], n_directions=directions)[0])
        return Verdict.compare((f"smallest eigenvalue over {directions} directions", lam), ">",
                               ("0", 0.0), lam > 0)

    def describe(x: np.ndarray) -> dict[str, Any]:
        v, _, w = weakest_direction(m, x, directions)
        return {"x": _vec(x), "v": _vec(v), "w": _vec(w)}

    res = _mapped_search(m, name, claim, lambda s: _points(m, s), check, describe, examples,
                         seed, convex_shrink)
    if not m.convex_everywhere:
        return res
    cmap = convexity_map(m, seed=seed)
    if res.status != FAILED and cmap.worst is not None:
        # the search drew no point of a small bad region; the map's denser samples did
        x = np.asarray(cmap.worst)
        res = PropertyResult(name, claim, FAILED, tried=res.tried + cmap.samples,
                             passed=res.passed + round(cmap.samples * (1 - cmap.fraction)),
                             counterexample=describe(x), relation=">",
                             lhs=(f"smallest eigenvalue over {directions} directions",
                                  float(m.convexity(x[None], n_directions=directions)[0])),
                             rhs=("0", 0.0), seconds=res.seconds)
    if res.status == FAILED and res.counterexample:
        x = np.asarray(res.counterexample["x"])
        v, lam, w = weakest_direction(m, x, directions)
        bad = (f"not convex on {100 * cmap.fraction:.1f}% of {cmap.samples} points sampled "
               f"uniformly over the domain" if cmap.fraction else
               f"convex at all {cmap.samples} points of the convexity map (the bad region is "
               f"smaller than 1/{cmap.samples} of the domain)")
        near = ""
        if cmap.nearest is not None and cmap.nearest_scale is not None:
            near = (f"; the non-convex sample nearest the domain's centre is "
                    f"{fmt(cmap.nearest, 4)}, at {cmap.nearest_scale:.3f} of the domain's size")
        res.note = (f"F(x, .) is not convex at x = {fmt(_vec(x), 4)}: at the unit direction "
                    f"v = {fmt(_vec(v), 4)} the fundamental tensor has eigenvalue {lam:.3g} "
                    f"along w = {fmt(_vec(w), 4)} (the unit ball bends inwards there). F is "
                    f"{bad}{near}. Fix F there, or declare convex_everywhere = False with a "
                    f"convexity_note and the region is mapped instead. {res.note}").strip()
    return res


def check_reversibility(metric: Metric, *, examples: int = 100, seed: int = 0,
                        rtol: float = SYMMETRY_RTOL) -> PropertyResult:
    """As declared: a reversible metric has ``F(x, -v) = F(x, v)`` (relative ``rtol``); for
    a metric declared not reversible the property does not apply (``skipped``, with the
    asymmetric example that confirms the declaration), unless ``|F(x, -v) - F(x, v)| <=
    1e-3 F(x, v)`` on all ``examples`` draws: then it fails (declare ``reversible =
    True``)."""
    m = metric
    name = "reversibility"
    ex_strat = st.tuples(_points(m), vectors(m.dim))

    def gap(ex: tuple[np.ndarray, np.ndarray]) -> tuple[float, float]:
        x, v = ex
        return _f(m, x, -v), _f(m, x, v)

    def describe(ex: tuple[np.ndarray, np.ndarray]) -> dict[str, Any]:
        return {"x": _vec(ex[0]), "v": _vec(ex[1])}

    if m.reversible:
        def check(ex: tuple[np.ndarray, np.ndarray]) -> Verdict:
            a, b = gap(ex)
            return Verdict.compare(("F(x, -v)", a), "==", ("F(x, v)", b),
                                   abs(a - b) <= rtol * abs(b),
                                   "the metric is declared reversible")

        return search(name, "F(x, -v) = F(x, v) (declared reversible)", ex_strat, check,
                      describe, examples=examples, rng=seeded(seed, name))

    # declared not reversible: an asymmetric example must exist; search for one
    def symmetric(ex: tuple[np.ndarray, np.ndarray]) -> Verdict:
        a, b = gap(ex)  # "fails" = asymmetric: found (its two sides name the asymmetry)
        return Verdict.compare(("F(x, -v)", a), "!=", ("F(x, v)", b),
                               abs(a - b) <= ASYMMETRY_MIN * abs(b))

    found = search(name, "", ex_strat, symmetric, describe, examples=examples,
                   rng=seeded(seed, name))
    claim = "F(x, -v) != F(x, v) somewhere (declared not reversible)"
    if found.status == FAILED:  # an asymmetric example: the declaration holds
        seen = f" (asymmetry confirmed at {found.short_example(200)}: {found.sides()})"
        return PropertyResult(name, claim, SKIPPED, seconds=found.seconds,
                              note=f"not applicable: {m.name} is declared not reversible"
                                   + seen)
    return PropertyResult(
        name, claim, FAILED, tried=found.tried, passed=0, seconds=found.seconds,
        note=(f"F(x, -v) = F(x, v) within {ASYMMETRY_MIN:g} relative on all {found.tried} "
              f"examples: the metric looks reversible; declare reversible = True (symmetric "
              f"distances, checked by distance-symmetry)"))


def check_lowered_forms(metric: Metric, *, examples: int = 100, seed: int = 0,
                        rtol: float = RTOL, hessian_rtol: float = HESSIAN_RTOL
                        ) -> PropertyResult:
    """The numpy and torch programs lowered from the CasADi graph (``metric.F`` on arrays
    and on float64 tensors) equal CasADi's own evaluation of the symbolic ``F``
    (``|diff| <= rtol max(1, |F|)``), and the lowered fundamental tensor equals CasADi's
    (``hessian_rtol``)."""
    import torch

    m = metric

    def check(ex: tuple[np.ndarray, np.ndarray]) -> Verdict:
        x, v = ex
        ref = float(np.asarray(m.casadi_F(x, v)).reshape(-1)[0])
        scale = max(1.0, abs(ref))
        got_np = _f(m, x, v)
        got_t = float(m.F(torch.from_numpy(x[None].copy()), torch.from_numpy(v[None].copy()))[0])
        for label, got in (("F lowered to numpy", got_np), ("F lowered to torch", got_t)):
            if not abs(got - ref) <= rtol * scale:
                return Verdict.compare((label, got), "==", ("F symbolic (CasADi)", ref), False,
                                       f"difference {got - ref:.3g} (tolerance {rtol:g} "
                                       "max(1, |F|))")
        (h,) = m.lowered_hessian(x[None], v[None])
        got_h = np.asarray(h).reshape(m.dim, m.dim).T  # CasADi is column-major
        ref_h = np.asarray(m.casadi_hessian(x, v))
        if not np.allclose(got_h, ref_h, rtol=hessian_rtol, atol=hessian_rtol):
            k = np.unravel_index(np.argmax(np.abs(got_h - ref_h)), got_h.shape)
            return Verdict.compare((f"fundamental tensor lowered [{k[0]},{k[1]}]",
                                    float(got_h[k])), "==",
                                   ("symbolic (CasADi)", float(ref_h[k])), False)
        return Verdict(True)

    return search("lowered-forms", "numpy/torch F and its Hessian equal the symbolic CasADi F",
                  st.tuples(_points(m), vectors(m.dim, low=1e-2)), check,
                  lambda ex: {"x": _vec(ex[0]), "v": _vec(ex[1])}, examples=examples,
                  rng=seeded(seed, "lowered-forms"))


def _build_second_derivative(metric: Metric) -> ca.Function:
    """``(z, u) -> u' Hess_z E(z) u`` with ``E = F(x, v)**2 / 2`` and ``z = (x, v)``, by
    CasADi's automatic differentiation of the metric's one expression."""
    d = metric.dim
    z = ca.SX.sym("z", 2 * d)
    u = ca.SX.sym("u", 2 * d)
    e = 0.5 * metric.F_sx(z[:d], z[d:]) ** 2
    h, _ = ca.hessian(e, z)
    return ca.Function("d2E", [z, u], [ca.mtimes([u.T, h, u])])


def check_smoothness(metric: Metric, *, examples: int = 100, seed: int = 0,
                     step: float = 2e-3, rtol: float = 1e-6) -> PropertyResult:
    """For a metric declared smooth: ``E = F**2 / 2`` is C^2 in ``(x, v)`` away from
    ``v = 0``, as IPOPT (exact Hessians) and exp/log (the spray) need: along a random
    direction ``u`` (``x`` part scaled by the domain's size, ``v`` part by ``|v|``), the
    second difference of ``E`` at steps ``h = step`` and ``h/2`` converges to CasADi's
    symbolic ``u' Hess E u`` (its error at ``h/2`` at most ``rtol (|E| + |Hess|)`` or
    shrinking by 0.6 from ``h``; a kink within ``h/2`` makes it grow like ``1/h``).
    Skipped for metrics declared not smooth."""
    m = metric
    name = "smoothness"
    claim = "F^2 is C^2 in (x, v) for v != 0 (symbolic Hessian = second differences)"
    if not m.smooth:
        return _not_smooth(m, name, claim, "exp/log refuse it and the solver uses its smooth "
                                           "reformulation")
    fn = m.derived("testing.joint_second_derivative", lambda: _build_second_derivative(m))
    d = m.dim
    lo, hi = m.domain.bounds()
    width = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    direction = (st.lists(st.floats(-1.0, 1.0), min_size=2 * d, max_size=2 * d)
                 .map(lambda c: np.asarray(c, float))
                 .filter(lambda c: float(np.linalg.norm(c)) > 0.1))

    def energy(z: np.ndarray) -> float:  # the symbolic F, as IPOPT and exp/log see it
        return 0.5 * float(np.asarray(m.casadi_F(z[:d], z[d:])).reshape(-1)[0]) ** 2

    def check(ex: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Verdict:
        x, v, c = ex
        c = c / np.linalg.norm(c)
        u = np.concatenate([c[:d] * width, c[d:] * np.linalg.norm(v)])
        z = np.concatenate([x, v])
        e0 = energy(z)
        sym = float(np.asarray(fn(z, u)).reshape(-1)[0])
        errs, d2s = [], []
        for h in (step, 0.5 * step):
            d2 = (energy(z + h * u) - 2.0 * e0 + energy(z - h * u)) / (h * h)
            d2s.append(d2)
            errs.append(abs(d2 - sym))
        ok = math.isfinite(sym) and (errs[1] <= rtol * (abs(e0) + abs(sym))
                                     or errs[1] <= 0.6 * errs[0])
        return Verdict.compare((f"second difference of F^2/2 (h = {0.5 * step:g})", d2s[1]), "==",
                               ("u' Hess(F^2/2) u (symbolic)", sym), ok,
                               f"error {errs[0]:.3g} at h = {step:g}, {errs[1]:.3g} at h/2: "
                               "not converging, F^2 has a kink here")

    res = search(name, claim,
                 st.tuples(_points(m, 0.9), vectors(d, low=0.1), direction), check,
                 lambda ex: {"x": _vec(ex[0]), "v": _vec(ex[1]),
                             "u": _vec(ex[2] / np.linalg.norm(ex[2]))},
                 examples=examples, rng=seeded(seed, name))
    if res.status == FAILED:
        return res
    # a kink on a thin set (|x0| = 0) is rarely within a step of hypothesis's draws:
    # sweep many points at once, at a larger step (the same test)
    found = _smoothness_sweep(m, fn, width, seed)
    if found is None:
        res.tried += SMOOTH_SWEEP
        res.passed += SMOOTH_SWEEP
        return res
    (x, v, u), got, sym, note, n_bad = found
    return PropertyResult(name, claim, FAILED, tried=res.tried + SMOOTH_SWEEP,
                          passed=res.passed + SMOOTH_SWEEP - n_bad,
                          counterexample={"x": _vec(x), "v": _vec(v), "u": _vec(u)},
                          lhs=(f"second difference of F^2/2 (h = {SMOOTH_SWEEP_STEP / 2:g})",
                               got), relation="==", rhs=("u' Hess(F^2/2) u (symbolic)", sym),
                          note=note, seconds=res.seconds)


#: Points and step of the smoothness sweep (after the hypothesis search).
SMOOTH_SWEEP = 4096
SMOOTH_SWEEP_STEP = 1e-2
#: Relative error of the sweep's second differences accepted without convergence.
SWEEP_RTOL = 1e-3
#: The sweep judges points where ``|u' Hess E u| h**2 <= SWEEP_RESOLVED |E|``.
SWEEP_RESOLVED = 1e-2


def _smoothness_sweep(m: Metric, fn: ca.Function, width: np.ndarray, seed: int) -> Any:
    """The smoothness test of `check_smoothness` (CasADi's F, evaluated in one
    batch) at `SMOOTH_SWEEP` uniform
    points (the domain scaled by 0.9 about its centre), unit ``v`` and random directions
    ``u``, steps `SMOOTH_SWEEP_STEP` and half of it (an error at most
    `SWEEP_RTOL` relative, or shrinking by 0.6); None if every point passes,
    else ``((x, v, u), second difference, symbolic, note, failing points)`` at the worst
    one."""
    d, n = m.dim, SMOOTH_SWEEP
    rng = np.random.default_rng([int(seed), 48, 2])
    x0 = m.domain.sample(n, rng)
    c = _centre_of(m)
    x = c + 0.9 * (x0 - c)
    v = rng.normal(size=(n, d))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    dirs = rng.normal(size=(n, 2 * d))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    u = np.concatenate([dirs[:, :d] * width, dirs[:, d:]], axis=1)
    z = np.concatenate([x, v], axis=1)

    f_map = m.casadi_F.map(n)  # the symbolic F, as IPOPT and exp/log see it

    def energy(zz: np.ndarray) -> np.ndarray:
        return 0.5 * np.asarray(f_map(zz[:, :d].T, zz[:, d:].T), float).reshape(-1) ** 2

    sym = np.asarray(fn.map(n)(z.T, u.T), float).reshape(-1)
    e0 = energy(z)
    errs, d2s = [], []
    for h in (SMOOTH_SWEEP_STEP, 0.5 * SMOOTH_SWEEP_STEP):
        d2 = (energy(z + h * u) - 2.0 * e0 + energy(z - h * u)) / (h * h)
        d2s.append(d2)
        errs.append(np.abs(d2 - sym))
    with np.errstate(all="ignore"):  # at the larger step a C^2 F whose third derivative
        # jumps (a cubic spline) converges at first order only: a kink of F^2 (first or
        # second derivative jumping) is an error that does not shrink and is not small.
        # Where the step does not resolve E's own curvature (|u'Hu| h^2 > SWEEP_RESOLVED
        # |E|: near a singularity of a smooth F, e.g. Panda's 1/r at the pole) second
        # differences say nothing yet: not judged
        unresolved = np.abs(sym) * SMOOTH_SWEEP_STEP**2 > SWEEP_RESOLVED * np.abs(e0)
        ok = unresolved | (np.isfinite(sym) & (
            (errs[1] <= SWEEP_RTOL * (np.abs(e0) + np.abs(sym))) | (errs[1] <= 0.6 * errs[0])))
    if ok.all():
        return None
    bad = ~ok
    k = int(np.flatnonzero(bad)[np.argmax(np.nan_to_num(errs[1][bad], nan=np.inf))])
    note = (f"error {errs[0][k]:.3g} at h = {SMOOTH_SWEEP_STEP:g}, {errs[1][k]:.3g} at h/2: "
            f"not converging, F^2 has a kink within {SMOOTH_SWEEP_STEP:g} of x along u; "
            f"{int(bad.sum())} of {n} swept points fail. "
            "Declare smooth = False if F is meant to have kinks.")
    return (x[k], v[k], dirs[k]), float(d2s[1][k]), float(sym[k]), note, int(bad.sum())


def _centre_of(m: Metric) -> np.ndarray:
    lo, hi = m.domain.bounds()
    if isinstance(m.domain, Disk):
        return np.asarray(m.domain.center, float)
    return 0.5 * (np.where(np.isfinite(lo), lo, 0.0) + np.where(np.isfinite(hi), hi, 0.0))


def metric_properties(metric: Metric, *, examples: int = 100, seed: int = 0,
                      convex_shrink: float | None = None) -> list[PropertyResult]:
    """Every property of ``F`` in this module, in order."""
    kw = {"examples": examples, "seed": seed}
    return [
        check_domain(metric, **kw),
        check_finite_positive(metric, **kw),
        check_homogeneity(metric, **kw),
        check_subadditivity(metric, convex_shrink=convex_shrink, **kw),
        check_strong_convexity(metric, convex_shrink=convex_shrink, **kw),
        check_reversibility(metric, **kw),
        check_lowered_forms(metric, **kw),
        check_smoothness(metric, **kw),
    ]
