"""Each choice beyond the paper, measured: short trainings of one environment with the
paper's settings (appendix B.1), with the toolkit's defaults, and with the defaults minus
one choice at a time; prints success on the default evaluation set, timesteps/s and
wall time at the same timestep budget (same seed).

Run:  python benchmarks/learn_ablation.py --env matsumoto --timesteps 2000000
      [--variants ours,paper,no-log1p,...] [--minutes 3]
"""

from __future__ import annotations

import argparse
import tempfile
from typing import Any

import torch

import learn

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
    "inter": ("ours", {"method": "inter"}),
    "two-to-one": ("ours", {"method": "two-to-one"}),
}


def run(env: str, name: str, timesteps: int, minutes: float | None, seed: int) -> dict:
    base, over = VARIANTS[name]
    make = learn.default_config if base == "ours" else learn.paper_config
    cfg = make(env, **{**over, "timesteps": timesteps, "minutes": minutes, "seed": seed,
                       "eval_every": 10_000})
    res = learn.train(cfg, tempfile.mkdtemp(prefix=f"abl_{name}_") + "/run", progress=False)
    return {"variant": name, "timesteps": res.timesteps, "wall_s": res.wall_seconds,
            "ts_per_s": res.final["timesteps_per_second"],
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
    rows = []
    for name in args.variants.split(","):
        if name not in VARIANTS:
            raise SystemExit(f"unknown variant {name!r}; known: {', '.join(VARIANTS)}")
        r = run(args.env, name, args.timesteps, args.minutes, args.seed)
        rows.append(r)
        print(r, flush=True)
    print(f"\n{args.env}, budget {args.timesteps} timesteps, seed {args.seed}")
    print(f"{'variant':<22} {'timesteps':>10} {'wall s':>8} {'ts/s':>8} {'success':>8} "
          f"{'mean max C':>10}")
    for r in rows:
        print(f"{r['variant']:<22} {r['timesteps']:>10} {r['wall_s']:>8.1f} "
              f"{r['ts_per_s']:>8.0f} {r['success']:>8.2f} {r['mean_max_cost']:>10.4f}")


if __name__ == "__main__":
    main()
