"""Car-like through the batched interior point (issue 45, item 2) against IPOPT.

Two measurements on fresh car-like pairs (``finsler.sample_pairs(carlike, K, seed)``,
default seed 20261202, a seed no plan was tuned on), one thread (numpy; OMP/MKL/OPENBLAS
one thread), CPU time (``time.process_time``) next to wall time (the machine may be shared:
CPU is the figure to compare):

1. Same seeds, one solver each: the default plan's seed curves at ``--segments`` (no
   ladder, no polishing), every row solved by :func:`solvers.newton.interior.interior_energy`
   (all rows in one batch) and by IPOPT alone (:func:`solvers.transcription.energy_nlp`,
   one row at a time). Per pair: the lowest converged energy of each, how many rows
   the interior point converged, and how many converged rows ended more than 1e-6
   (relative) above / below IPOPT from the same seed.
2. The whole solve: ``solvers.solve_batch(carlike, pairs, segments, workers=1,
   method="newton", seeds=plan)`` (the batched path; ``plan``: the default car-like plan
   with the ladder ``--coarse`` x ``--factor`` and ``--top`` rows carried) against the
   default ``solve_batch`` (IPOPT). Per pair: energies, the relative difference, status,
   method of the answer (``ipopt`` where the batched result was finished by IPOPT) and
   the reported KKT residual; time per pair.
3. With ``--work``: where the interior point's work goes, on the default plan's seed rows
   at ``--segments`` (all rows of all pairs in one batch, as measurement 1): per seed
   family the rows, how many converged / stalled / ended at the iteration cap, their
   median iterations and their share of all row iterations (a row's iterations are what
   it costs: every iteration evaluates its segments once and solves its system once).
   With ``--before REV`` the same rows are first solved by ``solvers/newton/interior.py`` as
   committed at git revision ``REV`` (e.g. ``9d23a82``, before this session's speed-ups):
   CPU and wall of both, statuses and energies compared; measurement 2 likewise runs the
   whole solve first with that version of the interior point (``--default-plan``: the
   default car-like plan as it is, not rebuilt from ``--coarse/--factor/--top``).
4. With ``--truth N``: the batched solve on the first N pairs of the ground-truth set
   (``sample_pairs(carlike, 50, 20261201)``) against the best-known energies that
   ``benchmarks/ground_truth.py`` cached (``results/ground_truth_cache``).

Usage::

    python benchmarks/nonsmooth_newton.py [--pairs 4] [--segments 256] [--seed 20261202]
        [--coarse 32] [--factor 2] [--top 3] [--default-plan] [--skip-rows] [--skip-ipopt]
        [--skip-whole] [--work [--before REV]] [--truth 0] [--tag NAME] [--no-write]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from results_file import ResultsFile, markdown_table  # noqa: E402

import finsler  # noqa: E402
import solvers  # noqa: E402
from solvers.inputs import domain_scale  # noqa: E402
from solvers.newton.interior import interior_energy  # noqa: E402
from solvers.seeding.plans import SeedPlan, seed_batch  # noqa: E402
from solvers.status import NewtonStatus  # noqa: E402
from solvers.transcription import energy_nlp  # noqa: E402

RTOL = 1e-6


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def same_seeds(m: finsler.Metric, pairs: np.ndarray, n: int) -> tuple[str, str]:
    K = pairs.shape[0]
    names, curves = seed_batch(m, pairs[:, 0], pairs[:, 1], n, SeedPlan.default(m))
    S = len(names)
    rows = curves.reshape(K * S, n + 1, m.dim)
    w0, c0 = _clock()
    ip = interior_energy(m, rows, scale=domain_scale(m))
    w1, c1 = _clock()
    nlp = energy_nlp(m, n)
    e_ipopt, ok_ipopt = np.full(len(rows), np.inf), np.zeros(len(rows), bool)
    for i, r in enumerate(rows):
        pts, st, _, _ = nlp.solve(r)
        ok_ipopt[i] = st.converged
        e_ipopt[i] = float(np.sum(m.path_costs(pts[None], check=False) ** 2))
    w2, c2 = _clock()
    conv = ip.status == NewtonStatus.CONVERGED
    both = conv & ok_ipopt
    rel = (ip.energy - e_ipopt) / e_ipopt
    out = []
    for k in range(K):
        s = slice(k * S, (k + 1) * S)
        bi = np.min(np.where(conv[s], ip.energy[s], np.inf))
        bo = np.min(np.where(ok_ipopt[s], e_ipopt[s], np.inf))
        out.append([k, f"{bi:.10g}", f"{bo:.10g}", f"{(bi - bo) / bo:+.1e}",
                    f"{int(conv[s].sum())}/{S}", int(np.sum(both[s] & (rel[s] > RTOL))),
                    int(np.sum(both[s] & (rel[s] < -RTOL)))])
        print(*out[-1], flush=True)
    table = markdown_table(["pair", "interior point best", "IPOPT best", "relative",
                            "IP converged", "rows above IPOPT", "rows below IPOPT"], out)
    summary = (f"{K} pairs x {S} seed rows at {n} segments: interior point (one batch) "
               f"wall {(w1 - w0) / K:.2f} s, CPU {(c1 - c0) / K:.2f} s per pair, "
               f"iterations median {np.median(ip.iterations):.0f}, max "
               f"{int(ip.iterations.max())}; IPOPT (row by row) wall {(w2 - w1) / K:.2f} s, "
               f"CPU {(c2 - c1) / K:.2f} s per pair. Rows converged by both: "
               f"{int(both.sum())}, of which {int(np.sum(both & (np.abs(rel) <= RTOL)))} "
               f"equal to 1e-6.")
    print(table)
    print(summary)
    return table, summary


def _family(name: str) -> str:
    """A seed row's family: its name up to the first ``[``, ``#`` or sign/digit suffix."""
    for i, ch in enumerate(name):
        if ch in "[#+-" or ch.isdigit():
            return name[:i] or name
    return name


def _load_before(rev: str) -> object:
    """``solvers/newton/interior.py`` as committed at git revision ``rev``, loaded as its own
    module (``interior_before``): the reference for ``--before``."""
    import importlib.util
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    src = subprocess.run(["git", "show", f"{rev}:solvers/newton/interior.py"], cwd=root, check=True,
                         capture_output=True, text=True).stdout
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "interior_before.py"
        path.write_text(src)
        spec = importlib.util.spec_from_file_location("interior_before", path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod  # (its dataclasses look their module up there)
        spec.loader.exec_module(mod)
    return mod


def _before(m: finsler.Metric, rows: np.ndarray, rev: str) -> tuple[object, float, float]:
    """The interior point as committed at ``rev`` on ``rows`` -> (result, wall, CPU)."""
    mod = _load_before(rev)
    mod.interior_energy(m, rows[:1], scale=domain_scale(m))
    w0, c0 = _clock()
    res = mod.interior_energy(m, rows, scale=domain_scale(m))
    w1, c1 = _clock()
    return res, w1 - w0, c1 - c0


def work(m: finsler.Metric, pairs: np.ndarray, n: int, before: str = ""
         ) -> tuple[str, str]:
    K = pairs.shape[0]
    names, curves = seed_batch(m, pairs[:, 0], pairs[:, 1], n, SeedPlan.default(m))
    S = len(names)
    rows = curves.reshape(K * S, n + 1, m.dim)
    interior_energy(m, rows[:1], scale=domain_scale(m))  # CasADi functions built untimed
    if before:
        old, wb, cb = _before(m, rows, before)
    w0, c0 = _clock()
    ip = interior_energy(m, rows, scale=domain_scale(m))
    w1, c1 = _clock()
    fam = np.array([_family(x) for x in names] * K)
    it, stt = ip.iterations, ip.status
    total = int(it.sum())
    out = []
    for f in dict.fromkeys(fam):
        sel = fam == f
        out.append([f, int(sel.sum()), int(np.sum(stt[sel] == NewtonStatus.CONVERGED)),
                    int(np.sum(stt[sel] == NewtonStatus.STALLED)),
                    int(np.sum(stt[sel] == NewtonStatus.MAX_ITERATIONS)),
                    f"{np.median(it[sel]):.0f}", f"{it[sel].sum() / total:.0%}"])
        print(*out[-1], flush=True)
    capped = stt == NewtonStatus.MAX_ITERATIONS
    table = markdown_table(["seed family", "rows", "converged", "stalled", "at the cap",
                            "median iterations", "share of iterations"], out)
    summary = (f"{K} pairs x {S} seed rows at {n} segments (one batch): wall "
               f"{(w1 - w0) / K:.2f} s, CPU {(c1 - c0) / K:.2f} s per pair; {total} row "
               f"iterations, {int(capped.sum())}/{len(rows)} rows at the cap "
               f"({ip.iterations.max()}) taking {it[capped].sum() / total:.0%} of them; "
               f"converged rows' iterations median "
               f"{np.median(it[stt == NewtonStatus.CONVERGED]):.0f}.")
    if before:
        conv = stt == NewtonStatus.CONVERGED
        oconv = old.status == NewtonStatus.CONVERGED
        both = conv & oconv
        rel = np.abs(ip.energy[both] - old.energy[both]) / old.energy[both]
        best = np.array([np.min(np.where(conv[k * S:(k + 1) * S],
                                         ip.energy[k * S:(k + 1) * S], np.inf))
                         for k in range(K)])
        obest = np.array([np.min(np.where(oconv[k * S:(k + 1) * S],
                                          old.energy[k * S:(k + 1) * S], np.inf))
                          for k in range(K)])
        summary += (f" Before (`solvers/newton/interior.py` at {before}, the same rows in the same "
                    f"run): wall {wb / K:.2f} s, CPU "
                    f"{cb / K:.2f} s per pair, {int(old.iterations.sum())} row iterations; "
                    f"after/before CPU {(c1 - c0) / cb:.2f}. Status the same on "
                    f"{int(np.sum(stt == old.status))}/{len(rows)} rows; rows converged by "
                    f"both: {int(both.sum())}, energies equal to max relative difference "
                    f"{np.max(rel, initial=0.0):.1e}; each pair's lowest converged energy "
                    f"after/before - 1: max {np.max(best / obest - 1):+.1e}, min "
                    f"{np.min(best / obest - 1):+.1e}.")
    print(table)
    print(summary)
    return table, summary


def whole(m: finsler.Metric, pairs: np.ndarray, n: int, plan: SeedPlan, ipopt: bool,
          before: str = "") -> tuple[str, str]:
    K = pairs.shape[0]
    # the graph seeder is built once per metric and process (a fixed cost): build it
    # outside the timing, as a long-running process would have it
    from solvers.seeding.plans import graph_seeder
    graph_seeder(m)
    if before:  # the same solve with solvers/newton/interior.py as committed at ``before``
        import solvers.newton.driver as batched_mod

        current = batched_mod.interior_energy
        batched_mod.interior_energy = _load_before(before).interior_energy
        try:
            wb0, cb0 = _clock()
            old = solvers.solve_batch(m, pairs, segments=n, workers=1, method="newton",
                                      seeds=plan, progress=False)
            wb1, cb1 = _clock()
        finally:
            batched_mod.interior_energy = current
    w0, c0 = _clock()
    new = solvers.solve_batch(m, pairs, segments=n, workers=1, method="newton", seeds=plan,
                              progress=False)
    w1, c1 = _clock()
    ref = (solvers.solve_batch(m, pairs, segments=n, workers=1, progress=False)
           if ipopt else [None] * K)
    w2, c2 = _clock()
    rows, rels = [], []
    for k, (a, b) in enumerate(zip(new, ref, strict=True)):
        rel = (a.energy - b.energy) / b.energy if b is not None else float("nan")
        rels.append(rel)
        rows.append([k, f"{a.energy:.10g}", "-" if b is None else f"{b.energy:.10g}",
                     f"{rel:+.1e}", a.status.label, a.method, f"{a.residual:.1e}",
                     "-" if b is None else b.status.label])
        print(*rows[-1], flush=True)
    rels = np.asarray(rels)
    table = markdown_table(["pair", "batched energy", "IPOPT energy", "relative",
                            "batched status", "answer by", "KKT residual", "IPOPT status"],
                           rows)
    summary = (f"{K} pairs, {n} segments, plan: coarse {plan.coarse}, factor {plan.factor}, "
               f"top {plan.refine_top}, polish {plan.polish}: batched (method='newton') wall "
               f"{(w1 - w0) / K:.2f} s, CPU {(c1 - c0) / K:.2f} s per pair, "
               f"{sum(r.method == 'ipopt' for r in new)} answers finished by IPOPT")
    if before:
        eo = np.array([r.energy for r in old])
        en = np.array([r.energy for r in new])
        summary += (f". Before (`solvers/newton/interior.py` at {before}, the same pairs in "
                    f"the same "
                    f"run): wall {(wb1 - wb0) / K:.2f} s, CPU {(cb1 - cb0) / K:.2f} s per pair, "
                    f"after/before CPU {(c1 - c0) / (cb1 - cb0):.2f}; energies after/before - "
                    f"1: max {np.max(en / eo - 1):+.1e}, min {np.min(en / eo - 1):+.1e}; "
                    f"status the same on "
                    f"{sum(a.status == b.status for a, b in zip(new, old, strict=True))}/{K}")
    if ipopt:
        summary += (f"; IPOPT (default) wall {(w2 - w1) / K:.2f} s, CPU {(c2 - c1) / K:.2f} s "
                    f"per pair. Batched at or below IPOPT (1e-6 relative) on "
                    f"{int(np.sum(rels <= RTOL))}/{K} pairs, worst {np.max(rels):+.1e}, best "
                    f"{np.min(rels):+.1e}.")
    print(table)
    print(summary)
    return table, summary


def truth(m: finsler.Metric, k: int, n: int, plan: SeedPlan) -> tuple[str, str]:
    """The batched solve on the first ``k`` ground-truth pairs (``sample_pairs(carlike, 50,
    20261201)``) against the best-known energies cached by ``ground_truth.py``."""
    import ground_truth

    path = ground_truth.cache_path(m, 20261201, 50, n, 20)
    with np.load(path, allow_pickle=False) as z:
        best = np.asarray(z["energy"], float)[:k]
    pairs = np.asarray(finsler.sample_pairs(m, 50, 20261201))[:k]
    w0, c0 = _clock()
    res = solvers.solve_batch(m, pairs, segments=n, workers=1, method="newton", seeds=plan,
                              progress=False)
    w1, c1 = _clock()
    gap = np.array([r.energy for r in res]) / best - 1.0
    rows = [[i, f"{r.energy:.10g}", f"{best[i]:.10g}", f"{gap[i]:+.1e}", r.method,
             r.status.label] for i, r in enumerate(res)]
    table = markdown_table(["pair", "batched energy", "best known", "gap", "answer by",
                            "status"], rows)
    summary = (f"First {k} ground-truth pairs (`sample_pairs(carlike, 50, 20261201)`, best "
               f"known from `{path.name}`): {int(np.sum(gap <= 1e-4))}/{k} within 1e-4, "
               f"{int(np.sum(gap <= 1e-2))}/{k} within 1e-2, worst {np.max(gap):+.1e}; wall "
               f"{(w1 - w0) / k:.2f} s, CPU {(c1 - c0) / k:.2f} s per pair.")
    print(table)
    print(summary)
    return table, summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=4)
    ap.add_argument("--segments", type=int, default=256)
    ap.add_argument("--seed", type=int, default=20261202)
    ap.add_argument("--coarse", type=int, default=32)
    ap.add_argument("--factor", type=int, default=2)
    ap.add_argument("--top", type=int, default=3)
    ap.add_argument("--default-plan", action="store_true",
                    help="measurement 2 with the default car-like plan as it is (ignores "
                    "--coarse, --factor, --top)")
    ap.add_argument("--skip-rows", action="store_true", help="skip measurement 1")
    ap.add_argument("--skip-ipopt", action="store_true", help="measurement 2 without IPOPT")
    ap.add_argument("--skip-whole", action="store_true", help="skip measurement 2")
    ap.add_argument("--work", action="store_true",
                    help="where the interior point's work goes (measurement 3)")
    ap.add_argument("--before", default="", metavar="REV",
                    help="with --work and measurement 2: also time solvers/newton/interior.py as "
                    "committed at REV (git) on the same rows / pairs in the same run")
    ap.add_argument("--truth", type=int, default=0,
                    help="also solve the first N ground-truth pairs against the cache")
    ap.add_argument("--tag", default="", help="appended to the results file's name")
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args()
    m = finsler.get_metric("carlike")
    pairs = np.asarray(finsler.sample_pairs(m, a.pairs, a.seed))
    plan = SeedPlan.default(m) if a.default_plan else dataclasses.replace(
        SeedPlan.default(m), coarse=a.coarse, factor=a.factor, refine_top=a.top)
    out = ResultsFile("nonsmooth_newton" + (f"_{a.tag}" if a.tag else ""),
                      "Car-like: batched interior point against IPOPT",
                      claim="nonsmooth-newton")
    out.add(f"Pairs: `finsler.sample_pairs(carlike, {a.pairs}, {a.seed})`, "
            f"{a.segments} segments, one thread.")
    if not a.skip_rows:
        t, s = same_seeds(m, pairs, a.segments)
        out.add("## 1. The same seed rows, each solver alone", t, "", s)
    if not a.skip_whole:
        t, s = whole(m, pairs, a.segments, plan, not a.skip_ipopt, a.before)
        out.add("## 2. The whole solve", t, "", s)
    if a.work:
        t, s = work(m, pairs, a.segments, a.before)
        out.add("## 3. Where the interior point's work goes", t, "", s)
    if a.truth:
        t, s = truth(m, a.truth, a.segments, plan)
        out.add("## 4. Against the best known (ground truth cache)", t, "", s)
    if not a.no_write:
        out.write()


if __name__ == "__main__":
    main()
