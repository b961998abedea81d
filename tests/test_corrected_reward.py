"""--zsrm-correct-every: the zsrm reward's model learning the labeler's verdict on the policy's frames."""
import numpy as np
import pytest
import torch

from zsrm.fullmodel.student import StudentConfig, StudentRewardNet
from zsrm.rewards.corrected import CorrectedZSRMReward
from zsrm.rl.config import TrainConfig
from zsrm.testing import ColourVLM

GOAL = "a yellow block on top of a red block"


def square_frames(n: int, bar: bool, seed: int) -> np.ndarray:
    """Dark noise with a bright square in the middle (the goal), and with ``bar`` a bright bar on top."""
    frames = np.random.default_rng(seed).integers(0, 60, (n, 32, 32, 3), dtype=np.uint8)
    frames[:, 10:20, 10:20] = 250
    if bar:
        frames[:, :4] = 200
    return frames


def bar_free(frames: np.ndarray) -> np.ndarray:
    """The test's labeler: the goal holds where there is no bar."""
    return frames[:, :4].mean(axis=(1, 2, 3)) < 120


def student() -> StudentRewardNet:
    torch.manual_seed(0)
    return StudentRewardNet(StudentConfig(image_size=32, widths=(8, 8, 8, 8), embed_dim=8), ColourVLM(), "testing")


def test_a_frame_the_policy_reaches_that_only_looks_like_the_goal_stops_paying_and_the_goal_pays():
    goal, fake = square_frames(8, False, 0), square_frames(8, True, 1)
    seen = []
    reward = CorrectedZSRMReward(student(), lambda f: (seen.append(len(f)), bar_free(f))[1], update_every=16,
                                 label_frames=8, steps=30, batch_size=16, lr=3e-3, min_each=4, seed=0)
    for _ in range(40):  # the policy reaches both: 640 frames, 40 updates of 8 labelled frames
        reward({"front": np.concatenate([goal, fake])}, GOAL)
    assert set(seen) == {8} and reward.labelled == 320
    assert 36 <= reward.updates <= 40  # the first waits until 4 of each kind are labelled
    assert reward({"front": fake}, GOAL).mean() == 0.0
    assert reward({"front": goal}, GOAL).mean() == 1.0
    assert (reward.score(fake, GOAL, "margin") < 0).all()


def test_no_update_until_the_labeler_has_seen_enough_of_both_kinds():
    updates = []
    reward = CorrectedZSRMReward(student(), bar_free, update_every=4, label_frames=4, steps=2, min_each=6,
                                 on_update=updates.append)
    goal, fake = square_frames(4, False, 0), square_frames(4, True, 1)
    for _ in range(3):  # 12 goal frames labelled, no other kind yet
        reward({"front": goal}, GOAL)
    assert reward.updates == 0 and reward.labelled_goal == 12
    reward({"front": fake}, GOAL)  # 4 others: still under 6
    assert reward.updates == 0
    reward({"front": fake}, GOAL)
    assert reward.updates == 1 and updates == [reward.model]
    with pytest.raises(ValueError, match="must be >= 1"):
        CorrectedZSRMReward(student(), bar_free, update_every=0)


def test_frames_labelled_before_training_let_the_first_update_come_before_the_policy_reaches_the_goal():
    goal, fake = square_frames(6, False, 0), square_frames(6, True, 1)
    labelled = (np.concatenate([goal, fake]), bar_free(np.concatenate([goal, fake])))
    reward = CorrectedZSRMReward(student(), bar_free, update_every=4, label_frames=4, steps=2, min_each=6,
                                 labelled=labelled)
    reward({"front": square_frames(4, True, 2)}, GOAL)  # the policy's frames: none is the goal
    assert reward.updates == 1 and reward.labelled_goal == 0
    assert len(reward.banks[True]) == 6 and len(reward.banks[False]) == 6 + 4
    for seed in range(3, 400):  # kept for good: the policy's frames never push them out
        reward.learn(square_frames(4, True, seed), GOAL)
    np.testing.assert_array_equal(reward.banks[True][:6], goal)
    np.testing.assert_array_equal(reward.banks[False][:6], fake)


def test_the_labeler_labels_exploration_renders_of_the_goals_scene_that_hold_its_objects(tmp_path):
    from types import SimpleNamespace

    from zsrm.rl.corrected import explored_labels
    from zsrm.rl.goals import task_entry

    calls = []

    class Labeler:  # the goal labeler's interface: task, camera, the cameras of its calibration, the front camera
        task, camera, needs_front = task_entry("place_inside").task, "tilted", True
        grounder = SimpleNamespace(data=SimpleNamespace(cameras=("tilted", "front")))

        def __call__(self, frames, front):
            calls.append(len(frames))
            assert front.shape == frames.shape
            return np.arange(len(frames)) % 2 == 0

    cfg = TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=5000, zsrm_correct_explore=40,
                      image_size=32)
    frames, holds = explored_labels(cfg, Labeler(), tmp_path)
    assert 0 < len(frames) < 40 and calls == [len(frames)]  # only renders holding the yellow block and the box
    assert frames.shape[1:] == (32, 32, 3) and holds.sum() == (len(frames) + 1) // 2
    again = explored_labels(cfg, Labeler(), tmp_path)  # kept: a resumed run does not label again
    assert calls == [len(frames)] and np.array_equal(again[1], holds)
    assert explored_labels(TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=5000),
                           Labeler(), tmp_path / "off") is None


def test_the_correction_is_a_zsrm_setting_written_only_when_on():
    on = TrainConfig(goal="place_between", reward="zsrm", zsrm_correct_every=5000)
    assert on.to_dict()["zsrm_correct_every"] == 5000 and on.zsrm_correct_frames == 128
    off = TrainConfig(goal="place_between", reward="zsrm").to_dict()
    assert not {"zsrm_correct_every", "zsrm_correct_frames", "zsrm_correct_box_area"} & set(off)  # committed runs match
    assert "zsrm_correct_box_area" not in on.to_dict()  # 0: the labeler as zsrm label's
    # a sweep's shared setting: the other rewards' runs are the same runs whatever it says
    assert TrainConfig(goal="stack", reward="oracle", zsrm_correct_every=5000,
                       zsrm_correct_box_area=0.0115) == TrainConfig(goal="stack", reward="oracle")
    assert TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_box_area=0.0115) == TrainConfig(
        goal="place_inside", reward="zsrm")  # read only by the correction
    boxless = TrainConfig(goal="stack", reward="zsrm", zsrm_correct_every=5000, zsrm_correct_box_area=0.0115)
    assert boxless == TrainConfig(goal="stack", reward="zsrm", zsrm_correct_every=5000)  # nor for goals without the box
    assert TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=5000,
                       zsrm_correct_box_area=0.0115).to_dict()["zsrm_correct_box_area"] == 0.0115
    for bad in ({"zsrm_correct_every": -1}, {"zsrm_correct_box_area": -0.1}):
        with pytest.raises(ValueError, match="must be >= 0"):
            TrainConfig(goal="stack", reward="zsrm", **bad)
    with pytest.raises(ValueError, match="no calibrated goal labeler"):
        TrainConfig(goal="a red cylinder behind a purple cylinder", scene="examples.own_scene.adapter:OwnScene",
                    reward="oracle", zsrm_correct_every=5000)


def test_the_goal_labeler_agrees_with_the_oracle_on_a_task_scene(tmp_path):
    from zsrm.grounding.goal_check import GoalLabeler
    from zsrm.rl.goals import task_entry
    from zsrm.rl.vice import goal_frames
    from zsrm.vlm import load_vlm

    cfg = TrainConfig(goal="place_between", reward="zsrm")
    frames, oracle = goal_frames(cfg, episodes=2)  # scripted and random episodes, the oracle's verdicts
    labeler = GoalLabeler.calibrated(task_entry(cfg.goal).task, "tabletop", cfg.image_size, tmp_path, load_vlm("scene"))
    said = labeler(frames)
    assert oracle.any() and (~oracle).any()
    # Grad-CAM of the goal's objects alone gives their points as of every colour's (each map its own)
    arrays = {"scene": np.zeros(8, np.int64), "images_front": frames[:8]}
    every, goal_only = labeler.grounder.shard(arrays), labeler.grounder.shard(arrays, colours=labeler.task.objects)
    located = [i for i, c in enumerate(labeler.grounder.data.colours) if c in labeler.task.objects]
    np.testing.assert_array_equal(every["gradcam_xy_front"][:, located], goal_only["gradcam_xy_front"][:, located])
    assert np.isnan(goal_only["gradcam_xy_front"][:, [i for i in range(4) if i not in located]]).all()
    assert (said == oracle).mean() >= 0.9
    assert said[oracle].mean() >= 0.8 and not said[~oracle].mean() > 0.1


def test_a_run_with_the_correction_reads_its_latest_model_on_resume(tmp_path):
    from zsrm.rewards.corrected import CorrectedZSRMReward
    from zsrm.rl.envs import make_reward

    cfg = TrainConfig(goal="place_between", reward="zsrm", zsrm_correct_every=5000)
    reward = make_reward(cfg, tmp_path)
    assert isinstance(reward, CorrectedZSRMReward) and reward.update_every == 5000 // cfg.action_repeat
    assert (tmp_path / "goal_labeler" / "manifest.json").is_file()
    with torch.no_grad():
        for p in reward.model.parameters():
            p.add_(0.01)
    reward.updates, reward.labelled, reward.labelled_goal = 3, 384, 100
    reward.on_update(reward.model)  # what an update keeps: the model and the counts
    resumed = make_reward(cfg, tmp_path)
    for a, b in zip(reward.model.parameters(), resumed.model.parameters()):
        assert torch.equal(a, b)
    assert (resumed.updates, resumed.labelled, resumed.labelled_goal) == (3, 384, 100)  # counted on


def test_the_box_area_check_stops_a_box_point_on_a_block_reading_inside_of(tmp_path, monkeypatch):
    import json

    from test_distill import run_probe

    # seed 903: the box's Grad-CAM point lands on the block resting 0.2 m from the box
    run_probe("box_area_check.py", monkeypatch, "--kinds", "hover", "--seeds", "903", "--scripted-episodes", "1",
              "--every", "3", "--calibration", str(tmp_path / "calib"), "--out", str(tmp_path / "check.json"))
    out = json.loads((tmp_path / "check.json").read_text())
    hover, scripted = out["hover"], out["scripted"]
    assert hover["oracle_goal"] == 0 and hover["unchecked"]["false_goal"] > 0.5 * hover["frames"]
    assert hover["checked"]["false_goal"] < 0.1 * hover["frames"]
    assert scripted["oracle_goal"] >= 5 and scripted["checked"]["recall"] >= 0.7
    assert scripted["checked"]["recall"] == scripted["unchecked"]["recall"]  # no goal frame lost


def test_the_labeler_gets_the_other_cameras_frames_of_the_steps_it_labels():
    seen = []

    def labeler(frames, left):
        np.testing.assert_array_equal(left, 255 - frames)  # the same steps' frames of the other camera
        seen.append(len(frames))
        return bar_free(frames)

    reward = CorrectedZSRMReward(student(), labeler, update_every=8, label_frames=5, steps=1, min_each=1,
                                 label_cameras=("left",))
    for seed in range(4):
        frames = square_frames(4, bar=seed % 2 == 0, seed=seed)
        reward({"front": frames, "left": 255 - frames}, GOAL)
    assert seen == [5, 5] and reward.labelled == 10 and reward.updates == 2


@pytest.mark.parametrize("check", ["zsrm_correct_front", "zsrm_correct_height"])
def test_the_front_and_height_checks_are_inside_of_settings_whose_training_scenes_render_the_front_camera(check):
    from zsrm.rl.envs import make_vec

    on = TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=5000, **{check: True})
    assert on.to_dict()[check] is True
    assert check not in TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=5000).to_dict()
    for other in ({"reward": "oracle"}, {"zsrm_correct_every": 0}, {"goal": "stack"}):  # read only by the correction
        assert not getattr(TrainConfig(**{**on.to_dict(), **other}), check)
    train, evaluate = make_vec(on, 1, 0, training=True), make_vec(on, 1, 0)
    assert set(train.observation_space.spaces) == {"tilted", "front"} and set(evaluate.observation_space.spaces) == {"tilted"}
    train.close(), evaluate.close()


def test_the_height_checks_ceiling_is_read_only_with_the_height_check():
    on = TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=5000, zsrm_correct_height=True,
                     zsrm_correct_lift_max=0.67)
    assert on.to_dict()["zsrm_correct_lift_max"] == 0.67
    assert "zsrm_correct_lift_max" not in TrainConfig(**{**on.to_dict(), "zsrm_correct_lift_max": 0.5}).to_dict()
    assert TrainConfig(**{**on.to_dict(), "zsrm_correct_height": False}).zsrm_correct_lift_max == 0.5


def test_two_cameras_rays_meet_at_the_world_point_both_see():
    import gymnasium as gym

    import zsrm.envs  # noqa: F401
    from zsrm.envs.cameras import pixel_rays, project, triangulate

    env = gym.make("zsrm/Tabletop-v0", task="stack", cameras=("front", "tilted"), image_size=64).unwrapped
    points = np.random.default_rng(0).uniform([-0.2, -0.1, 0.42], [0.2, 0.1, 0.55], (6, 3))
    tilted, front = project(env, "tilted", points, 64), project(env, "front", points, 64)
    tilted[0] = np.nan  # not located on one camera: no point
    found = triangulate(pixel_rays(env, "tilted", 64), tilted, pixel_rays(env, "front", 64), front)
    env.close()
    assert np.isnan(found[0]).all()
    np.testing.assert_allclose(found[1:], points[1:], atol=1e-9)


def test_the_front_and_height_checks_stop_inside_of_for_a_block_held_in_front_of_the_box(tmp_path, monkeypatch):
    import json

    from test_distill import run_probe
    from zsrm.rl.corrected import goal_labeler

    # seed 902: the block held 3 cm in front of the box, 8 cm up, reads as in it on the tilted camera
    run_probe("inside_front_check.py", monkeypatch, "--offsets", "-0.03", "--seeds", "902", "--scripted-episodes", "1",
              "--every", "3", "--calibration", str(tmp_path / "calib"), "--out", str(tmp_path / "check.json"))
    out = json.loads((tmp_path / "check.json").read_text())
    held, scripted = out["hover-0.03"], out["scripted"]
    assert held["oracle_goal"] == 0 and held["tilted_only"]["false_goal"] > 0.5 * held["frames"]
    assert held["front_check"]["false_goal"] < 0.1 * held["frames"]
    assert scripted["oracle_goal"] >= 5 and scripted["front_check"]["recall"] >= 0.8
    assert scripted["front_check"]["recall"] == scripted["tilted_only"]["recall"]  # no goal frame lost here
    # held 8 cm up, the block's triangulated centre is far above a resting one's; dropped in the box it is not
    assert held["height_check"]["false_goal"] == 0 and held["lift_tilted_false_goal_p10_p50_p90"][0] > 0.6
    assert scripted["height_check"]["recall"] >= 0.8 and scripted["lift_oracle_goal_p10_p50_p90"][1] < 0.4
    labeler = goal_labeler(TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=5000,
                                       zsrm_correct_height=True), tmp_path / "calib")
    with pytest.raises(ValueError, match="front camera's frames"):
        labeler(np.zeros((2, 64, 64, 3), np.uint8))
