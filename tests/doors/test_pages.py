"""The pages a reader opens: README.md, docs/ and the tests' own notes. Every relative link, inline ``[a](b)`` or
reference-style ``[a]: b``, leads to a file or folder the repository tracks (one left untracked here would be missing
from a clone), and no page keeps a placeholder that a script was to fill (an earlier session left ``E51_TABLE``
in docs/bodies/humanoid.md for a day)."""

from __future__ import annotations

import re
import subprocess
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted([ROOT / "README.md", *ROOT.glob("docs/**/*.md"), *ROOT.glob("tests/**/*.md")])
LINK = re.compile(r"\]\(([^)\s]+)\)")  # [text](target)
REFERENCE = re.compile(r"^ {0,3}\[(?!\^)[^\]]+\]:[ \t]*<?([^>\s]+)>?", re.MULTILINE)  # [label]: target, not [^1]:
#: a bare upper-case token ending as the scripts name what they fill in (not one quoted as code: `EXPLORE_TEXT`)
PLACEHOLDER = re.compile(r"(?<![`\w])[A-Z][A-Z0-9]*_(?:TABLE|TEXT|FIGURE|ROWS|HERE)\b")


@cache
def tracked() -> frozenset[Path] | None:
    """Every file git tracks in this checkout and every folder holding one; None outside a git checkout (then a
    link's target need only exist)."""
    try:
        listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    files = [ROOT / name for name in listed.decode("utf-8", "replace").split("\0") if name]
    folders = (folder for f in files for folder in f.parents if folder == ROOT or ROOT in folder.parents)
    return frozenset([*files, *folders])


def broken_links(page: Path, known: frozenset[Path] | None = None) -> list[str]:
    """The page's relative links whose target is missing (or, given ``known``, not among those paths)."""
    text = page.read_text(encoding="utf-8")
    out = []
    for link in [*LINK.findall(text), *REFERENCE.findall(text)]:
        if re.match(r"[a-z][a-z0-9+.-]*:", link) or link.startswith("#"):  # a web address, mailto:, an anchor
            continue
        target = (page.parent / link.split("#")[0]).resolve()
        if not target.exists() or (known is not None and target not in known):
            out.append(link)
    return out


def test_there_are_pages_to_check():
    assert len(PAGES) > 20


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_leads_to_a_file_and_no_placeholder_is_left(page):
    assert broken_links(page, tracked()) == []
    assert PLACEHOLDER.findall(page.read_text(encoding="utf-8")) == []


def test_the_checks_catch_a_broken_link_and_a_placeholder(tmp_path):
    page = tmp_path / "page.md"
    (tmp_path / "here.md").write_text("a page that exists, untracked\n", encoding="utf-8")
    page.write_text(
        "see [there](missing.md), [web](https://example.org), [ref][r] and [ok](here.md)\n\n"
        "[r]: gone/file.py\n\nE51_TABLE\n",
        encoding="utf-8",
    )
    assert broken_links(page) == ["missing.md", "gone/file.py"]
    known = frozenset({(tmp_path / "page.md").resolve()})
    assert broken_links(page, known) == ["missing.md", "here.md", "gone/file.py"]
    assert broken_links(page, known | {(tmp_path / "here.md").resolve()}) == ["missing.md", "gone/file.py"]
    assert PLACEHOLDER.findall(page.read_text(encoding="utf-8")) == ["E51_TABLE"]
    note = tmp_path / "note.md"
    note.write_text("a footnote[^1] and a bare label line\n\n[^1]: not a link\n[x]:\nword\n", encoding="utf-8")
    assert broken_links(note) == []  # neither a footnote nor the next line's first word is read as a link


def test_a_folder_outside_the_repository_is_not_tracked():
    known = tracked()
    if known is None:
        pytest.skip("not a git checkout")
    assert ROOT in known and (ROOT / "docs").resolve() in known and ROOT.parent not in known
