"""MkDocs hook: publish ``benchmarks/results/`` under ``results/`` in the site.

The measured results live beside the scripts that write them, not in ``docs/``: one folder
per claim (its current files, and older runs in its ``history/``). This hook adds every
Markdown file of those folders to the build at the same relative path (so the guides'
relative links ``results/CLAIM/NAME.md`` are checked by ``mkdocs build --strict``) and
writes ``results/index.md``: the folder's README (the table of claims) followed by a list
of every file with its title, claim by claim. It also unescapes ``\\|`` inside the code
spans of table rows (see `on_page_markdown`).
"""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"

_TABLE_CODE = re.compile(r"`[^`\n]*`")


def _title(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return path.stem


def on_files(files, config):
    listing = []
    for folder in sorted(p for p in RESULTS.iterdir() if p.is_dir()):
        current = sorted(folder.glob("*.md"))
        history = sorted((folder / "history").glob("*.md"))
        if not current and not history:
            continue  # a cache, not a claim
        listing.append(f"\n### {folder.name}\n")
        for path in current + history:
            rel = path.relative_to(RESULTS).as_posix()
            files.append(File.generated(config, f"results/{rel}", abs_src_path=str(path)))
            label = " (history)" if path.parent.name == "history" else ""
            listing.append(f"- [{_title(path)}]({rel}){label}")
    readme = (RESULTS / "README.md").read_text(encoding="utf-8")
    index = readme.rstrip() + "\n\n## Files\n" + "\n".join(listing) + "\n"
    files.append(File.generated(config, "results/index.md", content=index))
    return files


def on_page_markdown(markdown, page, config, files):
    """A table row's code span ``a\\|b`` as ``a|b``.

    GitHub splits a table row on every unescaped ``|``, even inside a code span, so the
    sources write ``\\|`` there; Python-Markdown's tables do not split inside code spans
    and would show the backslash.
    """
    lines = markdown.split("\n")
    for i, line in enumerate(lines):
        if line.lstrip().startswith("|") and "\\|" in line:
            lines[i] = _TABLE_CODE.sub(lambda m: m.group(0).replace("\\|", "|"), line)
    return "\n".join(lines)
