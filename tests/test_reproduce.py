"""zsrm reproduce at a tiny scale, end to end: every report artifact exists and parses, stages
are cached, and the report renders in a real (headless) browser with every figure loaded."""
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from PIL import Image

from zsrm.pipeline.reproduce import Reproduce

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def tiny_report(tmp_path_factory):
    root = tmp_path_factory.mktemp("reproduce")
    report, workdir = root / "report", root / "work"
    Reproduce(scale="tiny", workdir=str(workdir), report=str(report)).run()
    return report, workdir


def test_tiny_pipeline_writes_every_artifact(tiny_report):
    report, workdir = tiny_report
    page = (report / "index.html").read_text()
    markdown = (report / "README.md").read_text()
    assert "A policy trained from a sentence" in page and "Learning signal" in markdown
    figures = re.findall(r'<img class="figure" src="([^"]+)"', page)
    assert len(figures) >= 3  # the learning curve and the two GIFs at least
    for src in figures:
        with Image.open(report / src) as img:  # each figure exists and is a readable image
            img.verify()
    result = json.loads((report / "demo.json").read_text())
    for key in ("wall_s", "task", "zsrm_policy_mean", "zsrm_policy_se", "random_policy_mean", "random_policy_se"):
        assert key in result
    for stage in ("models", "policy_zsrm", "policy_random", "gifs"):
        assert json.loads((workdir / stage / "stage.json").read_text())["stage"] == stage


def test_finished_stages_are_skipped(tiny_report, tmp_path, capsys):
    report, workdir = tiny_report
    Reproduce(scale="tiny", workdir=str(workdir), report=str(tmp_path / "again")).run()
    out = capsys.readouterr().out
    assert out.count("cached") == 4


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is installed by tools/setup.sh (Debian package)")
def test_report_renders_in_a_headless_browser(tiny_report, tmp_path):
    report, _ = tiny_report
    dom = subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={tmp_path}",
         "--virtual-time-budget=5000", "--dump-dom", (report / "index.html").resolve().as_uri()],
        capture_output=True, text=True, timeout=120).stdout
    loaded = re.search(r'data-figures-loaded="(\d+)/(\d+)"', dom)
    assert loaded, "the page's load script did not run"
    ok, total = map(int, loaded.groups())
    assert total >= 3 and ok == total, f"{total - ok} of {total} figures did not load"


def test_tiny_cpu_scale_runs_every_stage(tmp_path):
    """The cpu scale's whole chain (pretrain, label, student, Ray sweep, task policies, rollouts,
    distill, Table 2) at a tiny size: every stage finishes and the report shows the run's own results."""
    report, workdir = tmp_path / "report", tmp_path / "work"
    Reproduce(scale="tiny-cpu", workdir=str(workdir), report=str(report)).run()
    stages = ("vlm", "data", "student", "policies", "task_policies", "rollouts", "distill", "table2")
    for stage in stages:
        assert json.loads((workdir / stage / "stage.json").read_text())["stage"] == stage
    learning = json.loads((workdir / "policies" / "learning.json").read_text())
    assert set(learning["place_right"]) == {"oracle", "zsrm", "random"}
    table = json.loads((workdir / "table2" / "table2.json").read_text())
    for policy in ("language", "primitive", "none"):
        assert {"mean", "se"} <= set(table[policy]["seen"]["test"])
    page = (report / "index.html").read_text()
    assert "What this run trained" in page
    for src in re.findall(r'<img class="figure" src="([^"]+)"', page):
        with Image.open(report / src) as img:
            img.verify()


def test_the_demo_learner_is_named_and_its_expected_range_read_from_its_sweep():
    from zsrm.pipeline.report import LEARNING_BY_CONFIG, expected_range
    from zsrm.pipeline.reproduce import SCALES, demo_stages

    by_name = {c: {s.name: s for s in demo_stages(SCALES["demo"], "scene", c)} for c in ("cpu", "v2")}
    assert by_name["cpu"]["policy_zsrm"].config["eval_deterministic"] is True
    assert "log_std_init" not in by_name["v2"]["policy_zsrm"].config  # v2's noise, as its runs wrote it
    assert by_name["v2"]["policy_zsrm"].config["eval_deterministic"] is False
    assert by_name["v2"]["policy_zsrm"].command.endswith("--config v2")
    spread = expected_range("place_right", learning=LEARNING_BY_CONFIG["cpu"])
    committed = json.loads(LEARNING_BY_CONFIG["cpu"].read_text())["place_right"]["zsrm"]["final_per_seed"]
    assert spread["seeds"] == len(committed) and spread["seeds_min"] == round(min(committed), 1)
    with pytest.raises(ValueError, match="--config is for the demo scales"):
        Reproduce(scale="cpu", config="v2").run()
