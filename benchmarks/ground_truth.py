"""Ground truth on fresh pairs: the default exact solve against a wide multistart.

For every registered metric (``finsler.list_metrics()``; ``--metrics`` picks some) this
draws fresh pairs ``finsler.sample_pairs(metric, K, --seed)`` (a seed no default was tuned
on), solves them at the paper's size (``2**metric.task.depth`` segments) with the default
``solvers.solve_batch(metric, pairs, segments=N, workers=1)``, and compares each pair's
energy with the best known: the lowest of a wide multistart at the final size (every seed
family: the straight line, bulges at six amplitudes, ``--best-starts`` random curves, the
graph's three shortest distinct routes, the metric's own ``seed_curves`` families, six
polishing restarts; no ladder, no
early drop; solved by the batched Newton method where it covers the metric, else IPOPT)
and of the default itself. It reports per metric: pairs within 1e-4 and 1e-2 relative
energy of the best known, the worst gap, the time per pair of the default (wall and CPU,
``time.process_time``), which seed families found the winning basins (of the multistart
and of the default), and the pairs where the default beat the multistart (the best known
is not the truth there).

The best known also includes every other method's answers on the same pairs: each run
keeps its default's per-pair energies (and ``--best-also`` part files of another method) in
``benchmarks/results/ground_truth_cache/<metric>-answers-<key>.json``
(``answer_store.py``), labelled by the method and a digest of its seed plan; the best known
is the lowest of the default, the multistart and every other label's converged answers
(stored answers only lower it; the measured default is always solved afresh).

The multistart is the expensive part: its energies are cached in
``benchmarks/results/ground_truth_cache/<metric>-<key>.npz`` (keyed by the metric's
parameters, the seed, K, N and the multistart's settings), written after every chunk of
pairs, so an interrupted run resumes and a rerun only redoes the default.

Against finslerax (``--finslerax-python``, issue 45's Matsumoto bar): for the metrics
finslerax's worker knows (``matsumoto``, ``randers``; ``benchmarks/peer_workers.py``, its
venv as ``benchmarks/peers.py``'s docstring says), finslerax 1.1's Gauss-Newton batched
with ``jax.vmap`` over the same pairs at the same size in the same run, one thread,
compiled first (compile time reported apart), its energies (the project's ``F``) against
the same best known; the default's time is then the median of ``--repeats`` runs, as is
finslerax's.

Usage::

    python benchmarks/ground_truth.py [--metrics carlike,panda-pole] [--pairs 100]
        [--seed 20261201] [--best-starts 20] [--chunk 5]
        [--finslerax-python PEERS/finslerax/bin/python] [--repeats 3]

Writes ``benchmarks/results/exact-solves/ground_truth-DATE.md`` (``results_file.py``).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")  # one thread, before numpy loads its BLAS

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import answer_store  # noqa: E402
import numpy as np  # noqa: E402
from results_file import RESULTS, ResultsFile, markdown_table  # noqa: E402

import finsler  # noqa: E402
from finsler.spec import MetricSpec  # noqa: E402
from solvers import SeedPlan, solve_batch  # noqa: E402
from solvers.newton.driver import covers  # noqa: E402
from solvers.seeding.plans import seed_family  # noqa: E402

CACHE = RESULTS / "ground_truth_cache"
TIGHT, LOOSE = 1e-4, 1e-2


def multistart_plan(metric: finsler.Metric, starts: int) -> SeedPlan:
    """Every seed family at the final size (three graph routes), ``starts`` random
    curves, six polishing restarts, nothing dropped."""
    return SeedPlan(bulges=(0.1, 0.2, 0.3, 0.45, 0.6, 0.8), random=starts, graph=True,
                    routes=3, seed=7, coarse=None, polish=6, polish_scale=0.05,
                    drop_after=0, own=True)


def cache_path(metric: finsler.Metric, seed: int, k: int, n: int, starts: int) -> Path:
    spec = MetricSpec.of(metric).to_dict()
    key = json.dumps({"spec": spec, "seed": seed, "K": k, "N": n, "starts": starts,
                      "plan": repr(multistart_plan(metric, starts))}, sort_keys=True)
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    return CACHE / f"{metric.name}-{digest}.npz"


def multistart_method(metric: finsler.Metric) -> str:
    """The multistart's solver: the batched Newton method where it covers a smooth ``F``,
    else IPOPT (also where the default is the batched interior point, so that the best
    known stays a second method's answer; the cache key does not depend on it)."""
    return "newton" if covers(metric) else "ipopt"


def best_known(metric: finsler.Metric, pairs: np.ndarray, n: int, starts: int, seed: int,
               chunk: int, first: int | None = None) -> dict[str, np.ndarray]:
    """The multistart's energy per pair and the families that reached it (within 1e-4),
    resumed from and saved to the cache after every chunk; ``first``: only the first so
    many pairs (the cache stays that of all ``pairs``)."""
    first = len(pairs) if first is None else first
    path = cache_path(metric, seed, len(pairs), n, starts)
    fields = ("energy", "converged", "families", "best_seed", "cpu")
    done: dict[str, list] = {f: [] for f in fields}
    if path.exists():
        with np.load(path, allow_pickle=False) as z:
            done = {f: list(z[f]) for f in fields if f in z}
        if "converged" not in done:  # an older cache: NaN for what did not converge
            done["converged"] = list(np.isfinite(np.asarray(done["energy"], float)))
    plan = multistart_plan(metric, starts)
    while len(done["energy"]) < first:
        a = len(done["energy"])
        part = pairs[a:a + chunk]
        c0 = time.process_time()
        rs = solve_batch(metric, part, segments=n, seeds=plan, workers=1, progress=False,
                         method=multistart_method(metric))
        cpu = (time.process_time() - c0) / len(part)
        for r in rs:
            e = r.energy
            fams = sorted({fam for fam, d in r.seed_families.items()
                           if d["best_energy"] is not None
                           and d["best_energy"] <= e * (1.0 + TIGHT)})
            done["energy"].append(e)
            done["converged"].append(bool(r.converged))
            done["families"].append(",".join(fams))
            done["best_seed"].append(r.best_seed)
            done["cpu"].append(cpu)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, energy=np.asarray(done["energy"], float),
                 converged=np.asarray(done["converged"], bool),
                 families=np.asarray(done["families"], str),
                 best_seed=np.asarray(done["best_seed"], str),
                 cpu=np.asarray(done["cpu"], float))
        tmp.replace(path)
        print(f"  {metric.name}: best known {len(done['energy'])}/{len(pairs)} pairs "
              f"({cpu:.1f} s CPU per pair)", flush=True)
    return {k: np.asarray(v)[:first] for k, v in done.items()}


#: The metrics finslerax's worker (``peer_workers.py``) knows, and their parameters there.
FINSLERAX = {"matsumoto": lambda m: {"height": m.height},
             "randers": lambda m: {"wind": [m.wind_x, m.wind_y]}}


def finslerax_energies(m: finsler.Metric, pairs: np.ndarray, n: int, python: str | None,
                       repeats: int) -> dict[str, object]:
    """finslerax's Gauss-Newton under ``jax.vmap`` over ``pairs`` (one thread, compiled
    first): ``{"energy", "wall", "cpu", "setup", "note"}`` (times per pair; energies with
    the project's ``F``, infinite where a path is not finite or leaves the domain), or
    ``{"skipped": reason}``."""
    from peers import run_peer

    check = np.stack([pairs[:8, 0], np.random.default_rng(1).normal(size=(min(8, len(pairs)),
                                                                         m.dim))], 1)
    job = {"metric": m.name, "task": "throughput", "pairs": pairs.tolist(), "segments": n,
           "check": check.tolist(), "repeats": repeats, "params": FINSLERAX[m.name](m)}
    fx = run_peer("finslerax", python, job)
    if "skipped" in fx:
        return fx
    e = np.full(len(pairs), np.inf)
    if fx.get("paths") is not None:
        for k, p in enumerate(np.asarray(fx["paths"], dtype=np.float64)):
            if (np.all(np.isfinite(p)) and np.allclose(p[[0, -1]], pairs[k], atol=1e-9)
                    and np.all(m.domain.contains(p, tol=1e-9))):
                e[k] = float(np.sum(m.cost(p[:-1], p[1:], check=False) ** 2))
    truth = m.F(check[:, 0], check[:, 1])
    gap = float(np.max(np.abs(np.asarray(fx["check"]) - truth) / truth))
    k = len(pairs)
    return {"energy": e, "wall": fx["seconds"] / k, "cpu": fx["cpu"] / k,
            "setup": fx["setup"], "note": f"finslerax {fx['version']} (its F equals the "
            f"project's to {gap:.1e})" + (f"; error: {fx['error']}" if fx.get("error") else "")}


def default_records(m: finsler.Metric, pairs: np.ndarray, n: int, repeats: int,
                    method: str = "auto") -> dict[str, object]:
    """The default ``solve_batch(m, pairs, segments=n, workers=1)`` after one untimed pair
    (lowering, graph): per pair its energy (as returned: a status that is not converged
    is counted, not hidden), status, best seed, seeds tried and whether its seeds
    disagree; wall and CPU time per pair (median of ``repeats`` runs)."""
    # builds (lowering, NLPs of the ladder's sizes, the graph), not timed: the default
    # plan with its seeds cut to the straight line and the graph (a car-like pair costs
    # ~30 solves with every seed)
    warm = dataclasses.replace(SeedPlan.default(m), bulges=(), random=0, own=False,
                               restarts=0, polish=0, routes=1)
    if method != "auto":  # that method's own default plan
        warm = dataclasses.replace(SeedPlan.default(m, method), bulges=(), random=0,
                                   own=False, restarts=0, polish=0, routes=1)
    solve_batch(m, pairs[:1], segments=n, seeds=warm, workers=1, progress=False,
                method=method)
    times = []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        rs = solve_batch(m, pairs, segments=n, workers=1, progress=False, method=method)
        times.append(((time.perf_counter() - t0) / len(pairs),
                      (time.process_time() - c0) / len(pairs)))
    return {"energy": [float(r.energy) if np.isfinite(r.energy) else float("inf")
                       for r in rs],
            "converged": [bool(r.converged) for r in rs],
            "best_seed": [r.best_seed for r in rs],
            "seeds": [int(r.seeds_tried) for r in rs],
            "disagree": [r.alternative_gap is not None for r in rs],
            "before_warp": [_before_warp(r) for r in rs],
            "warp_iterations": [sum(lv["iterations"] for lv in r.levels if lv.get("warp"))
                                for r in rs],
            "iterations": [int(r.iterations) for r in rs],
            # the warp pass's wall time per pair where the levels carry it (the IPOPT
            # path's batched warp pass; the batched path's levels carry none)
            "warp_wall": [sum(lv.get("wall_time", 0.0) for lv in r.levels if lv.get("warp"))
                          for r in rs],
            "wall": float(np.median([t[0] for t in times])),
            "cpu": float(np.median([t[1] for t in times]))}


def _before_warp(r) -> float:
    """The lowest converged energy of a result's rows other than its warp rows
    (``SeedPlan.warps``): those are solved last and nothing else starts from them, so this
    is the answer of the same plan without them (``inf``: no such row converged)."""
    e = [v for name, v in r.seed_energies.items()
         if seed_family(name) != "warp" and np.isfinite(v)]
    return float(min(e)) if e else float("inf")


def read_part(path: Path, meta: dict) -> dict:
    """One ``--part`` record file of the pairs ``meta`` (metric, K, seed, N) describes, with
    its plan ``label`` (older parts carry none: one of their method and energies)."""
    d = json.loads(Path(path).read_text())
    if {f: d.get(f) for f in meta} != meta:
        raise SystemExit(f"--best-also: {path} is not a part of {meta}")
    if not d.get("label"):
        d["label"] = (f"{d.get('method', 'auto')}-parts-unlabelled-"
                      f"{answer_store._digest(d['energy'])}")
    return d


def merge_parts(paths: list[Path], name: str, k: int, seed: int, n: int, upto: int
                ) -> dict[str, object]:
    """The records of ``--part`` runs (JSON files) of one metric joined in pair order;
    they must cover pairs 0..upto-1 of the ``k`` drawn once, with the same seed and size.
    Times: the mean per pair over all parts (each part one process, one thread)."""
    parts = sorted((json.loads(Path(p).read_text()) for p in paths), key=lambda d: d["a"])
    want = {"metric": name, "K": k, "seed": seed, "N": n}
    a = 0
    for d in parts:
        if {f: d[f] for f in want} != want or d["a"] != a:
            raise SystemExit(f"--merge: parts must be {want} and cover pairs 0..{upto - 1} in "
                             f"order; got {({f: d[f] for f in want}, d['a'], d['b'])}")
        a = d["b"]
    if a != upto:
        raise SystemExit(f"--merge: the parts cover pairs 0..{a - 1}, not 0..{upto - 1}")
    out: dict[str, object] = {f: [x for d in parts for x in d[f]] for f in
                              ("energy", "converged", "best_seed", "seeds", "disagree")}
    # absent from older parts
    for f in ("before_warp", "warp_iterations", "iterations", "warp_wall"):
        if all(f in d for d in parts):
            out[f] = [x for d in parts for x in d[f]]
    # the label of the plan the parts ran (answer_store.plan_label); parts of older runs
    # carry none: then one of their method and energies, never a current plan's
    labels = {d.get("label") for d in parts}
    out["label"] = (labels.pop() if len(labels) == 1 and None not in labels else
                    f"{parts[0].get('method', 'auto')}-parts-unlabelled-"
                    f"{answer_store._digest(out['energy'])}")
    for t in ("wall", "cpu"):
        out[t] = sum(d[t] * (d["b"] - d["a"]) for d in parts) / upto
    return out


def run_metric(name: str, k: int, seed: int, starts: int, chunk: int, repeats: int = 1,
               finslerax: str | None = None, parts: list[Path] | None = None,
               first: int | None = None, method: str = "auto",
               also: list[Path] | None = None) -> dict[str, object]:
    m = finsler.get_metric(name)
    n = 2 ** m.task.depth
    drawn = finsler.sample_pairs(m, k, seed)
    best = best_known(m, drawn, n, starts, seed, chunk, first)
    pairs = drawn[:first]
    if first is not None:
        k = first
    print(f"{name}: {k} pairs, {n} segments", flush=True)
    rec = (merge_parts(parts, name, len(drawn), seed, n, k) if parts
           else default_records(m, pairs, n, repeats, method))
    wall, cpu = rec["wall"], rec["cpu"]
    e_def = np.asarray(rec["energy"], dtype=np.float64)
    e_ms = np.where(np.isfinite(best["energy"]), best["energy"], np.inf)
    e_best = np.minimum(e_def, e_ms)
    # every method's answers on these pairs are kept (answer_store); the best known is the
    # lowest of the default, the multistart and every other stored label, so a default is
    # not measured against one solver alone, and answers of earlier runs are not lost
    spath = answer_store.store_path(m, seed, len(drawn), n)
    meta = {"metric": name, "seed": seed, "K": len(drawn), "N": n}
    for path in also or ():  # --best-also: another method's parts join the store
        o = read_part(path, meta)
        answer_store.record(spath, o["label"], o["energy"], o["converged"], meta, o["a"],
                            source=f"--best-also {Path(path).name}")
    label = rec.get("label") or answer_store.plan_label(m, method)
    answer_store.record(spath, label, e_def, rec["converged"], meta)
    others = answer_store.stored(answer_store.load(spath), k, exclude=label)
    other = None
    if others:
        e_st = np.min(np.stack(list(others.values())), axis=0)
        other = {"beat": int(np.sum(e_st < e_best * (1.0 - TIGHT))), "file": spath.name,
                 "labels": {}}
        e_best = np.minimum(e_best, e_st)
        pairs_of = [("multistart", e_ms), *others.items()]
        pairs_of += [(f"the lower of the default and {lb}", np.minimum(e_def, e))
                     for lb, e in others.items()]
        for what, e in pairs_of:
            g = e / e_best - 1.0
            other["labels"][what] = (int(np.sum(g <= TIGHT)), int(np.sum(g <= LOOSE)),
                                     float(np.max(g)))
    peer = None
    if finslerax is not None and name in FINSLERAX:
        peer = finslerax_energies(m, pairs, n, finslerax, repeats)
        if "energy" in peer:
            e_best = np.minimum(e_best, peer["energy"])
            g = peer["energy"] / e_best - 1.0
            peer.update(within_tight=int(np.sum(g <= TIGHT)),
                        within_loose=int(np.sum(g <= LOOSE)), above_1e3=int(np.sum(g > 1e-3)),
                        worst_gap=float(np.max(g)), failed=int(np.sum(~np.isfinite(g))))
    gap = e_def / e_best - 1.0
    beat = int(np.sum(e_def < e_ms * (1.0 - TIGHT)))
    win_ms: dict[str, int] = {}
    for fams in best["families"]:
        for f in str(fams).split(","):
            if f:
                win_ms[f] = win_ms.get(f, 0) + 1
    win_def: dict[str, int] = {}
    for b, g in zip(rec["best_seed"], gap, strict=True):
        if g <= TIGHT:
            f = seed_family(b)
            win_def[f] = win_def.get(f, 0) + 1
    warp = None
    if "before_warp" in rec and np.sum(rec.get("warp_iterations", [0])) > 0:
        # the same run without its warp rows: the rows before them are unchanged by them
        e_bw = np.asarray(rec["before_warp"], dtype=np.float64)
        g_bw = e_bw / e_best - 1.0
        warp = {"within_tight": int(np.sum(g_bw <= TIGHT)),
                "within_loose": int(np.sum(g_bw <= LOOSE)), "worst_gap": float(np.max(g_bw)),
                "lowered": int(np.sum(e_def < e_bw * (1.0 - TIGHT))),
                "share": float(np.sum(rec["warp_iterations"]) / np.sum(rec["iterations"])),
                "wall": float(np.mean(rec.get("warp_wall", [0.0])))}
    worst = int(np.argmax(gap))
    return {"warp": warp,
        "metric": name, "K": k, "N": n, "within_tight": int(np.sum(gap <= TIGHT)),
        "within_loose": int(np.sum(gap <= LOOSE)), "worst_gap": float(gap[worst]),
        "worst_pair": worst, "wall": wall, "cpu": cpu, "best_cpu": float(np.mean(best["cpu"])),
        "beat": beat, "not_converged": int(np.sum(~np.asarray(rec["converged"], bool))),
        "ms_not_converged": int(np.sum(~best["converged"])),
        "families_multistart": win_ms, "families_default": win_def,
        "seeds_default": float(np.mean(rec["seeds"])),
        "disagree": int(np.sum(rec["disagree"])), "gaps": gap, "peer": peer,
        "above_1e3": int(np.sum(gap > 1e-3)), "parts": len(parts or ()), "other": other,
    }


def _fmt(d: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(d.items(), key=lambda kv: -kv[1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--metrics", default="all",
                    help="comma-separated registered names, or 'all' (default)")
    ap.add_argument("--pairs", type=int, default=100, help="K fresh pairs per metric")
    ap.add_argument("--seed", type=int, default=20261201,
                    help="seed of the fresh pairs (never used for tuning)")
    ap.add_argument("--best-starts", type=int, default=20,
                    help="random starts of the best-known multistart")
    ap.add_argument("--pairs-for", action="append", default=[], metavar="NAME=K",
                    help="K pairs for one metric (repeatable), e.g. carlike=20")
    ap.add_argument("--chunk", type=int, default=5, help="pairs per cached chunk")
    ap.add_argument("--repeats", type=int, default=1,
                    help="timed runs of the default (and of finslerax); the median is kept")
    ap.add_argument("--finslerax-python", default=os.environ.get("FINSLERAX_PYTHON"),
                    help="python of a venv with finslerax 1.1 and jax[cpu] (see "
                         "benchmarks/peers.py): compare on matsumoto and randers; default "
                         "$FINSLERAX_PYTHON, none: no comparison")
    ap.add_argument("--part", metavar="A:B",
                    help="only the default on pairs A..B-1 of one metric, its per-pair "
                         "records written to --json (no best known, no results file): "
                         "parts run as separate processes, then --merge")
    ap.add_argument("--json", type=Path, help="where --part writes its records")
    ap.add_argument("--first", type=int, metavar="N",
                    help="only the first N of the K pairs drawn (one metric; the same "
                         "pairs as in a run on all K, the cache that of K)")
    ap.add_argument("--merge", type=Path, nargs="+", metavar="PART.json",
                    help="the table of one metric from --part records (covering all K "
                         "pairs) against the best known, instead of solving the default")
    ap.add_argument("--best-also", type=Path, nargs="+", metavar="PART.json",
                    help="--part records of another method on the same pairs, kept in the "
                         "answer store (answer_store.py), whose energies join the best known "
                         "(e.g. car-like's IPOPT default and its opt-in interior point)")
    ap.add_argument("--method", choices=("auto", "newton", "ipopt"), default="auto",
                    help="the method of the solve measured (default auto: the default "
                         "solve; newton: e.g. car-like's opt-in batched interior point)")
    args = ap.parse_args()
    if args.repeats < 1:
        raise SystemExit("--repeats must be at least 1")
    names = finsler.list_metrics() if args.metrics == "all" else args.metrics.split(",")
    for nm in names:
        finsler.get_metric(nm)  # an unknown name fails before any work
    count = dict.fromkeys(names, args.pairs)
    for item in args.pairs_for:
        nm, _, k = item.partition("=")
        if nm not in count or not k.isdigit():
            raise SystemExit(f"--pairs-for wants NAME=K with NAME one of {names}, got {item!r}")
        count[nm] = int(k)
    if min(count.values()) < 1:
        raise SystemExit("--pairs must be at least 1")
    if (args.part or args.merge or args.first or args.best_also) and len(names) != 1:
        raise SystemExit("--part, --merge, --first and --best-also take one metric "
                         "(--metrics NAME)")
    if args.first is not None and not 1 <= args.first <= count[names[0]]:
        raise SystemExit(f"--first must be between 1 and K = {count[names[0]]}")
    if args.part:
        a, _, b = args.part.partition(":")
        k = count[names[0]]
        if not (a.isdigit() and b.isdigit() and 0 <= int(a) < int(b) <= k) or not args.json:
            raise SystemExit(f"--part wants A:B with 0 <= A < B <= {k}, and --json OUT")
        m = finsler.get_metric(names[0])
        n = 2 ** m.task.depth
        rec = default_records(m, finsler.sample_pairs(m, k, args.seed)[int(a):int(b)], n,
                              args.repeats, args.method)
        rec.update(metric=m.name, K=k, seed=args.seed, N=n, a=int(a), b=int(b),
                   method=args.method, label=answer_store.plan_label(m, args.method))
        finsler.atomic_write_text(args.json, json.dumps(rec), "--json")
        print(f"{m.name} pairs {a}..{int(b) - 1}: {rec['cpu']:.2f} s CPU per pair", flush=True)
        return
    out = ResultsFile("ground_truth", title="Ground truth: the default exact solve against "
                      "a wide multistart on fresh pairs", claim="exact-solves")
    out.add(f"Fresh pairs `finsler.sample_pairs(metric, K, {args.seed})` at "
            "`2**task.depth` segments; default: `solve_batch(metric, pairs, segments=N, "
            f"workers=1{'' if args.method == 'auto' else f', method={args.method!r}'})`; "
            "best known: the lower of the default and a multistart at the "
            f"final size (every seed family, {args.best_starts} random starts, 6 polishing "
            "restarts, no ladder, no drop; batched Newton where it covers the metric, else "
            "IPOPT). Gap: relative discrete energy above the best known; a result whose "
            "status is not converged is counted as such, its energy still compared. "
            "Times: the "
            "default's per pair, one process (the machine is shared with other jobs: CPU "
            "time is the steadier figure).")
    rows, notes, peer_rows, peer_notes = [], [], [], []
    for nm in names:
        r = run_metric(nm, count[nm], args.seed, args.best_starts, args.chunk, args.repeats,
                       args.finslerax_python, args.merge, args.first, args.method,
                       args.best_also)
        if r["peer"] is not None:
            pr = r["peer"]
            if "skipped" in pr:
                peer_notes.append(f"- {nm}: finslerax skipped: {pr['skipped']}")
            else:
                peer_rows.append([nm, r["K"], r["N"], "project solve_batch (default)",
                                  f"{1e3 * r['wall']:.1f}", f"{1e3 * r['cpu']:.1f}", "-",
                                  f"{r['within_tight']}/{r['K']}", r["above_1e3"],
                                  r["not_converged"], f"{r['worst_gap']:.2e}"])
                peer_rows.append([nm, r["K"], r["N"], "finslerax GaussNewton, jax.vmap",
                                  f"{1e3 * pr['wall']:.1f}", f"{1e3 * pr['cpu']:.1f}",
                                  f"{pr['setup']:.1f}", f"{pr['within_tight']}/{r['K']}",
                                  pr["above_1e3"], pr["failed"], f"{pr['worst_gap']:.2e}"])
                peer_notes.append(f"- {nm}: {pr['note']}")
                print(markdown_table(PEER_HEAD, peer_rows[-2:]), flush=True)
        rows.append([r["metric"], r["K"], r["N"], f"{r['within_tight']}/{r['K']}",
                     f"{r['within_loose']}/{r['K']}", f"{r['worst_gap']:.2e}",
                     f"{1e3 * r['wall']:.1f}", f"{1e3 * r['cpu']:.1f}", r["beat"],
                     f"{r['not_converged']} / {r['ms_not_converged']}",
                     f"{r['seeds_default']:.0f}", r["disagree"], f"{r['best_cpu']:.1f}"])
        notes.append(f"- {nm}: winning basins found by (multistart, pairs per family) "
                     f"{_fmt(r['families_multistart'])}; by the default (family of its "
                     f"best seed on pairs within 1e-4) {_fmt(r['families_default'])}; worst "
                     f"pair {r['worst_pair']}; gaps above 1e-4 at pairs "
                     f"{np.flatnonzero(r['gaps'] > TIGHT).tolist()}"
                     + (f"; the default ran as {r['parts']} processes of one thread each "
                        "(`--part`, then `--merge`), its times the mean per pair over them"
                        if r["parts"] else "")
                     + (f"; the first {r['K']} of `sample_pairs(metric, {count[nm]}, "
                        f"{args.seed})` (`--first`)" if args.first else ""))
        if r.get("warp") is not None:
            w = r["warp"]
            notes.append(
                f"- {nm}: the same run without its warp rows (`SeedPlan.warps`, solved last, "
                "so the rows before them are those of the plan without warps): within 1e-4 "
                f"{w['within_tight']}/{r['K']}, within 1e-2 {w['within_loose']}/{r['K']}, "
                f"worst {w['worst_gap']:.2e}; the warp rows lowered {w['lowered']} pairs by "
                "more than 1e-4, "
                + (f"in {w['wall']:.2f} s of wall time per pair (the warp pass, batched)"
                   if w.get("wall") else
                   f"at {100 * w['share']:.0f} % of the default's row iterations"))
        if r["other"] is not None:
            o = r["other"]
            each = "; ".join(f"{lb} {t[0]}/{r['K']} (within 1e-2 {t[1]}, worst {t[2]:.2e})"
                             for lb, t in o["labels"].items())
            notes.append(
                f"- {nm}: the best known also includes the stored answers of other methods "
                f"or plans on the same pairs (`ground_truth_cache/{o['file']}`, "
                "benchmarks/answer_store.py), lower than both the default and the "
                f"multistart on {o['beat']} pairs; against it, within 1e-4: {each}")
        print(markdown_table(["metric", "K", "N", "within 1e-4", "within 1e-2", "worst gap",
                              "wall ms/pair", "CPU ms/pair", "default beat multistart",
                              "not converged (default / multistart)", "seeds", "seeds disagree",
                              "multistart CPU s/pair"], rows[-1:]), flush=True)
        print(notes[-1], flush=True)
    out.add(markdown_table(["metric", "K", "N", "within 1e-4", "within 1e-2", "worst gap",
                            "wall ms/pair", "CPU ms/pair", "default beat multistart",
                            "not converged (default / multistart)", "seeds", "seeds disagree",
                            "multistart CPU s/pair"], rows))
    out.add("Which seed families found the winning basins:", "\n".join(notes))
    if peer_rows or peer_notes:
        out.add(f"Against finslerax in the same run (the same pairs and size, one thread; "
                f"times the median of {args.repeats} run(s); finslerax compiled first, "
                "'setup'; the best known here includes finslerax's paths; a failure: a "
                "path not finite, off its pair or outside the domain):",
                markdown_table(PEER_HEAD, peer_rows) if peer_rows else "",
                "\n".join(peer_notes))
    out.write()


PEER_HEAD = ["metric", "K", "N", "method", "wall ms/pair", "CPU ms/pair", "setup s",
             "within 1e-4", "above 1e-3", "not converged / failed", "worst gap"]


if __name__ == "__main__":
    main()
