"""Certified intervals on fresh Matsumoto pairs (issue 10 bars).

For ``--pairs`` (20) Matsumoto pairs drawn with a seed the project never used for anything
else (``--seed`` 31337, :func:`finsler.sample_pairs`), this runs :func:`solvers.certify` at
the default mesh (target gap 1e-2) and at the fine one (target 1e-3), and prints per pair
the lower and upper bounds, the relative gap ``(upper - lower) / upper``, the gap of the
solver's own path (``path_gap``: the upper bound may instead come from the path with
switchbacks where F is not convex), the triangles, LP rows, the CPU time of the process
(``time.process_time``: the figure the bars of issue 46 are stated in, which the load of
other programs on the machine barely changes) and the wall time, then how many pairs meet
each bar and the median and largest CPU time. The figures also go to a results file
``benchmarks/results/certify/certify-DATE.md`` (:mod:`results_file`: command, commit,
machine and its load). A certified gap <= 1e-3 on
the solver's own path (the upper bound is its length) proves that path within 0.1 % of
the global optimum: the count of such pairs is printed.

Usage::

    python benchmarks/certify.py [--pairs 20] [--seed 31337] [--fine-time-limit SECONDS]
                                 [--skip-fine | --skip-default] [--skip-soundness]
                                 [--only 4,8,10]
                                 [--json out.json] [--no-results-file]

The presets' work budgets (refinement rounds, triangles) end each refinement, so the
figures do not depend on the machine or its load. ``--fine-time-limit`` (seconds per
pair, default none) may stop the fine refinement earlier: the row then says
``stopped_by time_limit`` and its gap depends on the machine. ``--only`` certifies a
subset of the pairs (their numbers in the set of ``--pairs``), e.g. to share the pairs
between two processes. One thread. The first pair's CPU time includes building the
metric's derivative programs (once per process).
Then (unless ``--skip-soundness``) the default mesh on 10 Poincare and 5 Randers pairs of
the same seed, whose exact distances are known: every interval must contain it.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from results_file import ResultsFile, markdown_table

import finsler
from finsler.infra.files import atomic_write_text
from solvers import MeshSpec, certify


def run(pairs: np.ndarray, spec: MeshSpec, time_limit: float | None, label: str,
        only: list[int]) -> list[dict]:
    m = finsler.get_metric("matsumoto")
    rows = []
    for i in only:
        s, g = pairs[i]
        t0, c0 = time.perf_counter(), time.process_time()
        r = certify(m, s, g, spec, time_limit=time_limit)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        rows.append({"cpu": cpu, "pair": i, "lower": r.lower, "upper": r.upper, "gap": r.gap,
                     "upper_source": r.upper_source, "path_gap": r.path_gap,
                     "triangles": r.triangles, "rows": r.lp_rows, "rounds": len(r.rounds),
                     "seconds": wall, "convexity": r.convexity, "stopped_by": r.stopped_by})
        print(f"{label:7s} {i:3d}  {r.lower:.7f}  {r.upper:.7f}  {r.gap:9.2e}  "
              f"{r.path_gap:9.2e}  {r.triangles:6d}  {r.lp_rows:7d}  {len(r.rounds):3d}  "
              f"{cpu:7.1f}  {wall:7.1f}  {r.stopped_by}", flush=True)
    return rows


def soundness(seed: int, counts: dict[str, int]) -> dict:
    """The default mesh on closed-form metrics: does every interval contain the exact
    distance (issue 46's soundness bar: 10 Poincare and 5 Randers pairs)?"""
    out: dict = {"rows": []}
    for name, k in counts.items():
        m = finsler.get_metric(name)
        for i, (s, g) in enumerate(finsler.sample_pairs(m, k, seed)):
            c0 = time.process_time()
            r = certify(m, s, g, "default")
            exact = float(m.distance(s, g)[0])
            row = {"metric": name, "pair": i, "lower": r.lower, "exact": exact,
                   "upper": r.upper, "gap": r.gap, "contains": bool(r.lower <= exact <= r.upper),
                   "cpu": time.process_time() - c0, "stopped_by": str(r.stopped_by)}
            out["rows"].append(row)
            print(f"sound   {name:9s} {i:2d}  {r.lower:.7f} <= {exact:.7f} <= {r.upper:.7f}  "
                  f"{row['contains']}  gap {r.gap:.2e}  cpu {row['cpu']:.1f}", flush=True)
    out["contained"] = sum(r["contains"] for r in out["rows"])
    print(f"soundness: the exact distance lies in {out['contained']}/{len(out['rows'])} "
          "intervals")
    return out


def summary(rows: list[dict], bar: float, label: str) -> dict:
    gaps = np.array([r["gap"] for r in rows])
    secs = np.array([r["seconds"] for r in rows])
    cpu = np.array([r["cpu"] for r in rows])
    met = int(np.sum(gaps <= bar))
    print(f"{label}: gap <= {bar:g} on {met}/{len(rows)} pairs; gap median {np.median(gaps):.2e}"
          f", max {gaps.max():.2e}; CPU median {np.median(cpu):.1f} s, max {cpu.max():.1f} s; "
          f"wall median {np.median(secs):.1f} s, max {secs.max():.1f} s, total {secs.sum():.0f} s")
    return {"bar": bar, "met": met, "pairs": len(rows), "gap_median": float(np.median(gaps)),
            "gap_max": float(gaps.max()), "cpu_median": float(np.median(cpu)),
            "cpu_max": float(cpu.max()), "seconds_median": float(np.median(secs)),
            "seconds_max": float(secs.max()), "seconds_total": float(secs.sum())}


def section(label: str, block: dict) -> str:
    """Markdown of one mesh preset's rows and summary."""
    sm = block["summary"]
    table = markdown_table(
        ["pair", "lower", "upper", "gap", "path_gap", "triangles", "LP rows", "rounds",
         "CPU s", "wall s", "stopped_by"],
        [[r["pair"], f"{r['lower']:.7f}", f"{r['upper']:.7f}", f"{r['gap']:.2e}",
          f"{r['path_gap']:.2e}", r["triangles"], r["rows"], r["rounds"], f"{r['cpu']:.1f}",
          f"{r['seconds']:.1f}", r["stopped_by"]] for r in block["rows"]])
    return (f"## {label} mesh (target gap {sm['bar']:g})\n\n{table}\n\n"
            f"Gap <= {sm['bar']:g} on {sm['met']}/{sm['pairs']} pairs; gap median "
            f"{sm['gap_median']:.2e}, max {sm['gap_max']:.2e}. CPU time per pair "
            f"(time.process_time): median {sm['cpu_median']:.1f} s, max {sm['cpu_max']:.1f} s; "
            f"wall median {sm['seconds_median']:.1f} s, max {sm['seconds_max']:.1f} s.\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=20)
    ap.add_argument("--seed", type=int, default=31337)
    ap.add_argument("--fine-time-limit", type=float, default=None,
                    help="seconds per pair after which the fine refinement starts no new "
                         "round (default: none; the preset's work budgets decide)")
    ap.add_argument("--skip-fine", action="store_true")
    ap.add_argument("--skip-default", action="store_true")
    ap.add_argument("--skip-soundness", action="store_true",
                    help="skip the closed-form check (10 Poincare, 5 Randers pairs)")
    ap.add_argument("--only", default=None, help="comma-separated pair numbers")
    ap.add_argument("--json", default=None, help="write the figures to this JSON file")
    ap.add_argument("--no-results-file", action="store_true",
                    help="do not write benchmarks/results/certify/certify-DATE.md")
    args = ap.parse_args()
    m = finsler.get_metric("matsumoto")
    pairs = finsler.sample_pairs(m, args.pairs, args.seed)
    only = list(range(args.pairs)) if args.only is None else [int(x) for x in
                                                               args.only.split(",")]
    if any(not 0 <= i < args.pairs for i in only):
        ap.error(f"--only takes pair numbers below --pairs ({args.pairs})")
    head = ("mesh    pair  lower      upper      gap        path_gap   triangles rows   "
            "rounds cpu_s   wall_s  stopped_by")
    print(head)
    # built now: its header gives the load at the start and the start time of the runs
    out = None if args.no_results_file else ResultsFile(
        "certify", title="Certified intervals on fresh Matsumoto pairs", claim="certify")
    doc: dict = {"seed": args.seed, "pairs": args.pairs, "only": only}
    if not args.skip_default:
        doc["default"] = {"rows": run(pairs, MeshSpec.preset("default"), None, "default",
                                      only)}
        doc["default"]["summary"] = summary(doc["default"]["rows"], 1e-2, "default mesh")
    if not args.skip_fine:
        doc["fine"] = {"rows": run(pairs, MeshSpec.preset("fine"), args.fine_time_limit,
                                   "fine", only), "time_limit": args.fine_time_limit}
        doc["fine"]["summary"] = summary(doc["fine"]["rows"], 1e-3, "fine mesh")
        own = sum(r["path_gap"] <= 1e-3 for r in doc["fine"]["rows"])
        print(f"fine mesh: the solver's own path is certified within 1e-3 of the global "
              f"optimum (path_gap <= 1e-3) on {own}/{len(only)} pairs")
    if not args.skip_soundness:
        doc["soundness"] = soundness(args.seed, {"poincare": 10, "randers": 5})
    if args.json:
        atomic_write_text(args.json, json.dumps(doc, indent=2), "benchmark figures")
    if out is not None:
        out.add(f"Pairs: finsler.sample_pairs(matsumoto, {args.pairs}, {args.seed}), pairs "
                f"{','.join(map(str, only))}; one thread (OMP_NUM_THREADS="
                f"{os.environ.get('OMP_NUM_THREADS')}). CPU time is time.process_time of this "
                "process around each certify call (the first pair's includes building the "
                "metric's derivative programs).")
        for key in ("default", "fine"):
            if key in doc:
                out.add(section(key, doc[key]))
        if "soundness" in doc:
            sd = doc["soundness"]
            out.add("## Soundness: closed-form metrics, default mesh\n\n" + markdown_table(
                ["metric", "pair", "lower", "exact", "upper", "gap", "contains", "CPU s"],
                [[r["metric"], r["pair"], f"{r['lower']:.7f}", f"{r['exact']:.7f}",
                  f"{r['upper']:.7f}", f"{r['gap']:.2e}", r["contains"], f"{r['cpu']:.1f}"]
                 for r in sd["rows"]]) + f"\n\nThe exact distance lies in {sd['contained']}/"
                f"{len(sd['rows'])} intervals (pairs: finsler.sample_pairs(metric, k, "
                f"{args.seed})).\n")
        out.write()


if __name__ == "__main__":
    main()
