"""The user documentation is reference text for a newcomer: the README short, no history in it or in docs/ (no
issue numbers, no commit hashes: git keeps those; measured figures live in benchmarks/RESULTS.md with theirs),
and every relative link resolving to a file of the repository."""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").rglob("*.md"))]

#: "issue 14", "issues 13 and 16", "#12": a tracker's numbers, history for git
ISSUE = re.compile(r"\bissues? \d+|(?<![\w&/])#\d+\b", re.I)
#: a hex word of 7 to 40 characters with both a digit and a letter: a commit hash
HEXWORD = re.compile(r"(?<![\w.-])[0-9a-f]{7,40}(?![\w.-])")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _is_hash(word: str) -> bool:
    return any(c.isdigit() for c in word) and any(c.isalpha() for c in word)


def _lines(page: Path):
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), start=1):
        yield f"{page.relative_to(ROOT)}:{number}", line


def test_the_readme_is_short():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 250


def test_the_user_docs_exist():
    assert (ROOT / "docs" / "index.md").is_file()
    assert len(PAGES) > 5


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_issue_numbers_or_commit_hashes(page):
    found = [f"{where}: {m.group(0)!r}" for where, line in _lines(page) for m in ISSUE.finditer(line)]
    found += [f"{where}: {m.group(0)!r}" for where, line in _lines(page) for m in HEXWORD.finditer(line)
              if _is_hash(m.group(0))]
    assert found == []


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    broken = []
    for where, line in _lines(page):
        for target in LINK.findall(line):
            if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
                continue  # a web address or an anchor on the same page
            path = unquote(target.split("#", 1)[0])
            if not (page.parent / path).exists():
                broken.append(f"{where}: {target}")
    assert broken == []


def test_the_patterns_catch_what_they_should():
    assert ISSUE.search("as issue 14 asked") and ISSUE.search("see #12.") and ISSUE.search("issues 13 and 16")
    assert not ISSUE.search("Tables 1-2, the 3rd issue of the journal, C#, &#8212;")
    assert [m.group(0) for m in HEXWORD.finditer("at 95cf4e6, f2404f4 and 3dc695d")] == ["95cf4e6", "f2404f4",
                                                                                       "3dc695d"]
    words = "the defaults, 1000000 samples, deadbeef, 0.1912765, 1e-7, 2.5e-05 and x10 0x1f"
    assert [w for w in (m.group(0) for m in HEXWORD.finditer(words)) if _is_hash(w)] == []
