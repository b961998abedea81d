"""The ZSRM reward (zsrm/rewards/binarised.py) on hand-made embeddings, and in the rewards' wrappers."""
import numpy as np
import pytest
import torch

from zsrm.tasks.negatives import candidate_texts
from zsrm.rewards.binarised import ZSRMReward
from zsrm.vlm.base import VisionLanguageModel

GOAL = "a yellow block on top of a red block"
CANDIDATES = candidate_texts(GOAL)  # goal first, then its negatives


class LookupVLM(VisionLanguageModel):
    """Image k (a frame filled with value k) embeds to ``image_vectors[k]``; texts embed to
    ``text_vectors[text]`` (one-hot of their candidate index by default)."""

    backend = "lookup"
    gradcam_layer = "none"

    def __init__(self, image_vectors, text_vectors):
        super().__init__()
        self.image_vectors = torch.as_tensor(np.asarray(image_vectors), dtype=torch.float32)
        self.text_vectors = {t: torch.as_tensor(v, dtype=torch.float32) for t, v in text_vectors.items()}
        self.image_size = 8
        self.logit_scale = torch.nn.Parameter(torch.tensor(0.0))
        self.text_calls = 0

    def preprocess(self, images):
        return torch.as_tensor(np.asarray(images)[:, 0, 0, 0].astype(np.int64))

    def image_trunk(self, pixels):
        return pixels

    def image_head(self, features):
        return self.image_vectors[features]

    def encode_text_tokens(self, texts):
        self.text_calls += 1
        return torch.stack([self.text_vectors[t] for t in texts])

    def save(self, folder):
        raise NotImplementedError


def one_hot_texts(texts, dim):
    return {t: np.eye(dim)[i] for i, t in enumerate(texts)}


def frames(values, size=8):
    return np.stack([np.full((size, size, 3), v, np.uint8) for v in values])


@pytest.fixture
def vlm():
    d = len(CANDIDATES)
    e = np.eye(d)
    images = [
        e[0] * 2.0,  # 0: exactly the goal (scale does not matter: cosines)
        e[0] + 0.9 * e[1],  # 1: the goal, with some of the first negative
        e[-1],  # 2: the swapped order "a red block on top of a yellow block"
        0.5 * e[0] + e[2],  # 3: a negative wins
        -e[0],  # 4: opposite of the goal, and of nothing else: negatives (0) beat the goal (-1)
    ]
    return LookupVLM(images, one_hot_texts(CANDIDATES, d))


def test_binary_reward_is_one_only_when_the_goal_wins_the_argmax(vlm):
    reward = ZSRMReward(vlm)
    r = reward({"front": frames([0, 1, 2, 3, 4])}, GOAL)
    np.testing.assert_array_equal(r, [1, 1, 0, 0, 0])
    assert r.dtype == np.float32


def test_raw_score_and_margin_stay_available(vlm):
    x = frames([0, 1, 2, 3])
    raw = ZSRMReward(vlm, output="raw")({"front": x}, GOAL)
    np.testing.assert_allclose(raw, [1.0, 1 / np.sqrt(1 + 0.81), 0.0, 0.5 / np.sqrt(1.25)], atol=1e-6)
    margin = ZSRMReward(vlm, output="margin")({"front": x}, GOAL)
    binary = ZSRMReward(vlm)({"front": x}, GOAL)
    np.testing.assert_array_equal(margin > 0, binary > 0)
    np.testing.assert_allclose(margin[1], (1 - 0.9) / np.sqrt(1.81), atol=1e-6)


def test_goal_wording_is_canonicalised_before_scoring(vlm):
    r = ZSRMReward(vlm)({"front": frames([0, 2])}, "A yellow cube stacked on the red block.")
    np.testing.assert_array_equal(r, [1, 0])


def test_text_embeddings_are_computed_once_per_goal(vlm):
    reward = ZSRMReward(vlm)
    reward.prepare(GOAL)
    calls = vlm.text_calls
    for _ in range(3):
        reward({"front": frames([0, 1])}, GOAL)
    assert vlm.text_calls == calls == 1


@pytest.mark.parametrize("goal,camera", [
    ("a yellow block on the left of a red block", "front"),
    ("a yellow block in front of a red block", "left"),
    ("a blue puck close to a yellow puck", "tilted"),
])
def test_reads_the_camera_the_relation_needs(goal, camera):
    texts = candidate_texts(goal)
    vlm = LookupVLM([np.eye(len(texts))[0]], one_hot_texts(texts, len(texts)))
    reward = ZSRMReward(vlm)
    reward.prepare(goal)
    assert reward.camera == camera
    others = {c: frames([255]) for c in ("front", "left", "tilted") if c != camera}  # would index out of range
    assert reward({camera: frames([0]), **others}, goal)[0] == 1.0
    with pytest.raises(ValueError, match=f"reads camera '{camera}'"):
        reward(others, goal)


def test_bad_output_and_non_spatial_goal_are_clear_errors(vlm):
    with pytest.raises(ValueError, match="unknown output"):
        ZSRMReward(vlm, output="soft")
    from zsrm.tasks.language import GoalError

    with pytest.raises(GoalError):
        ZSRMReward(vlm)({"front": frames([0])}, "an inverted pendulum standing upright")


def test_plugs_into_the_gymnasium_wrapper_and_the_reward_curve():
    import gymnasium as gym

    import zsrm.envs  # noqa: F401
    from zsrm.testing import ColourVLM
    from zsrm.rewards import ZeroShotReward
    from zsrm.evaluation.curves import record_trajectory, reward_curve

    goal = "a blue puck close to a yellow puck"
    reward = ZSRMReward(ColourVLM(image_size=32))
    env = ZeroShotReward(gym.make("zsrm/Pushing-v0", task=goal, cameras=("tilted",)), reward, goal)
    env.reset(seed=0)
    _, r, _, _, info = env.step(env.action_space.sample())
    assert r in (0.0, 1.0) and info["zsrm_reward"] == r
    env.close()
    rows = reward_curve(record_trajectory(goal, cameras=("tilted",), steps=3), [reward])
    assert len(rows) == 4 and all(row["zsrm_reward"] in (0.0, 1.0) for row in rows)


@pytest.mark.parametrize("goal", ["a yellow block on top of a red block", "a yellow puck close to a blue puck"])
def test_the_shipped_student_rewards_the_end_of_a_scripted_episode_and_not_its_start(goal):
    from zsrm.fullmodel import load_reward_backbone
    from zsrm.evaluation.curves import record_trajectory

    reward = ZSRMReward(load_reward_backbone("student"))
    camera = reward.goal_camera(goal)
    traj = record_trajectory(goal, cameras=(camera,), steps=40, seed=0)
    assert not traj.infos[0]["is_success"] and traj.infos[-1]["is_success"]  # the oracle, for the check only
    frames = traj.observations[camera][[0, -1]]
    assert reward({camera: frames}, goal).tolist() == [0.0, 1.0]
