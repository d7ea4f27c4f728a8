"""``benchmarks/results/``: one folder per claim, and the README's table of claims.

The table (claim | current file | script | command) is the index of every measured figure:
each link must resolve, each current file must sit at the top of its claim's folder (older
runs are in ``history/``), and every file at the top of a claim's folder must be named in
the table (a new run is either promoted to current or moved to ``history/``). Paths to
results files written anywhere in the repository (README, docs, code comments) must exist.
``ResultsFile`` writes into a claim's folder and never reuses a name.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
INDEX = RESULTS / "README.md"
NOT_CLAIMS = {"ground_truth_cache"}  # data the scripts reuse, no figures

_LINK = re.compile(r"(?<!!)\[[^\[\]\n]*\]\(([^)\s]+)\)")
_ROW = re.compile(r"^\|(.+)\|\s*$")
_PENDING = re.compile(r"not measured yet: `([\w./-]+\.md)`")


def claims_table(text: str) -> list[dict[str, str]]:
    """The rows of the first table after ``## Claims``, as dicts keyed by its header."""
    section = text.split("\n## Claims", 1)[1]
    rows, header = [], None
    for line in section.splitlines():
        m = _ROW.match(line.strip())
        if not m:
            if header is not None and rows:
                break
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", m.group(1))]
        if header is None:
            header = cells
        elif not all(set(c) <= set("-: ") for c in cells):
            rows.append(dict(zip(header, cells)))
    return rows


def check_index(results: Path) -> list[str]:
    """Every problem of a results folder and its README's table of claims, one line each."""
    problems = []
    rows = claims_table((results / "README.md").read_text(encoding="utf-8"))
    if not rows:
        return ["no table of claims"]
    current: set[Path] = set()
    for row in rows:
        claim, cell = row.get("claim", "?"), row.get("current file", "")
        targets = _LINK.findall(cell)
        pending = _PENDING.findall(cell)
        if not targets and not pending:
            problems.append(f"{claim}: no current file")
        if len(targets) > 3:
            problems.append(f"{claim}: {len(targets)} current files (split the claim)")
        for target in targets:
            dest = (results / target).resolve()
            if not dest.is_file():
                problems.append(f"{claim}: {target}: no such file")
                continue
            rel = dest.relative_to(results.resolve())
            if len(rel.parts) != 2:
                problems.append(f"{claim}: {target}: a current file sits at the top of a "
                                "claim's folder, not in history/ or elsewhere")
            current.add(dest)
        for target in pending:
            if (results / target).exists():
                problems.append(f"{claim}: {target} exists: link it")
        others = " ".join(v for k, v in row.items() if k != "current file")
        for other in _LINK.findall(others):
            if not re.match(r"^[a-z]+:", other) and not (results / other).exists():
                problems.append(f"{claim}: {other}: no such file")
    for path in sorted(results.glob("*.md")):
        if path.name != "README.md":
            problems.append(f"{path.name}: a results file outside a claim's folder")
    for folder in sorted(p for p in results.iterdir() if p.is_dir()):
        if folder.name in NOT_CLAIMS:
            continue
        for path in sorted(folder.glob("*.md")):
            if path.resolve() not in current:
                problems.append(f"{path.relative_to(results)}: not named in the table of "
                                "claims (cite it as current, or git mv it to history/)")
        for path in sorted(folder.iterdir()):
            if path.is_dir() and path.name != "history":
                problems.append(f"{path.relative_to(results)}: only history/ goes in a "
                                "claim's folder")
    return problems


def test_every_claim_links_an_existing_current_file() -> None:
    assert check_index(RESULTS) == []


def test_the_index_check_finds_problems(tmp_path: Path) -> None:
    (tmp_path / "a" / "history").mkdir(parents=True)
    (tmp_path / "a" / "a-1.md").write_text("# a\n")
    (tmp_path / "a" / "a-2.md").write_text("# a, a new run nobody promoted\n")
    (tmp_path / "a" / "history" / "a-0.md").write_text("# a, older\n")
    (tmp_path / "stray.md").write_text("# at the top\n")
    (tmp_path / "README.md").write_text(
        "# R\n\n## Claims\n\n| claim | current file | script | command |\n"
        "| --- | --- | --- | --- |\n"
        "| one | [ok](a/a-1.md) | `a.py` | `python a.py` |\n"
        "| two | [gone](a/a-9.md) | `a.py` | `python a.py` |\n"
        "| three | [old](a/history/a-0.md) | `a.py` | `python a.py` |\n"
        "| four | nothing | `b.py` | `python b.py` |\n"
        "| five | not measured yet: `a/a-1.md` | `c.py` | `python c.py` |\n")
    found = check_index(tmp_path)
    assert any("a-9.md: no such file" in p for p in found), found
    assert any("history" in p and "three" in p for p in found), found
    assert any("four: no current file" in p for p in found), found
    assert any("five" in p and "link it" in p for p in found), found
    assert any("stray.md" in p for p in found), found
    assert any("a/a-2.md: not named" in p for p in found), found
    assert not any("a-1.md: not named" in p for p in found), found
    assert len(found) == 6, found


def test_the_table_names_scripts_that_exist_and_write_where_the_table_says() -> None:
    rows = claims_table(INDEX.read_text(encoding="utf-8"))
    for row in rows:
        folders = {t.split("/")[0] for t in _LINK.findall(row["current file"])}
        folders |= {t.split("/")[0] for t in _PENDING.findall(row["current file"])}
        for script in re.findall(r"`(\w+\.py)`", row["script"]):
            path = ROOT / "benchmarks" / script
            if not path.exists():
                assert _PENDING.search(row["current file"]), (row["claim"], script)
                continue
            written = set(re.findall(r"claim=\"([\w-]+)\"", path.read_text(encoding="utf-8")))
            if written:
                assert written <= folders or folders <= written, (row["claim"], script, written)


def _claims_written_by(script: Path) -> list[object]:
    """The ``claim=`` of every ``ResultsFile(...)`` call of a script (None: no such keyword,
    or not a string constant)."""
    import ast

    found = []
    for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "ResultsFile":
            kw = {k.arg: k.value for k in node.keywords}
            value = kw.get("claim")
            found.append(value.value if isinstance(value, ast.Constant) else None)
    return found


def test_every_benchmark_writes_into_a_claim_of_the_table() -> None:
    """Each ``ResultsFile`` of a script under benchmarks/ names its claim's folder as a
    string, and that folder has a row in the table (a current file or a pending one)."""
    rows = claims_table(INDEX.read_text(encoding="utf-8"))
    folders = {t.split("/")[0] for row in rows
               for t in _LINK.findall(row["current file"]) + _PENDING.findall(row["current file"])}
    writers = 0
    for script in sorted((ROOT / "benchmarks").glob("*.py")):
        if script.name == "results_file.py":
            continue
        for claim in _claims_written_by(script):
            writers += 1
            assert claim in folders, (script.name, claim)
    assert writers >= 15


def test_no_mutation_report_at_the_root() -> None:
    assert not (ROOT / "mutation_report.md").exists()
    assert (RESULTS / "mutation" / "mutation_report.md").is_file()


_MENTION = re.compile(r"benchmarks/results/([\w./*-]+\.md)")


def _sources() -> list[Path]:
    """The repository's Python, Markdown and config files (not the results themselves, nor
    what runs and installs leave in the tree), then the results files."""
    import os

    skip = {"build", "dist", "runs", "report", "out", "site", "mutants", "node_modules",
            "results", "__pycache__"}
    out = []
    for top, dirs, names in os.walk(ROOT):
        dirs[:] = [d for d in dirs if d not in skip and not d.startswith(".")]
        out += [Path(top) / n for n in names if n.endswith((".py", ".md", ".yml", ".toml"))]
    return sorted(out) + sorted(RESULTS.glob("*/*.md"))


def test_every_results_path_written_in_the_repository_exists() -> None:
    """A path ``benchmarks/results/CLAIM/NAME.md`` in a comment, a docstring or a page names
    a file that exists (placeholders such as ``NAME-DATE.md`` and globs must match one)."""
    missing = []
    for path in _sources():
        for name in _MENTION.findall(path.read_text(encoding="utf-8", errors="replace")):
            if re.search(r"\b(DATE|NAME|CLAIM)\b|<", name):
                continue
            if not list(RESULTS.glob(name)):
                missing.append(f"{path.relative_to(ROOT)}: benchmarks/results/{name}")
    assert missing == []


def _results_file(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    sys.modules.pop("results_file", None)
    import results_file

    return results_file


def test_results_file_writes_into_its_claim_and_never_reuses_a_name(tmp_path, monkeypatch):
    rf = _results_file(monkeypatch)
    first = rf.ResultsFile("speed", title="Speed", claim="exact-solves", directory=tmp_path)
    day = f"{first.started:%Y-%m-%d}"
    (tmp_path / "exact-solves" / "history").mkdir(parents=True)
    (tmp_path / "exact-solves" / "history" / f"speed-{day}.md").write_text("# older\n")
    p1 = first.write()
    assert p1 == tmp_path / "exact-solves" / f"speed-{day}-2.md"
    second = rf.ResultsFile("speed", title="Speed", claim="exact-solves", directory=tmp_path)
    second.add("a second run the same day")
    p2 = second.write()
    assert p2 == tmp_path / "exact-solves" / f"speed-{day}-3.md"
    first.add("more rows")
    assert first.write() == p1  # a run rewrites its own file, and only that one
    assert "a second run" in p2.read_text() and "more rows" in p1.read_text()
    assert (tmp_path / "exact-solves" / "history" / f"speed-{day}.md").read_text() == "# older\n"


def test_results_file_reserves_its_name_before_writing(tmp_path, monkeypatch):
    """Two runs that pick a name at the same moment: the second sees the first's claim."""
    rf = _results_file(monkeypatch)
    a = rf.ResultsFile("run", title="A", claim="c", directory=tmp_path)
    b = rf.ResultsFile("run", title="B", claim="c", directory=tmp_path)
    (tmp_path / "c").mkdir()
    chosen = a.path()
    assert b.path() == chosen  # nothing written yet: the same free name
    pa, pb = a.write(), b.write()
    assert pa == chosen and pb != pa and pb.parent == pa.parent


@pytest.mark.parametrize("claim", ["", "a/b", "..", ".hidden", "a\\b"])
def test_results_file_needs_a_plain_claim_folder(claim, monkeypatch):
    rf = _results_file(monkeypatch)
    with pytest.raises(ValueError):
        rf.ResultsFile("x", title="X", claim=claim)


def headline_cells(readme: str) -> list[str]:
    """The cells of the README's headline table (the first table after ``## Headline``)."""
    section = readme.split("\n## Headline", 1)[1].split("\n## ", 1)[0]
    cells = []
    for line in section.splitlines():
        m = _ROW.match(line.strip())
        if m:
            row = [c.strip() for c in re.split(r"(?<!\\)\|", m.group(1))]
            if not all(set(c) <= set("-: ") for c in row):
                cells += row
    return cells


def _words(cell: str) -> int:
    return len(re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", cell).split())


def test_headline_cells_are_short_and_link_at_most_twice() -> None:
    """Every cell of the README's headline table: at most 40 words and two links (one
    figure; the detail is in the linked results file or a docs page), and every figure's
    row links a file of ``benchmarks/results/``."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    cells = headline_cells(readme)
    assert len(cells) >= 3 * 6
    long = [c for c in cells if _words(c) > 40 or len(_LINK.findall(c)) > 2]
    assert long == []
    rows = [cells[i:i + 3] for i in range(3, len(cells), 3)]
    for what, _, where in rows:
        assert any(t.startswith("benchmarks/results/") for t in _LINK.findall(where)), what


def test_the_headline_check_counts_words_and_links() -> None:
    cell = " ".join(["word"] * 39) + " [a link](x.md)"
    assert _words(cell) == 41
    where = "[r](benchmarks/" "results/a/b.md)"  # split: not a path of this repository
    table = ("\n## Headline figures\n\n| what | figure | measured in |\n| --- | --- | --- |\n"
             f"| a | {cell} | {where} |\n\n## Next\n| x | y |\n")
    assert headline_cells(table) == ["what", "figure", "measured in", "a", cell, where]
