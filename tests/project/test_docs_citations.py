"""The code cites the repository's own docs, and every citation and README link resolves.

The product contract the code was built to is not in the repository, so a citation of it
("SPEC 16") is one a reader cannot follow. Code, tests, benchmarks and scripts cite
`docs/<page>.md#<anchor>` instead; this keeps every such anchor a real heading of that page,
and every relative link of the README and the docs pages a real file (and heading).
"""

from __future__ import annotations

import re
from functools import cache
from itertools import pairwise
from pathlib import Path

import pytest
from markdown_it import MarkdownIt

ROOT = Path(__file__).resolve().parents[2]
CITING = ("app", "tests", "benchmarks", "scripts")
SUFFIXES = {".py", ".html", ".css", ".js", ".sh", ".toml", ".md", ".txt", ".cfg", ".ini"}
# "SPEC 16", "SPEC §4", "SPEC section 12", "spec section 12", "SPEC.md", "SPEC's", "SPEC:".
SPEC_CITATION = re.compile(
    r"\bSPEC(?:\s*(?:§|section)?\s*\d|\.md|'s|:)"  # the contract's own spelling
    r"|(?i:\bspec\s*(?:§|section)\s*\d)"  # and "spec section 12" in any case
)
DOC_CITATION = re.compile(r"\b((?:docs/[\w-]+|README)\.md)#([\w-]+)")
MD_LINK = re.compile(r"\]\(([^)\s]+)\)")


def _sources() -> list[Path]:
    return sorted(
        path
        for folder in CITING
        for path in (ROOT / folder).rglob("*")
        if path.is_file() and path.suffix in SUFFIXES and "__pycache__" not in path.parts
    )


def slug(heading: str) -> str:
    """GitHub's heading anchor: lowercase, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


@cache
def anchors(page: Path) -> frozenset[str]:
    """The anchors of a page's headings (code fences are not headings); repeats get -1, -2."""
    tokens = MarkdownIt().parse(page.read_text(encoding="utf-8"))
    seen: dict[str, int] = {}
    found = []
    for opening, inline in pairwise(tokens):
        if opening.type != "heading_open":
            continue
        words = ("text", "code_inline")
        text = "".join(child.content for child in inline.children or [] if child.type in words)
        base = slug(text)
        repeat = seen.get(base, 0)
        seen[base] = repeat + 1
        found.append(f"{base}-{repeat}" if repeat else base)
    return frozenset(found)


def test_slug_follows_github() -> None:
    assert slug("`llm_scope`: ask the model only where it matters") == (
        "llm_scope-ask-the-model-only-where-it-matters"
    )
    assert slug("In `/allocate`, the readers and the command line") == (
        "in-allocate-the-readers-and-the-command-line"
    )
    assert slug("Reading a run's schedule") == "reading-a-runs-schedule"


def test_anchors_skip_code_fences_and_number_repeats(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("# Top\n\n## Pins\n\n```bash\n# not a heading\n```\n\n### Pins\n")
    assert anchors(page) == {"top", "pins", "pins-1"}


def test_the_patterns_find_every_form_and_nothing_else() -> None:
    cited = ["(SPEC 16)", "SPEC §4", "SPEC section 12", "see spec section 3", "SPEC.md", "SPEC's"]
    assert all(SPEC_CITATION.search(text) for text in cited)
    assert not any(SPEC_CITATION.search(text) for text in ["_SPECS = {}", "spec: RunSpec"])
    line = "rules (docs/schedules.md#a-schedule-and-its-check; README.md#console)"
    assert DOC_CITATION.findall(line) == [
        ("docs/schedules.md", "a-schedule-and-its-check"),
        ("README.md", "console"),
    ]


def test_no_citation_of_the_contract_outside_the_repository() -> None:
    found = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
        for path in _sources()
        if path.name != Path(__file__).name
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if SPEC_CITATION.search(line)
    ]
    assert not found, "cite docs/<page>.md#<anchor> instead:\n" + "\n".join(found)


def _citations() -> list[tuple[str, str, str]]:
    return [
        (f"{path.relative_to(ROOT)}:{number}", page, anchor)
        for path in _sources()
        if path.name != Path(__file__).name
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        for page, anchor in DOC_CITATION.findall(line)
    ]


def test_the_code_cites_the_docs() -> None:
    # Guards the guard: a pattern that matched nothing would pass every check below.
    assert len(_citations()) > 200


@pytest.mark.parametrize("where,page,anchor", _citations())
def test_every_cited_anchor_is_a_heading(where: str, page: str, anchor: str) -> None:
    target = ROOT / page
    assert target.is_file(), f"{where}: {page} does not exist"
    assert anchor in anchors(target), (
        f"{where}: {page} has no heading '#{anchor}'; its anchors: {sorted(anchors(target))}"
    )


def _doc_links() -> list[tuple[str, Path, str]]:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    links = []
    for page in pages:
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            for target in MD_LINK.findall(line):
                if not re.match(r"[a-z][a-z+.-]*:", target):  # http:, mailto: ... are not ours
                    links.append((f"{page.relative_to(ROOT)}:{number}", page, target))
    return links


@pytest.mark.parametrize("where,page,target", _doc_links())
def test_every_relative_link_of_the_docs_resolves(where: str, page: Path, target: str) -> None:
    file, _, anchor = target.partition("#")
    linked = (page.parent / file).resolve() if file else page
    assert linked.exists(), f"{where}: {file} does not exist"
    if anchor and linked.suffix == ".md":
        assert anchor in anchors(linked), f"{where}: {file or page.name} has no heading '#{anchor}'"
