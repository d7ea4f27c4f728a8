"""Certified intervals in 3-D (issue 46, items 1-2): ``solvers.certificates.nd.certificate`` on
fresh pairs of
the closed-form ``poincare-slab`` (every interval must contain the exact distance) and of
``carlike`` (the lower bound must stay below the solver's path length, the best length
known for a fresh pair). Prints a table and writes it to benchmarks/results/certify-nd/
via results_file.py, with CPU time (time.process_time) next to wall time.

    python benchmarks/certify_nd.py --metric poincare-slab --pairs 10 --seed 20261207
    python benchmarks/certify_nd.py --metric carlike --pairs 10 --seed 20261208

The car-like upper bound is finite since path_length_bounds encloses F itself on pieces
across the metric's kinks (issue 46 item 1).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results_file import ResultsFile, markdown_table

import finsler
from solvers.certificates.nd.certificate import NDSpec, certify_nd


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--metric", default="poincare-slab")
    ap.add_argument("--pairs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=20261207)
    ap.add_argument("--only", default="", help="comma-separated pair indices")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--h-path", type=float, default=None)
    ap.add_argument("--max-rounds", type=int, default=None)
    ap.add_argument("--target-gap", type=float, default=None)
    ap.add_argument("--lp-rounds", type=int, default=None,
                    help="LP solves per mesh (default: the preset's)")
    ap.add_argument("--segments", type=int, default=None,
                    help="segments of the solver's path (default: 4 x the task's)")
    ap.add_argument("--element", default=None, choices=("P1", "P2", "auto"),
                    help="the potential (default: the preset's)")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--verbose", action="store_true",
                    help="log each LP, separation and proof of the P2 element")
    args = ap.parse_args()
    if args.verbose:
        logging.basicConfig(format="%(asctime)s %(message)s")
        logging.getLogger("solvers.certificates.nd.p2").setLevel(logging.DEBUG)
    m = finsler.get_metric(args.metric)
    spec = NDSpec.preset(args.preset)
    changes = {k: v for k, v in (("h_path", args.h_path), ("max_rounds", args.max_rounds),
                                 ("target_gap", args.target_gap),
                                 ("lp_rounds", args.lp_rounds),
                                 ("segments", args.segments),
                                 ("element", args.element)) if v is not None}
    spec = dataclasses.replace(spec, **changes)
    pairs = finsler.sample_pairs(m, args.pairs, args.seed)
    idx = [int(i) for i in args.only.split(",")] if args.only else list(range(args.pairs))
    rows = []
    closed = m.provides("distance")
    out = ResultsFile(f"certify_nd-{args.metric}",
                      title=f"Certified intervals in 3-D: {args.metric}", claim="certify-nd")
    for i in idx:
        s, g = pairs[i]
        c0, w0 = time.process_time(), time.perf_counter()
        r = certify_nd(m, s, g, spec)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        exact = float(m.distance(s, g)[0]) if closed else float("nan")
        path_len = float(m.path_length_error(r.path).value)
        row = {"pair": i, "lower": f"{r.lower:.6f}", "upper": f"{r.upper:.6f}",
               "gap": f"{r.gap:.2e}", "R": f"{r.verified_ratio:.5f}", "cells": r.cells,
               "region": r.relevant_cells, "status": r.status.label,
               "cpu s": f"{cpu:.1f}", "wall s": f"{wall:.1f}"}
        if closed:
            row["exact"] = f"{exact:.6f}"
            row["contains"] = bool(r.lower <= exact <= r.upper)
        else:
            row["lower <= path length"] = bool(r.lower <= path_len)
        rows.append(row)
        print(row, flush=True)
        if not args.no_write and len(rows) < len(idx):  # what is finished survives a kill
            out.sections = []
            out.add(f"In progress: {len(rows)} of {len(idx)} pairs.",
                    markdown_table(list(rows[0]), [list(r.values()) for r in rows]))
            out.write()
    gaps = np.array([float(r["gap"]) for r in rows])
    cpus = np.array([float(r["cpu s"]) for r in rows])
    summary = (f"{len(rows)} pairs of {args.metric} (sample_pairs seed {args.seed}), spec "
               f"{dataclasses.asdict(spec)}: median gap {np.median(gaps):.3e}, max "
               f"{gaps.max():.3e}; median CPU {np.median(cpus):.1f} s, max {cpus.max():.1f} s"
               + ("; the machine was shared with other jobs (wall >> CPU)." if sum(
                   float(r["wall s"]) for r in rows) > 1.3 * cpus.sum() else "."))
    if closed:
        summary += (f" Every interval contains the exact distance: "
                    f"{all(r['contains'] for r in rows)}.")
    print(summary)
    if args.no_write:
        return
    header = list(rows[0])
    out.sections = []
    out.add(summary, markdown_table(header, [[r[k] for k in header] for r in rows]))
    print(out.write())


if __name__ == "__main__":
    main()
