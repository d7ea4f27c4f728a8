"""Time of ``geodesics check`` (default settings) on the registered metrics and on the
metrics of ``tests/helpers/broken_metrics.py`` (each wrong in one way, and the valid ones there),
each in a fresh process (imports and NLP builds included, one thread: OMP_NUM_THREADS=1),
with its exit status, failed (root cause first), inconclusive properties and the slowest
property; written to ``benchmarks/results/check/check_speed-DATE.md``.

    .venv/bin/python benchmarks/check_speed.py [--examples 100,200] [--only NAME,...]
                                               [--no-broken] [--two-d]

CPU seconds (the child's user + system time) are given beside wall seconds: on a machine
shared with other work the wall time is the larger; the 60 s bar of issue 48 is for one
core, which the CPU time measures.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BROKEN = ROOT / "tests" / "broken_metrics.py"
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_file import ResultsFile, markdown_table  # noqa: E402


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(name: str, examples: int, module: Path | None) -> dict:
    cmd = [sys.executable, "-m", "validation.cli", "check", "--metric", name, "--json",
           "--examples", str(examples)]
    if module is not None:
        cmd += ["--metric-module", str(module)]
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1")
    t0, c0 = time.perf_counter(), _child_cpu()
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    wall, cpu = time.perf_counter() - t0, _child_cpu() - c0
    row = {"name": name, "wall": wall, "cpu": cpu, "exit": out.returncode,
           "stderr_lines": len(out.stderr.splitlines())}
    try:
        doc = json.loads(out.stdout)
    except json.JSONDecodeError:
        return {**row, "failed": ["(no JSON)"], "inconclusive": [], "mapped": [],
                "slowest": "-", "error": out.stderr[-500:]}
    slow = max(doc["properties"], key=lambda p: p["seconds"])
    return {**row, "failed": doc["failed"], "inconclusive": doc.get("inconclusive", []),
            "mapped": [p["name"] for p in doc["properties"] if p["status"] == "mapped"],
            "not_run": len(doc.get("not_run", [])),
            "slowest": f"{slow['name']} {slow['seconds']:.1f} s",
            "check_seconds": doc["seconds"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", default="100",
                    help="comma-separated --examples values (default 100)")
    ap.add_argument("--only", default="", help="comma-separated metric names")
    ap.add_argument("--no-broken", action="store_true", help="skip tests/helpers/broken_metrics.py")
    ap.add_argument("--two-d", action="store_true", help="only 2-D metrics")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    import finsler

    jobs = [(n, None) for n in finsler.list_metrics()]
    if not args.no_broken:
        import broken_metrics

        jobs += [(n, BROKEN) for n in (*broken_metrics.EXPECTED, *broken_metrics.VALID)]
    if args.only:
        keep = set(args.only.split(","))
        jobs = [j for j in jobs if j[0] in keep]
    if args.two_d:
        jobs = [j for j in jobs if finsler.get_metric(j[0]).dim == 2]
    sizes = [int(e) for e in args.examples.split(",")]
    out = ResultsFile("check_speed", title="geodesics check: time per metric", claim="check")
    header = ["metric", "examples", "wall s", "CPU s", "exit", "failed (root cause first)",
              "inconclusive", "not run", "slowest property", "stderr lines"]
    print("  ".join(header), flush=True)
    for examples in sizes:
        rows = []
        for name, module in jobs:
            r = run(name, examples, module)
            row = [name, examples, f"{r['wall']:.1f}", f"{r['cpu']:.1f}", r["exit"],
                   ", ".join(r["failed"]) or "-", ", ".join(r["inconclusive"]) or "-",
                   r.get("not_run", "-"), r["slowest"], r["stderr_lines"]]
            if r["mapped"]:
                row[5] += f" (mapped: {', '.join(r['mapped'])})"
            rows.append(row)
            print("  ".join(str(c) for c in row), flush=True)
        out.add(f"## --examples {examples}", "", markdown_table(header, rows), "")
    out.add("Each row is one `python -m validation.cli check --metric NAME --json "
            "--examples N` process (with `--metric-module tests/helpers/broken_metrics.py` for the "
            "broken-* and valid-* metrics), OMP_NUM_THREADS=1; CPU s is the process's user + "
            "system time. `stderr lines`: lines the JSON run printed on stderr (warnings "
            "are caught and summarised in the JSON, so 0 is expected).")
    out.write()


if __name__ == "__main__":
    main()
