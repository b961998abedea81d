"""The `zsrm` command line for the scenes, and the demo report."""
import csv
import json

import numpy as np
from PIL import Image

from zsrm.cli import main


def test_render_writes_three_cameras_side_by_side(tmp_path):
    out = tmp_path / "stack.png"
    assert main(["render", "stack", "--out", str(out), "--size", "64"]) == 0
    assert np.asarray(Image.open(out)).shape == (64, 192, 3)


def test_render_accepts_a_goal_sentence(tmp_path):
    out = tmp_path / "goal.png"
    assert main(["render", "a green block on the left of a blue block", "--out", str(out), "--size", "32"]) == 0
    assert out.exists()


def test_bad_goal_is_one_clear_line(tmp_path, capsys):
    assert main(["render", "a purple block on top of a red block", "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown colour 'purple'" in err[0] and "Traceback" not in err[0]


def test_scripted_eval_writes_json(tmp_path):
    out = tmp_path / "s.json"
    assert main(["scripted-eval", "--tasks", "stack", "--episodes", "1", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["stack"] == 1.0


def test_demo_writes_a_report(tmp_path):
    out = tmp_path / "report"
    assert main(["demo", "--out", str(out), "--episodes", "1"]) == 0
    for name in ("README.md", "scenes.png", "policies.csv", "policies.png", "random_episode_tabletop.gif",
                 "reward_yellow_puck_blue.csv", "reward_yellow_block_red.png"):
        assert (out / name).exists(), name
    with open(out / "reward_yellow_block_red.csv") as f:
        curve = list(csv.DictReader(f))
    assert {"base_reward", "zsrm_reward", "oracle"} <= set(curve[0])
    assert {float(r["zsrm_reward"]) for r in curve} <= {0.0, 1.0}  # the binarised reward
    assert "zsrm agrees with oracle" in (out / "README.md").read_text()
    rows = json.loads((out / "policies.json").read_text())
    assert {r["policy"] for r in rows} == {"random", "scripted"}
