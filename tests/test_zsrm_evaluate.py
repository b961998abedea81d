"""Evaluation of the rewards against the oracle (zsrm/evaluation/reward_quality.py, metrics.py) and the commands."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from zsrm.evaluation.metrics import auroc, best_threshold_f1, binary_metrics
from zsrm.evaluation.reward_quality import evaluate_rewards, rollout_frames, task_camera
from zsrm.rewards.binarised import ZSRMReward


def test_binary_metrics_on_known_counts():
    m = binary_metrics([1, 1, 1, 0, 0, 0], [1, 1, 0, 1, 0, 0])
    assert m["precision"] == pytest.approx(2 / 3) and m["recall"] == pytest.approx(2 / 3)
    assert m["f1"] == pytest.approx(2 / 3) and m["accuracy"] == pytest.approx(4 / 6)
    assert binary_metrics([0, 0], [1, 0])["f1"] == 0.0  # nothing predicted: 0, not a division error
    empty = binary_metrics([], [])  # no frames (a goal whose objects no frame holds): no warning
    assert empty["f1"] == 0.0 and np.isnan(empty["accuracy"])


def test_auroc_and_best_threshold():
    assert auroc([0.1, 0.2, 0.8, 0.9], [0, 0, 1, 1]) == 1.0
    assert auroc([0.9, 0.8, 0.2, 0.1], [0, 0, 1, 1]) == 0.0
    assert np.isnan(auroc([0.1, 0.2], [1, 1]))
    assert best_threshold_f1([0.1, 0.2, 0.8, 0.9], [0, 0, 1, 1]) == 1.0


def test_task_cameras():
    assert [task_camera(t) for t in ("stack", "place_left", "place_right", "push_close")] == \
        ["front", "front", "front", "tilted"]
    with pytest.raises(ValueError, match="unknown spatial task"):
        task_camera("pendulum")


def test_rollout_frames_hold_reached_and_unreached_goals():
    frames = rollout_frames("stack", scripted_episodes=1, random_episodes=1, seed=5, every=5, progress=False)
    assert frames.images.shape[1:] == (64, 64, 3) and frames.camera == "front"
    assert set(frames.source) == {"scripted", "random"}
    scripted = frames.source == "scripted"
    assert frames.success[scripted].any() and not frames.success[scripted][0]  # reached, not at the start
    assert len(set(frames.episode)) == 2 and (frames.step % 5 == 0).all()


def test_evaluate_rewards_scores_every_model_and_task():
    from zsrm.testing import ColourVLM

    frames = {"push_close": rollout_frames("push_close", 1, 1, seed=3, every=10, progress=False)}
    out = evaluate_rewards({"a": ZSRMReward(ColourVLM(32))}, frames,
                           raw_scores={"a": lambda f: f.success.astype(float)})  # a perfect raw score
    m = out["a"]["push_close"]
    assert {"precision", "recall", "f1", "auroc", "auroc_margin", "f1_best_threshold", "frames"} <= set(m)
    assert m["auroc"] == 1.0 and m["frames"] == len(frames["push_close"])


def _zsrm(*args):
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}
    env.pop("ZSRM_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "zsrm.cli", *args], capture_output=True, text=True, env=env,
                          timeout=120)


def test_cli_missing_inputs_are_one_line_errors(tmp_path):
    proc = _zsrm("finetune", "--data", str(tmp_path / "nothing"))
    assert proc.returncode == 2 and "run zsrm reward-data, or zsrm collect and zsrm label, first" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    proc = _zsrm("eval-reward", "--zsrm", str(tmp_path / "nope"))
    assert proc.returncode == 2 and "train it with zsrm finetune" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    proc = _zsrm("eval-reward", "--compare", "base=x")
    assert proc.returncode == 2 and "NAME=FOLDER" in proc.stderr


def test_cli_eval_reward_writes_the_table_and_curves(tmp_path):
    from zsrm.vlm import create_scene_vlm

    create_scene_vlm("tiny", seed=0).save(tmp_path / "vlm")
    out = tmp_path / "eval.json"
    proc = _zsrm("eval-reward", "--zsrm", str(tmp_path / "vlm"), "--base", str(tmp_path / "vlm"), "--tasks",
                 "place_left", "--compare", f"again={tmp_path / 'vlm'}", "--scripted-episodes", "1", "--random-episodes", "1", "--every", "10",
                 "--out", str(out), "--curves", str(tmp_path / "curves"), "--curve-steps", "5", "--quiet")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(out.read_text())
    assert {"zsrm", "again", "base", "meta"} <= set(res)
    assert res["again"]["place_left"] == res["zsrm"]["place_left"]  # the same model, reported twice
    assert 0.0 <= res["zsrm"]["place_left"]["f1"] <= 1.0 and "f1" in res["base"]["place_left"]
    assert (tmp_path / "curves" / "place_left.png").stat().st_size > 0
    header = (tmp_path / "curves" / "place_left.csv").read_text().splitlines()[0]
    assert "zsrm_reward" in header and "base_reward" in header and "zsrm_raw_reward" in header
