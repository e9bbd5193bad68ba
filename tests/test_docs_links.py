"""Every relative link of the README, the changelog, the manual (``docs/``) and the research
record (``experiments/``) leads somewhere: the file
exists and, for a ``page.md#anchor`` link, the page has that heading (GitHub's anchor
rule: lower case, punctuation dropped, spaces as hyphens)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FENCED = re.compile(r"```.*?```", re.S)
LINK = re.compile(r"\]\(([^)\s]+)\)")


def heading_anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading's text."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def page_anchors(page: Path) -> set[str]:
    text = FENCED.sub("", page.read_text(encoding="utf-8"))
    return {heading_anchor(line.lstrip("#")) for line in text.splitlines()
            if line.startswith("#")}


def test_heading_anchor_follows_github():
    assert heading_anchor(" The clean-up as the default") == "the-clean-up-as-the-default"
    assert heading_anchor("Test missions (flown once, 2026-12-02, the shipped prior: seed 0)") \
        == "test-missions-flown-once-2026-12-02-the-shipped-prior-seed-0"


def test_every_relative_link_of_the_readme_and_docs_resolves():
    pages = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md")),
             *sorted((ROOT / "experiments").rglob("*.md"))]
    broken = []
    for page in pages:
        for target in LINK.findall(FENCED.sub("", page.read_text(encoding="utf-8"))):
            if re.match(r"[a-z]+:", target):  # https:, mailto:
                continue
            path, _, anchor = target.partition("#")
            linked = page.parent / path if path else page
            if not linked.exists() or (anchor and linked.suffix == ".md"
                                       and anchor not in page_anchors(linked)):
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, broken
