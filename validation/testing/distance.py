"""Properties of the metric's distance as the solver computes it: ``d(x, x) = 0``,
``d >= 0`` (``> 0`` for ``x != y``), the triangle inequality, the straight segment's
length as an upper bound, symmetry for reversible metrics, a closed-form distance or
geodesic the user supplies against the solved one, the certified interval containing the
solved distance (2-D), and the midpoint of a solved geodesic splitting its length in
halves -- each within the solver's stated errors.

Distances come from an *oracle*, a strategy object (``solve(metric, x, y) ->``
`Solved`): `DiscreteDistance` (default: the task's discrete geodesic refined
to a relative tolerance by `solvers.solve_geodesic` with ``tol``, from few segments,
fast, valid through non-convex regions) or `ContinuumDistance` (the pseudospectral
`solvers.distance`, accurate to ``1e-8`` for smooth Finsler metrics; a curve through a
non-convex region is reported ``not_convex`` and its examples are mapped). Every property of
one check draws its examples from the same seeded stream of triples ``(x, y, z)`` and the
solves are cached, so the properties share their solves.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from hypothesis import strategies as st

from finsler import Metric
from finsler.errors import InputError
from finsler.status import Outcome
from validation import strategies as vs
from validation.testing.engine import SKIPPED, PropertyResult, Verdict, search, seeded

__all__ = [
    "ContinuumDistance",
    "DiscreteDistance",
    "DistanceOracle",
    "Solved",
    "SolvedDistances",
    "check_certificate",
    "check_closed_form",
    "check_distance_positive",
    "check_distance_symmetry",
    "check_distance_zero",
    "check_midpoint_halves",
    "check_segment_bound",
    "check_triangle_inequality",
    "closed_form_of",
    "distance_checks",
    "distance_properties",
]

#: The mesh of the certificate property: the ``coarse`` preset of `solvers.certify`
#: (its work budget: at most 3 LP rounds and 3000 triangles per pair, not a wall-clock
#: limit, so the result depends on the seed only).
CERTIFY_MESH = "coarse"
#: Examples of the certificate property beyond the plane (the first one drawn is x = y, so
#: at most two certificates): one costs 2-5 s on a flat 3-D box and 10-26 s on
#: ``poincare-slab`` with the coarse preset, 11-13 s on the 7-D Panda (conformal lower bound),
#: against well under a second in 2-D.
CERTIFY_EXAMPLES_ND = 3
#: The certificate's work counts a budget note names, as far as the result carries them.
_WORK = ("triangles", "directions", "cells", "lp_rows", "boxes")
#: What a failed distance property suspects: F passed the properties the distance needs
#: (else the property is not run), so the solve or its error estimate.
SOLVE_HINT = ("F passed the properties this one needs, so suspect the solve: a local "
              "minimum, or an error estimate too small (`geodesics solve` on the pair with "
              "more segments or seeds).")
#: What a failed closed-form property suspects: the formula.
CLOSED_FORM_HINT = ("The solver's value passed the other distance properties: check the "
                    "closed form (the metric's `distance` method, or the one given as "
                    "`check(closed_form=...)`).")


@dataclass
class Solved:
    """One solved distance ``d(x, y)``: ``value`` with the solver's stated ``error``
    (absolute), its ``status`` (the solver's member of the status family; an oracle of
    one's own may give a word); ``usable``: a value with a stated error (a converged
    solve); ``mapped``: the solve crossed a region where ``F(x, .)`` is not convex and the
    oracle does not resolve it. ``path`` ``(n+1, dim)`` is the solved curve, ``curve(t)``
    its points ``(T, dim)`` at fractions ``t`` of its length (to ``curve_slack`` of the
    domain's size, beyond what the stated length error implies), ``midpoint`` a point of it
    whose distance from ``x`` is within ``midpoint_slack`` of ``d(x, y) / 2``."""

    value: float
    error: float
    status: Outcome | str
    usable: bool
    mapped: bool = False
    path: np.ndarray | None = None
    midpoint: np.ndarray | None = None
    midpoint_slack: float = math.inf
    curve: Callable[[np.ndarray], np.ndarray] | None = None
    curve_slack: float = 1e-6
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """A value to judge a property by: usable and not in a mapped region."""
        return self.usable and not self.mapped


class DistanceOracle(Protocol):
    """How a property gets ``d(x, y)``: any object with ``solve(metric, x, y) -> Solved``
    and a ``name`` for reports."""

    name: str

    def solve(self, metric: Metric, x: np.ndarray, y: np.ndarray) -> Solved: ...


@dataclass(frozen=True)
class DiscreteDistance:
    """The discrete geodesic of `solvers.solve_geodesic`, globally seeded at
    ``segments`` and doubled (warm started) until the estimated error of the continuum
    length is below ``tol`` relative or ``max_segments`` is reached (default 8 to 64 for a
    smooth metric; 64 to 256 for one declared not smooth, whose discrete lengths converge
    at first order and change route with the resolution: measured on car-like, 8 to 64
    segments ended above the straight segment's length by more than the stated error on 2
    of 30 random pairs, 64 to 256 on none of 15); the stated error is
    the solver's ``error_estimate`` (Richardson extrapolation of the polyline lengths), at
    least ``error_floor`` relative: the extrapolation does not see IPOPT's own accuracy
    (constraints relaxed by ~1e-8, which moves a path along the domain's boundary; measured
    on a Randers pair along the box's side: 4.6e-10 off the closed form, 2.2e-10 stated).
    Positions along the path are taken at fractions of its length ``L`` (eq. 58 by adaptive
    quadrature, segment by segment; its points are equally spaced in C, which on the
    car-like metric underestimates turning segments by up to 7%): its vertex ``m`` nearest
    half the length, at length ``l`` from ``x`` along it, has ``l - (L - d) <= d(x, m) <=
    l`` (the triangle inequality), so it is within ``|l - L/2| + |L - d|`` (``|L - d|``
    bounded by ``|L - value| + error``) of half the distance; positions along it are good
    to ``|L - d| / d`` of the domain's size (plus the second-order error of interpolating
    within a segment). A path through points where
    ``F(x, .)`` is not convex (on a metric that documents such a region) is mapped: there
    discrete minimisers chatter and converge slowly to the relaxed distance, faster than
    the estimate can tell (measured on Matsumoto: 64 segments 1.7% above certify's upper
    bound, 1e-4 stated)."""

    tol: float = 1e-4
    segments: int | None = None
    max_segments: int | None = None
    error_floor: float = 1e-8

    @property
    def name(self) -> str:
        sizes = ("8 (64 if not smooth)" if self.segments is None else str(self.segments),
                 "64 (256)" if self.max_segments is None else str(self.max_segments))
        return f"discrete geodesic, tol {self.tol:g}, {sizes[0]} to {sizes[1]} segments"

    def sizes(self, metric: Metric) -> tuple[int, int]:
        """``(segments, max_segments)`` for ``metric``."""
        n0 = self.segments if self.segments is not None else (8 if metric.smooth else 64)
        mx = self.max_segments if self.max_segments is not None else (
            64 if metric.smooth else 256)
        return n0, max(mx, n0)

    def solve(self, metric: Metric, x: np.ndarray, y: np.ndarray) -> Solved:
        import solvers

        n0, mx = self.sizes(metric)
        r = solvers.solve_geodesic(metric, x, y, n0, tol=self.tol, max_segments=mx)
        value = float(r.length_estimate if r.length_estimate is not None else r.length)
        err = max(float(r.error_estimate if r.error_estimate is not None else math.inf),
                  self.error_floor * value)
        mapped = not metric.convex_everywhere and r.nonconvex_points > 0
        pts = np.asarray(r.points, float)
        seg = metric.segment_length_error(pts[:-1], pts[1:], check=False)
        cum = np.concatenate([[0.0], np.cumsum(np.asarray(seg.value, float))])
        length = float(cum[-1])
        excess = abs(length - value) + err + float(np.sum(seg.error))
        k = int(np.argmin(np.abs(cum - 0.5 * length)))  # the vertex nearest half the length

        def curve(t: np.ndarray) -> np.ndarray:
            return _along(pts, cum, t)

        return Solved(value, err, r.status, bool(r.converged), mapped, pts,
                      pts[k].copy(), excess + abs(cum[k] - 0.5 * length), curve,
                      1e-6 + excess / max(value, 1e-300),
                      {"segments": r.segments, "tol_reached": r.tol_reached,
                       "polyline_length": length})


@dataclass(frozen=True)
class ContinuumDistance:
    """The pseudospectral distance of [`solvers.distance`][solvers.distance] (``rtol``: None for its
    default, 1e-8 for smooth metrics); converged solves are usable, a curve through a
    non-convex region is mapped, anything else is a failure. The midpoint is the constant
    speed curve at ``t = 1/2``, within the stated error plus ``1e-10 d``."""

    rtol: float | None = None

    @property
    def name(self) -> str:
        return f"pseudospectral distance, rtol {self.rtol if self.rtol else 'default'}"

    def solve(self, metric: Metric, x: np.ndarray, y: np.ndarray) -> Solved:
        import solvers
        from solvers import DistanceStatus

        r = solvers.distance(metric, x, y, rtol=self.rtol)
        path = r.curve(np.linspace(0.0, 1.0, 65))
        return Solved(float(r.distance), float(r.error_estimate), r.status,
                      bool(r.converged), r.status is DistanceStatus.NOT_CONVEX, path,
                      path[32].copy(), float(r.error_estimate) + 1e-10 * float(r.distance),
                      r.curve, 1e-6, {"degrees": r.degrees})


class SolvedDistances:
    """Cache of ``oracle.solve`` for one metric: each ``(x, y)`` is solved once."""

    def __init__(self, metric: Metric, oracle: DistanceOracle) -> None:
        self.metric, self.oracle = metric, oracle
        self._cache: dict[tuple[bytes, bytes], Solved] = {}
        self.solves = 0

    def __call__(self, x: np.ndarray, y: np.ndarray) -> Solved:
        k = (np.asarray(x, float).tobytes(), np.asarray(y, float).tobytes())
        if k not in self._cache:
            self._cache[k] = self.oracle.solve(self.metric, np.asarray(x, float),
                                               np.asarray(y, float))
            self.solves += 1
        return self._cache[k]


def _unusable(what: str, s: Solved) -> Verdict:
    """An example whose solve gives no value to judge by: mapped (a documented non-convex
    region) or inconclusive (the solve did not converge: never a counterexample)."""
    if s.mapped:
        return Verdict(True, note=f"{what}: the solved curve crosses a region where F(x, .) "
                                  "is not convex", mapped=True)
    tried = ", ".join(f"{k} {v}" for k, v in s.extra.items() if k in ("segments", "degrees"))
    return Verdict.unjudged(f"a solve did not converge (status {s.status}"
                            + (f"; {tried}" if tried else "") + ")")


def _vec(x: np.ndarray) -> list[float]:
    return [float(a) for a in np.asarray(x).reshape(-1)]


def closed_form_of(metric: Metric) -> tuple[Callable[..., Any] | None, Callable[..., Any] | None]:
    """The closed-form ``(distance, geodesic)`` a metric provides (its declared hooks
    ``distance(x, y)`` and ``geodesic(x, y, t)``, `finsler.hooks`; a
    `finsler.ClosedFormMetric` has both), each ``None`` where it provides none."""
    return (metric.distance if metric.provides("distance") else None,
            metric.geodesic if metric.provides("geodesic") else None)


@dataclass
class DistanceSuite:
    """The shared state of one check's distance properties: the metric, the cached
    oracle, the seed (one stream of triples) and the region (``shrink``)."""

    metric: Metric
    solved: SolvedDistances
    seed: int = 0
    shrink: float = 1.0
    shrink_limit: int = 6

    @classmethod
    def make(cls, metric: Metric, oracle: DistanceOracle | None = None, seed: int = 0,
             shrink: float = 1.0, shrink_limit: int = 6) -> DistanceSuite:
        if not 0.0 < shrink <= 1.0:
            raise InputError(f"the distance region (shrink) must be in (0, 1], got {shrink!r}")
        return cls(metric, SolvedDistances(metric, oracle or DiscreteDistance()), int(seed),
                   float(shrink), int(shrink_limit))

    def triples(self) -> st.SearchStrategy[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        return vs.triples(self.metric, self.shrink)

    def size(self) -> float:
        """The domain's largest side (1 where unbounded)."""
        lo, hi = self.metric.domain.bounds()
        return float(np.max(np.where(np.isfinite(hi - lo), hi - lo, 1.0)))

    def run(self, name: str, claim: str, check: Callable[[Any], Verdict], examples: int,
            keys: str = "xyz", strategy: st.SearchStrategy[Any] | None = None,
            hint: str = SOLVE_HINT) -> PropertyResult:
        """Search ``check`` on this suite's triples (or ``strategy``); a failure's note ends
        with ``hint`` (what to suspect: by default the solve, since the properties of F
        it needs passed)."""
        def describe(t: tuple[np.ndarray, ...]) -> dict[str, Any]:
            return {k: _vec(p) for k, p in zip("xyz", t) if k in keys}

        res = search(name, claim, strategy if strategy is not None else self.triples(), check,
                     describe, examples=examples, rng=seeded(self.seed, "distances"),
                     shrink_limit=self.shrink_limit)
        if res.status == "mapped":
            res.note = (f"{res.mapped} of {res.tried} examples crossed a region where "
                        f"F(x, .) is not convex ({self.metric.convexity_note}): mapped")
        elif res.status == "failed":
            res.note = f"{res.note}. Distances by {self.solved.oracle.name}.".lstrip(". ")
            if hint:
                res.note = f"{res.note} {hint}"
        elif res.status == "inconclusive":
            res.note = (f"{res.note}. Distances by {self.solved.oracle.name}; `geodesics "
                        "solve` on the pair shows the solver's statuses (more segments or "
                        "seeds may converge).")
        if self.shrink < 1.0:
            res.note = (f"{res.note} Points drawn from the domain scaled by {self.shrink:.4g} "
                        "about its centre.").strip()
        return res


def check_distance_zero(suite: DistanceSuite, examples: int = 20) -> PropertyResult:
    """``d(x, x) = 0`` exactly."""

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        s = suite.solved(t[0], t[0])
        if not s.ok:
            return _unusable("d(x, x)", s)
        return Verdict.compare(("d(x, x)", s.value), "==", ("0", 0.0), s.value == 0.0)

    return suite.run("distance-zero", "d(x, x) = 0", check, examples, keys="x")


def check_distance_positive(suite: DistanceSuite, examples: int = 3) -> PropertyResult:
    """``d(x, y) >= 0``, and ``d(x, y) > 0`` for ``x != y``."""

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        x, y = t[0], t[1]
        s = suite.solved(x, y)
        if not s.ok:
            return _unusable("d(x, y)", s)
        distinct = not np.array_equal(x, y)
        ok = s.value > 0 if distinct else s.value >= 0
        return Verdict.compare(("d(x, y)", s.value), ">" if distinct else ">=", ("0", 0.0), ok,
                               f"solved with status {s.status}")

    return suite.run("distance-positive", "d(x, y) >= 0, and > 0 for x != y", check, examples,
                     keys="xy")


def check_triangle_inequality(suite: DistanceSuite, examples: int = 3) -> PropertyResult:
    """``d(x, z) <= d(x, y) + d(y, z)`` within the sum of the three stated errors."""

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        x, y, z = t
        parts = {"d(x, z)": suite.solved(x, z), "d(x, y)": suite.solved(x, y),
                 "d(y, z)": suite.solved(y, z)}
        for what, s in parts.items():
            if not s.ok:
                return _unusable(what, s)
        xz, xy, yz = parts.values()
        slack = xz.error + xy.error + yz.error + 1e-12 * (1.0 + xz.value)
        return Verdict.compare(("d(x, z)", xz.value), "<=", ("d(x, y) + d(y, z)",
                                                             xy.value + yz.value),
                               xz.value <= xy.value + yz.value + slack,
                               f"stated errors {xz.error:.2g}, {xy.error:.2g}, {yz.error:.2g}")

    return suite.run("triangle-inequality", "d(x, z) <= d(x, y) + d(y, z) (within the "
                     "stated errors)", check, examples)


def check_distance_symmetry(suite: DistanceSuite, examples: int = 3) -> PropertyResult:
    """For a reversible metric: ``d(x, y) = d(y, x)`` within the stated errors."""
    m = suite.metric
    name, claim = "distance-symmetry", "d(x, y) = d(y, x) for a reversible metric"
    if not m.reversible:
        return PropertyResult(name, claim, SKIPPED,
                              note=f"{m.name} is not declared reversible")

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        x, y = t[0], t[1]
        a, b = suite.solved(x, y), suite.solved(y, x)
        for what, s in (("d(x, y)", a), ("d(y, x)", b)):
            if not s.ok:
                return _unusable(what, s)
        slack = a.error + b.error + 1e-10 * max(a.value, 1.0)
        return Verdict.compare(("d(x, y)", a.value), "==", ("d(y, x)", b.value),
                               abs(a.value - b.value) <= slack,
                               f"stated errors {a.error:.2g}, {b.error:.2g}")

    return suite.run(name, claim, check, examples, keys="xy")


def check_closed_form(suite: DistanceSuite, examples: int = 3,
                      distance: Callable[..., Any] | None = None,
                      geodesic: Callable[..., Any] | None = None) -> PropertyResult:
    """A closed-form distance ``distance(x (N, dim), y (N, dim)) -> (N,)`` (and optionally
    geodesic ``geodesic(x, y, t (T,)) -> (N, T, dim)``, at arc-length fractions) the user
    supplies -- by default the metric's own, if it is a `finsler.ClosedFormMetric`
    -- against the solved one: ``|d_solved - d_closed| <=`` the stated error (plus
    ``1e-12 (1 + d)``), and the solved curve within ``curve_slack + sqrt(error / d)`` (of
    the domain's size) of the closed-form geodesic at ``t = 1/4, 1/2, 3/4``."""
    m = suite.metric
    name, claim = "closed-form-distance", "the supplied closed-form distance equals the solved one"
    if distance is None and geodesic is None:
        distance, geodesic = closed_form_of(m)
    if distance is None:
        return PropertyResult(name, claim, SKIPPED, note=(
            f"{m.name} supplies no closed-form distance: give the metric a `distance(x, y)` "
            "method (finsler.ClosedFormMetric), or pass one to "
            "`validation.testing.check(metric, closed_form=...)`"))
    lo, hi = m.domain.bounds()
    size = float(np.max(np.where(np.isfinite(hi - lo), hi - lo, 1.0)))

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        x, y = t[0], t[1]
        # both directions for a metric that is not reversible: the asymmetry is the true one
        for a, b, what in ((x, y, "d(x, y)"), (y, x, "d(y, x)"))[:1 if m.reversible else 2]:
            s = suite.solved(a, b)
            if not s.ok:
                return _unusable(what, s)
            ref = float(np.asarray(distance(a[None], b[None]), float).reshape(-1)[0])
            if not abs(s.value - ref) <= s.error + 1e-12 * (1.0 + abs(ref)):
                return Verdict.compare((f"{what} solved", s.value), "==", ("closed form", ref),
                                       False, f"stated error {s.error:.2g} "
                                              f"({suite.solved.oracle.name})")
        s = suite.solved(x, y)
        if geodesic is None or s.curve is None or s.value == 0.0:
            return Verdict(True)
        ts = np.array([0.25, 0.5, 0.75])
        want = np.asarray(geodesic(x[None], y[None], ts), float).reshape(len(ts), m.dim)
        got = np.asarray(s.curve(ts), float).reshape(len(ts), m.dim)
        dev = float(np.max(np.abs(got - want)))
        tol = size * (s.curve_slack + math.sqrt(max(s.error, 0.0) / max(s.value, 1e-300)))
        return Verdict.compare(("solved curve at t = 1/4, 1/2, 3/4", _vec(got)), "==",
                               ("closed-form geodesic", _vec(want)), dev <= tol,
                               f"largest deviation {dev:.3g} (tolerance {tol:.3g})")

    return suite.run(name, claim, check, examples, keys="xy", hint=CLOSED_FORM_HINT)


def _along(path: np.ndarray, cum: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """Points of a polyline ``(n+1, dim)`` at fractions ``ts`` ``(T,)`` of its length, from
    the cumulative lengths ``cum`` ``(n+1,)`` of its vertices -> ``(T, dim)``."""
    s = cum / cum[-1] if cum[-1] > 0 else np.linspace(0.0, 1.0, len(path))
    ts = np.asarray(ts, float).reshape(-1)
    return np.stack([np.interp(ts, s, path[:, k]) for k in range(path.shape[1])], 1)


def check_segment_bound(suite: DistanceSuite, examples: int = 3) -> PropertyResult:
    """``d(x, y)`` is at most the length of the straight coordinate segment (eq. 58, by
    adaptive quadrature with its error), a curve from ``x`` to ``y`` (checked where the
    segment lies in the domain)."""
    m = suite.metric

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        x, y = t[0], t[1]
        s = suite.solved(x, y)
        if not s.ok:
            return _unusable("d(x, y)", s)
        along = x + np.linspace(0.0, 1.0, 17)[:, None] * (y - x)
        if not bool(np.all(m.domain.contains(along, tol=1e-9))):
            return Verdict(True, note="the segment leaves the domain")
        seg = m.segment_length_error(x, y, check=False)
        bound = float(seg.value) + float(seg.error)
        return Verdict.compare(("d(x, y)", s.value), "<=", ("straight segment's length", bound),
                               s.value <= bound + s.error + 1e-12 * (1.0 + bound),
                               f"stated error {s.error:.2g}")

    return suite.run("segment-bound", "d(x, y) <= the length of the straight segment x -> y",
                     check, examples, keys="xy")


def check_certificate(suite: DistanceSuite, examples: int = 2, mesh: Any = CERTIFY_MESH
                      ) -> PropertyResult:
    """The certified interval of `solvers.certify` (a proven lower bound, and the
    proven length of the solved curve as upper bound) contains the solved distance within
    its stated error: ``lower <= d + error`` and ``d - error <= upper``, on pairs at least
    1e-3 of the domain's size apart (the certificate's mesh is far coarser; certify fails
    on near-coincident points). In 2-D the lower bound is the mesh LP's; in
    3-D a verified potential's (`solvers.certificates.nd.certificate.certify_nd`, which needs ``F(x,
    .)`` convex on the whole domain: skipped otherwise); beyond 3-D only a metric providing
    ``conformal_factor_sx`` is certified (a lower bound, the upper one the path's), any
    other is skipped. Beyond the plane at most ``CERTIFY_EXAMPLES_ND`` examples are drawn
    (each certificate takes seconds to a minute). The interval is
    proven whatever certify's status, so a pair outside it is a failure; a pair whose
    certificate ends without a usable bound within the mesh's work budget
    (``corrections_too_large``, ``lp_failed``) is inconclusive, and on a metric that
    documents non-convexity a pair whose region is not Finsler is not attempted
    (mapped). Skipped for metrics declared not smooth (certify's enclosures of second
    derivatives prove nothing across a kink: measured on ``(1 + 0.3 |x0|) |v|``, its
    "proven" upper bound 6.9e-7 below the quadrature length of the same path)."""
    m = suite.metric
    name = "certificate"
    claim = "certify's interval [lower, upper] contains the solved distance"
    if m.dim > 3 and not m.provides("conformal_factor_sx"):
        return PropertyResult(name, claim, SKIPPED, note=(
            f"{m.name} is {m.dim}-D and not conformal: certify proves intervals in 2-D and "
            "3-D, and lower bounds beyond 3-D only for metrics providing conformal_factor_sx"))
    if m.dim == 3 and not m.convex_everywhere:
        return PropertyResult(name, claim, SKIPPED, note=(
            f"{m.name} does not declare F(x, .) convex on the whole domain "
            f"({m.convexity_note}): the 3-D certificate needs it"))
    if m.dim != 2:
        examples = min(examples, CERTIFY_EXAMPLES_ND)
    if not m.smooth:
        return PropertyResult(name, claim, SKIPPED, note=(
            f"{m.name} is declared not smooth: certify's bounds are proven where F is twice "
            "differentiable (Metric.path_length_bounds and the dual bound's corrections "
            "enclose second derivatives), so its interval would prove nothing here"))

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        import solvers

        x, y = t[0], t[1]
        s = suite.solved(x, y)
        if not s.ok:
            return _unusable("d(x, y)", s)
        if np.array_equal(x, y):
            return Verdict(True)
        if not m.convex_everywhere:
            lam = m.convexity(_region_samples(m, s.path, x, y), n_directions=32)
            if float(lam.min()) < 0:  # not Finsler there: no certified interval to expect
                return Verdict(True, mapped=True, note=(
                    "certificate not attempted: F(x, .) is not convex on the pair's region "
                    f"(smallest eigenvalue {float(lam.min()):.3g} near the solved path)"))
        c = solvers.certify(m, x, y, mesh, path=s.path)
        if c.status.label in ("corrections_too_large", "lp_failed"):
            work = "".join(f", {getattr(c, k)} {k.replace('_', ' ')}" for k in _WORK
                           if isinstance(getattr(c, k, None), int))
            return Verdict.unjudged(
                f"certify ran out of its work budget (status {c.status.label}: mesh "
                f"{mesh if isinstance(mesh, str) else 'given'}{work}; interval "
                f"[{c.lower:.6g}, {c.upper:.6g}])")
        if c.lower > s.value + s.error:
            return Verdict.compare(("certified lower bound", c.lower), "<=",
                                   ("d(x, y) + error", s.value + s.error), False)
        return Verdict.compare(("d(x, y) - error", s.value - s.error), "<=",
                               ("certified upper bound", c.upper),
                               s.value - s.error <= c.upper,
                               f"interval [{c.lower:.8g}, {c.upper:.8g}], gap {c.gap:.2g}")

    apart = vs.pairs(m, suite.shrink, min_separation=1e-3 * suite.size())
    return suite.run(name, claim, check, examples, keys="xy", strategy=apart)


def _region_samples(m: Metric, path: np.ndarray | None, x: np.ndarray, y: np.ndarray
                    ) -> np.ndarray:
    """Points of the region a certificate of ``(x, y)`` meshes finest: the solved path's
    vertices and points around them (within 5% of the domain's size), in the domain."""
    pts = np.asarray(path if path is not None else np.stack([x, y]), float)
    lo, hi = m.domain.bounds()
    size = float(np.max(np.where(np.isfinite(hi - lo), hi - lo, 1.0)))
    rng = np.random.default_rng(0)
    around = pts[rng.integers(0, len(pts), 256)] + 0.05 * size * rng.uniform(-1, 1, (256, m.dim))
    both = np.concatenate([pts, np.asarray(m.domain.project(around), float)])
    return both[m.domain.contains(both, tol=1e-9)]


def check_midpoint_halves(suite: DistanceSuite, examples: int = 2) -> PropertyResult:
    """The midpoint ``m`` of the solved geodesic from ``x`` to ``y`` splits it in halves:
    ``|d(x, m) - d(x, y)/2|`` and ``|d(m, y) - d(x, y)/2|`` within the oracle's stated
    midpoint accuracy plus the stated errors."""

    def check(t: tuple[np.ndarray, ...]) -> Verdict:
        x, y = t[0], t[1]
        s = suite.solved(x, y)
        if not s.ok:
            return _unusable("d(x, y)", s)
        if s.value == 0.0 or s.midpoint is None:
            return Verdict(True)
        mid = suite.metric.domain.project(s.midpoint[None])[0]
        half = 0.5 * s.value
        for what, h in (("d(x, m)", suite.solved(x, mid)), ("d(m, y)", suite.solved(mid, y))):
            if not h.ok:
                return _unusable(what, h)
            slack = s.midpoint_slack + h.error + 0.5 * s.error + 1e-12 * (1.0 + s.value)
            if abs(h.value - half) > slack:
                return Verdict.compare((what, h.value), "==", ("d(x, y) / 2", half), False,
                                       f"difference {h.value - half:.3g}, allowed {slack:.3g}"
                                       f" (midpoint m = {tuple(round(float(v), 6) for v in mid)})")
        return Verdict(True)

    return suite.run("midpoint-halves", "the midpoint m of a solved geodesic has "
                     "d(x, m) = d(m, y) = d(x, y)/2", check, examples, keys="xy")


def distance_properties(metric: Metric, *, examples: int = 3, seed: int = 0,
                        oracle: DistanceOracle | None = None, shrink: float = 1.0,
                        closed_form: Callable[..., Any] | None = None,
                        closed_form_geodesic: Callable[..., Any] | None = None,
                        certify_examples: int | None = None, zero_examples: int = 20,
                        shrink_limit: int = 6) -> list[PropertyResult]:
    """Every distance property, sharing one cache of solves. ``examples``: triples per
    property (the first one hypothesis draws is degenerate, x = y = z);
    ``certify_examples``: pairs for the certificate (default ``examples - 1``, at least 2);
    ``shrink_limit``: new solves allowed while shrinking a counterexample."""
    suite = DistanceSuite.make(metric, oracle, seed, shrink, shrink_limit)
    return [fn() for _, fn in distance_checks(suite, examples, closed_form, closed_form_geodesic,
                                              certify_examples, zero_examples)]


def distance_checks(suite: DistanceSuite, examples: int = 3,
                    closed_form: Callable[..., Any] | None = None,
                    closed_form_geodesic: Callable[..., Any] | None = None,
                    certify_examples: int | None = None, zero_examples: int = 20
                    ) -> list[tuple[str, Callable[[], PropertyResult]]]:
    """``(name, run)`` of every distance property on ``suite``, in order, not yet run (so
    a caller can leave out those whose prerequisites failed)."""
    cert = max(2, examples - 1) if certify_examples is None else certify_examples
    return [
        ("distance-zero", lambda: check_distance_zero(suite, zero_examples)),
        ("distance-positive", lambda: check_distance_positive(suite, examples)),
        ("triangle-inequality", lambda: check_triangle_inequality(suite, examples)),
        ("segment-bound", lambda: check_segment_bound(suite, examples)),
        ("distance-symmetry", lambda: check_distance_symmetry(suite, examples)),
        ("closed-form-distance", lambda: check_closed_form(suite, examples, closed_form,
                                                           closed_form_geodesic)),
        ("certificate", lambda: check_certificate(suite, cert)),
        ("midpoint-halves", lambda: check_midpoint_halves(suite, max(2, examples - 1))),
    ]
