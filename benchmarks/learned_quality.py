"""Learned paths against exact geodesics on fresh pairs: the policy alone, with its segments
equalized, and with the route search (issue 11 bars).

For each environment, ``--pairs`` pairs drawn with ``--seed`` (default 777: neither the
default evaluation set's seed nor the validation set's; no setting was chosen on it), the
exact discrete geodesics at the task's resolution (:func:`solvers.solve_batch`, globally
seeded, cached in ``--cache`` so an interrupted run resumes), and for every policy (the
shipped one, or ``--runs ENV=DIR[,DIR...]``, e.g. one run per training seed):

* success (every segment cost <= eps; several eps for Panda) of the plain recursive
  generation (``plain``), of the same paths with equalized segments only
  (``equalize``: :func:`learn.equalize_paths`, ``SearchSpec(levels=0, polish=0)``) and of
  :meth:`learn.Policy.search` with its default settings (``search``);
* the per-pair length ratio learned / exact (sum of C), mean, median, 95th percentile, max;
* time per path (batched) and evaluations of C per path.

With several runs per environment the last lines give mean +- standard error over them.
Exact ceilings (the min-max refined exact paths' success) are printed beside.

Usage::

    python benchmarks/learned_quality.py [--envs matsumoto,carlike,panda-pole] [--pairs 500]
        [--seed 777] [--exact-pairs N] [--runs matsumoto=DIR1,DIR2] [--checkpoint best]
        [--workers 2] [--cache DIR] [--json out.json]

``--exact-pairs N`` solves only the first N pairs exactly (ratios on those; success on
all). One torch thread.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

import finsler
import learn
import solvers
from finsler.files import atomic_write_text
from learn.runs import load_any_policy

EPS = {"panda-pole": (20.0, 10.0, 5.0)}
HOWS = ("plain", "equalize", "search")


def exact_reference(metric: finsler.Metric, pairs: np.ndarray, cache: Path,
                    workers: int) -> tuple[np.ndarray, np.ndarray]:
    """Exact lengths and min-max max segment costs of ``pairs`` (cached, resumable)."""
    done = cache.with_suffix(".npz")
    if done.is_file():
        z = np.load(done)
        return z["length"], z["minmax"]
    res = solvers.solve_batch(metric, pairs, minmax=True, workers=workers, progress=True,
                              checkpoint_dir=cache.with_suffix(".parts"))
    length = np.array([r.length if r.converged else np.nan for r in res])
    mm = np.array([r.minmax.max_segment_cost if r.minmax is not None else r.max_segment_cost
                   for r in res])
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(done, length=length, minmax=mm)
    return length, mm


def stats(r: np.ndarray) -> dict[str, float]:
    r = r[np.isfinite(r)]
    return {"mean": float(r.mean()), "median": float(np.median(r)),
            "p95": float(np.percentile(r, 95)), "max": float(r.max()), "pairs": int(r.size)}


def measure(pol: learn.Policy, pairs: np.ndarray, exact: np.ndarray, eps: tuple[float, ...]
            ) -> dict[str, dict]:
    m = pol.metric
    out = {}
    pol.generate(pairs[:1, 0], pairs[:1, 1])  # warm up
    for how in HOWS:
        t0 = time.perf_counter()
        if how == "plain":
            paths = pol.generate(pairs[:, 0], pairs[:, 1])
            evals = float(2**pol.depth)
        else:
            spec = learn.SearchSpec(levels=0, polish=0) if how == "equalize" else None
            res = pol.search(pairs[:, 0], pairs[:, 1], spec)
            paths, evals = res.paths, res.evaluations_per_path
        sec = (time.perf_counter() - t0) / len(pairs)
        costs = m.path_costs(paths)
        ratio = costs[: len(exact)].sum(1) / exact
        out[how] = {"success": {f"{e:g}": float(np.mean(costs.max(1) <= e)) for e in eps},
                    "ratio": stats(ratio), "ms_per_path": 1e3 * sec,
                    "evaluations_of_C_per_path": evals}
    return out


def line(label: str, row: dict) -> str:
    succ = " ".join(f"{100 * v:5.1f}%" for v in row["success"].values())
    r = row["ratio"]
    return (f"{label:44s} {succ}  {r['mean']:.4f} {r['median']:.4f} {r['p95']:.4f} "
            f"{r['max']:.4f}  {row['ms_per_path']:8.2f} {row['evaluations_of_C_per_path']:8.0f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--envs", default="matsumoto,carlike,panda-pole")
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--exact-pairs", type=int, default=None)
    ap.add_argument("--runs", action="append", default=[], metavar="ENV=DIR[,DIR...]")
    ap.add_argument("--checkpoint", default="best", choices=("best", "latest"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=Path("benchmark-cache"))
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    runs: dict[str, list[str]] = {}
    for item in args.runs:
        env, _, dirs = item.partition("=")
        if not dirs:
            ap.error(f"--runs takes ENV=DIR[,DIR...], got {item!r}")
        runs.setdefault(env, []).extend(d for d in dirs.split(",") if d)
    doc: dict = {"seed": args.seed, "pairs": args.pairs, "search": learn.SearchSpec().to_dict(),
                 "checkpoint": args.checkpoint, "envs": {}}
    for env in args.envs.split(","):
        m = finsler.get_metric(env)
        pairs = finsler.sample_pairs(m, args.pairs, args.seed)
        k = args.exact_pairs or args.pairs
        exact, mm = exact_reference(m, pairs[:k], args.cache / f"exact-{env}-{args.seed}-{k}",
                                    args.workers)
        eps = EPS.get(env, (m.task.eps,))
        ceiling = " ".join(f"{100 * np.mean(mm <= e):5.1f}%" for e in eps)
        print(f"\n== {env}: {args.pairs} fresh pairs (seed {args.seed}), exact lengths on {k}; "
              f"eps {', '.join(f'{e:g}' for e in eps)}; exact ceiling {ceiling}")
        print(f"{'policy / paths':44s} {'success':>{7 * len(eps)}s}  ratio: mean median p95"
              "    max     ms/path  C/path")
        sources = runs.get(env) or [env]
        rows = []
        for src in sources:
            pol = (learn.load_policy(src) if src == env
                   else load_any_policy(src, checkpoint=args.checkpoint))
            if not isinstance(pol, learn.Policy):
                raise SystemExit(f"{src}: the route search needs a midpoint policy")
            row = measure(pol, pairs, exact, eps)
            rows.append({"source": str(src), "checkpoint": pol.checkpoint, **row})
            for how in HOWS:
                print(line(f"{Path(src).name} ({pol.checkpoint}) {how}", row[how]), flush=True)
        if len(rows) > 1:
            for how in HOWS:
                for key in ("mean", "p95", "max"):
                    v = np.array([r[how]["ratio"][key] for r in rows])
                    print(f"  {how:6s} ratio {key:6s} over {len(rows)} runs: {v.mean():.4f} +- "
                          f"{v.std(ddof=1) / np.sqrt(len(v)):.4f}")
                for e in rows[0][how]["success"]:
                    v = np.array([r[how]["success"][e] for r in rows])
                    print(f"  {how:6s} success eps {e:>4s} over {len(rows)} runs: "
                          f"{100 * v.mean():.1f} +- {100 * v.std(ddof=1) / np.sqrt(len(v)):.1f}%")
        doc["envs"][env] = {"exact_pairs": k, "exact_ceiling": {
            f"{e:g}": float(np.mean(mm <= e)) for e in eps}, "policies": rows}
    if args.json:
        atomic_write_text(args.json, json.dumps(doc, indent=2), "benchmark figures")


if __name__ == "__main__":
    main()
