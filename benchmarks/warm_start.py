"""Learned warm starts for exact solves (issue 11, part 3): time and agreement.

For each task metric (``matsumoto`` n=64, ``carlike`` n=256, ``panda-pole`` n=32) on K
fresh pairs (seed 777: neither the default evaluation set's seed nor the validation
set's) this solves every pair twice, one pair at a time in this process:

* globally seeded: ``solvers.solve_geodesic(m, s, g, n)`` (the default seed plan: several
  initial curves, a lattice graph path in 2-D / 3-D, a roadmap for the arm);
* learned warm start: the shipped policy's path (``policy.generate``, all pairs in one
  batch) as the only initial path, ``solve_geodesic(..., initial=(path,),
  global_seeds=False)`` -- what ``geodesics solve --warm-start ENV`` does;
* with ``--recheck-above R`` (``geodesics solve --recheck-above R``): the pairs whose
  learned path's energy is above R times the warm optimum solved again with the global
  seeds plus the warm result (:func:`validation.cli_solve.recheck_flags`).

It prints the time per exact geodesic of both (the warm start's includes its share of
the batched path generation), the speed-up of the means, and on how many pairs the warm
start's energy is within 1e-6 (relative) of the globally seeded one, lower than it (the
learned route found a better local minimum) or higher (the warm start ended in a worse
local minimum: those pairs are listed), and how many are within 1e-4, 1e-3, 1e-2.
One-off setup (building the NLP and the seeding graph, loading the policy) is done on an
extra pair before timing and printed apart.

Usage::

    python benchmarks/warm_start.py [--pairs 100] [--metrics matsumoto,carlike,panda-pole]
        [--seed 777] [--recheck-above 1.05,1.3] [--search] [--json out.json]

``--search``: the warm starts are the route search's paths (:meth:`learn.Policy.search`,
``geodesics solve --warm-search``; its time is included). Pass ``--pairs`` per task as
``--pairs carlike=30`` (repeatable) to shorten a slow task.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

import finsler
from learn.runs import warm_start_paths
from solvers import solve_geodesic
from validation.cli_solve import recheck_flags

TASKS = {"matsumoto": 64, "carlike": 256, "panda-pole": 32}
#: Relative energy difference below which the two solves count as the same geodesic.
RTOL = 1e-6
#: Relative gaps (warm minus global, over global) at which the pairs are also counted.
GAPS = (1e-6, 1e-4, 1e-3, 1e-2)


def run_task(name: str, k: int, seed: int, recheck: tuple[float, ...] = (),
             search: bool = False) -> dict:
    m = finsler.get_metric(name)
    n = TASKS[name]
    pairs = finsler.sample_pairs(m, k + 1, seed)
    setup_pair, pairs = pairs[:1], pairs[1:]

    t0 = time.perf_counter()  # one-off: policy, NLP, seeding graph
    p0, _ = warm_start_paths(name, m, setup_pair, search=search)
    solve_geodesic(m, setup_pair[0, 0], setup_pair[0, 1], n, initial=(p0[0],),
                   global_seeds=False)
    solve_geodesic(m, setup_pair[0, 0], setup_pair[0, 1], n)
    setup = time.perf_counter() - t0

    t0 = time.perf_counter()
    paths, pol = warm_start_paths(name, m, pairs, search=search)
    gen = (time.perf_counter() - t0) / k
    warm_t, glob_t, warm_e, glob_e, warm_ok, glob_ok = [], [], [], [], [], []
    warm_res = []
    for i in range(k):
        s, g = pairs[i]
        t0 = time.perf_counter()
        w = solve_geodesic(m, s, g, n, initial=(paths[i],), global_seeds=False)
        warm_t.append(time.perf_counter() - t0 + gen)
        t0 = time.perf_counter()
        r = solve_geodesic(m, s, g, n)
        glob_t.append(time.perf_counter() - t0)
        warm_res.append(w)
        warm_e.append(w.energy)
        glob_e.append(r.energy)
        warm_ok.append(w.converged)
        glob_ok.append(r.converged)
    we, ge = np.array(warm_e), np.array(glob_e)
    # --recheck-above R: global seeds (plus the warm result) where the learned path's energy
    # is above R times the warm optimum; each pair's recheck is solved once and reused
    rechecks: dict[int, tuple[float, float]] = {}
    recheck_rows = []
    for ratio in recheck:
        flags = recheck_flags(m, paths, warm_res, ratio)
        for i in np.flatnonzero(flags):
            if int(i) not in rechecks:
                t0 = time.perf_counter()
                r = solve_geodesic(m, pairs[i, 0], pairs[i, 1], n,
                                   initial=(warm_res[i].points,))
                rechecks[int(i)] = (time.perf_counter() - t0, r.energy)
        e = np.array([rechecks[i][1] if flags[i] else we[i] for i in range(k)])
        t = np.array([warm_t[i] + (rechecks[i][0] if flags[i] else 0.0) for i in range(k)])
        rr = (e - ge) / ge
        recheck_rows.append({"ratio": ratio, "rechecked": int(flags.sum()),
                             "seconds_mean": t.mean(),
                             "speedup_mean": float(np.mean(glob_t) / t.mean()),
                             "equal_or_lower": int(np.sum(rr <= RTOL)),
                             "lower": int(np.sum(rr < -RTOL))})
    rel = (we - ge) / ge
    equal = np.abs(rel) <= RTOL
    better = rel < -RTOL
    worse = rel > RTOL
    wt, gt = np.array(warm_t), np.array(glob_t)
    return {
        "metric": name, "segments": n, "pairs": k, "seed": seed,
        "policy": f"{pol.source} ({pol.checkpoint})",
        "setup_seconds": setup,
        "generation_seconds_per_pair": gen,
        "warm_seconds": {"mean": wt.mean(), "median": float(np.median(wt)), "max": wt.max()},
        "global_seconds": {"mean": gt.mean(), "median": float(np.median(gt)),
                           "max": gt.max()},
        "speedup_mean": gt.mean() / wt.mean(),
        "speedup_median": float(np.median(gt) / np.median(wt)),
        "equal": int(equal.sum()), "better": int(better.sum()), "worse": int(worse.sum()),
        "warm_converged": int(np.sum(warm_ok)), "global_converged": int(np.sum(glob_ok)),
        "within": {f"{t:g}": int(np.sum(rel <= t)) for t in GAPS},
        "recheck": recheck_rows,
        "worse_pairs": [{"pair": int(i), "relative_energy_gap": float(rel[i]),
                         "pair_distance_coordinates": float(np.linalg.norm(
                             pairs[i, 1] - pairs[i, 0]))}
                        for i in np.flatnonzero(worse)],
    }


def _parse_pairs(items: list[str]) -> tuple[int, dict[str, int]]:
    default, per = 100, {}
    for it in items:
        name, sep, val = it.partition("=")
        if sep:
            per[name] = int(val)
        else:
            default = int(it)
    return default, per


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", action="append", default=[],
                    help="pairs per task (N, or TASK=N; repeatable), default 100")
    ap.add_argument("--metrics", default=",".join(TASKS))
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--json", default=None, help="also write the rows to this file")
    ap.add_argument("--search", action="store_true",
                    help="warm starts from the route search's paths")
    ap.add_argument("--recheck-above", default="1.05,1.3",
                    help="comma-separated ratios R of `geodesics solve --recheck-above R`")
    args = ap.parse_args()
    torch.set_num_threads(1)
    default, per = _parse_pairs(args.pairs)
    rows = []
    for name in [t.strip() for t in args.metrics.split(",") if t.strip()]:
        ratios = tuple(float(x) for x in args.recheck_above.split(",") if x.strip())
        r = run_task(name, per.get(name, default), args.seed, ratios, args.search)
        rows.append(r)
        print(f"{name} (n={r['segments']}, {r['pairs']} fresh pairs, seed {r['seed']}; "
              f"policy {r['policy']})")
        print(f"  one-off setup {r['setup_seconds']:.2f} s; learned paths "
              f"{1e3 * r['generation_seconds_per_pair']:.2f} ms per pair (batched)")
        for key, lab in (("global_seconds", "global seeding"),
                         ("warm_seconds", "learned warm start")):
            t = r[key]
            print(f"  {lab:<19} mean {t['mean']:.3f} s  median {t['median']:.3f} s  "
                  f"max {t['max']:.3f} s per exact geodesic")
        print(f"  speed-up {r['speedup_mean']:.1f}x (means), {r['speedup_median']:.1f}x "
              f"(medians)")
        print(f"  energy within {RTOL:g} of the globally seeded: {r['equal']}/{r['pairs']}; "
              f"lower (better minimum): {r['better']}; higher: {r['worse']}; converged: "
              f"warm {r['warm_converged']}, global {r['global_converged']}")
        print("  warm-start energy at most (1 + gap) x the globally seeded one: " + ", ".join(
            f"gap {t}: {c}/{r['pairs']}" for t, c in r["within"].items()))
        for c in r["recheck"]:
            print(f"  --recheck-above {c['ratio']:g}: {c['rechecked']} pairs re-solved with the "
                  f"global seeds; mean {c['seconds_mean']:.3f} s per geodesic, speed-up "
                  f"{c['speedup_mean']:.1f}x; equal or lower energy than global seeding: "
                  f"{c['equal_or_lower']}/{r['pairs']} (lower: {c['lower']})")
        for w in r["worse_pairs"]:
            print(f"    pair {w['pair']} (|g - s| = {w['pair_distance_coordinates']:.2f}): "
                  f"warm-start energy higher by {100 * w['relative_energy_gap']:.3g}%")
    if args.json:
        from learn.storage import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=2, default=float))


if __name__ == "__main__":
    main()
