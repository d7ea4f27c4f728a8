"""The default test run's time: ``python -m pytest -n 2`` (the README's test command) in
this checkout, wall and CPU time (the child processes' user + system, so both pytest-xdist
workers count), with the counts pytest prints.

Usage::

    python benchmarks/suite_time.py [--repeats 1]

Writes ``benchmarks/results/cli/suite_time-DATE.md``. Run it on a quiet machine: the suite
itself uses both cores.
"""

from __future__ import annotations

import argparse
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

from results_file import ResultsFile, markdown_table

ROOT = Path(__file__).resolve().parents[1]


def run_once() -> tuple[float, float, str]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "-q", "-p",
                          "no:cacheprovider"], cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = [ln for ln in out.stdout.splitlines() if re.search(r"\d+ (passed|failed)", ln)]
    summary = lines[-1].strip("= ") if lines else f"no summary (exit {out.returncode})"
    if out.returncode != 0:
        print(out.stdout[-3000:], file=sys.stderr)
    return wall, cpu, summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    out = ResultsFile("suite_time", title="The default test run's time", claim="cli")
    rows = []
    for k in range(args.repeats):
        wall, cpu, summary = run_once()
        rows.append([k + 1, f"{wall / 60:.2f} min", f"{cpu / 60:.2f} min", summary])
        print(rows[-1], flush=True)
    out.add("`python -m pytest -n 2` (the README's test command; `-m 'not slow'` by the "
            "project's defaults), from the repository's root.",
            markdown_table(["run", "wall", "CPU (user + system)", "pytest's summary"], rows))
    out.write()


if __name__ == "__main__":
    main()
