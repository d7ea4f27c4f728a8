"""Every ```python snippet of README.md and docs/guides/ runs as written.

Each page's snippets run in order in one fresh interpreter (a subprocess), in a temporary
folder, sharing their names as a reader's session would: a snippet that needs an import
must show it. Two first-line comments change what happens to a snippet:

- ``# NAME.py ...``: the snippet is also a file the page tells the reader to save; it is
  written to the folder (of every page: ``check.md`` imports the ``wavy.py`` of the README
  and ``metrics.md``), and a ``test_*.py`` one is run with pytest after the page's snippets.
- ``# not run by the snippet test: REASON``: skipped, and the reason is shown on the page
  (trainings of minutes). The test lists what it skipped.

The README's shown outputs of its quick commands (``$ geodesics solve ...``, ``certify``,
``evaluate``) are checked against a real run, so that they cannot go stale.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs" / "guides").glob("*.md"))]
FENCE = re.compile(r"^```python[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)
FILE = re.compile(r"^# ([\w.-]+\.py)\b")
SKIP = re.compile(r"^# not run by the snippet test: (\S.*)$")

RUNNER = """
import json, sys
snippets = json.load(open(sys.argv[1]))
scope = {"__name__": "__main__"}
for label, code in snippets:
    exec(compile(code, label, "exec"), scope)
"""


def snippets(page: Path) -> list[tuple[int, str]]:
    """The page's ```python blocks, each with the line its code starts on."""
    text = page.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in FENCE.finditer(text)]


def _saved_files() -> dict[str, str]:
    """Every snippet that names a file, by file name (the same name must mean one text)."""
    files: dict[str, str] = {}
    for page in PAGES:
        for _, code in snippets(page):
            m = FILE.match(code)
            if m:
                assert files.get(m.group(1), code) == code, f"two texts for {m.group(1)}"
                files[m.group(1)] = code
    return files


def _pages_with_snippets() -> list[Path]:
    return [page for page in PAGES if snippets(page)]


def test_the_pages_have_snippets():
    names = {p.name for p in _pages_with_snippets()}
    assert {"README.md", "metrics.md", "check.md", "exact-solves.md"} <= names


@pytest.mark.parametrize("page", _pages_with_snippets(), ids=lambda p: p.name)
def test_page_snippets_run(page: Path, tmp_path: Path):
    for name, code in _saved_files().items():
        (tmp_path / name).write_text(code, encoding="utf-8")
    run, skipped, tests = [], [], []
    for line, code in snippets(page):
        first = code.splitlines()[0] if code.strip() else ""
        if SKIP.match(first):
            skipped.append(f"{page.name}:{line}: {SKIP.match(first).group(1)}")
            continue
        run.append((f"{page.relative_to(ROOT)}:{line}", code))
        m = FILE.match(first)
        if m and m.group(1).startswith("test_"):
            tests.append(m.group(1))
    (tmp_path / "_snippets.json").write_text(json.dumps(run), encoding="utf-8")
    (tmp_path / "_runner.py").write_text(RUNNER, encoding="utf-8")
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": str(tmp_path)}
    proc = subprocess.run(
        [sys.executable, "_runner.py", "_snippets.json"], cwd=tmp_path, env=env,
        capture_output=True, text=True, timeout=900,
    )
    assert proc.returncode == 0, f"{page.name}'s snippets failed:\n{proc.stderr[-4000:]}"
    for name in tests:
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", name, "-q", "-p", "no:cacheprovider", "-n", "0",
             "-o", "addopts=", "--rootdir", str(tmp_path)],
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900,
        )
        assert proc.returncode == 0, f"{page.name}: pytest {name} failed:\n{proc.stdout[-4000:]}"
    if skipped:
        print("skipped, with the reason the page gives:\n" + "\n".join(skipped))


#: README commands whose shown output is checked against a real run (a few seconds each);
#: the others (check, train, report) take minutes or depend on the load.
CHECKED_COMMANDS = ("geodesics solve --metric matsumoto --start",
                    "geodesics certify --metric poincare", "geodesics evaluate --env matsumoto")
SHELL_BLOCK = re.compile(r"^```\n\$ (geodesics [^\n]*)\n(.*?)^```", re.S | re.M)
#: Shown lines that hold a time (they change from run to run) are not compared.
TIMED = re.compile(r"wall time|^time |s CPU|\d+(\.\d+)? s\)?$")


def shown_outputs(page: Path) -> list[tuple[str, list[str]]]:
    """The ``$ geodesics ...`` blocks of ``page``: (command, shown output lines)."""
    return [(cmd, body.splitlines()) for cmd, body in SHELL_BLOCK.findall(page.read_text())]


@pytest.mark.parametrize("prefix", CHECKED_COMMANDS)
def test_readme_shows_what_the_command_prints(prefix: str, tmp_path: Path):
    """Every shown line (but ``...`` and times) is a line the command prints today."""
    blocks = [(c, lines) for c, lines in shown_outputs(ROOT / "README.md")
              if c.startswith(prefix)]
    assert len(blocks) == 1, blocks
    cmd, shown = blocks[0]
    exe = Path(sys.executable).with_name("geodesics")
    proc = subprocess.run([str(exe), *cmd.split()[1:]], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    printed = {ln.replace(f"{ROOT}/", "").rstrip() for ln in proc.stdout.splitlines()}
    stale = [ln for ln in shown if ln.strip() != "..." and not TIMED.search(ln)
             and ln.rstrip() not in printed]
    assert not stale, f"README's output of `{cmd}` is stale; it now prints:\n{proc.stdout}"
