"""What the policy sees: the frozen VLM's Grad-CAM-layer feature map, read by keypoints.

The scene VLM's last convolutional ReLU already says where each object is (its Grad-CAM
maps locate them, paper 2.2), so the policy reads that map instead of learning vision from
the sparse reward. The trunk is frozen and runs once per observation, batched over the envs
(:class:`VecImageFeatures`), so PPO's epochs reuse the stored maps. A trainable 1x1 conv turns
the map into ``K`` heat maps and a spatial softmax into ``K`` expected (x, y) positions plus
each map's peak strength (:class:`KeypointExtractor`, after Levine et al. 2016).

The VLM was pretrained to tell which coloured objects are present; it hardly sees the gripper
(a probe on its map reads the fingers' open/closed state no better than chance). So a small
CNN on the raw image, trained by RL, adds its own keypoints (``pixels=True``): with it the
probe's error on the grip state falls from 0.45 to 0.11 and on the gripper's position from
2.3 to 0.7 cm (``python probes/policy_vision_probe.py``).
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from torch import nn

FEATURES_KEY = "features"
IMAGE_KEY = "image"


class VecImageFeatures(VecEnvWrapper):
    """Replace a camera's images by the frozen VLM trunk's feature maps ``(C, h, w)`` float32
    and the frame itself (CHW uint8), for :class:`KeypointExtractor`.

    ``trunk_size`` and ``pixel_size`` (0: the camera's size) shrink the frame (area average)
    before the trunk and for the pixel CNN: at 32 px the trunk costs a quarter of its 64 px
    time and its map is 8x8 (``benchmarks/train_profile.py``). Put it outside the reward
    wrapper, so the reward still scores the camera's frames. Terminal observations in
    ``infos`` are converted too (PPO bootstraps truncated episodes from them).
    """

    def __init__(self, venv: VecEnv, vlm, camera: str, trunk_size: int = 0, pixel_size: int = 0):
        if camera not in venv.observation_space.spaces:
            raise ValueError(f"the env observes {', '.join(venv.observation_space.spaces)}, not camera {camera!r}")
        self.vlm = vlm.eval()
        for p in self.vlm.parameters():
            p.requires_grad_(False)
        self.camera = camera
        size = venv.observation_space[camera].shape[0]
        self.trunk_size, self.pixel_size = check_view(trunk_size, size), check_view(pixel_size, size)
        with torch.no_grad():
            c, h, w = self.vlm.image_trunk(self.trunk_input(np.zeros((1, size, size, 3), np.uint8))).shape[1:]
        space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, np.inf, (c, h, w), np.float32),
                                 IMAGE_KEY: gym.spaces.Box(0, 255, (3, self.pixel_size, self.pixel_size), np.uint8)})
        super().__init__(venv, observation_space=space)

    def trunk_input(self, images: np.ndarray) -> torch.Tensor:
        pixels = self.vlm.preprocess(images)
        if pixels.shape[-1] != self.trunk_size:
            pixels = nn.functional.interpolate(pixels, size=self.trunk_size, mode="area")
        return pixels

    @torch.no_grad()
    def features(self, images: np.ndarray) -> np.ndarray:
        return self.vlm.image_trunk(self.trunk_input(images)).float().cpu().numpy()

    def frames(self, images: np.ndarray) -> np.ndarray:
        """(N, H, W, 3) uint8 -> (N, 3, s, s) uint8 at the pixel CNN's side ``s`` (area average)."""
        return shrink_frames(images, self.pixel_size)

    def convert(self, images: np.ndarray) -> dict:
        """Camera frames (N, H, W, 3) uint8 -> the policy's observation (maps and CHW frames)."""
        return {FEATURES_KEY: self.features(images), IMAGE_KEY: self.frames(images)}

    def _convert(self, obs) -> dict:
        return self.convert(obs[self.camera])

    def reset(self):
        return self._convert(self.venv.reset())

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        terminal = [i for i, info in enumerate(infos) if "terminal_observation" in info]
        if terminal:
            converted = self.convert(np.stack([infos[i]["terminal_observation"][self.camera] for i in terminal]))
            for j, i in enumerate(terminal):
                infos[i]["terminal_observation"] = {k: v[j] for k, v in converted.items()}
        return self._convert(obs), rewards, dones, infos


def shrink_frames(images: np.ndarray, side: int) -> np.ndarray:
    """(N, H, W, 3) uint8 -> (N, 3, side, side) uint8: the mean of each k x k block, rounded
    half to even (``side`` divides H = W). The same numbers as numpy's float64 block mean, in a
    quarter of its time: the sum of k x k bytes over k * k is exact, or at least 1 / (2 k^2)
    from a tie, in float32 (a test checks it against the numpy mean)."""
    x = torch.from_numpy(np.ascontiguousarray(images)).permute(0, 3, 1, 2)
    if x.shape[-1] != side:
        x = nn.functional.avg_pool2d(x.float(), x.shape[-1] // side).round_().to(torch.uint8)
    return x.contiguous().numpy()


def check_view(size: int, camera_size: int) -> int:
    """The side a frame is shrunk to (0: the camera's own), which must divide the camera's."""
    size = int(size) or camera_size
    if size < 8 or camera_size % size:
        raise ValueError(f"a policy view of {size} px must be at least 8 and divide the camera's {camera_size} px")
    return size


def policy_view(venv: VecEnv, vlm, cfg) -> VecImageFeatures:
    """What a policy trained with TrainConfig ``cfg`` sees of ``venv``: its goal camera through
    the frozen VLM trunk and the pixel CNN, at the sizes ``cfg`` names."""
    from zsrm.rl.goals import goal_camera

    return VecImageFeatures(venv, vlm, goal_camera(cfg.goal, cfg.scene), cfg.trunk_size, cfg.pixel_size)


class SpatialSoftmax(nn.Module):
    """``(N, K, h, w)`` heat maps to their expected (x, y) in [-1, 1] and their peak value.

    Each map is standardised over its cells before the softmax: untrained heat maps are
    nearly flat, and without it every keypoint starts at the image centre whatever the image
    (measured: a spread of 0.004 across frames), which leaves PPO nothing to learn from.
    """

    def __init__(self, h: int, w: int, temperature: float = 0.5):
        super().__init__()
        ys, xs = torch.meshgrid(torch.linspace(-1, 1, h), torch.linspace(-1, 1, w), indexing="ij")
        self.register_buffer("grid", torch.stack([xs.flatten(), ys.flatten()], dim=1))  # (h*w, 2)
        self.log_temperature = nn.Parameter(torch.tensor(float(np.log(temperature))))

    def forward(self, maps: torch.Tensor) -> torch.Tensor:
        flat = maps.flatten(2)
        # mean and (unbiased) std once for both uses: half the time of calling std() twice. The
        # variance's floor keeps the gradient finite on a flat map (a frame the trunk sees nothing in)
        mean = flat.mean(dim=-1, keepdim=True)
        centred = flat - mean
        std = (centred.square().sum(dim=-1, keepdim=True) / (flat.shape[-1] - 1) + 1e-12).sqrt() + 1e-6
        attention = torch.softmax(centred / (std * self.log_temperature.exp()), dim=-1)
        peak = ((flat.amax(dim=-1, keepdim=True) - mean) / std).squeeze(-1)
        points = attention @ self.grid  # (N, K, 2)
        return torch.cat([points.flatten(1), peak / 4.0], dim=1)


class PixelKeypoints(nn.Module):
    """A small CNN on the raw frame to ``K`` keypoints, trained by RL. ``stride`` 4 (the default) or 2:
    its heat maps are a quarter or half the frame's side (at 32 px a cell is 8 or 4 cm of table)."""

    def __init__(self, size: int, keypoints: int = 16, stride: int = 4):
        super().__init__()
        if stride not in (2, 4):
            raise ValueError(f"the pixel CNN's stride is 2 or 4, got {stride}")
        self.cnn = nn.Sequential(nn.Conv2d(3, 16, 3, 2, 1), nn.ReLU(), nn.Conv2d(16, 32, 3, stride // 2, 1), nn.ReLU(),
                                 nn.Conv2d(32, keypoints, 3, 1, 1))
        self.softmax = SpatialSoftmax(size // stride, size // stride)
        self.out_dim = 3 * keypoints

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.softmax(self.cnn(images.float() / 255.0))


class KeypointExtractor(BaseFeaturesExtractor):
    """VLM feature map -> 1x1 convs -> K keypoints (x, y, strength), with the pixel CNN's
    keypoints beside them (``pixels``, its stride ``pixel_stride``), -> a linear layer. ``pair_scale`` > 0 adds every pair of
    keypoints' difference (x_j - x_i, y_j - y_i) times ``pair_scale``: where one thing is from
    another, at a finer scale than the frame's [-1, 1]. PPO on true state learnt push_close from
    the puck's place relative to the pusher in units of 10 cm, not from absolute places
    (``probes/push_state_ppo.py``); on pixels these pairs did not (docs/training.md)."""

    def __init__(self, observation_space: gym.spaces.Dict, keypoints: int = 32, features_dim: int = 256,
                 pixels: bool = True, pair_scale: float = 0.0, pixel_stride: int = 4):
        super().__init__(observation_space, features_dim)
        c, h, w = observation_space[FEATURES_KEY].shape
        self.heat = nn.Sequential(nn.Conv2d(c, 64, 1), nn.ReLU(), nn.Conv2d(64, keypoints, 1))
        self.softmax = SpatialSoftmax(h, w)
        self.pixels = PixelKeypoints(observation_space[IMAGE_KEY].shape[-1], stride=pixel_stride) if pixels else None
        self.pair_scale = float(pair_scale)
        self.branches = (keypoints, *((self.pixels.out_dim // 3,) if pixels else ()))  # keypoints per branch
        count = sum(self.branches)
        self.points_dim = 3 * count  # what points() gives (the inverse-dynamics head reads it)
        self.out = nn.Sequential(nn.Linear(self.points_dim + (count * (count - 1) if pair_scale else 0), features_dim),
                                 nn.ReLU())

    def heat_maps(self, maps: torch.Tensor) -> torch.Tensor:
        """``self.heat`` (two 1x1 convs) as matrix products over channels-last cells: the same
        weights and result, half the time of Conv2d's 1x1 path on this CPU."""
        first, second = self.heat[0], self.heat[2]
        x = nn.functional.relu(nn.functional.linear(maps.permute(0, 2, 3, 1), first.weight.flatten(1), first.bias))
        return nn.functional.linear(x, second.weight.flatten(1), second.bias).permute(0, 3, 1, 2)

    def points(self, observations: dict) -> torch.Tensor:
        """The keypoints (x, y, strength) of both branches, before the linear layer."""
        points = self.softmax(self.heat_maps(observations[FEATURES_KEY]))
        if self.pixels is not None:
            points = torch.cat([points, self.pixels(observations[IMAGE_KEY])], dim=1)
        return points

    def forward(self, observations: dict) -> torch.Tensor:
        points = self.points(observations)
        if self.pair_scale:
            points = torch.cat([points, self.pair_scale * pair_differences(self.keypoint_xy(points))], dim=1)
        return self.out(points)

    def keypoint_xy(self, points: torch.Tensor) -> torch.Tensor:
        """``(N, M, 2)``: the (x, y) of every keypoint in :meth:`points`' output, in which each branch
        holds its K points' (x, y) pairs, then their K strengths."""
        xy, start = [], 0
        for k in self.branches:
            xy.append(points[:, start:start + 2 * k])
            start += 3 * k
        return torch.cat(xy, dim=1).reshape(len(points), -1, 2)


def pair_differences(xy: torch.Tensor) -> torch.Tensor:
    """``(N, M, 2)`` points -> ``(N, M (M - 1))``: ``xy[j] - xy[i]`` for every pair i < j.

    >>> pair_differences(torch.tensor([[[0., 0.], [1., 2.], [3., 3.]]]))
    tensor([[1., 2., 3., 3., 2., 1.]])
    """
    i, j = torch.triu_indices(xy.shape[1], xy.shape[1], offset=1)
    return (xy[:, j] - xy[:, i]).flatten(1)
