"""The baselines' parts: VICE's goal classifier and its training frames, ICM's curiosity."""
import numpy as np
import pytest
import torch

from zsrm.rewards.vice import GoalClassifier, OnlineVICEReward, VICEReward, fit_goal_classifier
from zsrm.rl.config import TrainConfig, preset
from zsrm.rl.curiosity import ICM, VecCuriosity
from zsrm.rl.envs import make_vec
from zsrm.rl.vice import goal_frames


def test_vice_frames_hold_true_goal_images():
    frames, labels = goal_frames(TrainConfig(goal="push_close", image_size=32), episodes=2)
    assert frames.shape[1:] == (32, 32, 3) and frames.dtype == np.uint8
    assert len(frames) == len(labels) and 0 < labels.sum() < len(labels)  # scripted rollouts reach the goal


def test_goal_classifier_learns_saves_and_reloads(tmp_path):
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 60, (40, 32, 32, 3), dtype=np.uint8)
    labels = np.arange(40) % 2 == 0
    frames[labels, 10:20, 10:20] = 250  # the "goal": a bright square
    clf = fit_goal_classifier(frames, labels, image_size=32, steps=80, seed=0)
    reward = VICEReward(clf, camera="tilted")
    assert np.array_equal(reward({"tilted": frames}, "a goal"), labels.astype(np.float32))
    clf.save(tmp_path)
    again = GoalClassifier.from_folder(tmp_path)
    with torch.no_grad():
        assert torch.allclose(again(frames), clf(frames))


def test_goal_classifier_needs_both_classes():
    with pytest.raises(ValueError, match="goal and non-goal"):
        fit_goal_classifier(np.zeros((4, 32, 32, 3), np.uint8), np.ones(4, bool), image_size=32)


def test_online_vice_stops_paying_for_a_frame_the_policy_keeps_reaching_that_only_looks_like_the_goal():
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 60, (40, 32, 32, 3), dtype=np.uint8)
    labels = np.arange(40) % 2 == 0
    frames[labels, 10:20, 10:20] = 250  # the goal: a bright square in the middle
    clf = fit_goal_classifier(frames, labels, image_size=32, steps=80, seed=0)
    fake = frames[~labels][:8].copy()
    fake[:, 10:20, 10:20] = 250
    fake[:, :4] = 200  # ... and a bright bar the true goal frames never show
    saved = []
    reward = OnlineVICEReward(clf, "tilted", frames[labels], frames[~labels], update_every=16, steps=30, memory=64,
                              batch_size=32, seed=0, on_update=saved.append)
    assert reward({"tilted": fake}, "a goal").all()  # fooled at first
    for _ in range(12):  # the policy keeps reaching it: 96 frames, 6 updates
        reward({"tilted": fake}, "a goal")
    assert reward.updates == 6 and len(saved) == 6 and saved[-1] is clf
    assert not reward({"tilted": fake}, "a goal").any()
    assert reward({"tilted": frames[labels]}, "a goal").mean() >= 0.9  # the true goal still pays


def test_online_vice_with_oracle_labels_keeps_paying_for_the_goal_the_policy_reaches():
    rng = np.random.default_rng(1)
    frames = rng.integers(0, 60, (40, 32, 32, 3), dtype=np.uint8)
    labels = np.arange(40) % 2 == 0
    frames[labels, 10:20, 10:20] = 250
    reached = frames[labels][:8].copy()
    reached[:, :4] = 200  # the policy's goal frames: the goal, and a bar the fitted-on ones never show
    infos = [{"is_success": True}] * len(reached)
    paid = {}
    for oracle_labels in (False, True):
        clf = fit_goal_classifier(frames, labels, image_size=32, steps=80, seed=0)
        reward = OnlineVICEReward(clf, "tilted", frames[labels], frames[~labels], update_every=16, steps=30,
                                  memory=64, batch_size=32, seed=0, oracle_labels=oracle_labels)
        assert reward({"tilted": reached}, "a goal", infos).all()
        for _ in range(12):
            reward({"tilted": reached}, "a goal", infos)
        paid[oracle_labels] = reward({"tilted": reached}, "a goal", infos).mean()
        assert len(reward.positives) == 20 + 64 * oracle_labels  # the 20 fitted-on goal frames, the latest 64 reached
    assert paid[False] == 0.0  # all the policy's frames negatives: the goal it reaches stops paying
    assert paid[True] == 1.0
    with pytest.raises(ValueError, match="needs the env's infos"):
        reward({"tilted": reached}, "a goal", None)


def test_vice_updates_are_read_by_the_vice_reward_alone_and_unwritten_when_off():
    default = TrainConfig(goal="stack", reward="vice").to_dict()
    assert default["vice_update_every"] == 4000 and default["vice_oracle_labels"] is True  # the default since 2026-12-06
    fixed = TrainConfig(goal="stack", reward="vice", vice_update_every=0)
    assert not fixed.vice_oracle_labels  # a classifier fitted once has no policy frames to label
    assert "vice_update_every" not in fixed.to_dict() and "vice_oracle_labels" not in fixed.to_dict()
    # a run written before the settings existed had a classifier fitted once, and reads so
    legacy = TrainConfig.from_dict({"goal": "stack", "reward": "vice"})
    assert (legacy.vice_update_every, legacy.vice_oracle_labels) == (0, False)
    assert preset("v2", goal="stack", reward="vice").vice_update_every == 0  # the old default, by name
    # a sweep's shared setting: any other reward's run is the same run whatever it says
    assert TrainConfig(goal="stack", reward="oracle", vice_update_every=20) == TrainConfig(goal="stack", reward="oracle")
    assert "vice_update_every" not in TrainConfig(goal="stack", reward="oracle").to_dict()
    with pytest.raises(ValueError, match="vice_update_every must be >= 0"):
        TrainConfig(goal="stack", reward="vice", vice_update_every=-1)


def test_icm_learns_what_the_action_did():
    torch.manual_seed(0)
    icm = ICM(action_dim=2, image_size=32)
    rng = np.random.default_rng(0)
    obs = np.zeros((64, 32, 32, 3), np.uint8)
    obs[:, 12:20, 12:20] = 255  # a square the action moves left or right
    actions = rng.uniform(-1, 1, (64, 2)).astype(np.float32)
    next_obs = np.stack([np.roll(o, 4 if a[0] > 0 else -4, axis=1) for o, a in zip(obs, actions)])
    opt = torch.optim.Adam(icm.parameters(), lr=1e-3)
    history = []
    for _ in range(150):
        forward_error, inverse_loss = icm.losses(obs, actions, next_obs)
        history.append(inverse_loss.item())
        loss = icm.beta * forward_error.mean() + (1 - icm.beta) * inverse_loss
        opt.zero_grad()
        loss.backward()
        opt.step()
    # The inverse model reads the move's direction from the two frames (only a[0]'s sign shows).
    assert history[-1] < 0.7 * history[0]


def test_curiosity_rewards_every_env_and_keeps_transitions():
    venv = VecCuriosity(make_vec(TrainConfig(goal="push_close"), 3, 0), "tilted")
    venv.reset()
    for _ in range(4):
        _, rewards, _, infos = venv.step(np.random.uniform(-1, 1, (3, 2)).astype(np.float32))
        assert rewards.shape == (3,) and np.all(rewards >= 0)
        assert all("curiosity_reward" in info for info in infos)
    losses = venv.update(epochs=1, batch_size=4)
    assert set(losses) == {"forward_loss", "inverse_loss"} and venv.transitions == []
