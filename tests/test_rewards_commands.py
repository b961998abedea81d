"""``zsrm reward`` and ``zsrm reward-curve`` end to end, with a small randomly initialised scene VLM."""
import csv
import json

import numpy as np
import pytest
from PIL import Image

from zsrm.cli import main
from zsrm.rewards import BaseReward
from zsrm.rewards.files import read_image, score_files

GOAL = "a yellow puck close to a blue puck"


@pytest.fixture(scope="module")
def vlm_folder(tmp_path_factory):
    from zsrm.vlm.scene import create_scene_vlm

    folder = tmp_path_factory.mktemp("vlm")
    create_scene_vlm("tiny", seed=0).save(folder)
    return folder


@pytest.fixture
def images(tmp_path):
    rng = np.random.default_rng(0)
    paths = []
    for i, (size, ext) in enumerate([(64, "png"), (64, "jpg"), (48, "png")]):
        path = tmp_path / f"frame{i}.{ext}"
        Image.fromarray(rng.integers(0, 255, (size, size, 3), dtype=np.uint8)).save(path)
        paths.append(path)
    return paths


def test_reward_prints_one_score_per_image(vlm_folder, images, capsys):
    from zsrm.vlm import load_vlm

    assert main(["reward", "--goal", GOAL, "--vlm", str(vlm_folder), *map(str, images)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split("\t")[1] for line in lines] == list(map(str, images))
    printed = np.array([float(line.split("\t")[0]) for line in lines])
    reward = BaseReward(load_vlm(vlm_folder), mode="dot")
    want = [reward.score(read_image(p)[None], GOAL)[0] for p in images]
    np.testing.assert_allclose(printed, want, atol=1e-5)


def test_reward_json_and_projection(vlm_folder, images, capsys):
    args = ["reward", "--goal", GOAL, "--vlm", str(vlm_folder), "--mode", "projection",
            "--baseline", "two pucks on a table", "--alpha", "1", "--json", *map(str, images[:2])]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mode"] == "projection" and len(out["scores"]) == 2
    assert all(-1.0 <= v <= 1.0 for v in out["scores"].values())


def test_score_files_groups_sizes(toy_vlm, images):
    scores = score_files(images, "a red block", BaseReward(toy_vlm, mode="cosine"))
    assert len(scores) == 3 and toy_vlm.image_calls == 2  # the two 64 px images in one batch


@pytest.mark.parametrize("extra, message", [
    (["--goal", "  "], "non-empty sentence"),
    (["--goal", GOAL, "--mode", "projection"], "needs --baseline"),
    (["--goal", GOAL, "--baseline", "a table"], "only with --mode projection"),
    (["--goal", GOAL, "--alpha", "2"], "--alpha must be in"),
])
def test_reward_bad_options(vlm_folder, images, capsys, extra, message):
    assert main(["reward", "--vlm", str(vlm_folder), *extra, str(images[0])]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_reward_bad_files(vlm_folder, tmp_path, capsys):
    assert main(["reward", "--goal", GOAL, "--vlm", str(vlm_folder), str(tmp_path / "missing.png")]) == 2
    assert "no such image file" in capsys.readouterr().err
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    assert main(["reward", "--goal", GOAL, "--vlm", str(vlm_folder), str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "cannot read" in err and len(err.splitlines()) == 1


def test_reward_curve_writes_table_and_plot(vlm_folder, tmp_path, capsys):
    out = tmp_path / "fig5"
    args = ["reward-curve", "--vlm", str(vlm_folder), "--steps", "6", "--image-size", "32", "--out", str(out)]
    assert main(args) == 0
    with out.with_suffix(".csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["step", "distance", "base_reward", "oracle"] and len(rows) == 7
    assert out.with_suffix(".png").stat().st_size > 10_000
    assert "spearman_with_closeness" in capsys.readouterr().out


def test_eval_reward_writes_its_curves_beside_a_report_written_elsewhere():
    from zsrm.pipeline.measure import EvalReward

    assert EvalReward().curves_folder() == "results/reward_curves"  # the committed figure's folder
    assert EvalReward(out="runs/x/reward.json").curves_folder() == "runs/x/reward_curves"
    assert EvalReward(out="runs/x/reward.json", curves="").curves_folder() == ""
    assert EvalReward(out="runs/x/reward.json", curves="elsewhere").curves_folder() == "elsewhere"
