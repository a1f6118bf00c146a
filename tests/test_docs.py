"""The documentation's rules: pages by reader, history only in the CHANGELOG, every relative link resolves.

``docs/*.md`` are user guides and method pages (the current behaviour), ``docs/results/*.md`` the measured figures
(each section with its command and commit), ``CHANGELOG.md`` the history. A dated entry in a guide or a method page
is history that belongs in the CHANGELOG.
"""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
GUIDES_AND_METHODS = sorted((REPO / "docs").glob("*.md")) + [REPO / "README.md"]
RESULTS = sorted((REPO / "docs" / "results").glob("*.md"))
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")
LINK = re.compile(r"\]\(([^)\s#]+\.md)(#[^)\s]*)?\)")


def _anchors(page: Path) -> set[str]:
    """GitHub's anchors of a page's headings: lower case, punctuation dropped, spaces to dashes."""
    headings = re.findall(r"^#+\s+(.*)$", page.read_text(), flags=re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-") for heading in headings}


@pytest.mark.parametrize("page", GUIDES_AND_METHODS, ids=lambda page: page.name)
def test_guides_and_method_pages_hold_no_dated_entries(page):
    dated = [line for line in page.read_text().splitlines() if DATE.search(line)]
    assert dated == [], f"{page.name}: dated lines belong in CHANGELOG.md: {dated[:3]}"


def test_every_results_page_names_its_commands_and_commits():
    assert len(RESULTS) >= 5
    for page in RESULTS:
        text = page.read_text()
        assert re.search(r"\bcommit\b", text) and "`" in text, page.name
        assert re.search(r"\b[0-9a-f]{7}\b", text), f"{page.name} names no commit"


def test_index_lists_every_page():
    index = (REPO / "docs" / "index.md").read_text()
    listed = {Path(target).as_posix() for target, _ in LINK.findall(index)}
    pages = {page.relative_to(REPO / "docs").as_posix() for page in (REPO / "docs").glob("*.md") if page.name != "index.md"}
    pages |= {page.relative_to(REPO / "docs").as_posix() for page in RESULTS}
    assert pages - listed == set()


@pytest.mark.parametrize("page", GUIDES_AND_METHODS + RESULTS + [REPO / "CHANGELOG.md"], ids=lambda page: page.name)
def test_relative_links_resolve(page):
    broken = []
    for target, anchor in LINK.findall(page.read_text()):
        if "://" in target:
            continue
        linked = (page.parent / target).resolve()
        if not linked.exists():
            broken.append(target)
        elif anchor and anchor[1:] not in _anchors(linked):
            broken.append(target + anchor)
    assert broken == [], f"{page.name}: {broken}"


def test_pages_named_in_the_code_exist():
    named = set()
    for package in ("humancal", "assets", "pipelines", "evaluation", "resources", "scripts", "tests"):
        for module in (REPO / package).rglob("*.py"):
            named |= set(re.findall(r"\bdocs/[\w/]+\.md\b", module.read_text()))
    assert len(named) > 10
    assert sorted(page for page in named if not (REPO / page).exists()) == []
