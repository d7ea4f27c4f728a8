"""Learned generation vs exact solving: paths per second of the shipped policies on 1000
pairs per environment, and time per path of ``solvers.solve_geodesic`` on 20 of them,
printed side by side with the ratio (plus the length ratio learned / exact on those 20).

Run:  python benchmarks/generation_speed.py [--envs matsumoto,carlike,panda-pole]
      [--pairs 1000] [--solve 20] [--threads 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

import finsler
import learn


def learned_rate(policy: learn.Policy, pairs: np.ndarray, repeats: int = 3) -> float:
    """Best-of-``repeats`` paths per second for generating all ``pairs`` in one batch."""
    policy.generate(pairs[:10, 0], pairs[:10, 1])  # warm-up
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        policy.generate(pairs[:, 0], pairs[:, 1])
        best = min(best, time.perf_counter() - t)
    return len(pairs) / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--envs", default="matsumoto,carlike,panda-pole")
    ap.add_argument("--pairs", type=int, default=1000)
    ap.add_argument("--solve", type=int, default=20)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    try:
        import solvers
    except ImportError as err:  # the solver package is a separate layer
        solvers = None
        print(f"solvers unavailable ({err}); printing learned generation only")

    rows = []
    for env in args.envs.split(","):
        policy = learn.load_policy(env)
        m = policy.metric
        pairs = finsler.sample_pairs(m, args.pairs, seed=7)
        rate = learned_rate(policy, pairs)
        row = {"env": env, "D": policy.depth, "learned_paths_per_s": rate,
               "learned_s_per_path": 1.0 / rate}
        if solvers is not None and args.solve > 0:
            sub = pairs[: args.solve]
            learned = policy.generate(sub[:, 0], sub[:, 1])
            times, ratios, ok = [], [], 0
            for k in range(len(sub)):
                t = time.perf_counter()
                res = solvers.solve_geodesic(m, sub[k, 0], sub[k, 1])
                times.append(time.perf_counter() - t)
                ok += bool(res.converged)
                exact_len = float(res.length)
                ratios.append(float(m.path_costs(learned[k : k + 1]).sum()) / exact_len)
            row.update(solver_s_per_path=float(np.mean(times)), solver_converged=ok,
                       speedup=float(np.mean(times)) * rate,
                       length_ratio_mean=float(np.mean(ratios)),
                       length_ratio_median=float(np.median(ratios)))
        rows.append(row)
        print(row, flush=True)

    print()
    head = f"{'env':<11} {'D':>2} {'learned paths/s':>16} {'learned s/path':>15} " \
           f"{'solver s/path':>14} {'ratio':>10} {'len learned/exact':>18}"
    print(head)
    print("-" * len(head))
    for r in rows:
        sol = r.get("solver_s_per_path")
        print(f"{r['env']:<11} {r['D']:>2} {r['learned_paths_per_s']:>16.0f} "
              f"{r['learned_s_per_path']:>15.2e} "
              + (f"{sol:>14.3f} {r['speedup']:>10.0f} {r['length_ratio_mean']:>18.4f}"
                 if sol is not None else f"{'n/a':>14} {'n/a':>10} {'n/a':>18}"))


if __name__ == "__main__":
    main()
