"""Global seeding: initial curves for IPOPT and graph searches whose shortest paths seed it.

* :func:`seed_curves`: straight line, curves bulging to either side (several amplitudes),
  seeded random smooth perturbations; all projected into the domain.
* :class:`GraphSeeder`: a dense lattice over the domain for ``dim <= 3`` or a sampled
  roadmap (k nearest neighbours) for higher dimensions, edge weights the straight-segment
  lengths of eq. (58) (Gauss-Legendre quadrature of ``F``), built once per metric
  (:func:`graph_seeder`, cached). A query links start and goal to their nearest nodes and
  runs Dijkstra (``scipy.sparse.csgraph``); the path is resampled to ``n + 1`` points at
  equal cost spacing.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from finsler.metric import Metric

__all__ = [
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

    ``bulges``: amplitudes (fractions of ``|g - s|``) of the sine bulges, each tried on
    both sides (in 2-D; in higher dimensions along seeded random directions orthogonal to
    ``g - s``); ``random``: number of seeded random smooth perturbations; ``graph``: use the
    lattice / roadmap shortest path; ``seed``: seed of the random perturbations.

    Multiresolution (``coarse`` set): every seed is solved with ``coarse`` segments (or
    the requested ``n`` if smaller); ``restarts`` perturbed copies of the best coarse
    optimum (smooth random perturbations of ``restart_scale * |g - s|``) are solved too;
    then only the ``refine_top`` lowest distinct optima are carried up the ladder
    :meth:`ladder` (sizes x ``factor`` up to ``n``), warm started by interpolation, and at
    every level a candidate more than ``drop_rtol`` (relative energy) above the best
    stops. ``coarse=None`` solves every seed at the requested size. ``polish``: basin
    hopping at the final size, that many perturbations (``polish_scale * |g - s|``) of
    the current best, each kept if its energy is lower (near-equal discrete local minima
    of non-convex metrics lie close together). ``drop_after`` / ``drop_factor`` (batched
    Newton solves only, :mod:`solvers.batched`): a seed still running after
    ``drop_after`` iterations whose energy is above ``drop_factor`` times the best
    converged energy of its pair stops there (``0``: never). ``own``: add the metric's
    own seed curves where it provides them (the ``seed_curves`` hook, :mod:`finsler.hooks`;
    e.g. car-like: Hermite curves along the headings). ``routes``: distinct graph routes
    per pair (:meth:`GraphSeeder.routes`; with ``graph``). ``polish_rounds`` (batched
    Newton solves): the polish in that many rounds of ``polish`` rows each, every round
    perturbing the best row so far (the IPOPT path polishes one try at a time and
    re-bases after each, so it ignores it). ``equalize`` (batched solves; ``0``: off): a
    row of the first size whose energy is above ``1 + equalize`` times
    ``length**2 / n`` (segment costs far from even: a discrete minimum of a metric with
    kinks that few long segments make cheap, car-like's up to 2.3x) is resampled at equal
    cost spacing and solved again beside it. ``warps`` (``0``: off; solved by the
    batched method, :func:`solvers.batched.covers_opt_in`, also after IPOPT's solves,
    ignored where it does not cover the metric):
    after the polish, that many reparametrised copies of the best row so far
    (:func:`warped_batch`: the same curve, its points slid along it by a smooth warp of
    the parameter), in ``warp_rounds`` rounds each starting from the best row so far.
    A metric with kinks has a discrete minimum for each segment at which the path
    changes phase (car-like: where the heading reaches its bound or the turn becomes
    tight); sliding the points moves those switches, which perturbing them does not.
    ``barriers`` (batched interior point, metrics that are not smooth; ``()``: none): the
    plan's own seeds of the first size solved again once per factor, the interior
    point's first barrier parameter (``InteriorOptions.mu0``) times it (rows named
    ``<seed>%mu<factor>``): its barrier path decides which basin a seed ends in, and
    other starting barriers end in other basins.
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
    # plan's repr, which stays that of the plans before this field (one round)
    polish_rounds: int = field(default=1, repr=False)
    equalize: float = field(default=0.0, repr=False)
    warps: int = field(default=0, repr=False)
    warp_scale: float = field(default=0.06, repr=False)
    warp_rounds: int = field(default=1, repr=False)
    barriers: tuple[float, ...] = field(default=(), repr=False)

    def __post_init__(self) -> None:
        from finsler.errors import InputError

        if any(not (np.isfinite(a) and a > 0) for a in self.bulges):
            raise InputError(f"bulge amplitudes must be positive, got {self.bulges!r}")
        if isinstance(self.routes, bool) or not isinstance(self.routes, int) \
                or self.routes < 1:
            raise InputError(f"routes must be a positive integer, got {self.routes!r}")
        if isinstance(self.polish_rounds, bool) or not isinstance(self.polish_rounds, int) \
                or self.polish_rounds < 1:
            raise InputError(f"polish_rounds must be a positive integer, got "
                             f"{self.polish_rounds!r}")
        if isinstance(self.warp_rounds, bool) or not isinstance(self.warp_rounds, int) \
                or self.warp_rounds < 1:
            raise InputError(f"warp_rounds must be a positive integer, got "
                             f"{self.warp_rounds!r}")
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
        for name in ("random", "restarts", "polish", "drop_after", "warps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise InputError(f"{name} must be a non-negative integer, got {v!r}")
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
        the metric can do, never by its name.

        A metric may return a :class:`SeedPlan` from its ``seed_plan()`` hook
        (:mod:`finsler.hooks`); else (the hook's default ``None``): a metric that declares
        ``unique_geodesics`` -> the straight line alone; high dimension (> 3) -> a few
        random curves (20) and the roadmap, coarse size 32; not
        smooth (e.g. car-like: kinks that the energy penalises in one long segment) ->
        five bulge amplitudes up to 0.8 and four random curves (with the metric's own
        seed curves where it provides them), coarse size 256 (IPOPT only), 3 restarts of
        the best seed (0.02 |g - s|), 6 polishing steps (0.05 |g - s|) and, last, 3 rounds
        of 12 warped copies of the answer solved by the batched interior point
        (``warps``); for the batched interior point a x2 ladder from 128, uneven rows
        solved again (``equalize``) and, last, 2 rounds of 6 warped copies of the best; not
        convex everywhere (e.g. Matsumoto: local minima round the hill, near-equal discrete
        minima in the non-convex regions) -> bulges at six amplitudes, 20 random curves
        and the graph: for the batched Newton method solved at 16 segments, every
        distinct optimum within 0.5 % of the best carried up a x4 ladder, then 2 rounds
        of basin hopping at the final size (6 perturbations of 0.15 |g - s| of the best
        so far each), nothing dropped; for IPOPT at 64 segments, the best 4 refined;
        convex and smooth (Finsler, e.g.
        Riemannian or Randers: few local minima) -> the straight line and one bulge each
        side at 16 segments (and, for IPOPT, the graph). Measured in
        ``benchmarks/solver_speed.py`` and ``benchmarks/peers.py --throughput``.
        """
        plan = metric.seed_plan()
        if plan is not None:
            if not isinstance(plan, SeedPlan):
                from finsler.errors import InputError

                raise InputError(f"{type(metric).__name__}.seed_plan() must return a "
                                 f"SeedPlan, got {type(plan).__name__}")
            return plan
        newton = method == "newton" or (method == "auto" and metric.smooth)
        if metric.unique_geodesics:
            # one geodesic joins every two points: the straight line converges to it
            return SeedPlan(bulges=(), random=0, graph=False)
        if metric.dim > 3:
            # measured on 10 Panda pairs (n = 32): coarse 8 missed the best energy by up to
            # 6.6% on 2 pairs and saved no time; 32 keeps the task size exact. 20 random
            # curves instead of 2: on 10 other pairs the 2 misses of the plan (0.5 % and
            # 1.2 % above 121 IPOPT starts) were found; 0.13 s per pair against 0.04 s
            # (batched Newton, one process, 10 tuning pairs sample_pairs(panda, 10, 11))
            return SeedPlan(bulges=(0.3,), random=20, graph=True, coarse=32)
        if not metric.smooth:
            # measured on 40 car-like pairs: (0.3,) alone missed a lower energy on 10 of
            # them, by up to 157%; these 14 starts were within 0.5% of 19 starts on all 40.
            # The kinks need resolution: on 10 car-like pairs at 256 segments, seeds at 16
            # (or 64) then 256 ended up to 0.4% (0.3%) above the same seeds at 256 on 4 (2)
            # pairs, so the ladder starts at 256
            # Polishing (6 perturbations of 0.15 |g - s| of the best at the final size): on
            # 16 tuning pairs (sample_pairs(carlike, 16, 11), with the Hermite seeds) 16
            # within 1e-4 of the best of three plans against 14 without (worst 9e-3), at
            # 9.7 s CPU per pair against 8.7 s (scale 0.05: 14, worst 1.9e-3).
            # Issue 45: on 50 fresh pairs (sample_pairs(carlike, 50, 20261201)) that plan
            # (bulges 0.15, 0.3, 0.5, 0.7; polish at 0.15) was more than 1e-4 above a wide
            # multistart on 7. Per seed on those 7: bulges of 0.8 and 0.45 (not in it) were
            # the winning seeds or the winning polish's base on 4 (pairs 19, 32, 34, 43);
            # polishing at 0.15 (seed 0) improved none of the 5 that needed polishing, at
            # 0.05 two, at 0.02 three. This plan (bulges 0.15, 0.3, 0.45, 0.6, 0.8; 3
            # restarts of the best seed at 0.02, then 6 polishing steps at 0.05) reached
            # the best known on 5 of the 7 (below it on 3: by 1e-3, 6e-5, 1.9e-3; the
            # others 5.9e-4 and 2.7e-4 above), without the restarts 4; 3 solves more per
            # pair. On 10 tuning pairs (sample_pairs(carlike, 20, 11)[:10]) every seed set
            # tried reached the best of all its solves from its best seed alone, and this
            # plan's answer is never above its best seed.
            # Last, warped copies of IPOPT's answer solved by the batched interior point
            # (solvers.pairs._warp_ladders; SeedPlan.warps): IPOPT reaches the right route
            # (100/100 within 1e-2 of the best known on the tuning pairs, seed 20261214)
            # but often not its lowest discrete minimum, the one where the path changes
            # phase a segment earlier or later (71/100 within 1e-4); the interior point
            # from the warped copies reaches it. On those pairs (against the lowest of
            # every run; IPOPT 24 s CPU per pair, two jobs on two cores): 2 rounds of 6
            # copies 92/100 within 1e-4 (1.3 s), 3 rounds of 6 95/100 (1.9 s), 2 rounds of
            # 12 97/100 (2.6 s), 3 rounds of 12 98/100 (4.1 s, worst 2.9e-3), 2 rounds of
            # 24 97/100 (5.6 s); all 100/100 within 1e-2. The interior point first
            # solving IPOPT's answer itself changed nothing. A ladder before the warps
            # (seeds at 128 or 64, the best 6 distinct within 30 % carried to 256; first 20
            # tuning pairs, IPOPT expanded, alone): 10.8 / 9.6 s CPU per pair against 13.8 s,
            # 19/20 within 1e-4 both (worst 1.1e-4 / 6.2e-2) against 20/20. Fewer seeds: on
            # the first 64 tuning pairs, the best of fewer bulge amplitudes and random curves
            # (chosen on the first 32) against the best of all 31 seeds, on the other 32:
            # bulges (0.15, 0.6, 0.8) and 4 random curves (27 seeds) 30/32 within 1e-4, worst
            # 2.9e-3; no bulges nor random curves (17) 26/32: every seed family is kept
            plan = SeedPlan(bulges=(0.15, 0.3, 0.45, 0.6, 0.8), random=4, graph=True,
                            coarse=256, restarts=3, restart_scale=0.02, polish=6,
                            polish_scale=0.05, warps=12, warp_rounds=3)
            if newton:
                # the batched interior point (method="newton", opt-in; issue 45): every seed
                # at 128 segments, the best 6 distinct optima within 30 % of the best
                # carried to 256. Tuning pairs sample_pairs(carlike, 20, 20261206), 256
                # segments, one thread (machine loaded ~7 on 2 cores): within 1e-4 of the
                # lowest of three variants and of a wide IPOPT multistart (first 5 pairs)
                # on 20/20, worst +4e-5, 3.9 s CPU per pair; the earlier plan (every seed
                # at 32, a x2 ladder, best 3, drop 5 %) 17/20, worst +1e-3, 1.8 s; seeds
                # at 64, best 6: 17/20, worst +2.3e-4, 2.6 s; a 100x larger first barrier
                # parameter (mu0 = 10, nearer IPOPT's): 1/5 on the first 5. The kinks need
                # the resolution: the coarse ranking misleads at 32 and 64. But on
                # sample_pairs(carlike, 10, 20261207) against a wide IPOPT multistart: 6/10
                # (worst +3.4e-3, 4.6 s; the earlier plan 6/10, worst +9.5e-3), where
                # IPOPT's plan reached 10/10 before: the interior point settles in nearer
                # basins that IPOPT's long steps leave (pair 3: only IPOPT from the
                # tangent-6 Hermite curve). On the report pairs (sample_pairs(carlike, 100,
                # 20261201), never tuned on): 88/100 within 1e-4 (the earlier plan 79),
                # 96/100 within 1e-2 (90), below the multistart on 13, but worst +3.5 (pair
                # 57: its basin only from the third graph route; IPOPT's plan reaches it),
                # 3.6 s CPU per pair on a loaded machine, against IPOPT's 89/100, 100/100,
                # worst +4.5e-3, 10.5 s (benchmarks/results/ground_truth-2026-11-28-16.md,
                # -10.md). Not the default for that reason.
                # No seed plan closes the gap (tuning pairs sample_pairs(carlike, 10,
                # 20261207) and (.., 10, 20261208), 256 segments, one thread, loaded
                # machine; against the lowest of every run): IPOPT's default 20/20 (12.4 s
                # CPU per pair), this plan 12/20 (worst +0.26, 3.65 s); 3 graph routes, or 6
                # routes and the best 10 carried (4.3 s): the same energies. On its 8
                # misses: every seed at 256 (no 128 level, 8.4 s) 1/8 within 1e-4, the
                # +0.26 pair still missed although IPOPT reaches it from the same
                # hermite-track seed at 256; 16 random curves and the best 10 (6.6 s), with
                # or without 2 polishing rounds: 0/8; polishing 3 rounds at 0.15 (7.6 s):
                # 1/8; IPOPT from this plan's answer (0.3 s): lower on none of 10, higher
                # on 4. The seeds' own energies (before solving) do not rank the winners:
                # IPOPT's winning seed was 21st-29th of 30 on 5 of 20 pairs (the seeds
                # break the heading constraints), so solving only the best-ranked seeds
                # would drop winners. The interior point ends in other, mostly slightly
                # higher discrete minima than IPOPT from the same seeds (1e-4 to 3e-3,
                # one +26 %): the gap is the local method's, not the seeds'.
                # Many rows at 128 end in discrete minima with uneven segment costs (energy
                # up to 2.3x length**2 / n: a few long segments cheaper than the curve they
                # cut), ranked low and dropped; resampled at equal cost spacing and solved
                # again (equalize=0.05) they reach basins the others miss. On the 20 misses
                # of sample_pairs(carlike, 100, 20261214): lower on 6, higher on none,
                # 4/20 within 1e-4 of the best known against 1/20; on 50 fresh pairs
                # (sample_pairs(carlike, 100, 20261236)[:50]) lower on 3 (one by 44 %),
                # higher on 1 (by 2e-4), 49/50 within 1e-4 of the lower of the two against
                # 47/50, CPU +14 % (6.7 against 5.9 s per pair, two jobs on two cores); on
                # the report pairs (seed 20261201, 100) lower on 4, higher on 2, both
                # 84/100 within 1e-4 of the best known, 5.9 against 5.3 s CPU per pair alone
                # (benchmarks/results/ground_truth-2026-11-29-2.md)
                # Most of the remaining small gaps (1e-4 to 1e-2) are discrete minima that
                # differ only in the segment where the path changes phase (the heading
                # reaches its bound, a turn becomes tight): 27 of 31 rows agreed on one, and
                # perturbing the points does not move it. Warped copies of the best (the
                # same curve, points slid along it: warps=6, warp_rounds=2) do: on the
                # tuning pairs (seed 20261214) the warp rows won on 55 of 100 pairs, 92/100
                # within 1e-4 of the best known (which they lowered) against 70/100 for the
                # stored answers of the plan before equalize, 7.9 s CPU per pair, loaded
                # (benchmarks/results/ground_truth-2026-11-29-3.md)
                return replace(plan, coarse=128, factor=2, refine_top=6, drop_rtol=0.3,
                               equalize=0.05, warps=6, warp_rounds=2)
            return plan
        if not metric.convex_everywhere:
            bulges = (0.1, 0.2, 0.3, 0.45, 0.6, 0.8)
            if newton:
                # batched Newton (issue 45). The seeds' optima at 16 segments rank the
                # final-size optima badly (near-equal discrete minima of the non-convex
                # metric differ between sizes). On the 3 misses of the one-round plan (20
                # random, ladder x2, polish 6 at 0.15 once) on sample_pairs(m, 100,
                # 424242) (pairs 41, 50, 93; up to 1.3e-3 above a wide multistart), the
                # winning seed at 16 led to a final optimum 5e-4 to 2e-3 above, and one
                # polishing round from it did not get down; all 34 seeds solved at 64
                # directly (4x the cost per row) reached 2 of the 3. Polishing in rounds,
                # each perturbing the best so far, reaches all 3: 2 rounds of 6 at
                # 0.15 |g - s|, with a ladder 16 -> 64 (x4; the level at 32 changed no
                # answer). Tuning on 6 x 100 fresh pairs (seeds 424242, 777, 777001,
                # 20261124, 31337, 5150; n = 64), within 1e-4 of the best of the
                # multistart and every plan tried: 594/600 (100, 99, 100, 99, 98, 98),
                # worst 7e-4, against 586/600 (worst 1.3e-3) for the one-round plan.
                # 3 rounds of 4: 593-595/600 at ~1.13x the CPU time of 2 rounds of 6
                # (10.2 against 8.9 ms per pair, median of 3, machine loaded; a round
                # costs a fixed ~40 sequential Newton steps over its rows); 3 rounds of 3:
                # 592; one round of 12 (first four sets): 99, 99, 100, 99; perturbation
                # sizes 0.1 or 0.2: no better; 12 random curves instead of 20: 594/600 at
                # ~0.9x the time, but on sample_pairs(m, 3, 5) (tests/test_solvers.py)
                # 3.9e-4 above on one pair. On sets never used for tuning, finslerax 1.1
                # in the same run (one thread, machine load 6-9): seed 20261201 100/100,
                # worst 1.4e-5, 13.0 ms CPU per pair against finslerax's 16.1; seed
                # 20261215 99/100, worst 1.2e-4, 11.7 against 16.8 (the same energies as 3
                # rounds of 4, which took 11.7 against 11.5 and 10.1 against 10.4;
                # benchmarks/results/ground_truth-2026-11-28-14.md, -15.md; -12, -13)
                return SeedPlan(bulges=bulges, random=20, graph=True, coarse=16, factor=4,
                                refine_top=8, drop_rtol=0.005, polish=6, polish_scale=0.15,
                                polish_rounds=2, drop_after=0)
            # measured on 100 fresh Matsumoto pairs (n = 64, benchmarks/solver_speed.py,
            # seed 2611): 8 seeds at 16 segments reached the best-known energy (1e-4) on
            # 96, 50 seeds at 16 on 93 (the coarse ranking misleads: discrete minima of the
            # non-convex metric differ between sizes), 34 seeds at 32 on 99 (worst 3e-4)
            # but on a second set (seed 8123) one pair 1.5e-3 above; the same 34 seeds at
            # 64: 99 and 100 pairs, worst 1.2e-4, 0.6 s per pair on 2 busy cores
            return SeedPlan(bulges=bulges, random=20, graph=True, coarse=64, refine_top=4)
        if newton:
            # the batched Newton method: no graph (its query costs more than the solve)
            return SeedPlan(bulges=(0.3,), random=0, graph=False, coarse=16)
        return SeedPlan(bulges=(0.3,), random=0, graph=True, coarse=16)


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
    """:func:`perturbed_curves` of many paths ``(K, n+1, dim)`` at once -> ``(K, k, n+1,
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


class GraphSeeder:
    """Shortest paths on a graph over the domain (lattice for ``dim <= 3``, roadmap above).

    ``nodes`` ``(N, dim)``; directed edges ``(rows, cols)`` with weights the eq. (58)
    lengths of the straight segments. Built once; queries are independent of each other.
    """

    def __init__(self, metric: Metric, nodes: np.ndarray, k_link: int, radius: float) -> None:
        self.metric = metric
        self.nodes = nodes
        self.tree = cKDTree(nodes)
        self.k_link = k_link
        self.radius = radius

    @classmethod
    def lattice(cls, metric: Metric, spacing: tuple[float, ...], reach: tuple[int, ...]
                ) -> GraphSeeder:
        """Regular lattice of the given spacing per coordinate over the domain's bounding
        box (nodes inside the domain), edges to every offset within ``reach`` per
        coordinate whose entries have no common divisor (no duplicated collinear edges)."""
        flat, inside, shape = cls._grid(metric, spacing)
        index = -np.ones(flat.shape[0], dtype=np.int64)
        index[inside] = np.arange(int(inside.sum()))
        index = index.reshape(shape)
        offsets = [
            o
            for o in np.ndindex(*(2 * r + 1 for r in reach))
            if any(v != r for v, r in zip(o, reach))
        ]
        offsets = [tuple(v - r for v, r in zip(o, reach)) for o in offsets]
        offsets = [o for o in offsets if math.gcd(*[abs(v) for v in o]) == 1]
        rows, cols = [], []
        ijk = np.stack(np.meshgrid(*[np.arange(m) for m in shape], indexing="ij"), -1)
        ijk = ijk.reshape(-1, metric.dim)[inside]
        for o in offsets:
            nb = ijk + np.asarray(o)
            ok = np.all((nb >= 0) & (nb < np.asarray(shape)), axis=1)
            src = np.flatnonzero(ok)
            dst = index[tuple(nb[ok].T)]
            good = dst >= 0
            rows.append(src[good])
            cols.append(dst[good])
        self = cls(metric, flat[inside], k_link=2 ** metric.dim * 2,
                   radius=float(np.linalg.norm(spacing)) * max(reach))
        self._set_edges(np.concatenate(rows), np.concatenate(cols))
        return self

    @staticmethod
    def _grid(metric: Metric, spacing: tuple[float, ...]
              ) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
        """The lattice's points over the domain's bounding box ``(P, dim)``, which lie
        inside the domain ``(P,)``, and the grid's shape."""
        lo, hi = metric.domain.bounds()
        axes = [np.arange(a, b + 1e-12, h) for a, b, h in zip(lo, hi, spacing)]
        axes = [ax + 0.5 * ((b - a) - (ax[-1] - ax[0])) for ax, a, b in zip(axes, lo, hi)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
        flat = grid.reshape(-1, metric.dim)
        return flat, np.asarray(metric.domain.contains(flat), bool), grid.shape[:-1]

    @classmethod
    def lattice_nodes(cls, metric: Metric, spacing: tuple[float, ...]) -> np.ndarray:
        """The nodes of :meth:`lattice` (inside the domain), without its edges."""
        flat, inside, _ = cls._grid(metric, spacing)
        return flat[inside]

    @classmethod
    def roadmap(cls, metric: Metric, n_nodes: int, k: int, seed: int = 0) -> GraphSeeder:
        """Roadmap of ``n_nodes`` uniform samples (seeded), each linked both ways to its
        ``k`` nearest neighbours (Euclidean in coordinates)."""
        rng = np.random.default_rng(seed)
        nodes = metric.domain.sample(n_nodes, rng)
        tree = cKDTree(nodes)
        _, nb = tree.query(nodes, k=k + 1)
        rows = np.repeat(np.arange(n_nodes), k)
        cols = nb[:, 1:].reshape(-1)
        r = np.concatenate([rows, cols])
        c = np.concatenate([cols, rows])
        key = _unique(r * n_nodes + c)
        self = cls(metric, nodes, k_link=k, radius=np.inf)
        self._set_edges(key // n_nodes, key % n_nodes)
        return self

    @classmethod
    def aligned(cls, metric: Metric, nodes: np.ndarray, steps: tuple[float, ...],
                directions: int = 200, keep: int = 16, base: GraphSeeder | None = None
                ) -> GraphSeeder:
        """A graph for anisotropic metrics (3-D): from every node, edges along the
        ``keep`` directions of least ``F(node, u)`` among ``directions`` unit vectors
        ``u`` (a Fibonacci sphere), each ``steps`` long, to the node nearest to their end
        (car-like: forward along the node's heading, turning either way; no edge
        sideways or backwards, which cost ``sqrt(1 + c_p)`` times more). Only values of
        ``F`` choose the directions. ``base``: a graph whose nodes and edges are kept too
        (its lattice links for the moves the chosen directions miss)."""
        if metric.dim != 3:
            from finsler.errors import InputError

            raise InputError(f"aligned graphs are 3-D; the metric has dim {metric.dim}")
        i = np.arange(directions) + 0.5
        phi, th = np.arccos(1.0 - 2.0 * i / directions), np.pi * (1.0 + 5.0**0.5) * i
        u = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
        if base is not None:
            nodes = np.vstack([base.nodes, nodes])
        tree = cKDTree(nodes)
        keep = min(keep, directions)
        rows, cols = [], []
        chunk = max(1, 400_000 // directions)
        for a in range(0, nodes.shape[0], chunk):
            x = nodes[a:a + chunk]
            f = metric.F(np.repeat(x, directions, 0), np.tile(u, (len(x), 1)))
            f = np.asarray(f).reshape(len(x), directions)
            best = np.argpartition(f, keep - 1, axis=1)[:, :keep] if keep < directions \
                else np.argsort(f, 1)
            src = np.repeat(np.arange(a, a + len(x)), keep)
            for step in steps:
                end = (x[:, None] + step * u[best]).reshape(-1, 3)
                _, dst = tree.query(end)
                good = metric.domain.contains(end) & (dst != src)
                rows.append(src[good])
                cols.append(dst[good])
        if base is not None:
            rows.append(base.rows)
            cols.append(base.cols)
        n = nodes.shape[0]
        key = _unique(np.concatenate(rows) * n + np.concatenate(cols))
        self = cls(metric, nodes, k_link=base.k_link if base is not None else 16,
                   radius=np.inf)
        self._set_edges(key // n, key % n)
        return self

    def _set_edges(self, rows: np.ndarray, cols: np.ndarray) -> None:
        w = np.empty(rows.size)
        chunk = 200_000
        for a in range(0, rows.size, chunk):
            sl = slice(a, a + chunk)
            w[sl] = self.metric.segment_length(self.nodes[rows[sl]], self.nodes[cols[sl]], 4)
        self.rows, self.cols, self.weights = rows, cols, w

    def path(self, s: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Shortest graph path from ``s`` to ``g``: (points ``(m+1, dim)``, edge costs
        ``(m,)``), or ``None`` if the graph does not connect them."""
        return self.paths(np.asarray(s)[None], np.asarray(g)[None])[0]

    def paths(self, starts: np.ndarray, goals: np.ndarray
              ) -> list[tuple[np.ndarray, np.ndarray] | None]:
        """Shortest graph paths of many pairs ``(K, dim)`` at once (one graph with a start
        and a goal node per pair: a start node has only outgoing links, a goal node only
        incoming ones, so no path crosses another pair's; one Dijkstra call from all the
        start nodes)."""
        return [r[0] if r else None for r in self.routes(starts, goals, 1)]

    def routes(self, starts: np.ndarray, goals: np.ndarray, count: int
               ) -> list[list[tuple[np.ndarray, np.ndarray]]]:
        """Up to ``count`` distinct routes per pair (``(K, dim)`` each), shortest first:
        after each route, the edges touching its inner nodes cost ``ROUTE_PENALTY`` times
        more and Dijkstra runs again (another side of an obstacle or a hill); a route
        through the same nodes as an earlier one is not repeated. Per pair a list of
        (points ``(m+1, dim)``, edge costs ``(m,)``), empty if the graph does not connect
        the pair."""
        s_all = np.asarray(starts, dtype=np.float64).reshape(-1, self.metric.dim)
        g_all = np.asarray(goals, dtype=np.float64).reshape(-1, self.metric.dim)
        K = s_all.shape[0]
        nn = self.nodes.shape[0]
        k = min(self.k_link, nn)
        _, si = self.tree.query(s_all, k=k)
        _, gi = self.tree.query(g_all, k=k)
        si, gi = si.reshape(K, k), gi.reshape(K, k)
        m = self.metric
        ws = m.segment_length(np.repeat(s_all, k, 0), self.nodes[si.reshape(-1)], 4)
        wg = m.segment_length(self.nodes[gi.reshape(-1)], np.repeat(g_all, k, 0), 4)
        wd = np.atleast_1d(m.segment_length(s_all, g_all, 4))
        S = nn + np.arange(K)
        G = nn + K + np.arange(K)
        rows = np.concatenate([self.rows, np.repeat(S, k), gi.reshape(-1), S])
        cols = np.concatenate([self.cols, si.reshape(-1), np.repeat(G, k), G])
        w = np.concatenate([self.weights, ws, wg, wd])
        w = np.maximum(w, 1e-300)  # csgraph drops explicit zeros
        size = nn + 2 * K
        graph = sp.csr_matrix((w, (rows, cols)), shape=(size, size))
        allnodes = np.vstack([self.nodes, s_all, g_all])
        found: list[list[np.ndarray]] = []
        for j in range(K):
            mine: list[np.ndarray] = []
            g_j, used = graph, np.zeros(size, bool)
            for _ in range(count):
                # the direct link bounds the distance: nothing farther needs exploring
                dist, pred = dijkstra(g_j, directed=True, indices=int(S[j]),
                                      return_predecessors=True,
                                      limit=float(w[-K + j]) * 1.000001)
                if not np.isfinite(dist[G[j]]):
                    break
                seq = [int(G[j])]
                while seq[-1] != S[j]:
                    seq.append(int(pred[seq[-1]]))
                seq.reverse()
                inner = np.asarray(seq[1:-1], dtype=np.int64)
                if not mine or not np.all(used[inner]):
                    mine.append(np.asarray(seq))
                if len(mine) >= count or len(seq) <= 2:
                    break
                used[inner] = True
                coo = g_j.tocoo()
                data = np.where(used[coo.row] | used[coo.col],
                                coo.data * ROUTE_PENALTY, coo.data)
                g_j = sp.csr_matrix((data, (coo.row, coo.col)), shape=(size, size))
            found.append(mine)
        # edge costs of every route in one evaluation
        flat = [allnodes[seq] for mine in found for seq in mine]
        out: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(K)]
        if flat:
            a = np.concatenate([p[:-1] for p in flat])
            b = np.concatenate([p[1:] for p in flat])
            costs = np.atleast_1d(m.segment_length(a, b, 4))
            it = iter(np.split(costs, np.cumsum([len(p) - 1 for p in flat])[:-1]))
            pts = iter(flat)
            for j, mine in enumerate(found):
                out[j] = [(next(pts), next(it)) for _ in mine]
        return out


def _unique(keys: np.ndarray) -> np.ndarray:
    """Sorted distinct values of an integer array (``np.unique``; sorting and comparing
    neighbours is several times faster here than numpy 2's hash-based path)."""
    k = np.sort(keys)
    return k[np.concatenate([[True], k[1:] != k[:-1]])] if k.size else k


#: How much more the edges at an earlier route's nodes cost when the next route is sought.
ROUTE_PENALTY = 3.0


def graph_seeds(metric: Metric, starts: np.ndarray, goals: np.ndarray, n: int,
                plan: SeedPlan) -> list[list[tuple[str, np.ndarray]]]:
    """The plan's graph seeds per pair (``plan.routes`` distinct routes of the metric's
    graph, resampled to ``n + 1`` points at equal cost spacing): names ``graph`` (the
    shortest route), ``graph-r1``, ``graph-r2``, ...; none without ``plan.graph``."""
    if not plan.graph:
        return [[] for _ in range(np.asarray(starts).reshape(-1, metric.dim).shape[0])]
    found = graph_seeder(metric).routes(starts, goals, plan.routes)
    return [[("graph" if r == 0 else f"graph-r{r}", resample(p, c, n))
             for r, (p, c) in enumerate(mine)] for mine in found]


def graph_seeder(metric: Metric) -> GraphSeeder:
    """The graph of ``metric``, built once per metric (``metric.derived``; sizes chosen for
    the speed targets)."""
    return metric.derived("seeding.graph", lambda: _build_graph_seeder(metric))


def _build_graph_seeder(metric: Metric) -> GraphSeeder:
    if metric.dim == 2:
        lo, hi = metric.domain.bounds()
        h = float(np.max(hi - lo)) / 48.0
        return GraphSeeder.lattice(metric, (h, h), (3, 3))
    if metric.dim == 3:
        lo, hi = metric.domain.bounds()
        hx = float(np.max(hi[:2] - lo[:2])) / 20.0
        ht = float(hi[2] - lo[2]) / 32.0
        base = GraphSeeder.lattice(metric, (hx, hx, ht), (2, 2, 1))
        # aligned edges from a finer lattice, and the lattice's own: on 12 car-like
        # tuning pairs (sample_pairs(carlike, 12, 11), 256 segments) the graph route
        # solved by IPOPT ended below the lattice's alone on 3 pairs (energy 0.154
        # against 0.743 not converged, 0.211 against 0.624, 0.933 against 1.481), 3e-4
        # above on one, equal (1e-4) on the rest; the aligned edges alone lost 2.1x on
        # one pair. 100 directions, 12 kept: 2 of the 3 gains lost. Built once per metric:
        # 52k nodes, 1.6M edges, 14 s on a loaded machine (the lattice alone 0.4 s)
        fine = GraphSeeder.lattice_nodes(metric, (hx / 2, hx / 2, ht))
        return GraphSeeder.aligned(metric, fine, (0.075 * float(np.max(hi[:2] - lo[:2])),
                                                  0.15 * float(np.max(hi[:2] - lo[:2]))),
                                   base=base)
    return GraphSeeder.roadmap(metric, n_nodes=1500, k=10, seed=0)
