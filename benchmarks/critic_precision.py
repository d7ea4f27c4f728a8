"""How far a trained critic is off the cost of the policy's own paths, level by level of
the midpoint tree, beside the policy's success: for midpoint runs (a run directory keeps
its critic in each checkpoint), on pairs drawn with ``--seed`` (the project's tuning pairs
by default, never the reporting ones).

For each run, its deterministic paths between the pairs are cut at every level into
sub-pairs; a sub-pair's true cost is the sum of C over the path's segments between its
ends (one evaluation of C per segment, counted below), and the critic's error is
``V / cost - 1``. The actor places each midpoint where the critic's two halves balance,
so the critic's error at a level bounds how evenly and how short the policy can split
there.

Run:  python benchmarks/critic_precision.py DIR[:best|latest] ... [--pairs 500]
      [--seed 4242] [--eps 20,10,5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

import finsler
import learn


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="run directories, each optionally :best or :latest")
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--seed", type=int, default=4242,
                    help="seed of the pairs (default: the tuning pairs)")
    ap.add_argument("--eps", default="",
                    help="comma-separated tolerances for the success column (default: the "
                         "task's)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    if args.pairs < 1:
        ap.error(f"--pairs must be at least 1, got {args.pairs}")
    try:
        eps_list = [float(e) for e in args.eps.split(",") if e]
    except ValueError:
        ap.error(f"--eps must be comma-separated numbers, got {args.eps!r}")
    if not all(np.isfinite(e) and e > 0 for e in eps_list):
        ap.error(f"--eps values must be positive and finite, got {args.eps!r}")
    torch.set_num_threads(args.threads)
    for spec in args.runs:
        run, _, ck = spec.partition(":")
        ck = ck or "best"
        t = time.perf_counter()
        try:
            policy = learn.load_policy(run, checkpoint=ck)
            critic = learn.load_critic(run, checkpoint=ck).double()
        except (finsler.InputError, learn.CorruptFileError) as err:
            raise SystemExit(f"critic_precision: {err}") from None
        m = policy.metric
        pairs = finsler.sample_pairs(m, args.pairs, args.seed)
        paths = policy.generate(pairs[:, 0], pairs[:, 1])
        costs = m.path_costs(paths)
        eps = eps_list or [policy.eps]
        success = " / ".join(f"{100 * np.mean(costs.max(1) <= e):.1f}" for e in eps)
        errors = learn.critic_level_errors(m, paths, critic)
        print(f"{run} ({policy.checkpoint}, {m.name}, critic {critic.transform}"
              f"{', symmetric' if critic.symmetric else ''}): {args.pairs} pairs (seed "
              f"{args.seed}), success {success}% at eps {' / '.join(map(str, eps))}, mean "
              f"length {costs.sum(1).mean():.4g}; {costs.size} evaluations of C; "
              f"{time.perf_counter() - t:.1f} s")
        print("  level  sub-pairs  mean |V/cost - 1|   bias   5% .. 95%")
        for lev, e in enumerate(errors):
            print(f"  {lev:5d}  {e.size:9d}  {100 * np.abs(e).mean():15.2f}%  "
                  f"{100 * e.mean():+5.2f}%  {100 * np.percentile(e, 5):+.1f} .. "
                  f"{100 * np.percentile(e, 95):+.1f}%")


if __name__ == "__main__":
    main()
