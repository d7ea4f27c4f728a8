"""Each choice beyond the paper, measured: short trainings of one environment with the
paper's settings (appendix B.1), with the toolkit's defaults, and with the defaults minus
one choice at a time; prints success on the default evaluation set, the mean length
ratio learned/exact on it (exact: ``solvers.solve_batch`` at the same 2**D segments),
evaluations of C per second and wall time at the same budget of evaluations of C, counted
all-inclusive (same seed).

Run:  python benchmarks/learn_ablation.py --env matsumoto --timesteps 2000000
      [--variants ours,paper,no-log1p,...] [--minutes 3]
"""

from __future__ import annotations

import argparse
import tempfile
from typing import Any

import numpy as np
import torch

import finsler
import learn
import solvers

#: variant name -> (base, overrides); base "ours" = learn.default_config, "paper" =
#: learn.paper_config.
VARIANTS: dict[str, tuple[str, dict[str, Any]]] = {
    "ours": ("ours", {}),
    "paper": ("paper", {}),
    "paper-lr1e-3": ("paper", {"lr": 1e-3}),
    "paper-depth-schedule": ("ours", {"depth_schedule": "paper"}),
    "no-log1p": ("ours", {"critic_transform": "none"}),
    "no-residual": ("ours", {"actor_residual": False}),
    "no-input-scaling": ("ours", {"normalize_inputs": False}),
    "constant-lr": ("ours", {"lr_schedule": "constant"}),
    "no-zero-pairs": ("ours", {"zero_pairs": False}),
    "1-epoch-batch-2048": ("ours", {"epochs": 1, "minibatch_size": 2048}),
    "td-0.9": ("ours", {"targets": "td", "td_lambda": 0.9}),
    "no-path-energy": ("ours", {"path_energy_weight": 0.0}),
    "path-energy-0.3": ("ours", {"path_energy_weight": 0.3}),
    "path-energy-3": ("ours", {"path_energy_weight": 3.0}),
    "3-epochs": ("ours", {"epochs": 3}),
    "unfused-adam": ("ours", {"fused_adam": False}),
    "explore-std-0.05": ("ours", {"explore_std": 0.05}),
    "route-search-8": ("ours", {"route_candidates": 8}),
    "inter": ("ours", {"method": "inter"}),
    "two-to-one": ("ours", {"method": "two-to-one"}),
}


def run(env: str, name: str, timesteps: int, minutes: float | None, seed: int,
        exact: np.ndarray) -> dict:
    base, over = VARIANTS[name]
    make = learn.default_config if base == "ours" else learn.paper_config
    cfg = make(env, **{**over, "timesteps": timesteps, "minutes": minutes, "seed": seed,
                       "eval_every": 10_000})
    with tempfile.TemporaryDirectory(prefix=f"abl_{name}_") as tmp:  # removed afterwards
        out = tmp + "/run"
        res = learn.train(cfg, out, progress=False)
        policy = learn.load_policy(out, checkpoint="latest")
    pairs = finsler.default_pairs(policy.metric)
    paths = policy.generate(pairs[:, 0], pairs[:, 1])
    ratio = policy.metric.path_costs(paths).sum(1) / exact
    return {"variant": name, "timesteps": res.timesteps, "wall_s": res.wall_seconds,
            "ratio": float(np.mean(ratio)),
            "C_per_s": res.final["evaluations_per_second"],
            "success": res.final["success_rate"],
            "mean_max_cost": res.final["mean_max_segment_cost"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="matsumoto")
    ap.add_argument("--timesteps", type=int, default=2_000_000)
    ap.add_argument("--minutes", type=float, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    args = ap.parse_args()
    torch.set_num_threads(1)
    names = args.variants.split(",")
    for name in names:
        if name not in VARIANTS:
            raise SystemExit(f"unknown variant {name!r}; known: {', '.join(VARIANTS)}")
    metric = finsler.get_metric(args.env)
    exact_res = solvers.solve_batch(metric, finsler.default_pairs(metric),
                                    2 ** metric.task.depth, progress=False)
    if not all(r.converged for r in exact_res):
        print("warning: some exact solves did not converge; their ratios are upper bounds")
    exact = np.array([r.length for r in exact_res])
    rows = []
    for name in names:
        r = run(args.env, name, args.timesteps, args.minutes, args.seed, exact)
        rows.append(r)
        print(r, flush=True)
    print(f"\n{args.env}, budget {args.timesteps} evaluations of C (all-inclusive), seed "
          f"{args.seed}; success and lengths of the last checkpoint on the default set")
    print(f"{'variant':<22} {'C evals':>10} {'wall s':>8} {'C/s':>8} {'success':>8} "
          f"{'mean max C':>10} {'length/exact':>12}")
    for r in rows:
        print(f"{r['variant']:<22} {r['timesteps']:>10} {r['wall_s']:>8.1f} "
              f"{r['C_per_s']:>8.0f} {r['success']:>8.2f} {r['mean_max_cost']:>10.4f} "
              f"{r['ratio']:>12.4f}")


if __name__ == "__main__":
    main()
