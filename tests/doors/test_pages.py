"""The pages a reader opens: README.md, docs/ and the tests' own notes. Every relative link leads to a file or folder
of the repository, and no page keeps a placeholder that a script was to fill (an earlier session left ``E51_TABLE``
in docs/bodies/humanoid.md for a day)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted([ROOT / "README.md", *ROOT.glob("docs/**/*.md"), *ROOT.glob("tests/**/*.md")])
LINK = re.compile(r"\]\(([^)\s]+)\)")
#: a bare upper-case token ending as the scripts name what they fill in (not one quoted as code: `EXPLORE_TEXT`)
PLACEHOLDER = re.compile(r"(?<![`\w])[A-Z][A-Z0-9]*_(?:TABLE|TEXT|FIGURE|ROWS|HERE)\b")


def broken_links(page: Path) -> list[str]:
    out = []
    for link in LINK.findall(page.read_text(encoding="utf-8")):
        if re.match(r"[a-z][a-z0-9+.-]*:", link) or link.startswith("#"):  # a web address, mailto:, an anchor
            continue
        if not (page.parent / link.split("#")[0]).exists():
            out.append(link)
    return out


def test_there_are_pages_to_check():
    assert len(PAGES) > 20


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_leads_to_a_file_and_no_placeholder_is_left(page):
    assert broken_links(page) == []
    assert PLACEHOLDER.findall(page.read_text(encoding="utf-8")) == []


def test_the_checks_catch_a_broken_link_and_a_placeholder(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("see [there](missing.md) and [here](https://example.org)\n\nE51_TABLE\n", encoding="utf-8")
    assert broken_links(page) == ["missing.md"]
    assert PLACEHOLDER.findall(page.read_text(encoding="utf-8")) == ["E51_TABLE"]
