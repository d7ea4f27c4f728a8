"""Globally seeded discrete geodesics for many pairs at once: every (pair, seed) problem
of a call is a row of one batched Newton solve (`solvers.newton.energy`).

The seed plan (`SeedPlan`: straight line, bulges, random curves,
the graph path, restarts) becomes rows of the batch at the plan's coarse size; a seed
clearly losing against its pair's best is dropped while the batch runs; the best few
distinct optima of each pair are carried up the plan's ladder of sizes in the same batched
way (warm started by interpolation); the best is polished by perturbed restarts at the
final size. IPOPT (`solvers.transcription`) stays the reference and the fallback: a
pair whose best candidate the Newton solve could not finish (an active domain constraint,
a stall, the iteration cap) is finished by IPOPT from that candidate, and metrics the
batched path does not cover by default (not ``smooth``: kinks that need the slack
reformulation) are solved by IPOPT alone, or on request (``method="newton"``) by the
batched primal-dual interior point of `solvers.newton.interior` on that reformulation.
Every result names its method and carries the first-order optimality residual of its
path (`solvers.newton.energy.energy_residual`; the KKT residual where ``F`` is not smooth).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from finsler.metrics.base import Metric
from solvers.inputs import domain_scale
from solvers.newton.backends import backend_for
from solvers.newton.energy import NewtonOptions, NewtonState, energy_residual
from solvers.newton.interior import InteriorOptions, covers_interior, interior_energy
from solvers.seeding.plans import (
    SeedPlan,
    graph_seeds,
    perturbed_batch,
    resample,
    seed_batch,
    warped_batch,
)
from solvers.status import NewtonStatus

__all__ = ["BatchOptions", "BatchSolution", "Rows", "covers", "covers_opt_in",
           "solve_pairs_batched"]

#: Relative energy difference under which two seeds count as agreeing with the best.
AGREE_RTOL = 1e-6


def covers(metric: Metric) -> bool:
    """True if the batched Newton path solves ``metric`` by default (``method="auto"``):
    ``F`` smooth away from zero velocity (the energy's Hessian exists), as the metric
    declares; otherwise IPOPT with the metric's smooth reformulation solves it (or, on
    request, ``method="newton"``, the batched interior point of `covers_opt_in`)."""
    return bool(metric.smooth)


def covers_opt_in(metric: Metric) -> bool:
    """True if ``method="newton"`` can solve ``metric`` in batches: a smooth ``F``
    (`covers`), or one that is not smooth but provides the ``smooth_square_sx`` hook
    (its slack reformulation), solved by the batched primal-dual interior point
    (`solvers.newton.interior.interior_energy`). Opt-in for the latter: on measured car-like
    pairs it does not yet reach IPOPT's optima on every pair (see
    ``benchmarks/nonsmooth_newton.py``)."""
    return covers(metric) or covers_interior(metric)


@dataclass(frozen=True)
class BatchOptions:
    """How the batch is run. ``newton``: the Newton settings; ``device``: ``None`` for
    numpy, or a torch device (``"cuda"``); ``local``: modify only the Hessian blocks that
    are not positive definite (else IPOPT-like global shifts, `NewtonState`);
    ``interior``: the interior-point settings for a metric that is not smooth (numpy
    only, `solvers.newton.interior.interior_energy`)."""

    newton: NewtonOptions = field(default_factory=NewtonOptions)
    device: Any = None
    local: bool = True
    interior: InteriorOptions = field(default_factory=InteriorOptions)


@dataclass
class Rows:
    """Rows of a batch, as arrays: ``pair`` ``(R,)`` (index of each row's pair),
    ``names`` (``R`` strings), ``points`` ``(R, n+1, d)``; once solved, ``energy``,
    ``status`` (`NewtonStatus`), ``iterations``, ``residual`` ``(R,)``."""

    pair: np.ndarray
    names: list[str]
    points: np.ndarray
    energy: np.ndarray = field(default_factory=lambda: np.zeros(0))
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    residual: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return len(self.names)

    @property
    def ok(self) -> np.ndarray:
        return (self.status == NewtonStatus.CONVERGED) & np.isfinite(self.energy)

    def take(self, idx: Any) -> Rows:
        idx = np.asarray(idx, dtype=np.int64)
        solved = len(self.energy) == len(self)
        return Rows(self.pair[idx], [self.names[i] for i in idx], self.points[idx],
                    *((self.energy[idx], self.status[idx], self.iterations[idx],
                       self.residual[idx]) if solved else ()))

    @staticmethod
    def cat(parts: list[Rows]) -> Rows:
        parts = [p for p in parts if len(p)]
        if not parts:
            return Rows(np.zeros(0, dtype=np.int64), [], np.zeros((0, 0, 0)))
        solved = all(len(p.energy) == len(p) for p in parts)
        return Rows(np.concatenate([p.pair for p in parts]),
                    [n for p in parts for n in p.names],
                    np.concatenate([p.points for p in parts]),
                    *((np.concatenate([p.energy for p in parts]),
                       np.concatenate([p.status for p in parts]),
                       np.concatenate([p.iterations for p in parts]),
                       np.concatenate([p.residual for p in parts])) if solved else ()))


def _ranked(rows: Rows) -> np.ndarray:
    """Row order: by pair, then converged first, then by energy."""
    return np.lexsort((rows.energy, ~rows.ok, rows.pair))


def _best(rows: Rows, k: int) -> np.ndarray:
    """Per pair ``(k,)``: the row of lowest energy among the converged ones, else among
    the finite ones, else ``-1``."""
    out = np.full(k, -1, dtype=np.int64)
    order = _ranked(rows)
    order = order[np.isfinite(rows.energy[order])]
    pairs, first = np.unique(rows.pair[order], return_index=True)
    out[pairs] = order[first]
    return out


def _best_of(rows: Rows, k: int, among: np.ndarray) -> np.ndarray:
    """`_best` among the rows where ``among`` ``(R,)`` is True (indices into
    ``rows``; ``-1`` for a pair with none)."""
    idx = np.flatnonzero(among)
    if idx.size == len(rows):
        return _best(rows, k)
    if idx.size == 0:
        return np.full(k, -1, dtype=np.int64)
    b = _best(rows.take(idx), k)
    return np.where(b >= 0, idx[np.maximum(b, 0)], -1)


def _agreeing(rows: Rows, k: int) -> np.ndarray:
    """Per pair: converged rows within ``AGREE_RTOL`` of the pair's best converged energy."""
    ok = rows.ok
    e0 = np.full(k, np.inf)
    np.minimum.at(e0, rows.pair[ok], rows.energy[ok])
    near = ok & (np.abs(rows.energy - e0[rows.pair]) <= AGREE_RTOL * np.maximum(
        e0[rows.pair], 1e-300))
    return np.bincount(rows.pair[near], minlength=k)


def _carried(rows: Rows, k: int, keep: int, drop_rtol: float, tol: float) -> np.ndarray:
    """Rows carried up the ladder: per pair the ``keep`` lowest-energy converged rows, one
    per optimum (paths within ``tol`` of a kept one are the same optimum), none more than
    ``drop_rtol`` above the pair's lowest; a pair with no converged row carries its
    ``keep`` lowest finite ones."""
    best = _best(rows, k)
    has = best >= 0
    e0 = np.full(k, np.inf)
    e0[has] = rows.energy[best[has]]
    ok = rows.ok
    pair_ok = np.zeros(k, bool)
    pair_ok[rows.pair[ok]] = True
    band = ok & (rows.energy <= e0[rows.pair] * (1.0 + drop_rtol))
    # rows equal to their pair's best (the common case) are dropped without a loop
    same = np.max(np.abs(rows.points - rows.points[np.maximum(best[rows.pair], 0)]),
                  axis=(1, 2)) <= tol
    out = list(best[has])
    rest = np.flatnonzero(band & ~same)
    if rest.size:
        order = rest[np.lexsort((rows.energy[rest], rows.pair[rest]))]
        kept: dict[int, list[int]] = {}
        for r in order:
            p = int(rows.pair[r])
            mine = kept.setdefault(p, [int(best[p])])
            if len(mine) >= keep:
                continue
            if any(np.max(np.abs(rows.points[r] - rows.points[o])) <= tol for o in mine):
                continue
            mine.append(int(r))
            out.append(int(r))
    # pairs without a converged row: their lowest finite rows
    for p in np.flatnonzero(~pair_ok & has):
        mine = np.flatnonzero((rows.pair == p) & np.isfinite(rows.energy))
        out.extend(int(i) for i in mine[np.argsort(rows.energy[mine])][1:keep])
    return np.sort(np.asarray(out, dtype=np.int64))


class _Runner:
    """Runs rows through `NewtonState`; counts iterations per pair."""

    def __init__(self, m: Metric, opts: BatchOptions, k: int) -> None:
        self.m, self.opts = m, opts
        self.ops = backend_for(opts.device)
        self.scale = domain_scale(m)
        self.iterations = np.zeros(k, dtype=np.int64)
        self.evaluations = 0
        self.value_evaluations = 0

    def solve(self, rows: Rows, drop_after: int = 0, drop_factor: float = 1.3,
              barrier: float = 1.0) -> Rows:
        """Newton-solve ``rows`` (all of one size); from iteration ``drop_after`` on
        (``0``: never) a running row above ``drop_factor`` times its pair's best
        converged energy stops (smooth metrics; the interior point of a metric that is not
        smooth runs every row to its end: no early drop). ``barrier``: the interior point's
        first barrier parameter times this (``InteriorOptions.mu0``)."""
        if not len(rows):
            return rows
        if not self.m.smooth:
            # the slack reformulation by the batched interior point; the reported residual
            # is left unknown (NaN) so that the results compute the KKT residual of the
            # points themselves (solvers.newton.kkt.kkt_residual), not the method's own
            opt = self.opts.interior if barrier == 1.0 else \
                replace(self.opts.interior, mu0=self.opts.interior.mu0 * barrier)
            res = interior_energy(self.m, rows.points, opt, scale=self.scale,
                                  groups=rows.pair)
            self.evaluations += res.evaluations
            self.value_evaluations += res.value_evaluations
            np.add.at(self.iterations, rows.pair, res.iterations)
            return Rows(rows.pair, rows.names, res.points, res.energy, res.status,
                        res.iterations, np.full(len(rows), np.nan))
        st = NewtonState(self.m, rows.points, self.opts.newton, self.ops, self.scale,
                         self.opts.local)
        it = 0
        while st.running:
            st.step()
            it += 1
            if drop_after and it >= drop_after:
                self._drop_losers(st, rows.pair, drop_factor)
        res = st.result()
        self.evaluations += res.evaluations
        self.value_evaluations += res.value_evaluations
        np.add.at(self.iterations, rows.pair, res.iterations)
        return Rows(rows.pair, rows.names, res.points, res.energy, res.status,
                    res.iterations, res.residual)

    @staticmethod
    def _drop_losers(st: NewtonState, pair: np.ndarray, factor: float) -> None:
        conv = st.status == NewtonStatus.CONVERGED
        if not conv.any() or st.active.size == 0:
            return
        best = np.full(pair.max() + 1, np.inf)
        np.minimum.at(best, pair[conv], st.energy[conv])
        act = st.active
        lose = st.energy[act] > factor * best[pair[act]]
        if lose.any():
            st.drop(act[lose])


@dataclass
class BatchSolution:
    """What a batch found: ``final``, every row solved at the final size (polishing
    restarts included); per pair ``(K,)``: ``best`` (index into ``final``, ``-1`` if none
    is finite), ``seeds_tried``, ``seeds_agreeing``, ``iterations``; ``levels``: one dict
    per level with per-pair arrays ``solved`` and ``iterations``; ``stats``: the batch's
    evaluations and level times; ``first``: the rows solved from the seeds (the ladder's
    first size, restarts included), for the evidence per seed family."""

    final: Rows
    best: np.ndarray
    seeds_tried: np.ndarray
    seeds_agreeing: np.ndarray
    iterations: np.ndarray
    levels: list[dict[str, Any]]
    stats: dict[str, Any]
    first: Rows | None = None

    def levels_of(self, k: int) -> list[dict[str, Any]]:
        """The ladder of pair ``k`` as the result objects report it."""
        out = []
        for lv in self.levels:
            d = {"segments": lv["segments"], "solved": int(lv["solved"][k]),
                 "iterations": int(lv["iterations"][k])}
            if lv.get("polish"):
                d["polish"] = True
            if lv.get("warp"):
                d["warp"] = True
            out.append(d)
        return out

    def rows_of(self) -> list[np.ndarray]:
        """Per pair, the indices of its rows in ``final``."""
        order = np.argsort(self.final.pair, kind="stable")
        bounds = np.searchsorted(self.final.pair[order], np.arange(len(self.best) + 1))
        return [order[bounds[k]:bounds[k + 1]] for k in range(len(self.best))]


def _level(rows: Rows, k: int, size: int, polish: bool = False) -> dict[str, Any]:
    lv = {"segments": size, "solved": np.bincount(rows.pair, minlength=k),
          "iterations": np.bincount(rows.pair, weights=rows.iterations,
                                    minlength=k).astype(np.int64)}
    if polish:
        lv["polish"] = True
    return lv


def solve_pairs_batched(m: Metric, pairs: np.ndarray, n: int, plan: SeedPlan,
                        opts: BatchOptions | None = None,
                        given: list[list[tuple[str, np.ndarray]]] | None = None,
                        global_seeds: bool = True) -> BatchSolution:
    """Seed, solve, carry up the ladder and polish every pair of ``pairs`` ``(K, 2, d)``
    (none of them short) in batches. ``given``: per pair, caller-given initial paths at
    the final size ``n`` (names, ``(n+1, d)``), solved beside the seeds (alone with
    ``global_seeds=False``). Returns a `BatchSolution`."""
    opts = opts or BatchOptions()
    K = pairs.shape[0]
    run = _Runner(m, opts, K)
    given = given or [[] for _ in range(K)]
    given_rows = Rows(np.array([k for k in range(K) for _ in given[k]], dtype=np.int64),
                      [name for g in given for name, _ in g],
                      np.array([p for g in given for _, p in g]).reshape(-1, n + 1, m.dim))
    given_names = set(given_rows.names)
    sizes = plan.ladder(n) if global_seeds else [n]
    levels: list[dict[str, Any]] = []
    stats: dict[str, Any] = {"levels": []}

    def polish(rows: Rows) -> Rows:
        # ``polish_rounds`` rounds of basin hopping: each perturbs the best row so far
        # (round r > 0 names its rows ``~p{r}.{j}``, draws seeds after round r - 1's)
        def perturbed(points: np.ndarray, rnd: int) -> np.ndarray:
            return np.stack([perturbed_batch(m, points, 1, plan.polish_scale,
                                             plan.seed + 1000 + rnd * plan.polish + j)[:, 0]
                             for j in range(plan.polish)], 1)

        return _hop(run, rows, K, given_names, plan, plan.polish_rounds, plan.polish, "p",
                    perturbed, levels, stats)
    tol = 1e-4 * domain_scale(m)
    if global_seeds:
        t0 = time.perf_counter()
        n0 = sizes[0]
        names, curves = seed_batch(m, pairs[:, 0], pairs[:, 1], n0, plan)
        S = len(names)
        seeds = Rows(np.repeat(np.arange(K), S), names * K, curves.reshape(K * S, n0 + 1, -1))
        parts = [seeds]
        tried = np.full(K, S, dtype=np.int64)
        if plan.graph or plan.field_routes:
            gs = graph_seeds(m, pairs[:, 0], pairs[:, 1], n0, plan)
            have = [(k, name, c) for k in range(K) for name, c in gs[k]]
            if have:
                parts.append(Rows(np.asarray([k for k, _, _ in have], dtype=np.int64),
                                  [name for _, name, _ in have],
                                  np.stack([c for _, _, c in have])))
                tried += np.asarray([len(g) for g in gs], dtype=np.int64)
        if len(sizes) == 1:
            parts.append(given_rows)
        first_rows = Rows.cat(parts)
        rows = run.solve(first_rows, plan.drop_after, plan.drop_factor)
        if plan.barriers and not m.smooth:
            # the same seeds again from other first barrier parameters: the interior
            # point's barrier path picks the basin, and each start picks other ones
            own = first_rows.take([i for i, nm in enumerate(first_rows.names)
                                   if nm not in given_names])
            rows = Rows.cat([rows] + [
                run.solve(Rows(own.pair, [f"{nm}%mu{f:g}" for nm in own.names], own.points),
                          barrier=f) for f in plan.barriers])
        if plan.restarts:  # of the best of the plan's own rows (see the polish below)
            best = _best_of(rows, K, np.array([nm not in given_names for nm in rows.names],
                                              dtype=bool))
            okp = np.flatnonzero((best >= 0) & rows.ok[np.maximum(best, 0)])
            if okp.size:
                b = best[okp]
                curves = perturbed_batch(m, rows.points[b], plan.restarts, plan.restart_scale,
                                         plan.seed)
                extra = Rows(np.repeat(okp, plan.restarts),
                             [f"{rows.names[i]}~{j}" for i in b for j in range(plan.restarts)],
                             curves.reshape(-1, n0 + 1, m.dim))
                rows = Rows.cat([rows, run.solve(extra, plan.drop_after, plan.drop_factor)])
        if plan.equalize:
            # rows whose segment costs are far from even (energy above (1 + equalize)
            # times length**2 / n): resampled at equal cost spacing and solved again
            costs = np.asarray(m.path_costs(rows.points, check=False))
            length = costs.sum(1)
            uneven = np.flatnonzero(rows.ok & (rows.energy > (1.0 + plan.equalize)
                                                * length**2 / n0))
            if uneven.size:
                eq = np.stack([resample(rows.points[i], costs[i], n0) for i in uneven])
                extra = Rows(rows.pair[uneven], [f"{rows.names[i]}=eq" for i in uneven], eq)
                rows = Rows.cat([rows, run.solve(extra)])
        agree = _agreeing(rows, K)
        first = rows
        levels.append(_level(rows, K, n0))
        stats["levels"].append({"segments": n0, "rows": len(rows),
                                "wall_time": time.perf_counter() - t0})
        at = plan.polish_size(n)
        if plan.polish and at == n0 and n0 < n:
            rows = polish(rows)
        for li, size in enumerate(sizes[1:], start=1):
            t1 = time.perf_counter()
            prev = sizes[li - 1]
            up = rows.take(_carried(rows, K, plan.refine_top, plan.drop_rtol, tol))
            names = [nm if "@" in nm else f"{nm}@{prev}" for nm in up.names]
            fine = np.stack([resample(p, np.ones(prev), size) for p in up.points]) \
                if len(up) else np.zeros((0, size + 1, m.dim))
            parts = [Rows(up.pair, names, fine)]
            if li == len(sizes) - 1:
                parts.append(given_rows)
            rows = run.solve(Rows.cat(parts))
            levels.append(_level(rows, K, size))
            stats["levels"].append({"segments": size, "rows": len(rows),
                                    "wall_time": time.perf_counter() - t1})
            if plan.polish and at == size and size < n:
                rows = polish(rows)
    else:
        tried = np.bincount(given_rows.pair, minlength=K)
        rows = run.solve(given_rows)
        levels.append(_level(rows, K, n))
        agree = _agreeing(rows, K)
        first = rows
    if global_seeds and plan.polish and plan.polish_size(n) == n:
        rows = polish(rows)
    if global_seeds and plan.warps:
        # reparametrised copies of the best row so far: the same curve with its points
        # slid along it, which moves the segments where a kinked metric's path changes
        # phase (round r > 0 names its rows ``~w{r}.{j}``)
        rows = _hop(run, rows, K, given_names, plan, plan.warp_rounds, plan.warps, "w",
                    lambda points, rnd: warped_batch(m, points, plan.warps, plan.warp_scale),
                    levels, stats)
    if not global_seeds:
        agree = _agreeing(rows, K)
    stats["evaluations"] = run.evaluations
    stats["value_evaluations"] = run.value_evaluations
    return BatchSolution(rows, _best(rows, K), tried, agree, run.iterations, levels, stats,
                         first)


def _hop(run: Any, rows: Rows, K: int, given_names: set[str], plan: SeedPlan, rounds: int,
         count: int, letter: str, curves_of: Any, levels: list[dict[str, Any]],
         stats: dict[str, Any]) -> Rows:
    """``rounds`` rounds of ``count`` rows per pair at the rows' size, each round from the
    best of the plan's own rows so far (a caller-given row, e.g. a learned warm start, is
    one more candidate beside them and changes nothing they do, so the result is never
    worse than without it): ``curves_of(points (P, n+1, dim), round)`` ->
    ``(P, count, n+1, dim)``, rows named ``<best>~<letter>[<round>.]<j>``. Returns every
    row; appends one level (``polish``; ``warp`` for letter ``w``) to ``levels`` and
    ``stats``."""
    t1 = time.perf_counter()
    n1, dim = rows.points.shape[1], rows.points.shape[2]
    new = []
    for rnd in range(rounds):
        best = _best_of(rows, K, np.array([nm not in given_names for nm in rows.names],
                                          dtype=bool))
        okp = np.flatnonzero((best >= 0) & rows.ok[np.maximum(best, 0)])
        if not okp.size:
            break
        b = best[okp]
        tag = "" if rnd == 0 else f"{rnd}."
        curves = curves_of(rows.points[b], rnd)
        extra = run.solve(Rows(np.repeat(okp, count),
                               [f"{rows.names[i].split('~')[0]}~{letter}{tag}{j}" for i in b
                                for j in range(count)],
                               curves.reshape(-1, n1, dim)),
                          plan.drop_after, plan.drop_factor)
        new.append(extra)
        rows = Rows.cat([rows, extra])
    extra = Rows.cat(new) if new else \
        Rows(np.zeros(0, dtype=np.int64), [], np.zeros((0, n1, dim)))
    warp = {"warp": True} if letter == "w" else {}
    levels.append({**_level(extra, K, n1 - 1, polish=True), **warp})
    stats["levels"].append({"segments": n1 - 1, "rows": len(extra), "polish": True, **warp,
                            "wall_time": time.perf_counter() - t1})
    return rows


def residuals(m: Metric, points: np.ndarray) -> np.ndarray:
    """`solvers.newton.energy.energy_residual` of paths ``(K, n+1, d)`` with the metric's
    domain size."""
    return energy_residual(m, points, domain_scale(m))
