"""MkDocs hook: publish ``benchmarks/results/*.md`` under ``results/`` in the site.

The measured results live beside the scripts that write them, not in ``docs/``; this hook
adds each file to the build (so the guides' relative links ``results/NAME.md`` are checked
by ``mkdocs build --strict``) and writes ``results/index.md``: the folder's README followed
by a list of every file with its title.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File

RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"


def _title(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return path.stem


def on_files(files, config):
    listing = []
    for path in sorted(RESULTS.glob("*.md")):
        if path.name == "README.md":
            continue
        files.append(File.generated(config, f"results/{path.name}", abs_src_path=str(path)))
        listing.append(f"- [{_title(path)}]({path.name})")
    readme = (RESULTS / "README.md").read_text(encoding="utf-8")
    index = readme.rstrip() + "\n\n## Files\n\n" + "\n".join(listing) + "\n"
    files.append(File.generated(config, "results/index.md", content=index))
    return files
