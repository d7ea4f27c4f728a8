"""Speed and quality of the exact solvers on the paper's tasks.

For each task metric (``matsumoto`` n=64, ``carlike`` n=256, ``panda-pole`` n=32) on its
default evaluation set (100 uniform pairs, fixed seed) this prints: median and max wall
time per pair of the globally seeded energy solve, the same including the min-max
refinement, IPOPT statuses, the ratio largest/mean segment cost, seed agreement, and the
exact-ceiling success rate (min-max max segment cost <= eps).

On the Matsumoto pairs it also runs, in the same process, the paper authors' way of
getting "true" geodesics: Adam (lr 1e-3, 1000 steps) on the same discrete energy from the
straight line (all pairs batched; points projected into the disk after each step), and
prints the per-pair relative energy gap (Adam minus ours, over ours) and the time ratio.

Usage::

    python benchmarks/solver_speed.py [--pairs 100] [--metrics matsumoto,carlike,panda-pole]

Timings are single-process (one pair at a time, as a user calling ``solve_geodesic``);
one-off setup (building the NLPs and the seeding graph) is timed separately.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

import finsler
from solvers import SeedPlan, solve_geodesic
from solvers.baseline import adam_energy_baseline
from solvers.seeding import graph_seeder
from solvers.transcription import energy_nlp, minmax_nlp

TASKS = {"matsumoto": 64, "carlike": 256, "panda-pole": 32}


def run_metric(name: str, k: int) -> dict:
    m = finsler.get_metric(name)
    n = TASKS[name]
    pairs = finsler.default_pairs(m, k)
    t0 = time.perf_counter()
    m.cost(pairs[:1, 0], pairs[:1, 1])  # compile the lowered metric once
    energy_nlp(m, n)
    minmax_nlp(m, n)
    plan = SeedPlan.default(m)
    if plan.graph:
        graph_seeder(m)
    setup = time.perf_counter() - t0
    results = []
    for s, g in pairs:
        results.append(solve_geodesic(m, s, g, n, seeds=plan, minmax=True))
    t_energy = np.array([r.wall_time - r.minmax.wall_time for r in results])
    t_total = np.array([r.wall_time for r in results])
    ratio = np.array([r.cost_ratio for r in results])
    statuses = {}
    for r in results:
        statuses[r.status.value] = statuses.get(r.status.value, 0) + 1
    mm_status = {}
    for r in results:
        mm_status[r.minmax.status.value] = mm_status.get(r.minmax.status.value, 0) + 1
    eps = m.task.eps
    success_mm = np.mean([r.minmax.max_segment_cost <= eps for r in results])
    success_energy = np.mean([r.max_segment_cost <= eps for r in results])
    # "no seed found a lower energy than the one returned"
    lower = sum(
        1
        for r in results
        if any(np.isfinite(e) and e < r.energy * (1 - 1e-12) for e in r.seed_energies.values())
    )
    print(f"\n== {name}  (n={n}, {k} pairs, {plan})")
    print(f"setup (NLPs + graph): {setup:.2f} s")
    print(f"energy solve, all seeds: median {np.median(t_energy):.3f} s, "
          f"max {np.max(t_energy):.3f} s per pair")
    print(f"with min-max refinement: median {np.median(t_total):.3f} s, "
          f"max {np.max(t_total):.3f} s per pair")
    print(f"IPOPT status (energy): {statuses}")
    print(f"IPOPT status (min-max): {mm_status}")
    print(f"largest/mean segment cost: median {np.median(ratio):.4f}, max {np.max(ratio):.4f}")
    print(f"seeds tried {results[0].seeds_tried}; agreeing with best: median "
          f"{np.median([r.seeds_agreeing for r in results]):.0f}, "
          f"min {min(r.seeds_agreeing for r in results)}")
    print(f"pairs where a seed found a lower energy than the one returned: {lower}")
    print(f"success (every C <= {eps:g}): energy solution {success_energy:.2%}, "
          f"exact ceiling (min-max) {success_mm:.2%}")
    return {"metric": m, "n": n, "pairs": pairs, "results": results, "t_energy": t_energy}


def compare_adam(info: dict) -> None:
    m, n, pairs, results = info["metric"], info["n"], info["pairs"], info["results"]
    torch.set_num_threads(1)
    _, e_adam, t_adam = adam_energy_baseline(m, pairs, n)
    ours = np.array([r.energy for r in results])
    gap = (e_adam - ours) / ours
    ours_time = float(np.sum(info["t_energy"]))
    print(f"\n== Adam (lr 1e-3, 1000 steps, straight-line start) vs ours on {m.name}")
    print(f"relative energy gap (Adam - ours)/ours: min {gap.min():.3e}, "
          f"median {np.median(gap):.3e}, max {gap.max():.3e}")
    worse = int(np.sum(gap < 0))
    print(f"pairs where Adam found a lower energy than ours: {worse} / {len(gap)}"
          + (f" (most negative gap {gap.min():.3e})" if worse else ""))
    print(f"time: Adam {t_adam:.2f} s for all {len(gap)} pairs batched "
          f"({t_adam / len(gap):.4f} s/pair); ours {ours_time:.2f} s "
          f"({ours_time / len(gap):.4f} s/pair); ratio ours/Adam {ours_time / t_adam:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=100)
    ap.add_argument("--metrics", default="matsumoto,carlike,panda-pole")
    args = ap.parse_args()
    for name in args.metrics.split(","):
        if name not in TASKS:
            raise SystemExit(f"unknown task metric {name!r}; choose from {', '.join(TASKS)}")
        info = run_metric(name, args.pairs)
        if name == "matsumoto":
            compare_adam(info)


if __name__ == "__main__":
    main()
