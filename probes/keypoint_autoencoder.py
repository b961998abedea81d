"""Can the policy's pixel keypoints learn where the pusher is without a reward or a state?

The keypoint precision probe (``probes/keypoint_precision.py``) finds the pucks read to about 1 cm
by every extractor (the VLM trunk locates coloured objects), but the pusher, which only the pixel
CNN sees, to 2-5 cm by PPO-trained extractors, against 0.5-0.9 cm for the same architecture trained
on true places. This probe trains the pixel CNN (zsrm's ``PixelKeypoints``) as the encoder of a
keypoint autoencoder, on frames of random actions alone (after Jakab et al. 2018): a frame is
rebuilt from another frame of its episode (appearance) and its own keypoints, drawn as Gaussian
blobs (geometry), so the keypoints must follow what moves; ``--inverse-weight`` adds zsrm's
inverse-dynamics loss (the random action from two consecutive frames' keypoints). It saves a frozen extractor (zsrm's
``KeypointExtractor``: the VLM branch untrained, the pixel branch the encoder) for
``keypoint_precision.py`` and ``push_pixel_sac.py --keypoints-from``.

    python probes/keypoint_autoencoder.py --out runs/keypoint-ae/push_close
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch import nn  # noqa: E402
from tqdm import tqdm  # noqa: E402

from zsrm.common.files import write_json  # noqa: E402
from zsrm.rl.auxiliary import InverseDynamics  # noqa: E402
from zsrm.rl.config import TrainConfig  # noqa: E402
from zsrm.rl.envs import make_vec  # noqa: E402
from zsrm.rl.features import KeypointExtractor, PixelKeypoints, policy_view, shrink_frames  # noqa: E402
from zsrm.rl.goals import goal_camera  # noqa: E402
from zsrm.vlm import load_vlm  # noqa: E402

EXTRACTOR = "extractor.pt"


def random_frames(goal: str, episodes: int, envs: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Goal-camera frames (N, 64, 64, 3) of uniform random actions, each frame's episode and the
    action taken after it (NaN after an episode's last frame)."""
    cfg = TrainConfig(goal=goal, reward="oracle")
    venv, camera = make_vec(cfg, envs, seed), goal_camera(goal)
    rng = np.random.default_rng(seed)
    frames, episode, actions = [], [], []
    for e in tqdm(range(0, episodes, envs), desc="frames", unit="episode", unit_scale=envs):
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
        self.appearance = nn.Sequential(conv(3, 32), nn.MaxPool2d(2), conv(32, 32), nn.MaxPool2d(2), conv(32, 32))
        # it rebuilds the frame at half its side (a quarter of the cost; the blobs' places stay continuous)
        self.decoder = nn.Sequential(conv(32 + 2 * keypoints, 64), nn.Upsample(scale_factor=2), conv(64, 32),
                                     nn.Conv2d(32, 3, 3, 1, 1))

    def points(self, frames: torch.Tensor) -> torch.Tensor:
        """(N, 3, s, s) uint8 -> (N, K, 2) keypoints' (x, y)."""
        k = self.keypoints.cnn[-1].out_channels
        return self.keypoints(frames)[:, :2 * k].reshape(len(frames), k, 2)

    def forward(self, source: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        xy_s, xy_t = self.points(source), self.points(target)
        # Jakab et al.: the source's keypoints too, so the decoder can move what is where it was
        maps = torch.cat([gaussian_maps(xy_t, self.side, self.sigma), gaussian_maps(xy_s, self.side, self.sigma)], 1)
        return self.decoder(torch.cat([self.appearance(source.float() / 255.0), maps], dim=1))


def train(model: KeypointAutoencoder, frames: torch.Tensor, episode: np.ndarray, actions: np.ndarray, envs: int,
          steps: int, batch: int, inverse_weight: float, seed: int, any_source: float = 0.0) -> list[float]:
    """Adam on the squared error of each rebuilt target frame (the source: another frame of its
    episode, or with probability ``any_source`` any frame, whose pucks lie elsewhere), plus
    ``inverse_weight`` times an inverse-dynamics loss: the random action taken between a frame and
    its env's next (``envs`` frames on) predicted from the two frames' keypoints."""
    rng = np.random.default_rng(seed)
    by_episode = {e: np.flatnonzero(episode == e) for e in np.unique(episode)}
    with_next = np.flatnonzero(~np.isnan(actions).any(axis=1))
    k = model.keypoints.cnn[-1].out_channels
    inverse = InverseDynamics(2 * k, actions.shape[1]) if inverse_weight else nn.Identity()
    optimiser = torch.optim.Adam([*model.parameters(), *inverse.parameters()], lr=1e-3)
    losses = []
    for _ in tqdm(range(steps), desc="autoencoder", unit="step"):
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


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--goal", default="push_close")
    p.add_argument("--episodes", type=int, default=320)
    p.add_argument("--pixel-size", type=int, default=64, help="side of the frame the keypoints read")
    p.add_argument("--pixel-stride", type=int, default=4)
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--batch-size", type=int, default=32)
    p.add_argument("--sigma", type=float, default=0.1, help="the blobs' std in the frame's [-1, 1] units")
    p.add_argument("--inverse-weight", type=float, default=0.0,
                   help="add this times an inverse-dynamics loss (the random action from two frames' keypoints)")
    p.add_argument("--any-source", type=float, default=0.0,
                   help="the fraction of rebuilds whose source is any frame, not one of the target's episode (the "
                        "keypoints must then say where the pucks are too)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    out, start = Path(args.out), time.time()
    out.mkdir(parents=True, exist_ok=True)
    envs = 8
    images, episode, actions = random_frames(args.goal, args.episodes, envs, args.seed)
    frames = torch.as_tensor(shrink_frames(images, args.pixel_size))
    model = KeypointAutoencoder(args.pixel_size, 16, args.pixel_stride, args.sigma)
    losses = train(model, frames, episode, actions, envs, args.steps, args.batch_size, args.inverse_weight, args.seed,
                   args.any_source)
    # the extractor a SAC run reads: an untrained VLM branch (seeded) beside the trained pixel branch
    cfg = TrainConfig(goal=args.goal, pixel_size=args.pixel_size, pixel_stride=args.pixel_stride)
    venv = make_vec(cfg, 1, args.seed)
    space = policy_view(venv, load_vlm(cfg.vlm), cfg).observation_space
    venv.close()
    extractor = KeypointExtractor(space, keypoints=cfg.keypoints, pixels=True, pixel_stride=args.pixel_stride)
    extractor.pixels.load_state_dict(model.keypoints.state_dict())
    torch.save({"state_dict": extractor.state_dict(), "settings": {"pixel_size": args.pixel_size,
                "pixel_stride": args.pixel_stride, "keypoints": cfg.keypoints}}, out / EXTRACTOR)
    write_json(out / "training.json", {
        "loss_first_100": float(np.mean(losses[:100])), "loss_last_100": float(np.mean(losses[-100:])),
        "frames": len(frames), "wall_s": round(time.time() - start, 1),
        "meta": {"machine": "x86_64, 2 cores, no GPU",
                 "command": "python probes/keypoint_autoencoder.py " + " ".join(argv or [])}})
    print(f"loss {np.mean(losses[:100]):.4f} -> {np.mean(losses[-100:]):.4f}; wrote {out / EXTRACTOR}")


def load_extractor(folder: str | Path, space, settings_only: bool = False):
    """The frozen extractor this probe saved in ``folder`` for a policy view of ``space``, and its
    settings (zsrm train's: keypoints, pixel size and stride); ``settings_only``: the settings alone."""
    saved = torch.load(Path(folder) / EXTRACTOR, weights_only=True)
    settings = saved["settings"]
    if settings_only:
        return settings
    extractor = KeypointExtractor(space, keypoints=settings["keypoints"], pixels=True,
                                  pixel_stride=settings["pixel_stride"])
    extractor.load_state_dict(saved["state_dict"])
    return extractor.eval(), settings


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
