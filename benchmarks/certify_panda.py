"""Sound lower bounds on Panda distances (issue 46, item 3): lower / upper on fresh pairs.

For ``--pairs`` (10) Panda pole pairs drawn with a seed the project never used for
anything else (``--seed`` 20261150, :func:`finsler.sample_pairs`; the method was tuned on
``sample_pairs(panda, 4, 11)``), this runs
:func:`solvers.certify_conformal.certify_conformal` with the work budget ``--max-boxes``
(box enclosures, default 1e6) and prints per pair: the Euclidean distance, the proven lower
bound, the upper bound (the solver's path length at the task's 32 segments, proven by
interval arithmetic), their ratio, the trivial bound proven by the same boxes (``m |y -
x|``, ``m`` the proven smallest factor over the reachable region) and its ceiling
(``f_seen |y - x|``, ``f_seen`` the smallest factor at any box centre: the trivial bound
with the exact minimum is at most this), whether the lower bound beats that ceiling, the
work, the CPU time of the process (``time.process_time``) and the wall time; then the
median ratio and how many pairs beat the trivial bound. The figures also go to
``benchmarks/results/certify_panda-DATE.md`` (:mod:`results_file`).

Usage::

    python benchmarks/certify_panda.py [--pairs 10] [--seed 20261150] [--max-boxes 1000000]
                                       [--no-results-file]

Work budgets (boxes, rounds) end each run: the figures do not depend on the machine's
speed. One thread.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from results_file import ResultsFile, markdown_table

import finsler
from solvers.certify_conformal import ConformalSpec, certify_conformal


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=20261150)
    ap.add_argument("--max-boxes", type=int, default=1_000_000)
    ap.add_argument("--no-results-file", action="store_true")
    args = ap.parse_args()
    out = ResultsFile("certify_panda", "Sound lower bounds on Panda distances (issue 46 "
                      "item 3)")  # started now: the header's times and load span the run
    m = finsler.get_metric("panda-pole")
    spec = ConformalSpec(max_boxes=args.max_boxes)
    header = ["pair", "|y-x|", "lower", "upper", "lower/upper", "trivial/upper",
              "ceiling/upper", "beats trivial", "boxes", "enclosures", "momentum", "status",
              "CPU s", "wall s"]
    rows, ratios, beats = [], [], 0
    for k, (x, y) in enumerate(finsler.sample_pairs(m, args.pairs, args.seed)):
        c0, w0 = time.process_time(), time.perf_counter()
        r = certify_conformal(m, x, y, spec)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        ceiling = r.min_factor_seen * r.euclidean
        beat = r.lower > ceiling
        beats += int(beat)
        ratios.append(r.ratio)
        rows.append([k, f"{r.euclidean:.3f}", f"{r.lower:.3f}", f"{r.upper:.3f}",
                     f"{r.ratio:.3f}", f"{r.trivial / r.upper:.3f}",
                     f"{ceiling / r.upper:.3f}", "yes" if beat else "no", r.boxes,
                     r.enclosures, f"{r.momentum:.2f}", r.status.label, f"{cpu:.1f}",
                     f"{wall:.1f}"])
        print(" | ".join(str(c) for c in rows[-1]), flush=True)
    table = markdown_table(header, rows)
    summary = (f"median lower/upper {float(np.median(ratios)):.3f} (bar: >= 0.8), lowest "
               f"{min(ratios):.3f}; the lower bound beats the trivial bound's ceiling on "
               f"{beats} of {len(ratios)} pairs (bar: all)")
    print(table)
    print(summary)
    if not args.no_results_file:
        out.add(f"{args.pairs} pairs `finsler.sample_pairs(panda-pole, {args.pairs}, "
                f"{args.seed})`, budget {args.max_boxes} box enclosures per pair, "
                f"`ConformalSpec` defaults otherwise; upper bound: the solver's path at "
                f"{m.task.segments} segments, proven (`path_length_bounds`). CPU time is "
                "`time.process_time` of the process (the machine was shared with other "
                "jobs: wall time is longer).", "", table, "", summary)
        out.write()


if __name__ == "__main__":
    main()
