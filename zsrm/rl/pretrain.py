"""Keypoints learnt before the reward: a keypoint autoencoder on frames of random actions.

The policy's pixel CNN (``PixelKeypoints``) is the encoder: a frame is rebuilt, at half its side,
from another frame (its appearance) and its own keypoints drawn as Gaussian blobs (its geometry),
so the keypoints must follow what moves (after Jakab et al., 2018); an inverse-dynamics loss (the
random action from two consecutive frames' keypoints, :class:`zsrm.rl.auxiliary.InverseDynamics`)
ties them to what the agent moves. No reward, state or goal is read: only the goal camera's frames
and the random actions taken. ``zsrm train --learner sac`` reads these keypoints, frozen
(docs/training.md: on push_close the pusher to 0.4-0.6 cm, against 2-5 cm for PPO-trained ones).

A pretrained folder holds ``config.json`` (kind ``zsrm-keypoints``: the settings of the views it
reads, the env steps its frames took) and ``model.safetensors`` (a ``KeypointExtractor`` whose
pixel branch is the encoder; its VLM branch is untrained, seeded).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from zsrm.common.registry import WEIGHTS_FILE, build_model, load_weights, read_config, save_folder
from zsrm.rl.auxiliary import InverseDynamics
from zsrm.rl.config import TrainConfig
from zsrm.rl.envs import make_vec
from zsrm.rl.features import KeypointExtractor, PixelKeypoints, shrink_frames
from zsrm.rl.goals import goal_camera

KIND = "zsrm-keypoints"
FRAME_ENVS = 8  # envs stepped side by side while the random frames are collected
# keypoints of the pixel CNN (KeypointExtractor's pixel branch; the VLM branch has cfg.keypoints)
PIXEL_KEYPOINTS = 16


def random_frames(cfg: TrainConfig, episodes: int, envs: int, seed: int,
                  progress: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Goal-camera frames (N, side, side, 3) of uniform random actions in ``cfg``'s scenes, each
    frame's episode and the action taken after it (NaN after an episode's last frame). Every env
    restarts when the first one's episode ends."""
    venv, camera = make_vec(cfg, envs, seed), goal_camera(cfg.goal, cfg.scene)
    rng = np.random.default_rng(seed)
    frames, episode, actions = [], [], []
    for e in tqdm(range(0, episodes, envs), desc="frames", unit="episode", unit_scale=envs, disable=not progress):
        obs = venv.reset()
        for _ in range(cfg.episode_decisions):
            action = rng.uniform(-1, 1, (envs, *venv.action_space.shape)).astype(np.float32)
            frames.append(obs[camera])
            episode.append(e + np.arange(envs))
            obs, _, dones, _ = venv.step(action)
            actions.append(np.where(dones[:, None], np.nan, action))  # the next frame is another episode's
            if dones.any():  # the next frames come after a reset: no action leads to them
                actions[-1][:] = np.nan
                break
    venv.close()
    return np.concatenate(frames), np.concatenate(episode), np.concatenate(actions)


def gaussian_maps(xy: torch.Tensor, side: int, sigma: float) -> torch.Tensor:
    """(N, K, 2) points in [-1, 1] -> (N, K, side, side) Gaussian blobs of std ``sigma`` (in [-1, 1] units)."""
    grid = torch.linspace(-1, 1, side)
    gx = torch.exp(-(grid[None, None] - xy[..., 0:1]) ** 2 / (2 * sigma ** 2))  # (N, K, side)
    gy = torch.exp(-(grid[None, None] - xy[..., 1:2]) ** 2 / (2 * sigma ** 2))
    return gy[..., :, None] * gx[..., None, :]


def conv(c_in: int, c_out: int) -> nn.Module:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, 1, 1), nn.ReLU())


class KeypointAutoencoder(nn.Module):
    """``PixelKeypoints`` on the target frame, a small CNN on the source frame, and a decoder from
    both (at a quarter of the frame's side, upsampled once) to the target frame at half its side."""

    def __init__(self, size: int, keypoints: int, stride: int, sigma: float = 0.1):
        super().__init__()
        self.keypoints, self.sigma, self.side = PixelKeypoints(size, keypoints, stride), sigma, size // 4
        self.count = keypoints
        self.appearance = nn.Sequential(conv(3, 32), nn.MaxPool2d(2), conv(32, 32), nn.MaxPool2d(2), conv(32, 32))
        # it rebuilds the frame at half its side (a quarter of the cost; the blobs' places stay continuous)
        self.decoder = nn.Sequential(conv(32 + 2 * keypoints, 64), nn.Upsample(scale_factor=2), conv(64, 32),
                                     nn.Conv2d(32, 3, 3, 1, 1))

    def points(self, frames: torch.Tensor) -> torch.Tensor:
        """(N, 3, s, s) uint8 -> (N, K, 2) keypoints' (x, y)."""
        return self.keypoints(frames)[:, :2 * self.count].reshape(len(frames), self.count, 2)

    def forward(self, source: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        xy_s, xy_t = self.points(source), self.points(target)
        # Jakab et al.: the source's keypoints too, so the decoder can move what is where it was
        maps = torch.cat([gaussian_maps(xy_t, self.side, self.sigma), gaussian_maps(xy_s, self.side, self.sigma)], 1)
        return self.decoder(torch.cat([self.appearance(source.float() / 255.0), maps], dim=1))


def train_autoencoder(model: KeypointAutoencoder, frames: torch.Tensor, episode: np.ndarray, actions: np.ndarray,
                      envs: int, steps: int, batch: int, inverse_weight: float, seed: int, any_source: float = 0.0,
                      progress: bool = True) -> list[float]:
    """Adam on the squared error of each rebuilt target frame (the source: another frame of its
    episode, or with probability ``any_source`` any frame, whose objects lie elsewhere), plus
    ``inverse_weight`` times an inverse-dynamics loss: the random action taken between a frame and
    its env's next (``envs`` frames on) predicted from the two frames' keypoints."""
    rng = np.random.default_rng(seed)
    by_episode = {e: np.flatnonzero(episode == e) for e in np.unique(episode)}
    with_next = np.flatnonzero(~np.isnan(actions).any(axis=1))
    inverse = InverseDynamics(2 * model.count, actions.shape[1]) if inverse_weight else nn.Identity()
    optimiser = torch.optim.Adam([*model.parameters(), *inverse.parameters()], lr=1e-3)
    losses = []
    for _ in tqdm(range(steps), desc="autoencoder", unit="step", disable=not progress):
        target = rng.integers(0, len(frames), batch)
        source = np.array([rng.choice(by_episode[episode[t]]) for t in target])
        if any_source:
            anywhere = rng.random(batch) < any_source
            source[anywhere] = rng.integers(0, len(frames), int(anywhere.sum()))
        rebuilt = model(frames[source], frames[target])
        loss = (rebuilt - nn.functional.avg_pool2d(frames[target].float() / 255.0, 2)).square().mean()
        if inverse_weight:
            before = rng.choice(with_next, batch)
            points = model.points(frames[np.concatenate([before, before + envs])]).flatten(1)
            predicted = inverse(points[:batch], points[batch:])
            loss = loss + inverse_weight * (predicted - torch.as_tensor(actions[before])).square().mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        losses.append(loss.item())
    return losses


def pretrain_keypoints(cfg: TrainConfig, space, folder: str | Path, progress: bool = True,
                       shared: str | Path | None = None) -> tuple[KeypointExtractor, int]:
    """The frozen extractor a ``--learner sac`` run reads on its policy view ``space``, and the env
    steps its frames took: loaded from ``folder`` when a run made it there, else pretrained there on
    ``cfg.pretrain_episodes`` episodes of random actions for ``cfg.pretrain_steps`` Adam steps
    (rebuild + inverse dynamics, half the sources from any episode; seeded by ``cfg.seed``).

    ``shared``: a folder where runs that differ only in their reward share their pretraining (a
    sweep's): no reward is read, so the oracle and zsrm runs of one goal and seed pretrain the same
    weights; the first to finish keeps them there (``shared/<key>``) and later ones copy them."""
    folder = Path(folder)
    if (folder / "config.json").is_file():
        return load_keypoints(folder, space, run=cfg.identity())
    kept = Path(shared) / pretraining_key(cfg) if shared is not None else None
    if kept is not None and (kept / "config.json").is_file():
        extractor, env_steps = load_keypoints(kept, space, run=pretraining_identity(cfg))
        save_folder(folder, {**read_config(kept, kind=KIND), "run": cfg.identity()}, {WEIGHTS_FILE: extractor})
        return extractor, env_steps
    start = time.time()
    torch.manual_seed(cfg.seed)
    frame_cfg = dataclasses.replace(cfg, reward="oracle")  # the frames' scenes; no reward is read
    images, episode, actions = random_frames(frame_cfg, cfg.pretrain_episodes, FRAME_ENVS, cfg.seed, progress)
    frames = torch.as_tensor(shrink_frames(images, cfg.pixel_size))
    model = KeypointAutoencoder(cfg.pixel_size, PIXEL_KEYPOINTS, cfg.pixel_stride)
    losses = train_autoencoder(model, frames, episode, actions, FRAME_ENVS, cfg.pretrain_steps, 32, 1.0, cfg.seed,
                               any_source=0.5, progress=progress)
    extractor = keypoint_extractor(space, cfg.keypoints, cfg.pixel_stride)
    extractor.pixels.load_state_dict(model.keypoints.state_dict())
    env_steps = len(frames) * cfg.action_repeat
    config = {"kind": KIND, "run": cfg.identity(), "keypoints": cfg.keypoints, "pixel_size": cfg.pixel_size,
              "pixel_stride": cfg.pixel_stride, "env_steps": env_steps, "frames": len(frames),
              "loss_first_100": float(np.mean(losses[:100])), "loss_last_100": float(np.mean(losses[-100:])),
              "wall_s": round(time.time() - start, 1)}
    save_folder(folder, config, {WEIGHTS_FILE: extractor})
    if kept is not None:  # written config last: a run beside this one reads whole weights or none
        save_folder(kept, {**config, "run": pretraining_identity(cfg)}, {WEIGHTS_FILE: extractor})
    return freeze(extractor), env_steps


def pretraining_identity(cfg: TrainConfig) -> dict:
    """The settings a run's pretraining depends on: all of the run's but its reward's."""
    return {**cfg.identity(), "reward": None, "reward_model": None, "zsrm_output": None}


def pretraining_key(cfg: TrainConfig) -> str:
    """A folder name for the pretraining of ``cfg`` (:func:`pretraining_identity`, hashed)."""
    text = json.dumps(pretraining_identity(cfg), sort_keys=True)
    return f"{cfg.goal.replace(' ', '_')[:40]}-{cfg.seed}-{hashlib.sha256(text.encode()).hexdigest()[:12]}"


def keypoint_extractor(space, keypoints: int, pixel_stride: int) -> KeypointExtractor:
    """An untrained extractor of the pretrained ones' shape (``PIXEL_KEYPOINTS`` in its pixel branch)."""
    return KeypointExtractor(space, keypoints=keypoints, pixels=True, pixel_stride=pixel_stride)


def freeze(extractor: KeypointExtractor) -> KeypointExtractor:
    for param in extractor.parameters():
        param.requires_grad_(False)
    return extractor.eval()


@torch.no_grad()
def points_of(extractor: KeypointExtractor, observation: dict) -> torch.Tensor:
    """The keypoints (:meth:`KeypointExtractor.points`) of a batch of policy views given as arrays."""
    return extractor.points({k: torch.as_tensor(np.asarray(v)) for k, v in observation.items()})


def load_keypoints(folder: str | Path, space, run: dict | None = None) -> tuple[KeypointExtractor, int]:
    """A pretrained folder's frozen extractor for a policy view of ``space``, and its env steps;
    with ``run`` (a config's identity), refused when pretrained for a run of other settings."""
    config = read_config(folder, kind=KIND, schema={
        "kind": str, "run": dict, "keypoints": int, "pixel_size": int, "pixel_stride": int, "env_steps": int,
        "frames": int, "loss_first_100": float, "loss_last_100": float, "wall_s": float})
    if run is not None and config.run != run:
        raise ValueError(f"the keypoints in {folder} were pretrained for a run with other settings; pass --fresh "
                         "to start over or use another --out")
    extractor = build_model(folder, lambda: keypoint_extractor(space, config.keypoints, config.pixel_stride))
    load_weights(extractor, folder)
    return freeze(extractor), config.env_steps
