"""The double pendulum of Figure 4: pose captions from the true pose, the pendulum renders in
the scene VLM's pretraining, PPO with the base and oracle rewards, and the Figure 4 plot."""
import doctest
import json
from pathlib import Path

import numpy as np
import pytest

import zsrm.data.pendulum_renders as pendulum_renders
import zsrm.rl.ppo as ppo
from zsrm.cli import main
from zsrm.data.pendulum_renders import PendulumPoser, load_pendulum_renders, render_pendulum_scenes
from zsrm.tasks.pendulum import (CAPTIONS, GOAL, NEGATIVES, POSES, all_pendulum_captions, mirrored,
                                 pendulum_caption, pose_class, tip_offset)
from zsrm.vlm.pretrain import PretrainConfig, make_batch

TINY_RL = dict(n_envs=2, n_steps=32, batch_size=32, n_epochs=1, eval_episodes=2, keypoints=4)


def pole_pixels(image: np.ndarray) -> np.ndarray:
    """(row, column) of the poles' cyan pixels."""
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return np.argwhere((g > 50) & (abs(g - b) < 25) & (r < 0.6 * g))


# --- captions from the true pose ---------------------------------------------------------------
@pytest.fixture(scope="module")
def poser():
    p = PendulumPoser(64)
    yield p
    p.close()


def test_captions_match_the_pose_upright_leaning_fallen(poser):
    cart = {}
    for name, qpos in {"upright": (0.0, 0.0, 0.0), "fallen": (0.0, np.pi, 0.0),
                       "leaning_left": (0.0, -0.8, 0.0), "leaning_right": (0.0, 0.8, 0.0)}.items():
        image, dx, z = poser.render(qpos)
        assert pose_class(dx, z) == name, (name, dx, z)
        rng = np.random.default_rng(0)
        assert {pendulum_caption(name, rng) for _ in range(30)} == set(CAPTIONS[name])
        cart[name] = pole_pixels(image)
    # The image agrees with the words: the upright pole reaches far above where the fallen one
    # lies, and a pole leaning left (right) shows left (right) of the centre, where the cart is.
    assert cart["upright"][:, 0].min() < cart["fallen"][:, 0].min() - 15
    assert cart["leaning_left"][:, 1].mean() < 30 < cart["leaning_right"][:, 1].mean()
    assert GOAL == "an inverted pendulum standing upright" and GOAL in CAPTIONS["upright"]
    assert "upright" not in " ".join(NEGATIVES) and len(NEGATIVES) == len(POSES) - 1


def test_pose_bands_and_the_simulator_agree(poser):
    rng = np.random.default_rng(1)
    for _ in range(20):
        qpos = (rng.uniform(-0.8, 0.8), rng.uniform(-np.pi, np.pi), rng.uniform(-np.pi, np.pi))
        _, dx, z = poser.render(qpos)
        assert np.allclose(tip_offset(qpos[1], qpos[2]), (dx, z), atol=1e-6)
    assert pose_class(0.0, 1.05) is None  # between upright and leaning: never captioned
    assert pose_class(0.05, 0.6) is None  # low but straight over the cart: no side to name
    assert mirrored("leaning_right") == "leaning_left" and mirrored("fallen") == "fallen"
    with pytest.raises(ValueError, match="unknown pendulum pose"):
        pendulum_caption("sideways", np.random.default_rng(0))
    assert len(set(all_pendulum_captions())) == sum(len(c) for c in CAPTIONS.values())


def test_renders_are_seeded_balanced_and_cached(tmp_path, monkeypatch):
    a = render_pendulum_scenes(range(12), seed=3, size=32)
    b = render_pendulum_scenes([5, 6], seed=3, size=32)
    assert np.array_equal(a["images"][5:7], b["images"]) and np.array_equal(a["pose"][5:7], b["pose"])
    assert len(set(a["pose"].tolist())) >= 3
    for dx, z in a["tip"]:  # every render's class is read from its true tip position
        assert pose_class(dx, z) is not None
    assert [POSES[p] for p in a["pose"]] == [pose_class(dx, z) for dx, z in a["tip"]]

    first = load_pendulum_renders(tmp_path, scenes=5, shard_size=4, seed=3, image_size=32, progress=False)
    assert len(first["images"]) == 5 and sorted(p.name for p in tmp_path.glob("shard-*")) == [
        "shard-0000.npz", "shard-0001.npz"]
    assert np.array_equal(first["images"], a["images"][:5])
    monkeypatch.setattr(pendulum_renders, "render_pendulum_scenes", lambda *a, **k: pytest.fail("re-rendered"))
    again = load_pendulum_renders(tmp_path, scenes=5, shard_size=4, seed=3, image_size=32, progress=False)
    assert all(np.array_equal(first[k], again[k]) for k in first)
    with pytest.raises(ValueError, match="other settings"):
        load_pendulum_renders(tmp_path, scenes=5, shard_size=4, seed=4, image_size=32, progress=False)


def test_docstring_examples():
    import zsrm.tasks.pendulum

    for module in (zsrm.tasks.pendulum, pendulum_renders):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
        assert result.attempted > 0 and result.failed == 0, module.__name__


# --- pretraining ---------------------------------------------------------------------------------
def test_zero_pendulum_scenes_keeps_the_shipped_vlm_identity():
    from zsrm.vlm.scene import SHIPPED_SCENE_DIR

    shipped = json.loads((SHIPPED_SCENE_DIR / "config.json").read_text())["meta"]["config"]
    assert PretrainConfig().identity() == shipped
    assert PretrainConfig(pendulum_scenes=0).identity() == shipped
    assert PretrainConfig(pendulum_scenes=8).identity() == {**shipped, "pendulum_scenes": 8}


def test_a_pendulum_vlm_never_overwrites_the_shipped_one(tmp_path, capsys):
    assert main(["pretrain-vlm", "--pendulum-scenes", "4", "--workdir", str(tmp_path / "w"), "--quiet"]) == 2
    assert "--out" in capsys.readouterr().err
    assert not (tmp_path / "w").exists()


def test_mixed_batches_caption_a_mirrored_lean_as_the_other_side():
    n = 6
    data = {"images": np.zeros((n, 8, 8, 3), np.uint8), "visible": np.full((n, 4), 50, np.int32),
            "shape": np.zeros(n, np.uint8)}
    images = np.zeros((n, 8, 8, 3), np.uint8)
    images[:, :, 0] = 255  # a mark in the left column: in the right one once mirrored
    pendulum = {"images": images, "pose": np.full(n, POSES.index("leaning_left"), np.uint8)}
    cfg = PretrainConfig(batch_size=12, image_size=8)
    seen = set()
    for step in range(4):
        batch, captions = make_batch(data, np.arange(n), step, cfg, pendulum=pendulum)
        again = make_batch(data, np.arange(n), step, cfg, pendulum=pendulum)
        assert np.array_equal(batch, again[0]) and captions == again[1]  # a function of (seed, step)
        for image, caption in zip(batch, captions):
            if image.max() == 0:  # a presence render
                assert "block" in caption
                continue
            side = "left" if image[0, 0, 0] == 255 else "right"
            assert caption in CAPTIONS[f"leaning_{side}"], (side, caption)
            seen.add(side)
    assert seen == {"left", "right"}


def test_pretraining_with_pendulum_renders_runs_a_tiny_model(tmp_path):
    out, work = tmp_path / "vlm", tmp_path / "work"
    args = ["pretrain-vlm", "--out", str(out), "--workdir", str(work), "--arch", "tiny", "--scenes", "2",
            "--shard-size", "2", "--steps", "3", "--batch-size", "8", "--checkpoint-every", "3", "--warmup-steps", "1",
            "--pendulum-scenes", "4", "--quiet"]
    assert main(args) == 0
    meta = json.loads((out / "config.json").read_text())["meta"]
    assert meta["config"]["pendulum_scenes"] == 4 and meta["pendulum_images"] == 4
    assert meta["pendulum_poses"] == list(POSES)
    assert sorted(p.name for p in (work / "pendulum-renders").glob("shard-*")) == ["shard-0000.npz", "shard-0001.npz"]
    from zsrm.rewards import BaseReward
    from zsrm.vlm import load_vlm

    reward = BaseReward(load_vlm(str(out)), camera="front", mode="binary", negatives=NEGATIVES)
    frames = render_pendulum_scenes(range(3), seed=0, size=64)["images"]
    assert set(reward({"front": frames}, GOAL).tolist()) <= {0.0, 1.0}


# --- the binarised base reward ------------------------------------------------------------------
def test_binary_base_reward_is_one_when_the_goal_beats_every_negative(toy_vlm, solid_frames):
    from zsrm.rewards import BaseReward

    reward = BaseReward(toy_vlm, camera="front", mode="binary", negatives=["a blue block", "a green block"])
    frames = solid_frames([(255, 0, 0), (0, 0, 255), (0, 255, 0)])
    assert reward({"front": frames}, "a red block").tolist() == [1.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="negatives"):
        BaseReward(toy_vlm, mode="binary")
    with pytest.raises(ValueError, match="only by mode 'binary'"):
        BaseReward(toy_vlm, mode="cosine", negatives=["a blue block"])


# --- RL ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("reward", ["base", "oracle"])
def test_a_few_hundred_ppo_steps_on_the_pendulum(tmp_path, reward, monkeypatch):
    from zsrm.rl import TrainConfig, train

    monkeypatch.setattr(ppo, "FINAL_EPISODES", 3)  # each eval env builds a GL context: the test's cost
    cfg = TrainConfig(goal="pendulum", reward=reward, steps=256, eval_every=128, checkpoint_every=128, **TINY_RL)
    summary = train(cfg, tmp_path, progress=False)
    assert summary["env_steps"] == 256 and [row["env_steps"] for row in summary["curve"]] == [128, 256]
    # The oracle episode return: gymnasium's reward (at most ~9.35 a step) over at most 100 steps.
    assert 0 < summary["final_mean"] <= 100 * 9.4 and summary["final_episodes"] == 3
    train_reward = [row["train_reward"] for row in summary["curve"]]
    if reward == "base":  # binary, so per episode at most one per decision
        assert all(0 <= r <= cfg.episode_decisions for r in train_reward)
    assert (tmp_path / "policy" / "model.safetensors").is_file()


def test_the_pendulum_metric_is_the_env_return(monkeypatch):
    import gymnasium as gym

    from zsrm.rl import TrainConfig
    from zsrm.rl.evaluate import eval_seed, evaluate

    cfg = TrainConfig(goal="pendulum", reward="random", action_repeat=2)
    result = evaluate(lambda obs: np.zeros((1, 1), np.float32), cfg, episodes=1, seed=0)
    env = gym.make("InvertedDoublePendulum-v5")  # the same start (seed), the same actions, from state
    env.reset(seed=eval_seed(0))
    total = 0.0
    for _ in range(100):
        _, r, terminated, truncated, _ = env.step(np.zeros(1))
        total += r
        if terminated:
            break
    assert result["episode_rewards"][0] == pytest.approx(total)
    assert result["success_rate"] == float(not terminated)


def test_rewards_that_read_a_relation_refuse_the_pendulum():
    from zsrm.rl import TrainConfig

    for reward in ("zsrm", "vice"):
        with pytest.raises(ValueError, match="pendulum"):
            TrainConfig(goal="pendulum", reward=reward)
    assert TrainConfig(goal="pendulum", reward="curiosity").start == "above"
    # The scene VLM never saw the pole; the pendulum reads the one that did.
    assert TrainConfig(goal="pendulum", reward="base").vlm == "scene-pendulum"
    assert TrainConfig(goal="stack", reward="base").vlm == "scene"


# --- sweep summary and Figure 4 ------------------------------------------------------------------
def synthetic_summaries():
    out = []
    for reward, level in (("base", 400.0), ("oracle", 300.0)):
        for seed in range(3):
            curve = [{"env_steps": s, "mean": level * s / 2000 + seed, "se": 5.0} for s in (1000, 2000)]
            out.append({"config": {"goal": "pendulum", "reward": reward, "seed": seed}, "env_steps": 2000,
                        "final_mean": level + seed, "final_se": 3.0, "final_success_rate": 0.5, "curve": curve})
    return out


def test_gathered_pendulum_summary_and_figure4(tmp_path, capsys):
    from zsrm.rl.sweep import gather, trial_grid

    assert [t["name"] for t in trial_grid(["pendulum"], ["base", "oracle"], [0])] == ["pendulum-base-0",
                                                                                     "pendulum-oracle-0"]
    # One sweep over the manipulation tasks and the pendulum: the pendulum skips zsrm and vice.
    names = [t["name"] for t in trial_grid(["stack", "pendulum"], ["oracle", "zsrm", "vice"], [0])]
    assert names == ["stack-oracle-0", "stack-zsrm-0", "stack-vice-0", "pendulum-oracle-0"]
    summary = gather(synthetic_summaries())
    assert summary["pendulum"]["base"]["final_mean"] == pytest.approx(401.0)
    assert summary["pendulum"]["oracle"]["seeds"] == 3
    path = tmp_path / "pendulum.json"
    path.write_text(json.dumps({**summary, "meta": {}}))
    figure4 = tmp_path / "rl" / "figure4.png"
    assert main(["plot", "--summary", str(path), "--figure4", str(figure4), "--figure6", str(tmp_path / "f6.png")]) == 0
    assert figure4.stat().st_size > 5000 and not (tmp_path / "f6.png").exists()  # no manipulation task
    assert main(["plot", "--summary", str(path), "--figure6", str(tmp_path / "f6.png")]) == 2
    assert "--figure4" in capsys.readouterr().err
    no_pendulum = tmp_path / "stack.json"
    no_pendulum.write_text(json.dumps({"stack": summary["pendulum"]}))
    assert main(["plot", "--summary", str(no_pendulum), "--figure4", str(tmp_path / "x.png")]) == 2


def test_sweep_passes_model_folders_by_absolute_path(tmp_path, monkeypatch):
    from zsrm.pipeline.learn import absolute_if_folder

    monkeypatch.chdir(tmp_path)
    (tmp_path / "vlm-pendulum").mkdir()
    assert absolute_if_folder("vlm-pendulum") == str(tmp_path / "vlm-pendulum")
    assert absolute_if_folder("scene") == "scene" and absolute_if_folder("student") == "student"
    assert Path(absolute_if_folder("vlm-pendulum")).is_absolute()


# --- does a VLM know the pose? (zsrm eval-pose) --------------------------------------------------
class PicksOneText:
    """A stand-in VLM whose every frame matches sentence ``k`` best, whatever it shows."""

    def __init__(self, k: int):
        self.k = k

    def similarity(self, images, texts):
        import torch

        sims = torch.zeros(len(images), len(texts))
        sims[:, self.k] = 1.0
        return sims


def test_pose_eval_scores_the_base_rewards_rule_against_the_true_pose():
    from zsrm.evaluation.pendulum_pose import pose_eval, pose_texts

    assert pose_texts()[0] == GOAL and tuple(pose_texts()[1:]) == NEGATIVES
    always_upright = pose_eval(PicksOneText(0), n_images=12, image_size=32, progress=False)
    confusion = np.array(always_upright["meta"]["confusion_rows_true_cols_predicted"])
    assert confusion.sum() == 12 and (confusion[:, 1:] == 0).all()
    share_upright = confusion[0, 0] / 12
    assert always_upright["accuracy"] == pytest.approx(share_upright) and always_upright["accuracy.upright"] == 1.0
    assert always_upright["accuracy.fallen"] == 0.0 and always_upright["upright.recall"] == 1.0
    assert always_upright["upright.precision"] == pytest.approx(share_upright)  # a survival bonus, not a pose
    never_upright = pose_eval(PicksOneText(3), n_images=12, image_size=32, progress=False)
    assert never_upright["upright.precision"] is None and never_upright["upright.f1"] == 0.0
    assert never_upright["accuracy"] == pytest.approx(confusion[3].sum() / 12)  # same seed: same renders


def test_eval_pose_command_writes_its_table(tmp_path, capsys):
    out = tmp_path / "pose.json"
    assert main(["eval-pose", "--vlm", "scene", "--images", "8", "--quiet", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["meta"]["command"].startswith("zsrm eval-pose --vlm scene --images 8")
    assert 0.0 <= result["accuracy"] <= 1.0 and len(result["meta"]["confusion_rows_true_cols_predicted"]) == 4
    capsys.readouterr()
    assert main(["eval-pose", "--vlm", "scene", "--images", "2"]) == 2
    assert "--images must be at least 4" in capsys.readouterr().err


def test_the_shipped_pendulum_vlm_loads_by_name_and_leaves_the_scene_vlm_alone():
    from zsrm.vlm import load_vlm
    from zsrm.vlm.factory import pinned, shipped_digest

    vlm = load_vlm("scene-pendulum")
    assert vlm.meta["pendulum_images"] > 0 and pinned("scene-pendulum").startswith("scene-pendulum@")
    assert shipped_digest("scene-pendulum") != shipped_digest("scene")
    assert "pendulum_images" not in load_vlm("scene").meta
