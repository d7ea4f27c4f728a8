"""The report's time-per-path table for every shipped policy, measured as the report does.

Per environment: the learned policy at batch 1, 100 and 10,000 (`validation.time_policy`:
warm, the median of ``--repeats`` calls, one torch thread), the exact solve as the report
runs it (`validation.exact_reference`: a globally seeded batched solve of ``--pairs`` pairs
with min-max refinement, one process; its share per path) and one pair at a time
(`solvers.solve_geodesic`, the median over ``--single`` pairs), and the speed-ups. The
pairs are the first of the environment's default evaluation set. Writes
``benchmarks/results/reports/report_timing-DATE.md``.

Usage::

    python benchmarks/report_timing.py [--envs matsumoto,panda-pole,carlike]
                                       [--pairs matsumoto=100,panda-pole=20,carlike=4]
                                       [--single 3] [--repeats 5] [--no-results-file]
"""

from __future__ import annotations

import argparse

from results_file import ResultsFile, markdown_table

import finsler
import learn
from validation.comparison import exact_reference, time_exact_single, time_policy

DEFAULT_PAIRS = {"matsumoto": 100, "panda-pole": 20, "carlike": 4}


def measure(env: str, k: int, single: int, repeats: int) -> dict:
    """The timings of one environment (seconds per path)."""
    policy = learn.load_policy(env)
    m = policy.metric
    pairs = finsler.default_pairs(m)[:k]
    learned = time_policy(policy, pairs, policy.depth, repeats=repeats)
    exact = exact_reference(m, pairs, 2**policy.depth, m.task.eps, workers=1, progress=False)
    one = time_exact_single(m, pairs, 2**policy.depth, single)
    return {"env": env, "depth": policy.depth, "pairs": k, "learned": learned,
            "exact_batch": float(exact.wall_time.mean()), "exact_single": one,
            "converged": int(exact.converged.sum())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--envs", default="matsumoto,panda-pole,carlike")
    ap.add_argument("--pairs", default=",".join(f"{e}={k}" for e, k in DEFAULT_PAIRS.items()))
    ap.add_argument("--single", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-results-file", action="store_true")
    args = ap.parse_args()
    sizes = {e: int(k) for e, k in (item.split("=") for item in args.pairs.split(","))}
    out = ResultsFile("report_timing", "The report's time per path, every shipped policy",
                      claim="reports")
    rows = []
    for env in args.envs.split(","):
        r = measure(env, sizes.get(env, 20), args.single, args.repeats)
        t = r["learned"]["seconds_per_path"]
        rows.append([env, r["depth"], f"{t[1]:.3g}", f"{t[100]:.3g}", f"{t[10_000]:.3g}",
                     f"{r['exact_single']:.3g}",
                     f"{r['exact_batch']:.3g} ({r['pairs']} pairs, {r['converged']} converged)",
                     f"{r['exact_single'] / t[1]:.3g}x", f"{r['exact_batch'] / t[10_000]:.3g}x"])
        print(rows[-1], flush=True)
    header = ["env", "D", "learned s/path, batch 1", "batch 100", "batch 10,000",
              "exact s/path, one pair at a time", "exact, batched (share per path)",
              "speed-up, one pair", "speed-up, batch 10,000 vs batched exact"]
    out.add(f"Learned: warm, the median of {args.repeats} calls (21 single-pair calls for "
            "batch 1), torch limited to 1 thread. Exact: `solvers.solve_geodesic` on the "
            f"first {args.single} pairs one at a time (median), and the report's batched "
            "solve (globally seeded, min-max refined, one process) of the pairs given.", "",
            markdown_table(header, rows))
    if not args.no_results_file:
        out.write()


if __name__ == "__main__":
    main()
