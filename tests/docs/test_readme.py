"""README is a guide, not a report (issue 45): under 200 lines, and every link it gives into the docs lands on a page
and a heading that exist (the site's build checks its own pages' anchors; README is not one of them)."""

from __future__ import annotations

import re
from pathlib import Path

from markdown.extensions.toc import slugify

ROOT = Path(__file__).parents[2]
README = ROOT / "README.md"


def anchors(page: Path) -> set[str]:
    """The anchors of a Markdown page's headings, as the site (and GitHub, for these headings) writes them."""
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.M | re.S)  # no headings inside code blocks
    return {slugify(h.strip().strip("`"), "-") for h in re.findall(r"^#{1,6} (.+)$", text, flags=re.M)}


def test_readme_is_short():
    assert len(README.read_text().splitlines()) < 200


def test_readmes_links_land_on_a_page_and_a_heading():
    links = re.findall(r"\]\(([^)#\s]+)(?:#([\w-]+))?\)", README.read_text())
    assert any(anchor for _, anchor in links), "README links no section of the results page"
    for path, anchor in links:
        if "://" in path:
            continue
        target = ROOT / path
        assert target.exists(), f"README links {path}, which does not exist"
        if anchor:
            assert anchor in anchors(target), f"README links {path}#{anchor}, which is no heading there"


def test_the_results_page_starts_with_its_contents():
    page = (ROOT / "docs" / "results.md").read_text()
    contents = page.split("\n## ")[1]
    assert contents.startswith("Contents") and "(#fresh-clone)" in contents and "results-archive.md" in page
