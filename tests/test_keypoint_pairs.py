"""The policy's keypoint pairs (TrainConfig.pair_scale): what the features hold, and how the setting is kept."""
import gymnasium as gym
import numpy as np
import pytest
import torch

from zsrm.rl.config import TrainConfig
from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY, KeypointExtractor, pair_differences


def extractor(pixels: bool, pair_scale: float) -> KeypointExtractor:
    space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, np.inf, (6, 8, 8), np.float32),
                             IMAGE_KEY: gym.spaces.Box(0, 255, (3, 16, 16), np.uint8)})
    return KeypointExtractor(space, keypoints=5, features_dim=8, pixels=pixels, pair_scale=pair_scale)


def observations(n: int = 3) -> dict:
    generator = torch.Generator().manual_seed(0)
    return {FEATURES_KEY: torch.rand(n, 6, 8, 8, generator=generator),
            IMAGE_KEY: torch.randint(0, 256, (n, 3, 16, 16), generator=generator, dtype=torch.uint8)}


@pytest.mark.parametrize("pixels", [True, False])
def test_keypoint_xy_reads_every_branchs_positions_and_no_strength(pixels):
    net = extractor(pixels, 0.0)
    obs = observations()
    points = net.points(obs)
    xy = net.keypoint_xy(points)
    pixel_count = net.pixels.out_dim // 3 if pixels else 0  # the pixel CNN's own keypoints
    assert xy.shape == (3, 5 + pixel_count, 2)
    vlm = net.softmax(net.heat_maps(obs[FEATURES_KEY]))
    torch.testing.assert_close(xy[:, :5], vlm[:, :10].reshape(3, 5, 2))
    if pixels:
        torch.testing.assert_close(xy[:, 5:], net.pixels(obs[IMAGE_KEY])[:, :2 * pixel_count].reshape(3, -1, 2))
    assert xy.abs().max() <= 1.0  # positions in the frame's [-1, 1], not the strengths


def test_pairs_are_every_difference_scaled_and_off_keeps_the_old_layer():
    xy = torch.tensor([[[0.0, 0.0], [0.5, -0.5], [1.0, 1.0]]])
    assert pair_differences(xy).tolist() == [[0.5, -0.5, 1.0, 1.0, 0.5, 1.5]]  # (1-0), (2-0), (2-1)
    plain, paired = extractor(True, 0.0), extractor(True, 3.0)
    count = 5 + plain.pixels.out_dim // 3
    assert plain.out[0].in_features == plain.points_dim == 3 * count  # the weights of runs before pairs
    assert paired.out[0].in_features == 3 * count + count * (count - 1)
    obs = observations()
    points = paired.points(obs)
    features = torch.cat([points, 3.0 * pair_differences(paired.keypoint_xy(points))], dim=1)
    torch.testing.assert_close(paired(obs), paired.out(features))


def test_pair_scale_is_unwritten_when_off_and_unread_by_the_random_policy():
    assert "pair_scale" not in TrainConfig(goal="push_close").to_dict()
    assert TrainConfig(goal="push_close", pair_scale=3.0).to_dict()["pair_scale"] == 3.0
    assert "pair_scale" not in TrainConfig(goal="push_close", reward="random", pair_scale=3.0).to_dict()
    with pytest.raises(ValueError, match="pair_scale must be >= 0"):
        TrainConfig(goal="push_close", pair_scale=-1.0)


@pytest.mark.parametrize("stride, cells", [(4, 4), (2, 8)])
def test_the_pixel_cnns_stride_sets_its_heat_maps_side(stride, cells):
    space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, np.inf, (6, 8, 8), np.float32),
                             IMAGE_KEY: gym.spaces.Box(0, 255, (3, 16, 16), np.uint8)})
    net = KeypointExtractor(space, keypoints=5, features_dim=8, pixel_stride=stride)
    images = observations()[IMAGE_KEY]
    assert net.pixels.cnn(images.float() / 255).shape[-2:] == (cells, cells)
    assert net.pixels.softmax.grid.shape == (cells * cells, 2)
    assert net(observations()).shape == (3, 8)  # the same keypoints and features, on finer maps


def test_pixel_stride_is_unwritten_at_4_and_checked():
    assert "pixel_stride" not in TrainConfig(goal="push_close").to_dict()  # runs before it stay the same runs
    assert TrainConfig(goal="push_close", pixel_stride=2).to_dict()["pixel_stride"] == 2
    assert "pixel_stride" not in TrainConfig(goal="push_close", reward="random", pixel_stride=2).to_dict()
    with pytest.raises(ValueError, match="pixel_stride is 2 or 4"):
        TrainConfig(goal="push_close", pixel_stride=3)
