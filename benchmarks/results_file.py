"""Write a benchmark's measurements to a file under ``benchmarks/results/<claim>/``.

Every figure the README or the docs cite lives in such a file, written by the script that
measured it, never typed by hand. The header says how to get the same figures again: the
command line, the commit (and whether the tree had uncommitted changes), the machine
(cores, load averages at the start and at the end, CPU model, Python and key package
versions) and the date.

Files are grouped by the claim they back (``benchmarks/results/README.md`` lists the claims,
the current file of each and the command that measures it again). A run writes a new file
``<claim>/<name>-DATE.md`` (``-2``, ``-3`` ... when that name is taken in the folder or in
its ``history/``), so no run overwrites another; the file it replaces as the evidence for a
claim moves to ``<claim>/history/`` (``git mv``) when the README and the docs are updated to
cite the new one.

Usage from a benchmark script (run as ``python benchmarks/NAME.py``, so this module is
importable by its name)::

    from results_file import ResultsFile
    out = ResultsFile("ground_truth", title="Ground truth on fresh pairs", claim="exact-solves")
    out.add("## Matsumoto", table_markdown)
    path = out.write()          # benchmarks/results/exact-solves/ground_truth-2026-12-07.md
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
_ROOT = Path(__file__).resolve().parents[1]


def _git(*args: str) -> str:
    try:
        out = subprocess.run(["git", *args], cwd=_ROOT, capture_output=True, text=True,
                             timeout=20, check=False)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def _versions() -> str:
    from importlib import metadata

    parts = [f"python {platform.python_version()}"]
    for name in ("numpy", "scipy", "casadi", "torch"):
        try:
            parts.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            pass
    return ", ".join(parts)


def markdown_table(header: list[str], rows: list[list[object]]) -> str:
    """A Markdown table; floats are written as given by ``str`` unless pre-formatted."""
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


class ResultsFile:
    """Collects sections of Markdown and writes them under a reproducibility header.

    ``name`` is the file's stem (the benchmark's name) and ``claim`` the folder of the claim
    it measures (a folder of ``benchmarks/results/``, listed in its README). ``stamp=True``
    appends the date (``NAME-YYYY-MM-DD.md``, then ``-2``, ``-3`` ... when that name is taken
    in the claim's folder or in its ``history/``) so reruns keep history. ``directory`` is
    the results root (``benchmarks/results/`` unless given).
    """

    def __init__(self, name: str, title: str, *, claim: str, stamp: bool = True,
                 directory: str | os.PathLike[str] | None = None) -> None:
        for what, value in (("name", name), ("claim", claim)):
            if not value or "/" in value or "\\" in value or value.startswith("."):
                raise ValueError(f"results {what} {value!r} is not a plain file or folder name")
        self.name = name
        self.title = title
        self.claim = claim
        self.stamp = stamp
        self.directory = (Path(directory) if directory is not None else RESULTS) / claim
        self.started = _dt.datetime.now(_dt.timezone.utc)
        self.load_start = _load()
        # the code that runs is the code at the start: a commit made while a long run goes
        # on must not be credited with its figures
        self.commit = _git("rev-parse", "HEAD") or "unknown"
        self.dirty = bool(_git("status", "--porcelain", "--untracked-files=no"))
        self.sections: list[str] = []
        self._written: Path | None = None

    def add(self, *chunks: str) -> None:
        """Append Markdown (headings, tables, paragraphs) in order."""
        self.sections.extend(c.rstrip() + "\n" for c in chunks)

    def header(self) -> str:
        now = _git("rev-parse", "HEAD") or "unknown"
        moved = f" (HEAD moved to `{now}` during the run)" if now != self.commit else ""
        cmd = " ".join(shlex.quote(a) for a in [Path(sys.executable).name, *sys.argv])
        ended = _dt.datetime.now(_dt.timezone.utc)
        return "\n".join([
            f"# {self.title}",
            "",
            f"- command: `{cmd}`",
            f"- commit: `{self.commit}`" + (" (with uncommitted changes)" if self.dirty else "")
            + moved,
            f"- machine: {os.cpu_count()} cores, {_cpu_model()}; load averages "
            f"(1, 5, 15 min) {self.load_start} at the start, {_load()} at the end",
            f"- software: {_versions()}",
            f"- date: {self.started:%Y-%m-%d %H:%M} to {ended:%H:%M} UTC",
            "",
        ])

    def _taken(self, filename: str) -> bool:
        return (self.directory / filename).exists() or (
            self.directory / "history" / filename).exists()

    def path(self) -> Path:
        """The first free name (not in the claim's folder, nor in its ``history/``)."""
        if not self.stamp:
            return self.directory / f"{self.name}.md"
        base = f"{self.name}-{self.started:%Y-%m-%d}"
        name, k = f"{base}.md", 2
        while self._taken(name):
            name, k = f"{base}-{k}.md", k + 1
        return self.directory / name

    def _claim_path(self) -> Path:
        """A free name, reserved by creating the file exclusively: two runs of one script
        started the same day (pairs split between processes) never share a file."""
        while True:
            p = self.path()
            if not self.stamp:
                return p
            try:
                os.close(os.open(p, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
            except FileExistsError:
                continue
            return p

    def write(self) -> Path:
        """Write the file atomically and return its path (also printed). A second call
        rewrites the same file (a benchmark that writes after every item loses nothing
        finished when it is interrupted)."""
        from finsler.infra.files import atomic_write_text

        self.directory.mkdir(parents=True, exist_ok=True)
        p = self._written or self._claim_path()
        self._written = p
        atomic_write_text(p, self.header() + "\n" + "\n".join(self.sections))
        print(f"results written to {p}")
        return p
