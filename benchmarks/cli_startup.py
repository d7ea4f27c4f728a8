"""How fast the command line answers (issue 47, item 4): whole-process CPU and wall time of
``geodesics --help``, ``geodesics solve --help`` and ``geodesics metrics``.

Each command runs ``--repeats`` times (default 5) as its own process, the console script
of the installed package (``geodesics`` beside this Python, else ``python -m
validation.cli``), its output discarded. CPU time is the child's user + system time
(``resource.getrusage(RUSAGE_CHILDREN)`` before and after each run, so it covers the
interpreter's start, every import and the work, and every thread: OpenBLAS's pool
included); wall time is ``time.perf_counter`` around the run. The median of the repeats is
the figure (min and max beside it). The bar is 0.3 s of CPU on an idle 2-core machine: the
header gives the load averages, since other processes slow a run down.

With ``--imports`` it also lists, per command, the heavy modules the run imported
(scipy.integrate, torch, hypothesis, cvxpy, casadi, numpy, pydantic, rich), from a probe
that invokes the typer app in a fresh interpreter (``tests/cli/test_cli_imports.py`` asserts
the first four stay out).

``--before DIR`` also times the same commands from another checkout of the project
(``python -m validation.cli`` with ``PYTHONPATH=DIR``; e.g. ``git worktree add DIR REV`` or
``git archive REV | tar -x -C DIR``), labelled with DIR, for a before/after table.

Usage::

    python benchmarks/cli_startup.py [--repeats 5] [--imports] [--before DIR] [--no-write]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from results_file import ResultsFile, markdown_table

COMMANDS = (["--help"], ["solve", "--help"], ["metrics"])
HEAVY = ("scipy.integrate", "torch", "hypothesis", "cvxpy", "pinocchio", "casadi", "numpy",
         "pydantic", "rich")
BAR = 0.3

_PROBE = r"""
import io, json, sys, contextlib
from validation.cli import app
with contextlib.redirect_stdout(io.StringIO()):
    try:
        app(args=json.loads(sys.argv[1]), standalone_mode=False)
    except SystemExit:
        pass
print(json.dumps([m for m in json.loads(sys.argv[2]) if m in sys.modules]))
"""


def entry_point() -> list[str]:
    script = Path(sys.executable).with_name("geodesics")
    if script.exists():
        return [str(script)]
    found = shutil.which("geodesics")
    return [found] if found else [sys.executable, "-m", "validation.cli"]


def one_run(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of one whole process running ``cmd`` (with ``env``: in
    the folder its PYTHONPATH names, so that checkout's packages are the ones imported)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True,
                   env=env, cwd=None if env is None else env["PYTHONPATH"])
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def imported(args: list[str], env: dict[str, str] | None = None) -> list[str]:
    done = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(args), json.dumps(HEAVY)],
                          capture_output=True, text=True, check=True, env=env,
                          cwd=None if env is None else env["PYTHONPATH"])
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--imports", action="store_true",
                    help="Also list the heavy modules each command imports.")
    ap.add_argument("--before", metavar="DIR", default=None,
                    help="Also time a checkout of another revision at DIR.")
    ap.add_argument("--no-write", action="store_true", help="Print only; write no file.")
    a = ap.parse_args()
    if a.repeats < 1:
        ap.error("--repeats must be >= 1")
    out = ResultsFile("cli_startup", title="Command-line start-up: CPU and wall time",
                      claim="cli")
    trees: list[tuple[str, list[str], dict[str, str] | None]] = [("this tree", entry_point(),
                                                                  None)]
    if a.before:
        env = dict(os.environ, PYTHONPATH=str(Path(a.before).resolve()))
        trees.insert(0, (a.before, [sys.executable, "-m", "validation.cli"], env))
    header = ["tree", "command", "CPU median (s)", "CPU min-max (s)", "wall median (s)",
              "wall min-max (s)", f"<= {BAR} s CPU"]
    if a.imports:
        header.append("heavy modules imported")
    rows = []
    for label, base, env in trees:
        one_run([*base, "--help"], env)  # warm the file cache: the first run reads the .pyc
        for args in COMMANDS:
            runs = [one_run(base + args, env) for _ in range(a.repeats)]
            cpu = [c for c, _ in runs]
            wall = [w for _, w in runs]
            row = [label, f"`geodesics {' '.join(args)}`", f"{statistics.median(cpu):.3f}",
                   f"{min(cpu):.3f}-{max(cpu):.3f}", f"{statistics.median(wall):.3f}",
                   f"{min(wall):.3f}-{max(wall):.3f}",
                   "yes" if statistics.median(cpu) <= BAR else "NO"]
            if a.imports:
                row.append(", ".join(imported(args, env)) or "-")
            rows.append(row)
            print("  ".join(row), flush=True)
    here = Path(__file__).resolve().parents[1]

    def shown(path: object) -> str:  # paths of this machine as relative or bare names
        text = str(path)
        return text.replace(f"{here}/", "") if text.startswith(f"{here}/") else Path(text).name

    out.add(f"Median of {a.repeats} whole-process runs each "
            f"(`{' '.join(shown(x) for x in trees[-1][1])} ...`"
            + (f"; `{shown(a.before)}` (the --before checkout): `python -m validation.cli ...` "
               "with PYTHONPATH set to it" if a.before else "")
            + ", output discarded; one untimed run first per tree). "
            "CPU = the child's user + system time (getrusage RUSAGE_CHILDREN), all threads "
            "included.", "", markdown_table(header, rows))
    if not a.no_write:
        out.write()


if __name__ == "__main__":
    main()
