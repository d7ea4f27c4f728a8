"""Mutation testing of the solver core and the property suite, one group at a time, and
a results file with the score and every surviving mutant (issue 48, item 6).

    python benchmarks/mutation.py                       # the DEFAULT groups below
    python benchmarks/mutation.py block_tridiagonal newton --max-children 2
    python benchmarks/mutation.py --report-only newton  # a run under way, as it stands
    python benchmarks/mutation.py testing               # all of validation/testing/, summed

For each group: the COMMITTED tree (``git archive HEAD``, so the score is for the commit
the results file names) is unpacked into ``build/mutation/GROUP/``, its ``[tool.mutmut]``
(``pyproject.toml``) gets the group's source files and its test files with ``-m mutation``
(the FAST focused tests, marked beside the module's other tests), and ``mutmut run``
(``nice``) mutates and tests them there. The results file
(``benchmarks/results/mutation/mutation-DATE.md``) gives per group the mutants, killed,
timeouts, survivors, score = (killed + timeout) / (mutants - skipped), the CPU time, the
commit of each source file, and the diff of every survivor; ``mutation_report.md`` in the
same folder gives the verdicts. A score from a group's focused tests is a lower bound of
the whole suite's.
Needs ``pip install -e ".[mutation]"`` (mutmut >= 3.8).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

from results_file import ResultsFile, markdown_table

ROOT = Path(__file__).resolve().parents[1]

#: group -> (files mutated, fast focused tests run against them). mutmut runs, per
#: mutant, only the selected tests that called the mutated function.
GROUPS: dict[str, tuple[list[str], list[str]]] = {
    "block_tridiagonal": (["solvers/newton/block_tridiagonal.py"],
                          ["tests/solvers/newton/test_block_tridiagonal.py",
                           "tests/solvers/newton/test_block_tridiagonal_rows.py"]),
    "certify_mesh": (["solvers/certificates/plane/mesh.py"],
                     ["tests/solvers/certificates/plane/test_certify_mesh.py"]),
    # certify_lp: its tests and the repair's (which run _solve_lp's repair branch)
    "certify_lp": (["solvers/certificates/plane/lp.py"],
                   ["tests/solvers/certificates/plane/test_certify_lp.py",
                    "tests/solvers/certificates/plane/test_certify_repair.py"]),
    "newton": (["solvers/newton/energy.py"], ["tests/solvers/newton/test_newton.py"]),
    # batched: the driver's own tests alone (closed forms, hand counts: 17 tests in ~3 s);
    # test_newton.py's batched solves took ~3 s a mutant for 53 %
    "batched": (["solvers/newton/driver.py"], ["tests/solvers/newton/test_driver.py"]),
}
#: the property suite one module at a time, each against its own fast tests
#: (``testing_engine``, ``testing_metric``, ...): small runs that can be spread; the score
#: of validation/testing/ is the sum over these groups
TESTING_MODULES = ["engine", "metric", "distance", "regions", "policy", "suite", "cases"]
GROUPS.update({f"testing_{m}": ([f"validation/testing/{m}.py"],
                                [f"tests/validation/testing/test_{m}.py"])
               for m in TESTING_MODULES})
#: names that stand for several groups: ``testing`` is every module of validation/testing/
#: (``__init__.py`` holds only imports: mutmut mutates function bodies, so it has no
#: mutants); the results file then adds a row summing them (the package's score)
ALIASES = {"testing": [f"testing_{m}" for m in TESTING_MODULES]}
#: extra pytest arguments of a group's selection: test_newton.py's dense block solves
#: (two minutes, and test_block_tridiagonal.py's job) call nothing of these modules
SELECT = {"newton": ["-k", "not block_tridiagonal_solve_matches_dense"]}
#: a group runs the tests of its files marked ``mutation`` (``@pytest.mark.mutation`` or a
#: module's ``pytestmark``): the fast focused ones, beside the other tests of the module
MARK = ["-m", "mutation and not slow"]
#: the groups run when none is named
DEFAULT = ["block_tridiagonal", "certify_mesh", "newton", "batched"]

_MUTMUT_SECTION = re.compile(r"^\[tool\.mutmut\]\n(?:(?!^\[).*\n?)*", re.M)


def _mutmut() -> str:
    exe = Path(sys.executable).with_name("mutmut")
    if not exe.exists():
        sys.exit("mutmut not found beside this Python: pip install -e '.[mutation]'")
    return str(exe)


def _toml_list(items: list[str]) -> str:
    return "[" + ", ".join(f'"{x}"' for x in items) + "]"


def used_tests(group: str) -> list[str]:
    """The group's test files that exist in the committed tree (a test file may come
    later than its module's first run)."""
    listed = subprocess.run(["git", "ls-files", *GROUPS[group][1]], cwd=ROOT,
                            capture_output=True, text=True, check=True).stdout.split()
    return [t for t in dict.fromkeys(GROUPS[group][1]) if t in listed]


def prepare(group: str, work: Path) -> Path:
    """The committed tree in ``work/group`` with the group's ``[tool.mutmut]``."""
    files, tests = GROUPS[group][0], used_tests(group)
    if not tests:
        raise SystemExit(f"group {group}: none of its tests {GROUPS[group][1]} exist")
    where = work / group
    if where.exists():
        shutil.rmtree(where)
    where.mkdir(parents=True)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True,
                          text=True, check=True).stdout.strip()
    (work / f"{group}.commit").write_text(head + "\n" + file_commits([*files, *tests]) + "\n")
    archive = subprocess.run(["git", "archive", head], cwd=ROOT, capture_output=True,
                             check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(where)], input=archive, check=True)
    py = (where / "pyproject.toml").read_text()
    section = "\n".join([
        "[tool.mutmut]",
        f"source_paths = {_toml_list(files)}",
        'also_copy = ["finsler", "solvers", "learn", "validation", "tests", "benchmarks"]',
        "pytest_add_cli_args_test_selection = "
        f"{_toml_list([*tests, *MARK, *SELECT.get(group, [])])}",
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-q", "-n", "0", "-x"]', ""])
    (where / "pyproject.toml").write_text(_MUTMUT_SECTION.sub(section, py))
    return where


def run(group: str, work: Path, children: int, niceness: int = 10) -> dict:
    where = prepare(group, work)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    # one thread per library: mutmut forks a worker per mutant from a process that has
    # imported numpy/torch, and a fork taken while a thread pool holds a lock can hang
    # without using CPU (mutmut's time limit is on CPU time: it would never fire)
    env = {**os.environ, **{v: "1" for v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                             "OPENBLAS_NUM_THREADS")}}
    proc = subprocess.run(["nice", "-n", str(niceness), _mutmut(), "run", "--max-children",
                           str(children)], cwd=where, capture_output=True, text=True,
                          check=False, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        tail = (proc.stdout + proc.stderr)[-3000:]
        return {"group": group, "error": f"mutmut run exited {proc.returncode}:\n{tail}",
                "wall": wall, "cpu": cpu}
    return collect(group, where, wall, cpu)


def collect(group: str, where: Path, wall: float | None, cpu: float | None) -> dict:
    """The statuses, counts and survivors' diffs of a group's (possibly running) run."""
    res = subprocess.run([_mutmut(), "results", "--all", "true"], cwd=where,
                         capture_output=True, text=True, check=True).stdout
    status: dict[str, str] = {}
    for line in res.splitlines():
        name, sep, st = line.strip().rpartition(": ")
        if sep:
            status[name] = st
    survivors = sorted(n for n, s in status.items() if s in ("survived", "no tests"))
    diffs = _diffs(where, survivors)
    count = {s: sum(1 for v in status.values() if v == s) for s in set(status.values())}
    return {"group": group, "status": status, "count": count, "survivors": survivors,
            "diffs": diffs, "wall": wall, "cpu": cpu}


_DIFFS = """
import json, sys, time
from mutmut.__main__ import find_mutant, get_diff_for_mutant
out = {}
for n in sys.argv[1:]:
    for attempt in range(5):  # a running mutmut may be rewriting the file it reads
        try:
            out[n] = get_diff_for_mutant(n, path=find_mutant(n).path)
            break
        except Exception as err:  # a mutant mutmut cannot show: say so in the results
            out[n] = f"(no diff: {err})"
            time.sleep(0.5)
print(json.dumps(out))
"""


def _diffs(where: Path, names: list[str]) -> dict[str, str]:
    """``mutmut show`` of every mutant in ``names``, in one process (one ``mutmut show``
    each takes seconds)."""
    if not names:
        return {}
    py = Path(sys.executable).with_name("python")
    out = subprocess.run([str(py), "-c", _DIFFS, *names], cwd=where, capture_output=True,
                         text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def file_commits(files: list[str]) -> str:
    out = []
    for f in files:
        c = subprocess.run(["git", "log", "-1", "--format=%h", "--", f], cwd=ROOT,
                           capture_output=True, text=True, check=False).stdout.strip()
        out.append(f"`{f}` @ {c or '?'}")
    return ", ".join(out)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("groups", nargs="*", metavar="GROUP",
                    help=f"groups to run (default: {', '.join(DEFAULT)}; also: "
                    f"{', '.join(g for g in GROUPS if g not in DEFAULT)})")
    ap.add_argument("--max-children", type=int, default=1,
                    help="mutmut's worker processes (default 1: the machine is shared)")
    ap.add_argument("--nice", type=int, default=10,
                    help="niceness of mutmut (default 10: other work goes first)")
    ap.add_argument("--report-only", action="store_true",
                    help="write the results of the runs under --work as they stand (a run "
                         "still going or stopped: its unchecked mutants are counted apart)")
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "mutation",
                    help="where the trees are unpacked and mutated")
    args = ap.parse_args(argv)
    unknown = [g for g in args.groups if g not in GROUPS and g not in ALIASES]
    if unknown:
        ap.error(f"unknown group(s) {unknown}; the groups are {', '.join(GROUPS)} (and "
                 f"{', '.join(f'{a} = {len(v)} groups' for a, v in ALIASES.items())})")
    named = [g for a in (args.groups or DEFAULT) for g in ALIASES.get(a, [a])]
    args.groups = list(dict.fromkeys(named))
    out = ResultsFile("mutation", title="Mutation testing of the solver core and the "
                      "property suite (mutmut)", claim="mutation")
    rows, sections = [], []
    sums = {"total": 0, "unchecked": 0, "killed": 0, "timeout": 0, "survived": 0,
            "caught": 0, "checked": 0}
    for g in args.groups:
        print(f"{'reading' if args.report_only else 'mutating'} {g} ...", flush=True)
        if args.report_only:
            if not (args.work / g / "mutants").exists():
                raise SystemExit(f"--report-only: no run of {g} under {args.work}")
            r = collect(g, args.work / g, None, None)
        else:
            r = run(g, args.work, args.max_children, args.nice)
        if "error" in r:
            rows.append([f"`{g}`", "-", "-", "-", "-", "-", "error", f"{r['cpu']:.0f}",
                         f"{r['wall']:.0f}"])
            sections.append(f"## {g}\n\n```\n{r['error']}\n```\n")
            print(r["error"], file=sys.stderr)
            continue
        c = r["count"]
        total, skipped = len(r["status"]), c.get("skipped", 0)
        unchecked = c.get("not checked", 0)
        caught = c.get("killed", 0) + c.get("timeout", 0)
        checked = total - skipped - unchecked
        score = 100.0 * caught / max(checked, 1)
        rows.append([f"`{g}`", total, unchecked, c.get("killed", 0), c.get("timeout", 0),
                     len(r["survivors"]), f"{score:.1f} %",
                     "-" if r["cpu"] is None else f"{r['cpu']:.0f}",
                     "-" if r["wall"] is None else f"{r['wall']:.0f}"])
        for k, v in (("total", total), ("unchecked", unchecked),
                     ("killed", c.get("killed", 0)), ("timeout", c.get("timeout", 0)),
                     ("survived", len(r["survivors"])), ("caught", caught),
                     ("checked", checked)):
            sums[k] += v
        other = {k: v for k, v in c.items() if k not in ("killed", "timeout", "survived",
                                                          "no tests", "not checked")}
        head, commits = (args.work / f"{g}.commit").read_text().splitlines()
        text = [f"## {g}", "", f"Mutated and tested: the committed tree of `{head[:10]}` "
                f"(`git archive`; uncommitted changes play no part); last commits of the "
                f"files: {commits}.",
                f"Other statuses: {other or 'none'}.", ""]
        if r["survivors"]:
            text.append(f"Survivors ({len(r['survivors'])}; `no tests` = no selected test "
                        "calls the function):\n")
            for n in r["survivors"]:
                text += [f"### `{n}` ({r['status'][n]})", "", "```diff",
                         r["diffs"][n].strip(), "```", ""]
        sections.append("\n".join(text))
        print(f"{g}: {caught}/{total - skipped} = {score:.1f} %", flush=True)
    if len(rows) > 1 and sums["checked"]:
        rows.append(["**all groups above**", sums["total"], sums["unchecked"],
                     sums["killed"], sums["timeout"], sums["survived"],
                     f"**{100.0 * sums['caught'] / sums['checked']:.1f} %**", "-", "-"])
    out.add("Score = (killed + timeout) / (mutants checked - skipped), against each "
            "group's fast focused tests only (a lower bound of the whole suite's score); "
            "`not checked`: mutants of a run still going or stopped (with `--report-only`). "
            "CPU = user + system seconds of mutmut and its workers (the machine is shared "
            "by other work, so wall time varies; `-`: not measured by a report-only run). "
            "Survived includes `no tests` (no selected test calls the function). Verdicts "
            "on the survivors: `mutation_report.md` in this folder.",
            markdown_table(["group", "mutants", "not checked", "killed", "timeout",
                            "survived", "score", "CPU s", "wall s"], rows),
            *sections)
    out.write()


if __name__ == "__main__":
    main()
