"""Globally seeded discrete geodesics for many pairs at once: every (pair, seed) problem
of a call is a row of one batched Newton solve (:mod:`solvers.newton`).

The seed plan (:class:`~solvers.seeding.SeedPlan`: straight line, bulges, random curves,
the graph path, restarts) becomes rows of the batch at the plan's coarse size; a seed
clearly losing against its pair's best is dropped while the batch runs; the best few
distinct optima of each pair are carried up the plan's ladder of sizes in the same batched
way (warm started by interpolation); the best is polished by perturbed restarts at the
final size. IPOPT (:mod:`solvers.transcription`) stays the reference and the fallback: a
pair whose best candidate the Newton solve could not finish (an active domain constraint,
a stall, the iteration cap) is finished by IPOPT from that candidate, and metrics the
batched path does not cover (not ``smooth``: kinks that need IPOPT's slack
reformulation) are solved by IPOPT alone. Every result names its method and carries the
first-order optimality residual of its path (:func:`solvers.newton.energy_residual`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from finsler.metric import Metric
from solvers.inputs import domain_scale, is_short_pair
from solvers.newton import (
    NewtonOptions,
    NewtonState,
    NewtonStatus,
    backend_for,
    energy_residual,
)
from solvers.seeding import (
    SeedPlan,
    graph_seeder,
    perturbed_batch,
    perturbed_curves,
    resample,
    seed_batch,
)

__all__ = ["BatchOptions", "Candidate", "covers", "solve_pairs_batched"]

#: Relative energy difference under which two seeds count as agreeing with the best.
AGREE_RTOL = 1e-6


def covers(metric: Metric) -> bool:
    """True if the batched Newton path solves ``metric``: ``F`` smooth away from zero
    velocity (the energy's Hessian exists), as the metric declares; otherwise IPOPT with
    the metric's smooth reformulation solves it."""
    return bool(metric.smooth)


@dataclass(frozen=True)
class BatchOptions:
    """How the batch is run. ``newton``: the Newton settings; ``device``: ``None`` for
    numpy, or a torch device (``"cuda"``); ``local``: modify only the Hessian blocks that
    are not positive definite (else IPOPT-like global shifts, :class:`NewtonState`)."""

    newton: NewtonOptions = field(default_factory=NewtonOptions)
    device: Any = None
    local: bool = True


@dataclass
class Candidate:
    """One solved row: its pair, name, points ``(n+1, d)``, energy, Newton status,
    iterations and residual."""

    pair: int
    name: str
    points: np.ndarray
    energy: float
    status: int
    iterations: int
    residual: float

    @property
    def ok(self) -> bool:
        return self.status == NewtonStatus.CONVERGED and bool(np.isfinite(self.energy))


class _Runner:
    """Runs rows through :class:`NewtonState` and keeps the per-pair bookkeeping."""

    def __init__(self, m: Metric, opts: BatchOptions) -> None:
        self.m, self.opts = m, opts
        self.ops = backend_for(opts.device)
        self.scale = domain_scale(m)
        self.iterations: dict[int, int] = {}
        self.evaluations = 0
        self.value_evaluations = 0

    def solve(self, rows: list[tuple[int, str, np.ndarray]], drop_after: int = 0,
              drop_factor: float = 1.3) -> list[Candidate]:
        """Newton-solve ``rows`` (pair, name, points ``(n+1, d)``, all of one size); from
        iteration ``drop_after`` on (``0``: never) a running row above ``drop_factor``
        times its pair's best converged energy stops."""
        if not rows:
            return []
        pts = np.stack([r[2] for r in rows])
        pair = np.array([r[0] for r in rows])
        st = NewtonState(self.m, pts, self.opts.newton, self.ops, self.scale, self.opts.local)
        it = 0
        while st.running:
            st.step()
            it += 1
            if drop_after and it >= drop_after:
                self._drop_losers(st, pair, drop_factor)
        res = st.result()
        self.evaluations += res.evaluations
        self.value_evaluations += res.value_evaluations
        out = []
        for k, (p, name, _) in enumerate(rows):
            self.iterations[p] = self.iterations.get(p, 0) + int(res.iterations[k])
            out.append(Candidate(p, name, res.points[k], float(res.energy[k]),
                                 int(res.status[k]), int(res.iterations[k]),
                                 float(res.residual[k])))
        return out

    def _drop_losers(self, st: NewtonState, pair: np.ndarray, factor: float) -> None:
        conv = st.status == NewtonStatus.CONVERGED
        if not conv.any() or st.active.size == 0:
            return
        best = np.full(pair.max() + 1, np.inf)
        np.minimum.at(best, pair[conv], st.energy[conv])
        act = st.active
        lose = st.energy[act] > factor * best[pair[act]]
        if lose.any():
            st.drop(act[lose])


def _distinct(m: Metric, cands: list[Candidate], keep: int, drop_rtol: float
              ) -> list[Candidate]:
    """The ``keep`` lowest-energy converged candidates, one per optimum (paths within 1e-4
    of the domain size of a kept one are the same optimum), none more than ``drop_rtol``
    above the lowest energy."""
    ranked = sorted((c for c in cands if c.ok), key=lambda c: c.energy)
    out: list[Candidate] = []
    tol = 1e-4 * domain_scale(m)
    for c in ranked:
        if len(out) >= keep or (out and c.energy > out[0].energy * (1.0 + drop_rtol)):
            break
        if any(np.max(np.abs(c.points - o.points)) <= tol for o in out):
            continue
        out.append(c)
    return out


def _by_pair(cands: list[Candidate], k: int) -> list[list[Candidate]]:
    out: list[list[Candidate]] = [[] for _ in range(k)]
    for c in cands:
        out[c.pair].append(c)
    return out


def _best(cands: list[Candidate]) -> Candidate | None:
    """Lowest energy among the converged candidates, else among the finite ones."""
    ok = [c for c in cands if c.ok]
    pool = ok or [c for c in cands if np.isfinite(c.energy)]
    return min(pool, key=lambda c: c.energy) if pool else None


@dataclass
class PairSolution:
    """What the batch found for one pair (before the result object is made)."""

    best: Candidate | None
    final: list[Candidate]
    seeds_tried: int
    seeds_agreeing: int
    levels: list[dict[str, Any]]
    iterations: int


def solve_pairs_batched(m: Metric, pairs: np.ndarray, n: int, plan: SeedPlan,
                        opts: BatchOptions | None = None,
                        given: list[list[tuple[str, np.ndarray]]] | None = None,
                        global_seeds: bool = True) -> tuple[list[PairSolution], dict]:
    """Seed, solve, carry up the ladder and polish every pair of ``pairs`` ``(K, 2, d)``
    (none of them short) in batches. ``given``: per pair, caller-given initial paths at
    the final size ``n`` (names, ``(n+1, d)``), solved beside the seeds (alone with
    ``global_seeds=False``). Returns one :class:`PairSolution` per pair and the batch's
    statistics (evaluations, level times)."""
    opts = opts or BatchOptions()
    run = _Runner(m, opts)
    K = pairs.shape[0]
    given = given or [[] for _ in range(K)]
    sizes = plan.ladder(n) if global_seeds else [n]
    levels: list[list[dict[str, Any]]] = [[] for _ in range(K)]
    tried = np.zeros(K, dtype=np.int64)
    agree = np.zeros(K, dtype=np.int64)
    stats: dict[str, Any] = {"levels": []}
    if global_seeds:
        t0 = time.perf_counter()
        n0 = sizes[0]
        rows: list[tuple[int, str, np.ndarray]] = []
        gpaths = (graph_seeder(m).paths(pairs[:, 0], pairs[:, 1]) if plan.graph
                  else [None] * K)
        names, curves = seed_batch(m, pairs[:, 0], pairs[:, 1], n0, plan)
        for k in range(K):
            seeds = list(zip(names, curves[k], strict=True))
            gp = gpaths[k]
            if gp is not None:
                seeds.append(("graph", resample(gp[0], gp[1], n0)))
            tried[k] = len(seeds)
            if len(sizes) == 1:
                seeds += given[k]
            rows += [(k, name, c) for name, c in seeds]
        cands = run.solve(rows, plan.drop_after, plan.drop_factor)
        if plan.restarts:
            extra = []
            for k, cs in enumerate(_by_pair(cands, K)):
                b = _best(cs)
                if b is not None and b.ok:
                    for j, c in enumerate(perturbed_curves(m, b.points, plan.restarts,
                                                           plan.restart_scale, plan.seed)):
                        extra.append((k, f"{b.name}~{j}", c))
            cands += run.solve(extra, plan.drop_after, plan.drop_factor)
        per = _by_pair(cands, K)
        for k, cs in enumerate(per):
            e0 = min((c.energy for c in cs if c.ok), default=np.inf)
            agree[k] = sum(1 for c in cs if c.ok and abs(c.energy - e0)
                           <= AGREE_RTOL * max(e0, 1e-300))
            levels[k].append({"segments": n0, "solved": len(cs),
                              "iterations": sum(c.iterations for c in cs)})
        stats["levels"].append({"segments": n0, "rows": len(cands),
                                "wall_time": time.perf_counter() - t0})
        for li, size in enumerate(sizes[1:], start=1):
            t1 = time.perf_counter()
            prev = sizes[li - 1]
            rows = []
            for k, cs in enumerate(per):
                keep = _distinct(m, cs, plan.refine_top, plan.drop_rtol)
                if not keep:  # nothing converged: carry the best attempts
                    keep = sorted((c for c in cs if np.isfinite(c.energy)),
                                  key=lambda c: c.energy)[: plan.refine_top]
                for c in keep:
                    name = c.name if "@" in c.name else f"{c.name}@{prev}"
                    rows.append((k, name, resample(c.points, np.ones(prev), size)))
                if li == len(sizes) - 1:
                    rows += [(k, name, p) for name, p in given[k]]
            cands = run.solve(rows)
            per = _by_pair(cands, K)
            for k, cs in enumerate(per):
                levels[k].append({"segments": size, "solved": len(cs),
                                  "iterations": sum(c.iterations for c in cs)})
            stats["levels"].append({"segments": size, "rows": len(cands),
                                    "wall_time": time.perf_counter() - t1})
    else:
        rows = [(k, name, p) for k in range(K) for name, p in given[k]]
        tried[:] = [len(g) for g in given]
        per = _by_pair(run.solve(rows), K)
    if global_seeds and plan.polish:
        t1 = time.perf_counter()
        rows = []
        bests = [(k, b) for k, b in enumerate(_best(cs) for cs in per)
                 if b is not None and b.ok]
        if bests:
            pts = np.stack([b.points for _, b in bests])
            curves = [perturbed_batch(m, pts, 1, plan.polish_scale, plan.seed + 1000 + j)
                      for j in range(plan.polish)]
            for i, (k, b) in enumerate(bests):
                base = b.name.split("~")[0]
                rows += [(k, f"{base}~p{j}", curves[j][i, 0]) for j in range(plan.polish)]
        extra = _by_pair(run.solve(rows, plan.drop_after, plan.drop_factor), K)
        for k in range(K):
            per[k] = per[k] + extra[k]
            levels[k].append({"segments": n, "solved": len(extra[k]), "polish": True,
                              "iterations": sum(c.iterations for c in extra[k])})
        stats["levels"].append({"segments": n, "rows": len(rows), "polish": True,
                                "wall_time": time.perf_counter() - t1})
    out = []
    for k in range(K):
        cs = per[k]
        b = _best(cs)
        if not global_seeds and b is not None:
            agree[k] = sum(1 for c in cs if c.ok and abs(c.energy - b.energy)
                           <= AGREE_RTOL * max(b.energy, 1e-300))
        out.append(PairSolution(b, cs, int(tried[k]), int(agree[k]), levels[k],
                                run.iterations.get(k, 0)))
    stats["evaluations"] = run.evaluations
    stats["value_evaluations"] = run.value_evaluations
    return out, stats


def residuals(m: Metric, points: np.ndarray) -> np.ndarray:
    """:func:`solvers.newton.energy_residual` of paths ``(K, n+1, d)`` with the metric's
    domain size."""
    return energy_residual(m, points, domain_scale(m))


def short_mask(m: Metric, pairs: np.ndarray) -> np.ndarray:
    return np.array([is_short_pair(m, p[0], p[1]) for p in pairs], dtype=bool)
