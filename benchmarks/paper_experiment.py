"""The paper's experiment on pairs nobody selected on: every run of a sweep directory (or
shipped policies) evaluated on K fresh pairs, mean +- standard error over seeds.

A sweep directory is ``DIR/<env>/<variant>/seed-<s>/`` (``geodesics sweep``). For every
(env, variant) the table gives, over seeds: success of the LAST checkpoint (no selection)
and of the best (validation-selected) checkpoint on K fresh pairs, all-inclusive
evaluations of C, the paper's count, wall time and which bound stopped the runs; the time
(in evaluations of C) at which a running mean of 5 validation evaluations first reached
each threshold. The fresh pairs come from ``--seed`` (default 777), which is neither the
default evaluation set's seed nor the validation set's.

Run:  python benchmarks/paper_experiment.py --sweep DIR [--pairs 500] [--seed 777]
      python benchmarks/paper_experiment.py --shipped [--pairs 500]  # shipped policies
Add ``--exact`` to also give the length ratio learned / exact (solves every fresh pair).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

import finsler
import learn
from learn.runs import load_any_policy
from learn.storage import RESULT_FILE, read_json, read_metrics
from validation.curves import running_mean_threshold


def _stats(values: list[float]) -> tuple[float, float]:
    a = np.asarray(values, dtype=float)
    se = float(a.std(ddof=1) / np.sqrt(len(a))) if len(a) > 1 else float("nan")
    return float(a.mean()), se


def first_running_mean(rows: list[dict], threshold: float) -> float | None:
    """Evaluations of C at which a running mean of 5 validation evaluations first reaches
    ``threshold`` (None if never)."""
    hit = running_mean_threshold(rows, threshold, window=5)
    return None if hit is None else float(hit.timesteps)


def _exact_lengths(metric: finsler.Metric, pairs: np.ndarray, cache: Path) -> np.ndarray:
    import solvers

    if cache.is_file():
        return np.load(cache)
    res = solvers.solve_batch(metric, pairs, workers=2, progress=True,
                              checkpoint_dir=cache.with_suffix(".parts"))
    lengths = np.array([r.length for r in res])
    np.save(cache, lengths)
    return lengths


def evaluate_run(run: Path | str, pairs: np.ndarray, exact: np.ndarray | None) -> dict:
    out = {}
    for ck in ("latest", "best"):
        pol = load_any_policy(run, checkpoint=ck)
        paths = pol.generate(pairs[:, 0], pairs[:, 1])
        ev = pol.evaluate(pairs)
        out[f"success_{ck}"] = ev.success_rate
        if exact is not None:
            ratio = pol.metric.path_costs(paths).sum(1) / exact
            out[f"ratio_{ck}"] = float(np.mean(ratio))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sweep", type=Path)
    ap.add_argument("--shipped", action="store_true")
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--exact", action="store_true")
    ap.add_argument("--json", type=Path, help="also write the table as JSON")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if args.seed in (finsler.DEFAULT_EVAL_SEED, finsler.VALIDATION_SEED):
        raise SystemExit("--seed must differ from the default evaluation and validation seeds")

    table = []
    if args.shipped:
        for env in learn.shipped_policies():
            pol = learn.load_policy(env)
            m = pol.metric
            pairs = finsler.sample_pairs(m, args.pairs, args.seed)
            exact = (_exact_lengths(m, pairs, Path(f"exact-{env}-{args.seed}-{args.pairs}.npy"))
                     if args.exact else None)
            ev = pol.evaluate(pairs)
            row = {"env": env, "success": ev.success_rate}
            for eps in sorted({m.task.eps, m.task.eps / 2, m.task.eps / 4}, reverse=True):
                row[f"success_eps_{eps:g}"] = pol.evaluate(pairs, eps=eps).success_rate
            if exact is not None:
                paths = pol.generate(pairs[:, 0], pairs[:, 1])
                r = m.path_costs(paths).sum(1) / exact
                row.update(ratio_mean=float(r.mean()), ratio_median=float(np.median(r)),
                           ratio_p95=float(np.quantile(r, 0.95)), ratio_max=float(r.max()))
            table.append(row)
            print(json.dumps(row))
    if args.sweep is not None:
        for env_dir in sorted(p for p in args.sweep.iterdir() if p.is_dir()):
            # the metric the runs trained on (parameters and user class from their config)
            runs = sorted(env_dir.glob("*/seed-*"))
            m = load_any_policy(runs[0]).metric if runs else finsler.get_metric(env_dir.name)
            others = {repr(load_any_policy(r).metric) for r in runs[1:]}
            if others - {repr(m)}:
                raise SystemExit(f"{env_dir}: the runs trained on different metrics "
                                 f"({sorted(others | {repr(m)})})")
            pairs = finsler.sample_pairs(m, args.pairs, args.seed)
            exact = (_exact_lengths(m, pairs, args.sweep / f"exact-{env_dir.name}-{args.seed}-"
                                    f"{args.pairs}.npy") if args.exact else None)
            for var_dir in sorted(p for p in env_dir.iterdir() if p.is_dir()):
                per_seed = []
                for run in sorted(var_dir.glob("seed-*")):
                    if not (run / RESULT_FILE).is_file():
                        print(f"# {run}: unfinished, left out")
                        continue
                    res = read_json(run / RESULT_FILE)
                    rows = read_metrics(run / "metrics.csv")
                    ev = evaluate_run(run, pairs, exact)
                    per_seed.append({**ev, "timesteps": res["timesteps"],
                                     "timesteps_paper": res["timesteps_paper"],
                                     "wall": res["wall_seconds"],
                                     "stopped_by": res["stopped_by"],
                                     "t90": first_running_mean(rows, 0.9),
                                     "t95": first_running_mean(rows, 0.95)})
                if not per_seed:
                    continue
                row = {"env": env_dir.name, "variant": var_dir.name, "seeds": len(per_seed),
                       "stopped_by": sorted({r["stopped_by"] for r in per_seed})}
                for key in per_seed[0]:
                    if key in ("stopped_by", "t90", "t95"):
                        continue
                    row[key] = _stats([r[key] for r in per_seed])
                for key in ("t90", "t95"):
                    row[key] = [r[key] for r in per_seed]
                table.append(row)
                print(f"{row['env']:<10} {row['variant']:<14} n={row['seeds']} "
                      f"last {row['success_latest'][0]:.1%} +- {row['success_latest'][1]:.1%}  "
                      f"best {row['success_best'][0]:.1%} +- {row['success_best'][1]:.1%}  "
                      f"C evals {row['timesteps'][0]:.3g} (paper count "
                      f"{row['timesteps_paper'][0]:.3g})  wall {row['wall'][0]:.0f} s  "
                      f"stopped by {','.join(row['stopped_by'])}"
                      + (f"  ratio(last) {row['ratio_latest'][0]:.4f}" if exact is not None
                         else ""))
    if args.json:
        args.json.write_text(json.dumps(table, indent=2))


if __name__ == "__main__":
    main()
