"""The built docs site renders what its sources mean.

Builds the site with ``mkdocs build --strict`` (offline, about 5 s) into a temporary folder
and reads the HTML: the API reference has no raw Sphinx role (``:func:`x```: mkdocstrings
renders docstrings as Markdown, where the docstrings write `x` or [`x`][full.path]), and
no page shows a literal ``\\|`` (the sources escape pipes of table code spans for GitHub;
``docs/hooks.py`` unescapes them for Python-Markdown). Skipped without the docs extra.
"""

from __future__ import annotations

import html
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mkdocs")
pytest.importorskip("mkdocstrings")
pytest.importorskip("material")

ROOT = Path(__file__).resolve().parents[2]
ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const|ref):(?=[`\w~])")
TAG = re.compile(r"<[^>]+>")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "-d", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
        env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return out


def _text_lines(page: Path) -> list[str]:
    """The page's visible text, one line per source line (tags removed, entities decoded)."""
    return [html.unescape(TAG.sub("", line)) for line in page.read_text("utf-8").splitlines()]


def test_api_pages_have_no_raw_sphinx_role(site):
    pages = sorted((site / "api").glob("*/index.html"))
    assert len(pages) >= 4, pages
    raw = [
        f"{page.parent.name}: {line.strip()[:160]}"
        for page in pages
        for line in _text_lines(page)
        if ROLE.search(line)
    ]
    assert not raw, f"{len(raw)} API lines with a raw Sphinx role:\n" + "\n".join(raw[:40])


def test_no_page_shows_an_escaped_pipe(site):
    cli = site / "cli" / "index.html"
    assert "geodesics certify" in cli.read_text("utf-8")
    pages = [cli, site / "index.html", *sorted((site / "guides").glob("*/index.html"))]
    shown = [
        f"{page.relative_to(site)}: {line.strip()[:160]}"
        for page in pages
        for line in _text_lines(page)
        if "\\|" in line
    ]
    assert not shown, "literal \\| on the site:\n" + "\n".join(shown[:20])


def test_cli_table_keeps_its_choices(site):
    """The unescaping keeps the pipe itself (and the row in one cell)."""
    text = "\n".join(_text_lines(site / "cli" / "index.html"))
    assert "[--mesh coarse|default|fine|p2]" in text
