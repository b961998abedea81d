"""zsrm train: a few hundred PPO steps with each reward, kill and resume, saved policies."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from zsrm.rl import TrainConfig, train
from zsrm.rl.evaluate import mean_se
from zsrm.rl.policy import PolicyBundle

TINY = dict(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, keypoints=4)


@pytest.mark.parametrize("reward", ["oracle", "zsrm", "base", "vice", "curiosity"])
def test_a_few_hundred_ppo_steps_with_each_reward(tmp_path, reward):
    cfg = TrainConfig(goal="push_close", reward=reward, steps=256, eval_every=128, checkpoint_every=128, **TINY)
    summary = train(cfg, tmp_path, progress=False)
    assert summary["env_steps"] == 256
    assert [row["env_steps"] for row in summary["curve"]] == [128, 256]
    assert 0 <= summary["final_mean"] <= 100 and summary["final_episodes"] == 30
    for name in ("config.json", "eval.csv", "summary.json", "policy/model.safetensors", "policy/config.json"):
        assert (tmp_path / name).is_file(), name
    assert list((tmp_path / "tb").iterdir()), "no TensorBoard events"
    assert len((tmp_path / "eval.csv").read_text().splitlines()) == 3


def test_online_vice_keeps_training_its_classifier_in_a_run(tmp_path):
    import torch

    from zsrm.rewards.vice import GoalClassifier

    cfg = TrainConfig(goal="push_close", reward="vice", vice_update_every=128, steps=256, eval_every=256,
                      checkpoint_every=256, **TINY)
    train(cfg, tmp_path, progress=False)
    fitted, latest = (GoalClassifier.from_folder(tmp_path / name) for name in ("vice", "vice_online"))
    frames = np.random.default_rng(0).integers(0, 255, (4, 64, 64, 3), dtype=np.uint8)
    with torch.no_grad():
        assert not torch.allclose(fitted(frames), latest(frames))  # updated on the policy's frames
    assert json.loads((tmp_path / "config.json").read_text())["vice_update_every"] == 128


def test_a_finished_run_is_not_trained_again(tmp_path):
    cfg = TrainConfig(goal="push_close", reward="random")
    first = train(cfg, tmp_path, progress=False)
    mtime = (tmp_path / "summary.json").stat().st_mtime_ns
    assert train(cfg, tmp_path, progress=False) == first
    assert (tmp_path / "summary.json").stat().st_mtime_ns == mtime


def eval_rows(path):
    """eval.csv's rows, wall time aside."""
    import csv

    return [{k: v for k, v in row.items() if k != "wall_s"} for row in csv.DictReader(path.open())]


def same_weights(a, b) -> bool:
    from safetensors.numpy import load_file

    wa, wb = load_file(str(a)), load_file(str(b))
    return wa.keys() == wb.keys() and all(np.array_equal(wa[k], wb[k]) for k in wa)


def kill_after_first_checkpoint(cfg: dict, folder, env_workers: int = 1) -> int:
    """Train ``cfg`` into ``folder`` in another process, SIGKILL it once its first checkpoint is
    written; the env steps the checkpoint holds."""
    code = ("import json, sys; from zsrm.rl import TrainConfig, train; "
            f"train(TrainConfig(**json.loads(sys.argv[1])), {str(folder)!r}, progress=False, env_workers={env_workers})")
    proc = subprocess.Popen([sys.executable, "-c", code, json.dumps(cfg)], env={**os.environ, "OMP_NUM_THREADS": "1"})
    state = folder / "checkpoint" / "state.json"
    deadline = time.time() + 300
    while not state.is_file() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert state.is_file() and not (folder / "summary.json").exists()
    return json.loads(state.read_text())["env_steps"]


@pytest.mark.parametrize("reward, extra", [("oracle", {}), ("curiosity", {}), ("oracle", {"augment_shift": 2})])
def test_killed_run_resumes_to_the_same_run(tmp_path, reward, extra):
    """Killed (SIGKILL) after its first checkpoint and resumed: the same eval.csv rows, final
    evaluation and policy weights as an unbroken run (issue 41, must-show 0); with the shift
    regulariser too (its generators and optimiser resume)."""
    cfg = dict(goal="place_right", reward=reward, seed=3, steps=768, eval_every=128, checkpoint_every=256, **TINY,
               **extra)
    whole = train(TrainConfig(**cfg), tmp_path / "whole", progress=False)

    cut = tmp_path / "cut"
    killed_at = kill_after_first_checkpoint(cfg, cut)
    assert 0 < killed_at < 768
    resumed = train(TrainConfig(**cfg), cut, progress=False)

    assert resumed["env_steps"] == 768
    assert eval_rows(cut / "eval.csv") == eval_rows(tmp_path / "whole" / "eval.csv")
    assert [row["env_steps"] for row in eval_rows(cut / "eval.csv")] == ["128", "256", "384", "512", "640", "768"]
    assert resumed["final_episode_rewards"] == whole["final_episode_rewards"]
    assert same_weights(cut / "policy" / "model.safetensors", tmp_path / "whole" / "policy" / "model.safetensors")


def test_a_damaged_run_state_is_one_line(tmp_path):
    from zsrm.common.files import ZsrmFileError

    cfg = TrainConfig(goal="push_close", reward="oracle", steps=256, eval_every=256, checkpoint_every=256, **TINY)
    train(cfg, tmp_path, progress=False)
    (tmp_path / "summary.json").unlink()
    state = tmp_path / "checkpoint" / "resume.json"
    good = state.read_text()
    state.write_text("[1, 2]")
    with pytest.raises(ZsrmFileError, match="resume.json"):
        train(cfg, tmp_path, progress=False)
    info = json.loads(good)
    info["envs"] = info["envs"][:1]
    state.write_text(json.dumps(info))
    with pytest.raises(ZsrmFileError, match="training envs"):
        train(cfg, tmp_path, progress=False)
    info = json.loads(good)
    del info["parts"]["train"]["info"]["next_eval"]
    state.write_text(json.dumps(info))
    with pytest.raises(ZsrmFileError, match="does not fit this run"):
        train(cfg, tmp_path, progress=False)


def test_resume_refuses_other_settings(tmp_path):
    cfg = TrainConfig(goal="push_close", reward="oracle", steps=128, eval_every=128, checkpoint_every=128, **TINY)
    train(cfg, tmp_path, progress=False)
    (tmp_path / "summary.json").unlink()
    other = TrainConfig(**{**cfg.to_dict(), "learning_rate": 1e-3})
    with pytest.raises(ValueError, match="learning_rate"):
        train(other, tmp_path, progress=False)


def test_saved_policy_reloads_and_acts_the_same(tmp_path):
    cfg = TrainConfig(goal="push_close", reward="oracle", steps=128, eval_every=128, checkpoint_every=128,
                      eval_deterministic=False, **TINY)
    summary = train(cfg, tmp_path, progress=False)
    # the final evaluation both ways: final_* is the one eval_deterministic names (sampled here)
    assert set(summary["final_by_actions"]) == {"mean", "sampled"}
    assert summary["final_by_actions"]["sampled"]["mean"] == summary["final_mean"]
    a, b = PolicyBundle.load(tmp_path / "policy"), PolicyBundle.load(tmp_path / "policy")
    rng = np.random.default_rng(0)
    space = a.policy.observation_space
    obs = {"features": rng.random((5, *space["features"].shape), np.float32),
           "image": rng.integers(0, 256, (5, *space["image"].shape), dtype=np.uint8)}
    assert np.array_equal(a.act(obs), b.act(obs))
    # ... and the same as the policy the run ended with (its last checkpoint).
    c = PolicyBundle.load(tmp_path / "checkpoint")
    assert np.array_equal(a.act(obs), c.act(obs))
    assert a.cfg == cfg
    # zsrm rollout samples the actions (eval_deterministic is off) from its seed: same seed, same episodes.
    from zsrm.rl.evaluate import rollout

    taken, act = [], PolicyBundle.act

    def record(self, obs, deterministic=True):
        taken.append(act(self, obs, deterministic))
        return taken[-1]

    runs = []
    for seed in (3, 3, 4):
        taken.clear()
        with pytest.MonkeyPatch.context() as m:
            m.setattr(PolicyBundle, "act", record)
            rollout(tmp_path / "policy", episodes=2, seed=seed)
        runs.append(np.concatenate(taken))
    assert not cfg.eval_deterministic and np.array_equal(runs[0], runs[1]) and not np.array_equal(runs[0], runs[2])
    # deterministic=True plays the mean action, False samples it, None as the run evaluated (sampled)
    asked = []

    def record_mode(self, obs, deterministic=True):
        asked.append(deterministic)
        return act(self, obs, deterministic)

    for deterministic, expected in ((True, True), (False, False), (None, False)):
        asked.clear()
        with pytest.MonkeyPatch.context() as m:
            m.setattr(PolicyBundle, "act", record_mode)
            rollout(tmp_path / "policy", episodes=2, seed=3, deterministic=deterministic)
        assert asked and set(asked) == {expected}


def test_policy_folder_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="config.json"):
        PolicyBundle.load(tmp_path)
    (tmp_path / "config.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match="zsrm-policy"):
        PolicyBundle.load(tmp_path)


def test_config_is_checked():
    with pytest.raises(ValueError, match="unknown reward"):
        TrainConfig(reward="vice!")
    with pytest.raises(ValueError, match="action_repeat"):
        TrainConfig(action_repeat=3)
    assert TrainConfig(action_repeat=4).episode_decisions == 25
    # A zsrm run records which shipped student it used; no other reward reads it, so their runs
    # are the same whatever it says (a sweep pinned to a retired student still finds them).
    assert TrainConfig(reward="zsrm").reward_model.startswith("student@")
    assert TrainConfig(reward="oracle").reward_model == "student"
    assert TrainConfig(reward="oracle", reward_model="student@0123456789ab").identity() == TrainConfig().identity()


def test_mean_se():
    assert mean_se([1.0]) == (1.0, 0.0)
    mean, se = mean_se([0.0, 2.0])
    assert mean == 1.0 and se == pytest.approx(1.0)


def test_device_is_checked_and_kept_out_of_the_run_config(tmp_path):
    import torch

    from zsrm.rl.ppo import resolve_device

    assert resolve_device("cpu") == "cpu"
    assert resolve_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(ValueError, match="expected cpu, cuda"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="sees no CUDA GPU"):
            resolve_device("cuda")
    cfg = TrainConfig(goal="push_close", reward="oracle", steps=128, eval_every=128, checkpoint_every=128, **TINY)
    summary = train(cfg, tmp_path / "run", progress=False, device="auto")
    assert "device" not in summary["config"]  # a run started on a GPU resumes on a CPU


def test_a_run_records_its_scenes_layout_so_an_older_layout_is_another_run():
    from zsrm.envs import PushingEnv, TabletopEnv

    assert PushingEnv.layout_version == 2 and TabletopEnv.layout_version == 1
    push, stack = TrainConfig(goal="push_close"), TrainConfig(goal="stack")
    assert push.to_dict()["layout_version"] == 2
    assert "layout_version" not in stack.to_dict()  # version 1 is left out: older stack runs still match
    old_push = {k: v for k, v in push.to_dict().items() if k != "layout_version"}  # as written before
    assert old_push != push.to_dict() and old_push != push.identity()
    assert TrainConfig.from_dict(old_push).layout_version == 2  # read back as the current layout
