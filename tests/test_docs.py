"""README.md and docs/: every docs page is linked from the README, no relative link is broken, the
README's Python example runs."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "results" / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _slug(heading: str) -> str:
    """GitHub's anchor of a markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    return {_slug(m.group(1)) for m in re.finditer(r"^#+ (.+)$", text, flags=re.M)}


def _relative_links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    return [link for link in LINK.findall(text) if not re.match(r"^[a-z]+:", link)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_relative_link_is_broken(page):
    broken = []
    for link in _relative_links(page):
        target, _, anchor = link.partition("#")
        path = (page.parent / target).resolve() if target else page
        if not path.exists():
            broken.append(link)
        elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
            broken.append(f"{link} (no such heading)")
    assert not broken, f"{page.relative_to(ROOT)}: broken links: {broken}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_pasted_error_output(page):
    """A table made by a script that failed leaves its traceback in the page instead."""
    text = page.read_text()
    assert "Traceback (most recent call last)" not in text, f"{page.relative_to(ROOT)} holds a traceback"


def test_every_docs_page_is_linked_from_the_readme():
    linked = {(ROOT / link.partition("#")[0]).resolve() for link in _relative_links(ROOT / "README.md")}
    missing = [p.name for p in (ROOT / "docs").glob("*.md") if p.resolve() not in linked]
    assert not missing, f"docs pages the README does not link: {missing}"


def test_the_readme_is_short():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 250


def test_the_link_checker_sees_a_broken_link(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n[ok](page.md#title) [bad](missing.md) [web](https://example.com)\n```\n[x](y.md)\n```\n")
    assert _relative_links(page) == ["page.md#title", "missing.md"]
    assert "title" in _anchors(page)


def test_the_readme_reward_example_runs():
    text = (ROOT / "README.md").read_text()
    code = re.search(r"## A reward from a sentence\n\n```python\n(.*?)```", text, flags=re.S).group(1)
    *setup, reward_line, oracle_line = code.splitlines()  # the last two lines show their values
    namespace: dict = {}
    exec(compile("\n".join(setup), "README.md", "exec"), namespace)
    assert float(eval(reward_line.split("#")[0], namespace)[0]) == 0.0
    assert eval(oracle_line.split("#")[0], namespace) == 0.0
