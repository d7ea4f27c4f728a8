"""Global seeding: the initial curves of the exact solver and the plan that chooses them.

* `SeedPlan`: which seed families to try, at which sizes, and what follows the first
  solves (restarts, polishing, warped copies); `SeedPlan.default` picks a metric's plan
  from what the metric can do (`DEFAULT_PLANS`, a table; the measurements behind each
  entry are in ``docs/guides/seed-plans.md``).
* `seed_curves` / `seed_batch`: the straight line, curves bulging to either side, seeded
  random smooth perturbations and the metric's own curves (its ``seed_curves`` hook), all
  projected into the domain.
* `graph_seeds`: routes of a graph over the domain (`solvers.seeding.graph`) or of a lattice field
  whose moves the metric chooses (`solvers.seeding.field`), resampled at equal cost spacing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from finsler.metrics.base import Metric
from solvers.seeding.field import FieldSpec, lattice_field
from solvers.seeding.graph import GraphSeeder, graph_seeder

__all__ = [
    "DEFAULT_PLANS",
    "GraphSeeder",
    "SeedPlan",
    "alternative_gap",
    "family_stats",
    "graph_seeder",
    "graph_seeds",
    "perturbed_batch",
    "perturbed_curves",
    "resample",
    "seed_batch",
    "seed_curves",
    "seed_family",
    "warped_batch",
]


@dataclass(frozen=True)
class SeedPlan:
    """Which initial curves to try, and how they are carried to the requested size (a
    strategy object, see STYLE.md).

    Seeds: ``bulges``, amplitudes (fractions of ``|g - s|``) of sine bulges, each tried on
    both sides (in 2-D; in higher dimensions along seeded random directions orthogonal to
    ``g - s``); ``random`` seeded random smooth perturbations (``seed``); ``graph``: the
    metric's graph (`solvers.seeding.graph`), ``routes`` distinct routes of it per pair;
    ``field_routes``: that many routes of the metric's lattice field (`solvers.seeding.field`, 2-D
    and 3-D metrics; ``field_resolution`` cells along the domain's longest side; each route
    after the first through a node at least ``field_separation`` cells from the routes
    before it, and at most ``field_ratio`` times the shortest's graph length); ``own``:
    the metric's own seed curves where it provides them (the ``seed_curves`` hook).

    Sizes: every seed is solved with ``coarse`` segments (or the requested ``n`` if
    smaller; ``None``: at ``n``); ``restarts`` perturbed copies of the best coarse optimum
    (``restart_scale * |g - s|``) are solved too; then the ``refine_top`` lowest distinct
    optima are carried up the ladder `ladder` (sizes x ``factor`` up to ``n``), warm
    started by interpolation, and at every level a candidate more than ``drop_rtol``
    (relative energy) above the best stops.

    After the seeds, at the final size: ``polish`` perturbations (``polish_scale * |g -
    s|``) of the best so far, in ``polish_rounds`` rounds (batched solves; IPOPT re-bases
    after every try), each kept if lower (near-equal discrete minima of non-convex metrics
    lie close together); batched solves polish at the ladder's size ``polish_at`` instead
    where the ladder reaches it (`polish_size`: near-equal discrete minima merge as segments
    are added, while a polish round's cost grows with them); ``warps`` reparametrised copies of
    the best (`warped_batch`: the same curve, its points slid along it by ``warp_scale``) in
    up to ``warp_rounds`` rounds, each from the best so far. A metric with kinks has a
    discrete minimum for each segment at which the path changes phase (car-like: where the
    heading reaches its bound or the turn becomes tight); sliding the points moves those
    switches, which perturbing them does not. IPOPT solves the warped copies from its warm
    options and stops at the first round that lowers nothing (a pair already at its lowest
    switch costs one round); the batched methods solve every round.

    Batched solves only: ``drop_after`` / ``drop_factor``: a seed still running after
    ``drop_after`` iterations whose energy is above ``drop_factor`` times the best converged
    energy of its pair stops there (``0``: never); ``equalize`` (``0``: off): a row of the
    first size whose energy is above ``1 + equalize`` times ``length**2 / n`` (segment
    costs far from even: few long segments across a kink) is resampled at equal cost
    spacing and solved again beside it; ``barriers`` (the batched interior point): the
    plan's seeds of the first size solved again once per factor of its first barrier
    parameter (rows ``<seed>%mu<factor>``), whose barrier path decides the basin a seed
    ends in.
    """

    bulges: tuple[float, ...] = (0.3,)
    random: int = 0
    graph: bool = True
    seed: int = 0
    coarse: int | None = None
    refine_top: int = 3
    restarts: int = 0
    restart_scale: float = 0.15
    drop_rtol: float = 0.05
    factor: int = 4
    polish: int = 0
    polish_scale: float = 0.03
    drop_after: int = 0
    drop_factor: float = 1.3
    own: bool = True
    routes: int = 1
    # not in the repr: benchmarks/ground_truth.py keys its cached multistarts by the
    # plan's repr, which stays that of the plans without these fields
    polish_rounds: int = field(default=1, repr=False)
    equalize: float = field(default=0.0, repr=False)
    warps: int = field(default=0, repr=False)
    warp_scale: float = field(default=0.06, repr=False)
    warp_rounds: int = field(default=1, repr=False)
    barriers: tuple[float, ...] = field(default=(), repr=False)
    polish_at: int | None = field(default=None, repr=False)
    field_routes: int = field(default=0, repr=False)
    field_resolution: int = field(default=64, repr=False)
    field_separation: float = field(default=8.0, repr=False)
    field_ratio: float = field(default=1.5, repr=False)

    def __post_init__(self) -> None:
        from finsler.errors import InputError

        if any(not (np.isfinite(a) and a > 0) for a in self.bulges):
            raise InputError(f"bulge amplitudes must be positive, got {self.bulges!r}")
        for name in ("routes", "polish_rounds", "warp_rounds"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")
        if not (isinstance(self.warp_scale, (int, float)) and not isinstance(
                self.warp_scale, bool) and np.isfinite(self.warp_scale)
                and 0 < self.warp_scale <= 0.1):
            raise InputError(f"warp_scale must be in (0, 0.1] (the largest warp, 2.5x it, "
                             f"must keep the parameter increasing), got {self.warp_scale!r}")
        if not isinstance(self.barriers, tuple) or any(
                isinstance(f, bool) or not isinstance(f, (int, float))
                or not (np.isfinite(f) and f > 0) or f == 1 for f in self.barriers):
            raise InputError(f"barriers must be a tuple of positive finite factors other "
                             f"than 1 (1 is the plan's own solve), got {self.barriers!r}")
        for name in ("random", "restarts", "polish", "drop_after", "warps", "field_routes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise InputError(f"{name} must be a non-negative integer, got {v!r}")
        if self.field_routes:
            FieldSpec(resolution=self.field_resolution)  # checks the resolution
        if not (isinstance(self.field_separation, (int, float))
                and not isinstance(self.field_separation, bool)
                and np.isfinite(self.field_separation) and self.field_separation > 0):
            raise InputError(f"field_separation must be a positive number of cells, got "
                             f"{self.field_separation!r}")
        if not (isinstance(self.field_ratio, (int, float)) and not isinstance(
                self.field_ratio, bool) and self.field_ratio >= 1):
            raise InputError(f"field_ratio must be a number >= 1, got {self.field_ratio!r}")
        if self.polish_at is not None and (isinstance(self.polish_at, bool) or not isinstance(
                self.polish_at, int) or self.polish_at < 2):
            raise InputError(f"polish_at must be None or an integer >= 2, got "
                             f"{self.polish_at!r}")
        if self.coarse is not None and (not isinstance(self.coarse, int) or self.coarse < 2):
            raise InputError(f"coarse must be None or an integer >= 2, got {self.coarse!r}")
        if not isinstance(self.refine_top, int) or self.refine_top < 1:
            raise InputError(f"refine_top must be a positive integer, got {self.refine_top!r}")
        if not isinstance(self.factor, int) or self.factor < 2:
            raise InputError(f"factor must be an integer >= 2, got {self.factor!r}")
        if isinstance(self.equalize, bool) or not isinstance(self.equalize, (int, float)) \
                or not (np.isfinite(self.equalize) and self.equalize >= 0):
            raise InputError(f"equalize must be a finite number >= 0, got {self.equalize!r}")
        for name in ("restart_scale", "drop_rtol", "polish_scale"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise InputError(f"{name} must be positive and finite, got {v!r}")
        if not (isinstance(self.drop_factor, (int, float)) and np.isfinite(self.drop_factor)
                and self.drop_factor > 1):
            raise InputError(f"drop_factor must be a finite number > 1, got "
                             f"{self.drop_factor!r}")

    def polish_size(self, n: int) -> int:
        """The ladder size at which the batched solves polish: the largest size of
        `ladder` not above ``polish_at`` (its first size if none is), ``n`` without
        ``polish_at``; the polished rows are then carried up with the others."""
        sizes = self.ladder(n)
        if self.polish_at is None:
            return n
        return max((s for s in sizes if s <= self.polish_at), default=sizes[0])

    def ladder(self, n: int) -> list[int]:
        """Sizes solved on the way to ``n`` segments: ``coarse``, ``coarse * factor``, ...,
        ``n`` (``[n]`` without ``coarse`` or when ``n <= coarse``)."""
        if self.coarse is None or n <= self.coarse:
            return [n]
        sizes = [self.coarse]
        while sizes[-1] * self.factor < n:
            sizes.append(sizes[-1] * self.factor)
        return [*sizes, n]

    @staticmethod
    def default(metric: Metric, method: str = "auto") -> SeedPlan:
        """The plan for ``metric`` and the solver ``method`` (``"newton"``, ``"ipopt"``, or
        ``"auto"``: Newton where it covers the metric, i.e. ``F`` smooth), chosen by what
        the metric can do, never by its name: the metric's ``seed_plan()`` hook if it
        gives one, else the first row of `DEFAULT_PLANS` whose condition the metric meets,
        with the solver's entry. ``docs/guides/seed-plans.md`` gives the measurements
        behind every entry."""
        plan = metric.seed_plan()
        if plan is not None:
            if not isinstance(plan, SeedPlan):
                from finsler.errors import InputError

                raise InputError(f"{type(metric).__name__}.seed_plan() must return a "
                                 f"SeedPlan, got {type(plan).__name__}")
            return plan
        newton = method == "newton" or (method == "auto" and metric.smooth)
        for _, applies, plans in DEFAULT_PLANS:
            if applies(metric):
                return plans["newton" if newton else "ipopt"]
        raise AssertionError("the last row of DEFAULT_PLANS applies to every metric")


_NOT_SMOOTH_IPOPT = SeedPlan(bulges=(), random=0, graph=False, own=False, coarse=None,
                             field_routes=6, warps=6, warp_rounds=6)
_NOT_SMOOTH_NEWTON = SeedPlan(bulges=(0.15, 0.3, 0.45, 0.6, 0.8), random=4, graph=True,
                              coarse=128, factor=2, refine_top=6, drop_rtol=0.3,
                              restarts=3, restart_scale=0.02, polish=6, polish_scale=0.05,
                              equalize=0.05, warps=6, warp_rounds=2)
_NOT_CONVEX = (0.1, 0.2, 0.3, 0.45, 0.6, 0.8)

#: The default plans: (what the metric is, the condition, {solver: plan}), first match
#: wins. The evidence for each entry: ``docs/guides/seed-plans.md``.
DEFAULT_PLANS: tuple[tuple[str, Any, dict[str, SeedPlan]], ...] = (
    ("unique geodesics (the straight line converges to the one geodesic)",
     lambda m: m.unique_geodesics,
     dict.fromkeys(("newton", "ipopt"), SeedPlan(bulges=(), random=0, graph=False))),
    ("more than 3 dimensions (a roadmap, random curves, coarse size 32)",
     lambda m: m.dim > 3,
     dict.fromkeys(("newton", "ipopt"),
                   SeedPlan(bulges=(0.3,), random=20, graph=True, coarse=32))),
    ("not smooth, 2-D or 3-D (kinks: the lattice field's routes, warped copies)",
     lambda m: not m.smooth and m.dim <= 3,
     {"ipopt": _NOT_SMOOTH_IPOPT, "newton": _NOT_SMOOTH_NEWTON}),
    ("not smooth (every generic family at the final size, warped copies)",
     lambda m: not m.smooth,
     {"ipopt": SeedPlan(bulges=(0.15, 0.3, 0.45, 0.6, 0.8), random=4, graph=True,
                        coarse=256, restarts=3, restart_scale=0.02, polish=6,
                        polish_scale=0.05, warps=6, warp_rounds=6),
      "newton": _NOT_SMOOTH_NEWTON}),
    ("not convex everywhere (local minima round a hill: six bulges, 20 random curves)",
     lambda m: not m.convex_everywhere,
     {"newton": SeedPlan(bulges=_NOT_CONVEX, random=20, graph=True, coarse=16, factor=4,
                         refine_top=8, drop_rtol=0.005, polish=6, polish_scale=0.15,
                         polish_rounds=2, drop_after=0, polish_at=64),
      "ipopt": SeedPlan(bulges=_NOT_CONVEX, random=20, graph=True, coarse=64,
                        refine_top=4)}),
    ("convex and smooth (few local minima)",
     lambda m: True,
     {"newton": SeedPlan(bulges=(0.3,), random=0, graph=False, coarse=16),
      "ipopt": SeedPlan(bulges=(0.3,), random=0, graph=True, coarse=16)}),
)


def resample(path: np.ndarray, weights: np.ndarray, n: int) -> np.ndarray:
    """Resample a polyline ``(m+1, dim)`` with per-edge costs ``(m,)`` at ``n + 1`` points of
    equal cumulative cost (linear interpolation within edges) -> ``(n+1, dim)``."""
    cum = np.concatenate([[0.0], np.cumsum(np.maximum(weights, 0.0))])
    if cum[-1] <= 0:
        cum = np.linspace(0.0, 1.0, len(path))
    target = np.linspace(0.0, cum[-1], n + 1)
    out = np.empty((n + 1, path.shape[1]))
    for d in range(path.shape[1]):
        out[:, d] = np.interp(target, cum, path[:, d])
    out[0], out[-1] = path[0], path[-1]
    return out


def seed_curves(
    metric: Metric, s: np.ndarray, g: np.ndarray, n: int, plan: SeedPlan
) -> list[tuple[str, np.ndarray]]:
    """Initial curves ``(n+1, dim)`` from ``s`` to ``g`` named by how they were made."""
    names, curves = seed_batch(metric, np.asarray(s)[None], np.asarray(g)[None], n, plan)
    if np.array_equal(s, g):
        return [(names[0], curves[0, 0])]
    return list(zip(names, curves[0], strict=True))


def seed_batch(metric: Metric, starts: np.ndarray, goals: np.ndarray, n: int,
               plan: SeedPlan) -> tuple[list[str], np.ndarray]:
    """The plan's initial curves for many pairs at once: names ``(S,)`` and curves
    ``(K, S, n+1, dim)`` from ``starts[k]`` to ``goals[k]`` (``(K, dim)``), projected into
    the domain: the straight line; sine bulges of each amplitude ``a * |g - s|`` to either
    side (perpendicular in the first two coordinates; in more than 3 dimensions along
    seeded random directions orthogonal to ``g - s``, amplitude ``a * max(|g - s|, 1)``);
    ``plan.random`` seeded smooth random perturbations (sine modes 1-3); with
    ``plan.own``, the metric's own seed curves (its ``seed_curves`` hook, named
    ``family[j]``). Every pair draws the same seeded numbers (the curves of one pair do
    not depend on the others)."""
    s_all = np.asarray(starts, dtype=np.float64).reshape(-1, metric.dim)
    g_all = np.asarray(goals, dtype=np.float64).reshape(-1, metric.dim)
    K, dim = s_all.shape
    t = np.linspace(0.0, 1.0, n + 1)[None, :, None]
    d = g_all - s_all  # (K, dim)
    line = s_all[:, None] + t * d[:, None]  # (K, n+1, dim)
    dist = np.linalg.norm(d, axis=1)
    rng = np.random.default_rng(plan.seed)
    perp = np.zeros((K, dim))
    if dim >= 2:
        # perpendicular in the first two coordinates (the plane for 2-D/3-D metrics)
        planar = np.linalg.norm(d[:, :2], axis=1)
        flat = planar <= 1e-12
        pn = np.where(flat, 1.0, planar)
        perp[:, 0] = np.where(flat, 1.0, -d[:, 1] / pn)
        perp[:, 1] = np.where(flat, 0.0, d[:, 0] / pn)
    bump = np.sin(np.pi * t)  # (1, n+1, 1)
    scale = dist if dim <= 3 else np.maximum(dist, 1.0)
    names = ["straight"]
    curves = [line]
    for a in plan.bulges:
        for sign in (1.0, -1.0):
            if dim > 3:
                e = rng.normal(size=dim)[None].repeat(K, 0)
                e = e - (np.sum(e * d, 1) / np.sum(d * d, 1).clip(1e-300))[:, None] * d
                e = e / np.linalg.norm(e, axis=1, keepdims=True).clip(1e-300)
            else:
                e = perp
            curves.append(line + (sign * a * scale)[:, None, None] * bump * e[:, None])
            names.append(f"bulge{'+' if sign > 0 else '-'}{a:g}#0")
    modes = np.arange(1, 4)
    sines = np.sin(np.pi * t[0] * modes[None, :])  # (n+1, 3)
    for k in range(plan.random):
        coef = rng.normal(size=(len(modes), dim)) * 0.15 / modes[:, None]
        curves.append(line + scale[:, None, None] * (sines @ coef)[None])
        names.append(f"random{k}")
    if plan.own and metric.provides("seed_curves"):
        for family, own in _own_curves(metric, s_all, g_all, t[0, :, 0]).items():
            curves.extend(np.moveaxis(own, 1, 0))
            names.extend(f"{family}[{j}]" for j in range(own.shape[1]))
    out = np.stack(curves, 1)  # (K, S, n+1, dim)
    out = np.asarray(metric.domain.project(out.reshape(-1, dim)),
                     dtype=np.float64).reshape(out.shape)
    out[:, :, 0] = s_all[:, None]
    out[:, :, -1] = g_all[:, None]
    return names, out


def _own_curves(metric: Metric, starts: np.ndarray, goals: np.ndarray, t: np.ndarray
                ) -> dict[str, np.ndarray]:
    """The metric's ``seed_curves`` hook, checked: ``{family: (K, S, T, dim)}``."""
    from finsler.errors import InputError

    got = metric.seed_curves(starts, goals, t)
    if not isinstance(got, dict):
        raise InputError(f"{type(metric).__name__}.seed_curves() must return a dict "
                         f"{{family: (K, S, T, dim) array}}, got {type(got).__name__}")
    want = (starts.shape[0], t.shape[0], metric.dim)
    out = {}
    for family, arr in got.items():
        c = np.asarray(arr, dtype=np.float64)
        if (not isinstance(family, str) or not _FAMILY.fullmatch(family) or c.ndim != 4
                or (c.shape[0], c.shape[2], c.shape[3]) != want):
            raise InputError(f"{type(metric).__name__}.seed_curves(): family {family!r} "
                             f"must be a word (letters, digits, '-') naming an array of "
                             f"shape ({want[0]}, S, {want[1]}, {want[2]}), got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise InputError(f"{type(metric).__name__}.seed_curves(): family {family!r} "
                             "has non-finite values")
        out[family] = c
    return out


#: A seed family's name (the ``seed_curves`` hook's keys).
_FAMILY = re.compile(r"[A-Za-z][A-Za-z0-9-]*")

#: The families of the generic seeds and of the solver's own candidates: the prefix of a
#: candidate's name (``bulge+0.3#0`` -> ``bulge``, ``random3`` -> ``random``).
_PREFIX = re.compile(r"[A-Za-z]+")


def seed_family(name: str) -> str:
    """The seed family of a candidate's name: ``straight``, ``bulge``, ``random``,
    ``graph``, ``initial`` (caller-given paths), a family of the metric's
    ``seed_curves`` hook (``hermite-track[2]`` -> ``hermite-track``), ``restart``
    (perturbed copies of the best coarse optimum, ``name~k``), ``polish`` (basin
    hopping at the final size, ``name~pk``) or ``warp`` (reparametrised copies of the
    best, ``name~wk``); the ladder's suffix ``@size`` is ignored."""
    base = re.sub(r"@\d+", "", name).removesuffix("~ipopt")
    if "~" in base:
        tail = base.rsplit("~", 1)[1]
        return {"p": "polish", "w": "warp"}.get(tail[:1], "restart")
    if "[" in base:
        return base.split("[", 1)[0]
    m = _PREFIX.match(base)
    return m.group(0) if m else base


def family_stats(names: list[str], energies: np.ndarray, converged: np.ndarray,
                 final: dict[str, float], rtol: float) -> dict[str, dict[str, Any]]:
    """Evidence per seed family for one pair: ``{family: {"tried", "agreeing",
    "best_energy"}}``. ``names`` / ``energies`` / ``converged`` are the candidates solved
    from the seeds (first size of the ladder): ``tried`` counts them, ``agreeing`` those
    converged within ``rtol`` (relative) of the best among them; ``final`` maps the names
    of the candidates solved at the final size to their energies (NaN: not converged):
    ``best_energy`` is the family's lowest there (``None``: none of its candidates reached
    the final size converged)."""
    e = np.asarray(energies, dtype=np.float64)
    ok = np.asarray(converged, bool) & np.isfinite(e)
    e0 = float(np.min(e[ok])) if ok.any() else np.inf
    out: dict[str, dict[str, Any]] = {}
    for name, en, good in zip(names, e.tolist(), ok.tolist(), strict=True):
        d = out.setdefault(seed_family(name), {"tried": 0, "agreeing": 0,
                                               "best_energy": None})
        d["tried"] += 1
        d["agreeing"] += int(good and abs(en - e0) <= rtol * max(e0, 1e-300))
    for name, en in final.items():
        if not np.isfinite(en):
            continue
        d = out.setdefault(seed_family(name), {"tried": 0, "agreeing": 0,
                                               "best_energy": None})
        if d["best_energy"] is None or en < d["best_energy"]:
            d["best_energy"] = float(en)
    return out


def alternative_gap(final: dict[str, float], best: float, rtol: float) -> float | None:
    """The relative energy gap ``e / best - 1`` of the best other local optimum among the
    candidates solved at the final size (energies ``final``; those within ``rtol`` of
    ``best`` count as the same optimum), or ``None`` when every converged candidate
    agrees with the best."""
    e = np.asarray([v for v in final.values() if np.isfinite(v)], dtype=np.float64)
    if not np.isfinite(best) or best <= 0:
        return None
    rel = e / best - 1.0
    rel = rel[rel > rtol]
    return float(np.min(rel)) if rel.size else None


def perturbed_curves(metric: Metric, path: np.ndarray, k: int, scale: float, seed: int
                     ) -> list[np.ndarray]:
    """``k`` seeded smooth random perturbations of ``path`` ``(n+1, dim)`` (sine modes
    1-3, amplitude ``scale * max(|g - s|, 1 if dim > 3)``, decaying with the mode), ends
    fixed, projected into the domain -> list of ``(n+1, dim)`` (restarts from an optimum:
    another basin nearby)."""
    return list(perturbed_batch(metric, np.asarray(path)[None], k, scale, seed)[0])


def perturbed_batch(metric: Metric, paths: np.ndarray, k: int, scale: float, seed: int
                    ) -> np.ndarray:
    """`perturbed_curves` of many paths ``(K, n+1, dim)`` at once -> ``(K, k, n+1,
    dim)`` (every path gets the same seeded coefficients, scaled by its own amplitude)."""
    p = np.asarray(paths, dtype=np.float64)
    n1, dim = p.shape[1], p.shape[2]
    t = np.linspace(0.0, 1.0, n1)[:, None]
    dist = np.linalg.norm(p[:, -1] - p[:, 0], axis=1)
    amp = scale * (dist if dim <= 3 else np.maximum(dist, 1.0))
    rng = np.random.default_rng([seed, 1])
    modes = np.arange(1, 4)
    sines = np.sin(np.pi * t * modes[None, :])  # (n+1, 3)
    coef = np.stack([rng.normal(size=(len(modes), dim)) / modes[:, None] for _ in range(k)])
    pert = np.einsum("tm,kmd->ktd", sines, coef)  # (k, n+1, dim)
    out = p[:, None] + amp[:, None, None, None] * pert[None]
    out = np.asarray(metric.domain.project(out.reshape(-1, dim)),
                     dtype=np.float64).reshape(out.shape)
    out[:, :, 0] = p[:, None, 0]
    out[:, :, -1] = p[:, None, -1]
    return out


def warped_batch(metric: Metric, paths: np.ndarray, k: int, scale: float) -> np.ndarray:
    """``k`` reparametrised copies of each path ``(K, n+1, dim)`` -> ``(K, k, n+1, dim)``:
    the point at parameter ``t`` moves to the curve's point at ``t + e sin(j pi t) / (j pi)``
    (linear interpolation along the polyline), copy ``i`` with mode ``j = 1 + (i // 2) % 3
    + 3 (i // 12)`` and ``e = +-scale * 2.5**((i // 6) % 2)`` (alternating signs).
    ``|e| < 1`` keeps the
    parameter increasing, so each copy traces the same curve with its points slid along
    it, by at most ``|e| / (j pi)`` of the curve; the ends stay."""
    p = np.asarray(paths, dtype=np.float64)
    n1, dim = p.shape[1], p.shape[2]
    t = np.linspace(0.0, 1.0, n1)
    out = np.empty((p.shape[0], k, n1, dim))
    for i in range(k):
        j = 1 + (i // 2) % 3 + 3 * (i // 12)
        e = (1.0 if i % 2 == 0 else -1.0) * scale * 2.5 ** ((i // 6) % 2)
        tw = np.clip(t + e * np.sin(j * np.pi * t) / (j * np.pi), 0.0, 1.0)
        pos = tw * (n1 - 1)
        lo = np.minimum(np.floor(pos).astype(np.int64), n1 - 2)
        w = (pos - lo)[None, :, None]
        out[:, i] = (1.0 - w) * p[:, lo] + w * p[:, lo + 1]
    out = np.asarray(metric.domain.project(out.reshape(-1, dim)),
                     dtype=np.float64).reshape(out.shape)
    out[:, :, 0] = p[:, None, 0]
    out[:, :, -1] = p[:, None, -1]
    return out


def _project(metric: Metric, curve: np.ndarray, s: np.ndarray, g: np.ndarray) -> np.ndarray:
    c = np.asarray(metric.domain.project(curve), dtype=np.float64)
    c[0], c[-1] = s, g
    return c


def graph_seeds(metric: Metric, starts: np.ndarray, goals: np.ndarray, n: int,
                plan: SeedPlan) -> list[list[tuple[str, np.ndarray]]]:
    """The plan's route seeds per pair, resampled to ``n + 1`` points at equal cost
    spacing: with ``plan.graph``, ``plan.routes`` distinct routes of the metric's graph
    (names ``graph``, ``graph-r1``, ...); with ``plan.field_routes``, that many routes of
    its lattice field (``field``, ``field-r1``, ...; a start's forward search is shared by its
    goals)."""
    s_all = np.asarray(starts, dtype=np.float64).reshape(-1, metric.dim)
    g_all = np.asarray(goals, dtype=np.float64).reshape(-1, metric.dim)
    out: list[list[tuple[str, np.ndarray]]] = [[] for _ in range(s_all.shape[0])]
    if plan.graph:
        found = graph_seeder(metric).routes(s_all, g_all, plan.routes)
        for mine, routes in zip(out, found, strict=True):
            mine += [("graph" if r == 0 else f"graph-r{r}", resample(p, c, n))
                     for r, (p, c) in enumerate(routes)]
    if plan.field_routes and metric.dim in (2, 3):
        lattice = lattice_field(metric, FieldSpec(resolution=plan.field_resolution))
        for mine, s, g in zip(out, s_all, g_all, strict=True):
            for r, pts in enumerate(lattice.routes(s, g, plan.field_routes,
                                                    plan.field_separation, plan.field_ratio)):
                w = metric.segment_length(pts[:-1], pts[1:], 4, check=False)
                mine.append(("field" if r == 0 else f"field-r{r}", resample(pts, w, n)))
    return out
