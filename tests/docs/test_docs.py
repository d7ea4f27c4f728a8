"""Every relative link and ``#heading`` anchor in README.md and docs/ resolves.

README.md is read as GitHub renders it (GitHub's heading slugs); the pages under docs/ as
MkDocs builds them (Python-Markdown's slugs; ``results/CLAIM/NAME.md`` is published from
``benchmarks/results/CLAIM/NAME.md`` by ``docs/hooks.py``). ``mkdocs build --strict`` in CI
checks the site again, with the API reference; this test needs no MkDocs and runs with the suite.
"""

from __future__ import annotations

import importlib
import re
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
RESULTS = ROOT / "benchmarks" / "results"

_FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.S | re.M)
_CODE = re.compile(r"`[^`\n]*`")
_LINK = re.compile(r"(?<!!)\[[^\[\]\n]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
_HEADING = re.compile(r"^(#{1,6})[ \t]+(.+?)[ \t]*#*[ \t]*$", re.M)


def _strip_code(text: str) -> str:
    """The text without fenced blocks and inline code (links there are not links)."""
    return _CODE.sub("", _FENCE.sub("", text))


def github_slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*]|<[^>]+>", "", heading).strip().lower()
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def mkdocs_slug(heading: str) -> str:
    """Python-Markdown's ``toc`` slug (MkDocs' default), of the heading's plain text."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = re.sub(r"[`*]|<[^>]+>", "", text)
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(path: Path, slug) -> set[str]:
    """The anchors of a Markdown file's headings, with ``-1``, ``-2`` ... for repeats."""
    seen: dict[str, int] = {}
    out = set()
    for _, title in _HEADING.findall(_FENCE.sub("", path.read_text(encoding="utf-8"))):
        base = slug(title)
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}" if slug is github_slug else f"{base}_{n}")
    return out


def _docs_target(page: Path, target: str) -> Path:
    """Where a relative link of a docs page points in the source tree."""
    resolved = (page.parent / target).resolve()
    try:
        rel = resolved.relative_to(DOCS)
    except ValueError:
        return resolved
    if rel.parts[:1] == ("results",):
        if rel.parts[1:] == ("index.md",):
            return RESULTS / "README.md"
        return RESULTS.joinpath(*rel.parts[1:])
    return resolved


def broken_links(path: Path, *, site: bool) -> list[str]:
    """The relative links and anchors of ``path`` that do not resolve, one line each."""
    problems = []
    for target in _LINK.findall(_strip_code(path.read_text(encoding="utf-8"))):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):
            continue  # http:, https:, mailto: ... are not checked (no network in tests)
        file_part, _, anchor = target.partition("#")
        if site and file_part.endswith("/"):
            problems.append(f"{path.name}: {target}: link a page (.md), not a folder")
            continue
        dest = path if not file_part else (
            _docs_target(path, file_part) if site else (path.parent / file_part).resolve())
        if not dest.exists():
            problems.append(f"{path.name}: {target}: no such file {dest}")
            continue
        if anchor and dest.suffix == ".md":
            dest_slug = mkdocs_slug if site or dest.is_relative_to(DOCS) else github_slug
            known = anchors(dest, dest_slug)
            if dest == RESULTS / "README.md" and site:
                known.add("files")  # the list docs/hooks.py appends to the index
            if anchor not in known:
                problems.append(f"{path.name}: {target}: no heading #{anchor} in {dest.name}")
    return problems


def _pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md"))


def test_readme_links_and_anchors_resolve() -> None:
    assert broken_links(README, site=False) == []


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(DOCS)))
def test_docs_links_and_anchors_resolve(page: Path) -> None:
    assert broken_links(page, site=True) == []


def test_the_checker_finds_broken_links(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "# Title\n\n## A heading: with `code`\n\n"
        "[ok](#a-heading-with-code) [bad anchor](#no-such) [bad file](missing.md)\n"
        "[ok file](page.md#title) [bad file anchor](page.md#nope) "
        "`[not a link](missing2.md)` [web](https://example.org/x)\n\n"
        "```\n[in a fence](missing3.md)\n```\n")
    found = broken_links(page, site=False)
    assert len(found) == 3, found
    assert any("#no-such" in p for p in found)
    assert any("missing.md" in p for p in found)
    assert any("#nope" in p for p in found)
    assert not any("missing2" in p or "missing3" in p for p in found)


def test_slugs_follow_github_and_mkdocs() -> None:
    assert github_slug("Defining a new metric") == "defining-a-new-metric"
    assert github_slug("Bad input, and the tests that check the checks") == (
        "bad-input-and-the-tests-that-check-the-checks")
    assert github_slug("The actor relative (`actor_relative`, default)") == (
        "the-actor-relative-actor_relative-default")
    assert github_slug("a -- b") == "a----b"
    assert mkdocs_slug("a -- b") == "a-b"
    assert mkdocs_slug("`solvers.solve_batch`") == "solverssolve_batch"


def test_readme_is_a_front_door() -> None:
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 450


def test_every_page_is_in_the_nav() -> None:
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    listed = set(re.findall(r":\s*([\w./-]+\.md)\s*$", nav, flags=re.M))
    pages = {str(p.relative_to(DOCS)) for p in _pages()}
    assert pages - listed == set(), "pages missing from mkdocs.yml's nav"
    assert {p for p in listed if not p.startswith("results/")} - pages == set()


def test_api_reference_documents_the_public_names() -> None:
    """The API pages name the public entry points, and every ``:::`` target exists."""
    text = "\n".join(p.read_text(encoding="utf-8") for p in sorted((DOCS / "api").glob("*.md")))
    for name in ("solvers.solve_batch", "solvers.certify", "finsler.Metric",
                 "validation.testing.check"):
        assert f"## `{name}`" in text, name
    targets = re.findall(r"^::: ([\w.]+)", text, flags=re.M)
    assert len(targets) >= 40
    for target in targets:
        module, _, attr = target.rpartition(".")
        assert hasattr(importlib.import_module(module), attr), target


def test_moved_results_say_where_they_come_from() -> None:
    moved = sorted(RESULTS.glob("**/*-moved.md"))
    assert moved
    for path in moved:
        head = path.read_text(encoding="utf-8").split("\n\n", 2)[1]
        for field in ("- moved from the README", "- command", "- commit", "- machine",
                      "- date"):
            assert field in head, (path.name, field)
        assert re.search(r"`[0-9a-f]{10}` 20\d\d-\d\d-\d\d", head), path.name


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(DOCS)))
def test_docs_python_blocks_are_python(page: Path) -> None:
    """Every ```python block of the guides compiles (they are fragments: the README's blocks
    run in tests/docs/test_readme.py)."""
    for block in re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), re.S):
        compile(block, str(page), "exec")


def test_metrics_guide_lists_every_hook() -> None:
    """The hooks table of docs/guides/metrics.md has a row for every `finsler.hooks.HOOKS`."""
    from finsler.hooks import HOOKS

    text = (DOCS / "guides" / "metrics.md").read_text(encoding="utf-8")
    rows = set(re.findall(r"^\| `(\w+)", text, flags=re.M))
    assert set(HOOKS) - rows == set()
