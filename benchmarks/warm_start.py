"""Learned warm starts inside the batched solve (issue 47, item 5): time and optima of
``geodesics solve --pairs P --warm-start ENV`` against the same command without it.

For each task metric (``matsumoto`` n=64, ``carlike`` n=256, ``panda-pole`` n=32) on K
fresh pairs (``finsler.sample_pairs(m, K, seed)``, default seed 20261130: not a seed any
plan or policy was tuned on) it runs the command line as whole processes, as a user
would, one after the other:

* default: ``geodesics solve --metric M --pairs P --segments n --no-progress --out D.json``
  (the global seed plan, batched Newton or IPOPT as ``--solver auto`` picks);
* warm: the same with ``--warm-start M`` (the shipped policy): the policy's path of each
  pair is one more start in the same batch, beside the global seeds.

Per command: wall time (``time.perf_counter``) and CPU time (the child's user + system,
``resource.getrusage(RUSAGE_CHILDREN)``: the interpreter's start, every import -- torch and
the policy for the warm start --, the solve), the median over ``--repeats`` runs (default
1); the first run of each pair of commands is preceded by an untimed ``geodesics
--help`` so every run finds the file cache warm. Per pair, from the JSON of both: the
warm start's energy against the default's, relative, counted worse above 1e-9 and 1e-6,
better below -1e-6, and the largest gap. With ``--old`` it also solves the pairs the way
``--warm-start`` did before issue 47 (the learned path alone, no global seeds:
``solvers.solve_batch(..., initial_paths=paths, global_seeds=False)``, in this process) and
counts the pairs where that ended worse than the default: the pairs where a warm start
*could* be worse. With ``--split`` it times, in this process (``time.process_time``, one
thread), the parts of the warm start's cost: importing learn and torch, loading the policy
and generating the K paths, and the batched solve with the learned rows against without
(after an untimed solve of one pair that builds and caches the metric's functions).

Usage::

    python benchmarks/warm_start.py [--pairs 100] [--metrics matsumoto,carlike,panda-pole]
        [--seed 20261130] [--repeats 1] [--old] [--split] [--no-write]

Pass ``--pairs`` per task as ``--pairs carlike=20`` (repeatable) to shorten a slow task.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from results_file import ResultsFile, markdown_table

import finsler

TASKS = {"matsumoto": 64, "carlike": 256, "panda-pole": 32}
#: Relative energy gaps (warm minus default, over default) counted as worse.
WORSE = (1e-9, 1e-6)
SEED = 20261130


def geodesics() -> list[str]:
    script = Path(sys.executable).with_name("geodesics")
    return [str(script)] if script.exists() else [sys.executable, "-m", "validation.cli"]


def timed(cmd: list[str]) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of one process running ``cmd`` (its output discarded;
    a failure raises with its stderr)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {done.returncode}: {done.stderr[-500:]}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def energies(path: Path) -> np.ndarray:
    return np.array([r["energy"] for r in json.loads(path.read_text())["results"]])


def old_energies(name: str, pairs: np.ndarray, n: int) -> np.ndarray:
    """The energies of the retired ``--warm-start`` (learned path alone)."""
    import torch

    import solvers
    from learn.runs import warm_start_paths

    torch.set_num_threads(1)
    m = finsler.get_metric(name)
    paths, _ = warm_start_paths(name, m, pairs)
    res = solvers.solve_batch(m, pairs, n, workers=1, progress=False, initial_paths=paths,
                              global_seeds=False)
    return np.array([r.energy for r in res])


def split_costs(name: str, pairs: np.ndarray, n: int) -> dict[str, float]:
    """CPU seconds of the warm start's parts, in this process: import of learn (torch),
    policy load + generation, and the solve with and without the learned rows (after an
    untimed solve of one pair that builds and caches the metric's functions)."""
    t0 = time.process_time()
    import torch

    import solvers
    from learn.runs import warm_start_paths

    torch.set_num_threads(1)
    t1 = time.process_time()
    m = finsler.get_metric(name)
    paths, _ = warm_start_paths(name, m, pairs)
    t2 = time.process_time()
    solvers.solve_batch(m, pairs[:1], n, minmax=True, workers=1, progress=False,
                        initial_paths=paths[:1])
    t3 = time.process_time()
    solvers.solve_batch(m, pairs, n, minmax=True, workers=1, progress=False)
    t4 = time.process_time()
    solvers.solve_batch(m, pairs, n, minmax=True, workers=1, progress=False,
                        initial_paths=paths)
    t5 = time.process_time()
    return {"import": t1 - t0, "policy": t2 - t1, "solve_default": t4 - t3,
            "solve_warm": t5 - t4}


def run_task(name: str, k: int, seed: int, repeats: int, old: bool, folder: Path,
             split: bool = False) -> dict:
    m = finsler.get_metric(name)
    n = TASKS[name]
    pairs = finsler.sample_pairs(m, k, seed)
    pfile = folder / f"{name}-pairs.npy"
    np.save(pfile, pairs)
    base = [*geodesics(), "solve", "--metric", name, "--pairs", str(pfile), "--segments",
            str(n), "--no-progress"]
    cmds = {"default": [*base, "--out", str(folder / f"{name}-default.json")],
            "warm": [*base, "--out", str(folder / f"{name}-warm.json"), "--warm-start", name]}
    times: dict[str, list[tuple[float, float]]] = {key: [] for key in cmds}
    for _ in range(repeats):
        timed([*geodesics(), "--help"])
        for key, cmd in cmds.items():
            times[key].append(timed(cmd))
            print(f"  {name} {key}: CPU {times[key][-1][0]:.2f} s, wall "
                  f"{times[key][-1][1]:.2f} s", flush=True)
    e_def = energies(folder / f"{name}-default.json")
    e_warm = energies(folder / f"{name}-warm.json")
    rel = (e_warm - e_def) / e_def
    out = {
        "metric": name, "segments": n, "pairs": k, "seed": seed,
        "cpu": {key: statistics.median(c for c, _ in v) for key, v in times.items()},
        "wall": {key: statistics.median(w for _, w in v) for key, v in times.items()},
        "worse": {f"{t:g}": int(np.sum(rel > t)) for t in WORSE},
        "better": int(np.sum(rel < -1e-6)),
        "largest_gap": float(rel.max()),
        "worse_pairs": [int(i) for i in np.flatnonzero(rel > WORSE[0])],
    }
    if split:
        out["split"] = split_costs(name, pairs, n)
    if old:
        rel_old = (old_energies(name, pairs, n) - e_def) / e_def
        out["old_worse"] = {f"{t:g}": int(np.sum(rel_old > t)) for t in WORSE}
        out["old_largest_gap"] = float(rel_old.max())
        out["old_worse_pairs"] = [int(i) for i in np.flatnonzero(rel_old > 1e-6)]
    return out


def _parse_pairs(items: list[str]) -> tuple[int, dict[str, int]]:
    default, per = 100, {}
    for it in items:
        name, sep, val = it.partition("=")
        if sep:
            per[name] = int(val)
        else:
            default = int(it)
    return default, per


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", action="append", default=[],
                    help="pairs per task (N, or TASK=N; repeatable), default 100")
    ap.add_argument("--metrics", default=",".join(TASKS))
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--old", action="store_true",
                    help="also count where the retired warm start (learned path alone) was "
                         "worse than the default")
    ap.add_argument("--split", action="store_true",
                    help="also time the parts of the warm start in this process")
    ap.add_argument("--no-write", action="store_true", help="Print only; write no file.")
    args = ap.parse_args()
    default, per = _parse_pairs(args.pairs)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in [t.strip() for t in args.metrics.split(",") if t.strip()]:
            rows.append(run_task(name, per.get(name, default), args.seed, args.repeats,
                                 args.old, Path(tmp), args.split))
            print(json.dumps(rows[-1]), flush=True)
    head = ["metric (n)", "pairs (seed)", "CPU default (s)", "CPU --warm-start (s)",
            "wall default (s)", "wall --warm-start (s)", "CPU ratio", "worse > 1e-9",
            "worse > 1e-6", "better < -1e-6", "largest relative gap"]
    table = [[f"{r['metric']} ({r['segments']})", f"{r['pairs']} ({r['seed']})",
              f"{r['cpu']['default']:.2f}", f"{r['cpu']['warm']:.2f}",
              f"{r['wall']['default']:.2f}", f"{r['wall']['warm']:.2f}",
              f"{r['cpu']['warm'] / r['cpu']['default']:.2f}", r["worse"]["1e-09"],
              r["worse"]["1e-06"], r["better"], f"{r['largest_gap']:.2e}"] for r in rows]
    res = ResultsFile("warm_start", title="--warm-start as one more start of the batched solve",
                      claim="warm-starts")
    res.add(f"Whole `geodesics solve --pairs P --segments n --no-progress --out F` processes "
            f"with and without `--warm-start METRIC` (the shipped policy), median of "
            f"{args.repeats} run(s) each; CPU = user + system of the process (torch and the "
            "policy's load included). Energies compared pair by pair from the two JSON "
            "files (relative gap = (warm - default) / default).", "",
            markdown_table(head, table))
    if args.old:
        res.add("", "The retired `--warm-start` (before issue 47: the learned path alone, "
                "`solve_batch(..., initial_paths=paths, global_seeds=False)`) on the same "
                "pairs, against the default:", "",
                markdown_table(["metric", "worse > 1e-9", "worse > 1e-6", "largest gap"],
                               [[r["metric"], r["old_worse"]["1e-09"], r["old_worse"]["1e-06"],
                                 f"{r['old_largest_gap']:.2e}"] for r in rows]))
    if args.split:
        res.add("", "Where the warm start's time goes, in one process (CPU s, "
                "`time.process_time`, one torch thread; the first task's import includes "
                "torch):", "",
                markdown_table(["metric", "import learn + torch", "policy load + paths",
                                "solve_batch default", "solve_batch + learned rows"],
                               [[r["metric"], *(f"{r['split'][key]:.2f}" for key in
                                                ("import", "policy", "solve_default",
                                                 "solve_warm"))] for r in rows]))
    if not args.no_write:
        res.write()


if __name__ == "__main__":
    main()
