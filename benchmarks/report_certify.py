"""What a report's certificates cost per pair (issue 46, item 5): the budgets
``geodesics report`` certifies with by default (``validation.report.certified_intervals``).

For each metric, ``--pairs`` fresh pairs ``finsler.sample_pairs(metric, K, --seed)`` are
solved (``solvers.solve_geodesic``, as the report's exact reference) and certified by
``solvers.certify`` with that path and the given presets (``coarse``: the quick report's,
``default``: the full report's), exactly as the report does. The table gives per pair the
interval, its gap, the status, the work (triangles / cells / boxes) and the CPU time of the
certificate alone (``time.process_time``; the solve is not counted, the report reuses its
exact paths). Run as ``python benchmarks/report_certify.py [--metric carlike ...]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results_file import ResultsFile, markdown_table

import finsler
import solvers
from validation.report_certify import certificate_row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--metric", action="append", default=None,
                    help="registered metric (repeat; default: poincare-slab, carlike, "
                         "panda-pole)")
    ap.add_argument("--preset", action="append", default=None,
                    help="certify preset (repeat; default: coarse)")
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=20261230)
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    out = ResultsFile("report_certify", title="Certificates of a report: cost per pair "
                      "(issue 46, item 5)",
                      claim="reports")  # the header's start: date and load now
    metrics = args.metric or ["poincare-slab", "carlike", "panda-pole"]
    presets = args.preset or ["coarse"]
    rows, summary = [], []
    for name in metrics:
        m = finsler.get_metric(name)
        pairs = finsler.sample_pairs(m, args.pairs, args.seed)
        paths = [solvers.solve_geodesic(m, s, g).points for s, g in pairs]
        for preset in presets:
            cpu = []
            for i, (s, g) in enumerate(pairs):
                c0, w0 = time.process_time(), time.perf_counter()
                res = solvers.certify(m, s, g, preset, path=paths[i])
                c1, w1 = time.process_time() - c0, time.perf_counter() - w0
                r = certificate_row(res)
                cpu.append(c1)
                work = ", ".join(f"{k} {v}" for k, v in r["work"].items())
                rows.append([name, preset, i, f"{r['lower']:.6g}", f"{r['upper']:.6g}",
                             f"{r['gap']:.2e}", r["status"], r["stopped_by"], work,
                             f"{c1:.1f}", f"{w1:.1f}"])
                print(*rows[-1], sep=" | ", flush=True)
            summary.append(f"- {name}, preset {preset}: median {statistics.median(cpu):.1f} s "
                           f"CPU per pair, max {max(cpu):.1f} s ({len(cpu)} pairs)")
    table = markdown_table(["metric", "preset", "pair", "lower", "upper", "gap", "status",
                            "stopped by", "work", "CPU s", "wall s"], rows)
    print("\n".join(summary))
    if args.no_write:
        return
    out.add(f"{args.pairs} pairs `finsler.sample_pairs(metric, {args.pairs}, {args.seed})` "
            "per metric, solved by `solvers.solve_geodesic`, then `solvers.certify(metric, "
            "s, g, preset, path=the solved path)` as `geodesics report` does. CPU time is "
            "`time.process_time` of the certificate alone (the machine was shared with other "
            "agents: wall time is longer).", table, "\n".join(summary))
    print(out.write())


if __name__ == "__main__":
    main()
