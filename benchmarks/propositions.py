"""Numerical checks of the paper's theory, printed as tables (validation.propositions).

* Proposition 2: exact dynamic programming of eqs. (9)-(11) on grids of 2-D closed-form
  metrics; error of V_i against the exact d and of pi_i against true midpoints, per grid
  size n (points per axis) and iteration i, over pairs with d >= d_min.
* Lemma 1 items 3 and 4: worst slack of the bounds over all iterations (<= 0: holds).
* Remark 3: eq. (13) with C = f o d stays at V = C != d; eq. (10) from the same V_0 moves
  towards d.
* Proposition 1: observed rate of C/d -> 1, and its failure where Matsumoto is not convex.

Usage: python benchmarks/propositions.py [--sizes 11 15 21] [--iterations 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

import finsler
from validation import propositions as P


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[17, 25, 33])
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--metrics", nargs="+", default=["poincare", "sphere", "randers"])
    args = ap.parse_args()
    torch.set_num_threads(1)

    keys = ["n", "G", "h", "i", "pairs", "V_err_max", "V_err_mean", "mid_err_max",
            "mid_err_mean", "mid_floor_max", "mid_coord_max"]
    for name in args.metrics:
        m = finsler.get_metric(name)
        t0 = time.perf_counter()
        rows = P.proposition2_table(m, tuple(args.sizes), args.iterations)
        print(f"\n## Proposition 2 on {name} ({time.perf_counter() - t0:.1f} s)\n")
        print(P.format_table(rows, keys))
        best = {}
        for r in rows:
            best.setdefault(r["n"], []).append(r["V_err_mean"])
        print("best mean |V_i - d|/d per grid:",
              ", ".join(f"n={n}: {min(v):.4f} (i={int(np.argmin(v))})" for n, v in best.items()))

    print("\n## Lemma 1 items 3 and 4 (worst slack over iterations; <= 0 means the bound holds)\n")
    print("| metric | n | delta | item 3 slack | item 4 slack | eps_i(delta) over i "
          "| grid defect |")
    print("|---|---|---|---|---|---|---|")
    for name in args.metrics:
        m = finsler.get_metric(name)
        dp = P.run_grid_dp(m, args.sizes[0], args.iterations)
        d = P.grid_distance(m, dp.points)
        deltas = [float(q) for q in np.quantile(d[d > 0], [0.05, 0.25, 1.0])]
        rep = P.check_lemma1(dp, d, deltas)
        for k, dl in enumerate(deltas):
            s3 = max(r[k] for r in rep.item3)
            s4 = max(r[k] for r in rep.item4)
            eps = ", ".join(f"{r[k]:.3f}" for r in rep.eps)
            print(f"| {name} | {args.sizes[0]} | {dl:.3f} | {s3:.2e} | {s4:.2e} | {eps} | "
                  f"{rep.grid_defect[k]:.3f} |")

    print("\n## Remark 3: C = f o d, f(h) = 2 sqrt(h+1) - 2\n")
    for name in args.metrics:
        r = P.remark3(finsler.get_metric(name), n=args.sizes[0], iterations=args.iterations)
        errs = ", ".join(f"{e:.3f}" for e in r.squared_rule_err)
        print(f"{name}: eq. (13) stays at V = C and pi(x, y) = x: {r.stays}; x is in the "
              f"argmin up to {r.x_in_argmin_gap:.1e}; max |C - d|/d = {r.gap_to_d:.3f}; "
              f"eq. (10) from the same V_0, max |V_i - d|/d by i: {errs}")

    print("\n## Proposition 1: C(x, x + t u) / d(x, x + t u)\n")
    ts = 0.1 * 2.0 ** -np.arange(7)
    cases = [("poincare", [0.3, 0.2], [0.6, 0.8]), ("sphere", [-0.4, 0.3], [1.0, 0.0]),
             ("randers", [0.1, 0.2], [0.6, -0.8]), ("matsumoto", [0.1, 0.05], [0.6, 0.8])]
    for name, x, u in cases:
        r = P.proposition1_rate(finsler.get_metric(name), np.array(x), np.array(u), ts[:5])
        errs = ", ".join(f"{e:.2e}" for e in r.err)
        print(f"{name} at {x}: |C/d - 1| for t = 0.1 / 2^k: {errs}; observed rate {r.rate:.3f}")
    m = finsler.get_metric("matsumoto")
    for p in ([0.4, 0.0], [0.6, 0.0], [0.8, 0.0]):
        r = P.proposition1_nonconvex(m, np.array(p), 0.05 * 2.0 ** -np.arange(6))
        rat = ", ".join(f"{v:.4f}" for v in r.ratio)
        print(f"matsumoto at |p| = {p[0]} (not convex), direction {np.round(r.u, 3)}: "
              f"C/d_upper = {rat} -> predicted F/F** = {r.limit:.4f}")


if __name__ == "__main__":
    main()
