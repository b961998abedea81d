"""``zsrm train --learner sac`` (zsrm.rl.sac, zsrm.rl.pretrain) at a tiny scale: the pretrained
keypoints, SAC's checkpoint and resume, its policy folder and the settings it refuses."""
import json

import numpy as np
import pytest
import torch

from zsrm.common.files import ZsrmFileError
from zsrm.rl.config import PRESETS, TrainConfig, preset

TINY = dict(goal="push_close", reward="oracle", learner="sac", pixel_size=64, n_envs=2, pretrain_episodes=4,
            pretrain_steps=3, eval_every=400, eval_episodes=1, checkpoint_every=400)


def tiny(steps: int, **more) -> TrainConfig:
    return TrainConfig(**{**TINY, "steps": steps, **more})


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    from zsrm.rl.learners import train

    out = tmp_path_factory.mktemp("sac") / "run"
    return out, train(tiny(1600), out, progress=False)


def test_a_sac_run_counts_the_pretrainings_env_steps_and_evaluates_after_them(finished):
    out, summary = finished
    keypoints = json.loads((out / "keypoints" / "config.json").read_text())
    offset = keypoints["env_steps"]
    assert offset == keypoints["frames"] * 4 > 0  # a frame per decision of 4 env steps
    assert summary["env_steps"] == 1600 and summary["final_episodes"] == 30
    assert [row["env_steps"] for row in summary["curve"]] == [offset + 400, offset + 800]
    assert set(summary["final_by_actions"]) == {"mean", "sampled"}
    assert summary["config"]["learner"] == "sac"


def test_a_sac_runs_policy_folder_plays_as_the_run_evaluated_it(finished):
    from zsrm.rl.evaluate import rollout
    from zsrm.rl.policy import load_policy
    from zsrm.rl.policy import SacPolicyBundle

    out, summary = finished
    bundle = load_policy(out / "policy")
    assert isinstance(bundle, SacPolicyBundle) and not any(p.requires_grad for p in bundle.extractor.parameters())
    played = rollout(out / "policy", episodes=30, seed=summary["config"]["seed"])
    assert played["mean"] == pytest.approx(summary["final_mean"])  # the same seeded episodes, the mean action


def test_the_saved_actor_is_sacs_and_its_keypoints_the_pretrained_ones(finished, tmp_path):
    from zsrm.rl.policy import load_policy, view_space
    from zsrm.rl.pretrain import load_keypoints

    out, _ = finished
    bundle = load_policy(out / "policy")
    space = bundle.extractor._observation_space
    pretrained, _ = load_keypoints(out / "keypoints", space)
    for (name, a), b in zip(bundle.extractor.state_dict().items(), pretrained.state_dict().values()):
        assert torch.equal(a, b), name
    obs = view_space(space["features"].shape, space["image"].shape[-1]).sample()
    batch = {k: np.stack([v, v]) for k, v in obs.items()}
    actions = bundle.act(batch)
    assert actions.shape == (2, 2) and np.abs(actions).max() <= 1.0
    assert np.array_equal(actions, bundle.act(batch))  # the mean action
    bundle.save(tmp_path / "again")
    np.testing.assert_array_equal(load_policy(tmp_path / "again").act(batch), actions)


def test_a_longer_run_resumes_from_the_checkpoint_with_its_buffer_and_rows(finished, tmp_path):
    import shutil

    from zsrm.rl.learners import train

    out, summary = finished
    again = tmp_path / "run"
    shutil.copytree(out, again)
    state = json.loads((again / "checkpoint" / "state.json").read_text())
    assert state["env_steps"] == 1600 and state["buffer"]["pos"] == (1600 - summary["curve"][0]["env_steps"] + 400) // 8
    longer = train(tiny(2400), again, progress=False)
    assert longer["curve"][:2] == summary["curve"]  # the finished evaluations kept, not played again
    assert [row["env_steps"] for row in longer["curve"][2:]] == [summary["curve"][-1]["env_steps"] + 400 * k
                                                                 for k in (1, 2)]
    assert json.loads((again / "checkpoint" / "state.json").read_text())["buffer"]["pos"] == state["buffer"]["pos"] + 100


def test_a_corrupt_replay_buffer_is_one_line_naming_it(finished, tmp_path):
    import shutil

    from zsrm.rl.learners import train

    out, _ = finished
    again = tmp_path / "run"
    shutil.copytree(out, again)
    (again / "checkpoint" / "replay.npz").write_bytes(b"not a buffer")
    with pytest.raises(ZsrmFileError, match="replay.npz"):
        train(tiny(2400), again, progress=False)


def test_keypoints_pretrained_for_other_settings_are_refused(finished, tmp_path):
    import shutil

    from zsrm.rl.learners import train

    out, _ = finished
    again = tmp_path / "run"
    shutil.copytree(out / "keypoints", again / "keypoints")
    with pytest.raises(ValueError, match="other settings"):
        train(tiny(1600, seed=1), again, progress=False)


def test_runs_that_differ_only_in_their_reward_share_one_pretraining(finished, tmp_path, monkeypatch):
    import zsrm.rl.pretrain as pretrain
    from zsrm.rl.policy import load_policy

    out, _ = finished
    space = load_policy(out / "policy").extractor._observation_space
    shared = tmp_path / "shared"
    first, steps = pretrain.pretrain_keypoints(tiny(1600), space, tmp_path / "oracle", progress=False, shared=shared)
    own, _ = pretrain.load_keypoints(out / "keypoints", space)  # the run pretrained alone: the same weights
    (kept,) = shared.iterdir()

    def boom(*args, **kwargs):
        raise AssertionError("pretrained again")

    monkeypatch.setattr(pretrain, "train_autoencoder", boom)
    base = tiny(1600, reward="base")
    second, again = pretrain.pretrain_keypoints(base, space, tmp_path / "base", progress=False, shared=shared)
    assert again == steps and list(shared.iterdir()) == [kept]
    for a, b, c in zip(first.state_dict().values(), second.state_dict().values(), own.state_dict().values()):
        assert torch.equal(a, b) and torch.equal(a, c)
    assert json.loads((tmp_path / "base" / "config.json").read_text())["run"] == base.identity()
    with pytest.raises(AssertionError, match="pretrained again"):  # another seed is other frames
        pretrain.pretrain_keypoints(tiny(1600, seed=1), space, tmp_path / "seed1", progress=False, shared=shared)


def test_sac_refuses_the_rewards_that_update_between_ppos_rollouts():
    for reward in ("curiosity", "vice"):
        with pytest.raises(ValueError, match="--learner sac"):
            TrainConfig(goal="stack", reward=reward, learner="sac")
    with pytest.raises(ValueError, match="corrected online"):
        TrainConfig(goal="stack", reward="zsrm", learner="sac", zsrm_correct_every=1000)
    with pytest.raises(ValueError, match="pixels"):
        TrainConfig(goal="stack", learner="sac", pixels=False)


def test_the_sac_settings_are_unwritten_for_ppo_and_random_runs():
    ppo = TrainConfig(goal="stack", pretrain_steps=5)
    assert not {"learner", "pretrain_steps", "pretrain_episodes"} & set(ppo.to_dict())
    random = preset("sac", goal="stack", reward="random")
    assert "learner" not in random.to_dict()
    sac = preset("sac", goal="push_close")
    assert (sac.learner, sac.pixel_size, sac.n_envs, sac.steps) == ("sac", 64, 4, 500_000)
    assert sac.to_dict()["learner"] == "sac" and "pretrain_steps" not in sac.to_dict()
    assert PRESETS["sac"]["learner"] == "sac"


def test_ppos_train_refuses_a_sac_config_and_the_learners_entry_sends_it_to_sac(tmp_path):
    from zsrm.rl import ppo, train

    with pytest.raises(ValueError, match="zsrm.rl.learners.train"):
        ppo.train(tiny(400), tmp_path / "run", progress=False)
    assert train.__module__ == "zsrm.rl.learners"
