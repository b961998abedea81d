"""The base reward (paper 2.1), goal-baseline projection (VLM-RMs) and the text cache."""
import numpy as np
import pytest
import torch

from zsrm.rewards.base import BaseReward, projection_reward

RED, BLUE, YELLOW = (255, 0, 0), (0, 0, 255), (255, 255, 0)


def test_dot_is_the_raw_embedding_dot_product(toy_vlm, solid_frames):
    reward = BaseReward(toy_vlm, camera="front", mode="dot")
    r = reward({"front": solid_frames([RED, BLUE])}, "a red block")
    # image (1, 0, 0) . text (1.1, 0.1, 0.1) = 1.1; image (0, 0, 1) . text = 0.1
    np.testing.assert_allclose(r, [1.1, 0.1], atol=1e-5)
    assert r.dtype == np.float32 and r.shape == (2,)


def test_cosine_ranks_the_matching_colour_first(toy_vlm, solid_frames):
    reward = BaseReward(toy_vlm, camera="front", mode="cosine")
    frames = {"front": solid_frames([RED, BLUE, YELLOW])}
    r_red, r_blue = reward(frames, "a red block"), reward(frames, "a blue block")
    assert r_red.argmax() == 0 and r_blue.argmax() == 1
    assert np.all(np.abs(r_red) <= 1 + 1e-6)


def test_reads_its_own_camera(toy_vlm, solid_frames):
    reward = BaseReward(toy_vlm, camera="tilted", mode="cosine")
    obs = {"front": solid_frames([BLUE]), "tilted": solid_frames([RED])}
    assert reward(obs, "red")[0] > 0.9
    with pytest.raises(ValueError, match="camera 'tilted'"):
        reward({"front": solid_frames([RED])}, "red")


def test_text_embedding_is_computed_once_per_goal(toy_vlm, solid_frames):
    reward = BaseReward(toy_vlm, camera="front")
    obs = {"front": solid_frames([RED, BLUE])}
    for _ in range(5):
        reward(obs, "a red block")
    assert toy_vlm.text_calls == 1
    assert reward.text_cache.hits == 4 and reward.text_cache.misses == 1
    reward(obs, "a blue block")  # a new goal: one more text call
    assert toy_vlm.text_calls == 2
    assert toy_vlm.image_calls == 6  # one batched image forward per call, whatever N


def test_without_cache_every_call_encodes(toy_vlm, solid_frames):
    reward = BaseReward(toy_vlm, camera="front", cache_texts=False)
    for _ in range(3):
        reward({"front": solid_frames([RED])}, "a red block")
    assert toy_vlm.text_calls == 3


def test_images_are_encoded_in_batches(toy_vlm, solid_frames):
    reward = BaseReward(toy_vlm, camera="front", mode="cosine", batch_size=2)
    frames = solid_frames([RED, BLUE, YELLOW, RED, BLUE])
    r = reward({"front": frames}, "red")
    assert toy_vlm.image_calls == 3
    one_by_one = np.concatenate([reward({"front": f[None]}, "red") for f in frames])
    np.testing.assert_allclose(r, one_by_one, atol=1e-6)


# --- goal-baseline projection (VLM-RMs, Definition 1) ---------------------------------------

def _explicit_projection_reward(x, g, b, alpha):
    """The definition with the full matrix: 1 - 0.5 ||(alpha P + (1 - alpha) I)(x - g)||^2."""
    x, g, b = (v / np.linalg.norm(v, axis=-1, keepdims=True) for v in (x, g, b))
    d = g - b
    P = np.outer(d, d) / d.dot(d)
    M = alpha * P + (1 - alpha) * np.eye(len(d))
    return 1 - 0.5 * np.sum(((x - g) @ M.T) ** 2, axis=-1)


def test_projection_matches_the_matrix_definition():
    rng = np.random.default_rng(0)
    x, g, b = rng.normal(size=(6, 5)), rng.normal(size=5), rng.normal(size=5)
    for alpha in (0.0, 0.3, 0.5, 1.0):
        got = projection_reward(torch.tensor(x), torch.tensor(g), torch.tensor(b), alpha).numpy()
        np.testing.assert_allclose(got, _explicit_projection_reward(x, g, b, alpha), atol=1e-5)


def test_projection_hand_made_embeddings():
    g, b = torch.tensor([1.0, 0.0, 0.0]), torch.tensor([0.0, 1.0, 0.0])
    x = torch.tensor([[1.0, 0.0, 0.0],   # the goal itself
                      [0.0, 1.0, 0.0],   # the baseline
                      [0.0, 0.0, 1.0],   # orthogonal to the goal-baseline plane
                      [1.0, 0.0, 1.0]])  # goal plus an irrelevant direction
    # alpha = 0: cosine similarity x . g
    np.testing.assert_allclose(projection_reward(x, g, b, 0.0), [1.0, 0.0, 0.0, np.sqrt(0.5)], atol=1e-6)
    # alpha = 1: only the component along g - b counts; x - g for the baseline is -(g - b)
    # -> 1 - 0.5 * 2 = 0; for (0, 0, 1): projection (-0.5, 0.5, 0) -> 1 - 0.25.
    r = projection_reward(x, g, b, 1.0).numpy()
    np.testing.assert_allclose(r[:3], [1.0, 0.0, 0.75], atol=1e-6)
    # The irrelevant direction costs less with the projection than with plain cosine.
    assert r[3] > projection_reward(x, g, b, 0.0)[3]


def test_projection_mode_in_base_reward(toy_vlm, solid_frames):
    reward = BaseReward(toy_vlm, camera="front", mode="projection", baseline="a block", alpha=1.0)
    r = reward({"front": solid_frames([RED, BLUE])}, "a red block")
    img = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    want = projection_reward(img, torch.tensor([1.1, 0.1, 0.1]), torch.tensor([0.1, 0.1, 0.1]), 1.0)
    np.testing.assert_allclose(r, want.numpy(), atol=1e-5)
    assert r[0] > r[1]
    reward.prepare("a red block")
    assert toy_vlm.text_calls == 1  # goal and baseline encoded together, once


def test_projection_rejects_a_baseline_equal_to_the_goal():
    v = torch.tensor([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="same embedding"):
        projection_reward(v[None], v, 2 * v, 0.5)


# --- bad input -------------------------------------------------------------------------------

@pytest.mark.parametrize("goal", ["", "   ", None, 3])
def test_empty_or_non_text_goal(toy_vlm, solid_frames, goal):
    with pytest.raises(ValueError, match="non-empty sentence"):
        BaseReward(toy_vlm)({"front": solid_frames([RED])}, goal)


@pytest.mark.parametrize("frames, match", [
    (np.zeros((2, 16, 16, 3), np.float32), "uint8"),
    (np.zeros((16, 16, 3), np.uint8), r"shape \(N, H, W, 3\)"),
    (np.zeros((2, 16, 16, 4), np.uint8), r"shape \(N, H, W, 3\)"),
    (np.zeros((0, 16, 16, 3), np.uint8), "empty"),
    ([[0]], "numpy array"),
])
def test_wrong_image_shape_or_dtype(toy_vlm, frames, match):
    with pytest.raises(ValueError, match=match):
        BaseReward(toy_vlm)({"front": frames}, "a red block")


def test_bad_options(toy_vlm):
    with pytest.raises(ValueError, match="unknown mode"):
        BaseReward(toy_vlm, mode="l2")
    with pytest.raises(ValueError, match="needs a baseline"):
        BaseReward(toy_vlm, mode="projection")
    with pytest.raises(ValueError, match="alpha"):
        BaseReward(toy_vlm, mode="projection", baseline="a table", alpha=1.5)
    with pytest.raises(ValueError, match="only by mode 'projection'"):
        BaseReward(toy_vlm, mode="cosine", baseline="a table")


def test_observations_and_infos_must_agree(toy_vlm, solid_frames):
    with pytest.raises(ValueError, match="same number of envs"):
        BaseReward(toy_vlm)({"front": solid_frames([RED, BLUE])}, "red", infos=[{}])
