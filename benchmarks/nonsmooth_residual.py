"""The optimality residual reported for a metric whose F is not smooth (issue 45, item 3):
the KKT residual of the reformulated (slack) problem against the energy's gradient that
results reported before, on fresh car-like pairs.

It solves K fresh pairs (``finsler.sample_pairs(carlike, K, seed)``, default seed
20261202: not a seed any plan was tuned on) with ``solvers.solve_batch(carlike, pairs,
segments=n, workers=1)`` on one thread (numpy, OMP/MKL/OPENBLAS one thread) and prints,
per pair: status, method, energy, the reported ``residual``
(:func:`solvers.newton.kkt.kkt_residual`), the energy's projected gradient
(:func:`solvers.newton.energy.energy_residual`, the measure reported before), and the CPU time
of the KKT residual of the path (``time.process_time``). Then the batch's wall and CPU
time per pair. The machine may be shared: CPU time is the figure to compare.

Usage::

    python benchmarks/nonsmooth_residual.py [--pairs 4] [--segments 256]
        [--seed 20261202] [--no-write]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from results_file import ResultsFile, markdown_table  # noqa: E402

import finsler  # noqa: E402
import solvers  # noqa: E402
from solvers.inputs import domain_scale  # noqa: E402
from solvers.newton.energy import energy_residual  # noqa: E402
from solvers.newton.kkt import kkt_residual  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=4)
    ap.add_argument("--segments", type=int, default=256)
    ap.add_argument("--seed", type=int, default=20261202)
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args()
    m = finsler.get_metric("carlike")
    pairs = finsler.sample_pairs(m, a.pairs, a.seed)
    scale = domain_scale(m)
    w0, c0 = time.perf_counter(), time.process_time()
    res = solvers.solve_batch(m, pairs, segments=a.segments, workers=1, progress=False)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    rows = []
    kkt, grad, tk = [], [], []
    for k, r in enumerate(res):
        t0 = time.process_time()
        mine = float(kkt_residual(m, r.points[None], scale)[0])
        tk.append(time.process_time() - t0)
        g = float(energy_residual(m, r.points[None], scale)[0])
        kkt.append(r.residual)
        grad.append(g)
        assert abs(mine - r.residual) <= 1e-9 * max(1.0, abs(mine)), (mine, r.residual)
        rows.append([k, r.status.label,
                     r.method, f"{r.energy:.10g}", f"{r.residual:.1e}", f"{g:.1e}",
                     f"{tk[-1] * 1e3:.1f}"])
        print(*rows[-1], flush=True)
    kkt_a, grad_a = np.asarray(kkt), np.asarray(grad)
    table = markdown_table(["pair", "status", "method", "energy", "residual (KKT)",
                            "energy gradient (before)", "KKT CPU ms"], rows)
    summary = (
        f"{a.pairs} pairs, {a.segments} segments, seed {a.seed}: solve_batch wall "
        f"{wall / a.pairs:.2f} s, CPU {cpu / a.pairs:.2f} s per pair (one thread; the "
        f"machine may be shared with other jobs: CPU is the figure to compare). "
        f"Reported residual (KKT of the slack problem): median {np.median(kkt_a):.1e}, "
        f"max {np.max(kkt_a):.1e}, {int(np.sum(kkt_a <= 1e-6))}/{a.pairs} at most 1e-6; "
        f"the energy's gradient at the same paths: median {np.median(grad_a):.1e}, max "
        f"{np.max(grad_a):.1e}. KKT residual CPU per path: median "
        f"{np.median(tk) * 1e3:.1f} ms.")
    print(table)
    print(summary)
    if not a.no_write:
        out = ResultsFile("nonsmooth_residual", "Car-like: the KKT residual reported "
                          "against the energy's gradient", claim="nonsmooth-newton")
        out.add("## Per pair", table, "", "## Summary", summary)
        out.write()


if __name__ == "__main__":
    main()
