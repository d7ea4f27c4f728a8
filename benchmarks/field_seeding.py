"""The lattice field behind the car-like seed plan: its build, a cold single solve, and many
goals from one start.

Three measurements, one thread, CPU time (``time.process_time``, children included where a
subprocess runs):

1. **The field** (`solvers.seeding.field.lattice_field` at the default plan's resolution): nodes,
   edges, moves kept, build time, and the median graph length over the true length on
   ``--pairs`` fresh pairs of a set whose best known energies are cached
   (``ground_truth.py``'s multistart); per pair the time of a route query.
2. **A cold solve** through the command line, ``geodesics solve --metric carlike --start
   ... --goal ...`` in a fresh process, ``--cold`` times (median; user + system CPU time
   of the child, its wall time).
3. **Many goals from one start**: ``--goals`` goals of ``sample_pairs(m, goals + 1,
   --seed)`` (each pair's goal) from the start of its first pair, in one
   ``solve_batch(m, pairs, segments=256, workers=1)``; CPU per goal, and the quality
   against a wide multistart of the same pairs (``ground_truth.multistart_plan``, cached in
   ``benchmarks/results/ground_truth_cache/``): pairs within 1e-4 and 1e-2 (relative
   energy) of the lower of the two.

Usage::

    python benchmarks/field_seeding.py [--seed 20261308] [--goals 100] [--cold 3]

Writes ``benchmarks/results/seed-plans/field_seeding-DATE.md``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from ground_truth import CACHE, multistart_method, multistart_plan  # noqa: E402
from results_file import ResultsFile, markdown_table  # noqa: E402

import finsler  # noqa: E402
import solvers  # noqa: E402
from finsler.spec import MetricSpec  # noqa: E402
from solvers.seeding.field import FieldSpec, lattice_field  # noqa: E402

TIGHT, LOOSE = 1e-4, 1e-2


def field_figures(m: finsler.Metric, plan: solvers.SeedPlan, pairs: np.ndarray,
                  lengths: np.ndarray) -> list[list[object]]:
    c0 = time.process_time()
    f = lattice_field(m, FieldSpec(resolution=plan.field_resolution))
    build = time.process_time() - c0
    ratios, t = [], []
    for (s, g), true in zip(pairs, lengths, strict=True):
        c1 = time.process_time()
        route = f.routes(s, g, plan.field_routes, plan.field_separation, plan.field_ratio)
        t.append(time.process_time() - c1)
        ratios.append(float(np.sum(m.segment_length(route[0][:-1], route[0][1:], 4)))
                      / true)
    nodes, edges = f.size
    return [["nodes / edges", f"{nodes} / {edges}"], ["moves kept", f.moves],
            ["build CPU", f"{build:.2f} s"],
            ["graph length / true length, median (range)",
             f"{np.median(ratios):.3f} ({min(ratios):.3f}-{max(ratios):.3f})"],
            ["route query CPU per pair, median", f"{1e3 * np.median(t):.1f} ms"]]


def cold_solve(pair: np.ndarray, repeats: int) -> list[list[object]]:
    exe = Path(sys.executable).with_name("geodesics")
    s, g = (",".join(f"{v:.6f}" for v in p) for p in pair)
    cmd = [str(exe), "solve", "--metric", "carlike", f"--start={s}", f"--goal={g}"]
    cpu, wall = [], []
    for _ in range(repeats):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, env={**os.environ})
        wall.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return [["command", "`" + " ".join(["geodesics", *cmd[1:]]) + "`"],
            ["CPU (user + system), median", f"{np.median(cpu):.2f} s "
             f"({', '.join(f'{c:.2f}' for c in cpu)})"],
            ["wall, median", f"{np.median(wall):.2f} s"]]


def one_start(m: finsler.Metric, seed: int, k: int) -> tuple[list[list[object]], dict]:
    drawn = finsler.sample_pairs(m, k + 1, seed)
    pairs = np.stack([np.repeat(drawn[:1, 0], k, 0), drawn[1:, 1]], 1)
    n = 2 ** m.task.depth
    key = json.dumps({"spec": MetricSpec.of(m).to_dict(), "one-start": seed, "K": k,
                      "N": n, "plan": repr(multistart_plan(m, 20))}, sort_keys=True)
    path = CACHE / f"{m.name}-onestart-{hashlib.sha256(key.encode()).hexdigest()[:12]}.npz"
    if path.exists():
        with np.load(path) as z:
            e_ms = z["energy"]
    else:
        e_ms = np.full(k, np.inf)
        for a in range(0, k, 10):
            rs = solvers.solve_batch(m, pairs[a:a + 10], segments=n,
                                     seeds=multistart_plan(m, 20), workers=1,
                                     progress=False, method=multistart_method(m))
            e_ms[a:a + 10] = [r.energy if r.converged else np.inf for r in rs]
            print(f"  multistart {min(a + 10, k)}/{k}", flush=True)
        np.savez(path, energy=e_ms)
    solvers.solve_batch(m, pairs[:1], segments=n, workers=1, progress=False)  # builds
    c0 = time.process_time()
    rs = solvers.solve_batch(m, pairs, segments=n, workers=1, progress=False)
    cpu = (time.process_time() - c0) / k
    e = np.array([r.energy if r.converged else np.inf for r in rs])
    best = np.minimum(e, e_ms)
    gap = e / best - 1.0
    rows = [["goals from one start", k], ["CPU per goal", f"{cpu:.3f} s"],
            ["within 1e-4 / 1e-2 of the best known", f"{int(np.sum(gap <= TIGHT))} / "
             f"{int(np.sum(gap <= LOOSE))}"], ["worst gap", f"{np.max(gap):.2e}"],
            ["below the multistart by more than 1e-4",
             int(np.sum(e < e_ms * (1 - TIGHT)))]]
    return rows, {"cpu": cpu, "gap": gap}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=20261308, help="fresh pairs' seed")
    ap.add_argument("--goals", type=int, default=100)
    ap.add_argument("--cold", type=int, default=3, help="cold CLI solves to time")
    ap.add_argument("--field-pairs-seed", type=int, default=20261307,
                    help="a pair set with a cached multistart (ground_truth.py)")
    args = ap.parse_args()
    m = finsler.get_metric("carlike")
    plan = solvers.SeedPlan.default(m)
    out = ResultsFile("field_seeding", title="The lattice field of the car-like plan",
                      claim="seed-plans")
    from ground_truth import cache_path

    cached = cache_path(m, args.field_pairs_seed, 100, 256, 20)
    pairs = finsler.sample_pairs(m, 100, args.field_pairs_seed)
    if cached.exists():
        with np.load(cached) as z:
            e = z["energy"]
        ok = np.isfinite(e)
        lengths = np.sqrt(256 * e[ok])  # sum C^2 = length**2 / n at equal spacing
        out.add(f"## The field (resolution {plan.field_resolution}; pairs of seed "
                f"{args.field_pairs_seed} with a cached multistart, true length = "
                "sqrt(256 x best energy))",
                markdown_table(["what", "figure"],
                               field_figures(m, plan, pairs[ok], lengths)))
    out.add("## A cold single solve (fresh process)",
            markdown_table(["what", "figure"], cold_solve(pairs[0], args.cold)))
    rows, _ = one_start(m, args.seed, args.goals)
    out.add(f"## Many goals from one start (seed {args.seed})",
            markdown_table(["what", "figure"], rows))
    print(out.write())


if __name__ == "__main__":
    main()
