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
2.3 to 0.7 cm (``python benchmarks/policy_vision_probe.py``).
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
    """Replace a camera's images by the frozen VLM trunk's feature maps ``(C, h, w)`` float32.

    Put it outside the reward wrapper, so the reward still scores pixels. Terminal
    observations in ``infos`` are converted too (PPO bootstraps truncated episodes from them).
    """

    def __init__(self, venv: VecEnv, vlm, camera: str):
        if camera not in venv.observation_space.spaces:
            raise ValueError(f"the env observes {', '.join(venv.observation_space.spaces)}, not camera {camera!r}")
        self.vlm = vlm.eval()
        for p in self.vlm.parameters():
            p.requires_grad_(False)
        self.camera = camera
        size = venv.observation_space[camera].shape[0]
        with torch.no_grad():
            c, h, w = self.vlm.image_trunk(self.vlm.preprocess(np.zeros((1, size, size, 3), np.uint8))).shape[1:]
        space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0.0, np.inf, (c, h, w), np.float32),
                                 IMAGE_KEY: gym.spaces.Box(0, 255, (3, size, size), np.uint8)})
        super().__init__(venv, observation_space=space)

    @torch.no_grad()
    def features(self, images: np.ndarray) -> np.ndarray:
        return self.vlm.image_trunk(self.vlm.preprocess(images)).float().cpu().numpy()

    def convert(self, images: np.ndarray) -> dict:
        """Camera frames (N, H, W, 3) uint8 -> the policy's observation (maps and CHW frames)."""
        return {FEATURES_KEY: self.features(images), IMAGE_KEY: np.ascontiguousarray(images.transpose(0, 3, 1, 2))}

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
        peak = (flat.amax(dim=-1) - flat.mean(dim=-1)) / (flat.std(dim=-1) + 1e-6)
        standard = (flat - flat.mean(dim=-1, keepdim=True)) / (flat.std(dim=-1, keepdim=True) + 1e-6)
        attention = torch.softmax(standard / self.log_temperature.exp(), dim=-1)
        points = attention @ self.grid  # (N, K, 2)
        return torch.cat([points.flatten(1), peak / 4.0], dim=1)


class PixelKeypoints(nn.Module):
    """A small CNN on the raw frame (stride 4) to ``K`` keypoints, trained by RL."""

    def __init__(self, size: int, keypoints: int = 16):
        super().__init__()
        self.cnn = nn.Sequential(nn.Conv2d(3, 16, 3, 2, 1), nn.ReLU(), nn.Conv2d(16, 32, 3, 2, 1), nn.ReLU(),
                                 nn.Conv2d(32, keypoints, 3, 1, 1))
        self.softmax = SpatialSoftmax(size // 4, size // 4)
        self.out_dim = 3 * keypoints

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.softmax(self.cnn(images.float() / 255.0))


class KeypointExtractor(BaseFeaturesExtractor):
    """VLM feature map -> 1x1 convs -> K keypoints (x, y, strength), with the pixel CNN's
    keypoints beside them (``pixels``), -> a linear layer."""

    def __init__(self, observation_space: gym.spaces.Dict, keypoints: int = 32, features_dim: int = 256,
                 pixels: bool = True):
        super().__init__(observation_space, features_dim)
        c, h, w = observation_space[FEATURES_KEY].shape
        self.heat = nn.Sequential(nn.Conv2d(c, 64, 1), nn.ReLU(), nn.Conv2d(64, keypoints, 1))
        self.softmax = SpatialSoftmax(h, w)
        self.pixels = PixelKeypoints(observation_space[IMAGE_KEY].shape[-1]) if pixels else None
        width = 3 * keypoints + (self.pixels.out_dim if pixels else 0)
        self.out = nn.Sequential(nn.Linear(width, features_dim), nn.ReLU())

    def points(self, observations: dict) -> torch.Tensor:
        """The keypoints (x, y, strength) of both branches, before the linear layer."""
        points = self.softmax(self.heat(observations[FEATURES_KEY]))
        if self.pixels is not None:
            points = torch.cat([points, self.pixels(observations[IMAGE_KEY])], dim=1)
        return points

    def forward(self, observations: dict) -> torch.Tensor:
        return self.out(self.points(observations))
