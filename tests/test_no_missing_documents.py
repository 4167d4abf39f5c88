"""No tracked file cites a document the repository lacks: no design-brief section citations (the
brief is not part of the repository), and every docs/ or README link, anchor included, resolves.
The README lists every page of docs/, and the thesis is cited in full."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEXT_SUFFIXES = {".py", ".toml", ".md", ".sh", ".txt", ".cfg", ".json", ".yml", ".yaml", ".html"}
#: a citation of the design brief, which the repository does not contain
BRIEF = re.compile(r"\bSPEC(?:\s*\d|\.md\b|\b)")
#: a path to a page of ours, optionally with an anchor, as code and docs cite them
PAGE = re.compile(r"(?<![\w/.-])((?:docs/)?[\w-]+\.md|README\.md)(#[\w-]+)?")


def tracked_text_files() -> list[Path]:
    try:
        names = subprocess.run(["git", "-C", str(ROOT), "ls-files"], capture_output=True, text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [ROOT / n for n in names if (ROOT / n).suffix in TEXT_SUFFIXES or n == "Makefile"]


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = heading.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    return {slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", page.read_text(encoding="utf-8"), re.M)}


def test_no_file_cites_the_design_brief():
    offenders = []
    for path in tracked_text_files():
        if path == Path(__file__).resolve():
            continue
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if BRIEF.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert not offenders, "\n".join(offenders)


def test_every_page_link_and_anchor_resolves():
    broken, checked = [], 0
    for path in tracked_text_files():
        if path == Path(__file__).resolve():
            continue
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            for match in PAGE.finditer(line):
                target, anchor = match.group(1), match.group(2)
                # relative links inside docs/ point at siblings; everywhere else paths are from the root
                base = path.parent if path.parent.name == "docs" and not target.startswith("docs/") else ROOT
                page = (base / target).resolve()
                if not page.is_file():
                    if target.startswith(("docs/", "README")) or path.parent.name == "docs":
                        broken.append(f"{path.relative_to(ROOT)}:{number}: {target} does not exist")
                    continue
                checked += 1
                if anchor and anchor[1:] not in anchors(page):
                    broken.append(f"{path.relative_to(ROOT)}:{number}: {target}{anchor}: no such heading")
    assert not broken, "\n".join(broken)
    assert checked > 50  # the code and the docs cite their pages: the scan saw them


def test_readme_lists_every_docs_page_and_the_thesis_is_cited_in_full():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    pages = sorted(p.name for p in (ROOT / "docs").glob("*.md"))
    assert pages, "docs/ is empty"
    for name in pages:
        assert f"(docs/{name})" in readme, name
    references = " ".join((ROOT / "docs" / "references.md").read_text(encoding="utf-8").split())
    assert "Benemerito, I." in references
    assert "Extended Discrete Element Method for subject specific modelling and analysis of the ankle joint contact mechanics" in references
    assert "INSIGNEO Institute" in references and "2018" in references
