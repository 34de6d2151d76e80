"""The repository's own design page (docs/design.md) is what docstrings cite: it exists, it is in the site's
navigation, and every section a docstring points to (`docs/design.md#anchor`) is a heading of it."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "docs" / "design.md"


def anchors() -> set[str]:
    """mkdocs' anchors of the page's headings: lower case, punctuation dropped, spaces as hyphens."""
    headings = re.findall(r"^#+ (.+)$", DESIGN.read_text(), re.M)
    return {re.sub(r"\s+", "-", re.sub(r"[^\w\s-]", "", h).strip().lower()) for h in headings}


def test_every_cited_section_of_the_design_page_exists():
    known = anchors()
    cited = {}
    for path in (ROOT / "src").rglob("*.py"):
        for anchor in re.findall(r"docs/design\.md#([\w-]+)", path.read_text()):
            cited.setdefault(anchor, str(path.relative_to(ROOT)))
    assert cited, "no docstring cites docs/design.md"
    missing = {a: where for a, where in cited.items() if a not in known}
    assert not missing, f"sections cited but not in docs/design.md (headings give {sorted(known)}): {missing}"


def test_no_docstring_points_to_a_design_file_outside_the_repository():
    stale = [str(p.relative_to(ROOT)) for p in (ROOT / "src").rglob("*.py") if "DESIGN.md" in p.read_text()]
    assert not stale, f"these cite a DESIGN.md the repository does not hold: {sorted(stale)}"


def test_the_design_page_is_in_the_site():
    assert "design.md" in (ROOT / "mkdocs.yml").read_text()
