"""results/README.md and README.md's headline table are what `zsrm results-page` writes from the result files."""
import doctest
import json
import shutil
from pathlib import Path

from zsrm.pipeline import results_page
from zsrm.pipeline.results_page import FIGURES, OTHER, SIDE, ResultsPage, headline, page, readme_with_headline, unlisted

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"


def test_the_committed_results_page_is_what_the_command_writes():
    assert (RESULTS / "README.md").read_text() == page(RESULTS), "results/README.md is stale: run zsrm results-page"


def test_the_readme_headline_numbers_equal_their_files():
    readme = (ROOT / "README.md").read_text()
    assert readme_with_headline(readme, RESULTS) == readme, "README.md's headline table is stale: run zsrm results-page"


def test_a_changed_result_file_changes_the_headline(tmp_path):
    for figure in FIGURES:
        (tmp_path / figure.file).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(RESULTS / figure.file, tmp_path / figure.file)
    assert headline(tmp_path) == headline(RESULTS)
    demo = json.loads((tmp_path / "demo.json").read_text())
    demo["zsrm_policy_mean"] += 1.0
    (tmp_path / "demo.json").write_text(json.dumps(demo))
    assert headline(tmp_path) != headline(RESULTS)


def test_every_results_file_is_a_figure_or_a_line_of_the_page():
    assert unlisted(RESULTS) == [], "results files the page does not name: add them to SIDE or OTHER"


def test_every_line_of_the_page_names_files_that_exist():
    files = [str(p.relative_to(RESULTS)) for p in RESULTS.rglob("*") if p.is_file()]
    for pattern, _ in SIDE + OTHER:
        assert any(_matches(f, pattern) for f in files), f"no file under results/ matches {pattern!r}"
    assert all((RESULTS / f.file).is_file() for f in FIGURES)


def test_side_experiments_live_under_side():
    assert all(pattern.startswith("side/") for pattern, _ in SIDE)
    assert not any(pattern.startswith("side/") for pattern, _ in OTHER)


def test_the_command_checks_and_writes(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert ResultsPage(check=True).run() == 0
    readme = tmp_path / "README.md"
    readme.write_text((ROOT / "README.md").read_text().replace("| 0.977 / 1.000 |", "| 0.999 / 1.000 |"))
    assert ResultsPage(readme=str(readme), check=True).run() == 1
    assert ResultsPage(readme=str(readme)).run() == 0
    assert readme.read_text() == (ROOT / "README.md").read_text()


def _matches(file: str, pattern: str) -> bool:
    import fnmatch

    return fnmatch.fnmatch(file, pattern.replace("**", "*"))


def test_docstring_examples():
    result = doctest.testmod(results_page)
    assert result.attempted > 0 and result.failed == 0
