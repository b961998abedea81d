"""Can the policy's pixel keypoints learn where the pusher is without a reward or a state?

The keypoint precision probe (``probes/keypoint_precision.py``) finds the pucks read to about 1 cm
by every extractor (the VLM trunk locates coloured objects), but the pusher, which only the pixel
CNN sees, to 2-5 cm by PPO-trained extractors, against 0.5-0.9 cm for the same architecture trained
on true places. This probe trains the pixel CNN (zsrm's ``PixelKeypoints``) as the encoder of a
keypoint autoencoder (``zsrm.rl.pretrain``, which ``zsrm train --learner sac`` runs), on frames
of random actions alone (after Jakab et al. 2018): a frame is rebuilt from another frame of its
episode (appearance) and its own keypoints, drawn as Gaussian blobs (geometry), so the keypoints
must follow what moves; ``--inverse-weight`` adds zsrm's inverse-dynamics loss (the random action
from two consecutive frames' keypoints). It saves a frozen extractor (zsrm's ``KeypointExtractor``:
the VLM branch untrained, the pixel branch the encoder) for
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

from zsrm.common.files import write_json  # noqa: E402
from zsrm.rl.config import TrainConfig  # noqa: E402
from zsrm.rl.envs import make_vec  # noqa: E402
from zsrm.rl.features import policy_view, shrink_frames  # noqa: E402
from zsrm.rl.pretrain import (KeypointAutoencoder, gaussian_maps, keypoint_extractor, random_frames,  # noqa: E402,F401
                               train_autoencoder)
from zsrm.vlm import load_vlm  # noqa: E402

EXTRACTOR = "extractor.pt"


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
    frame_cfg = TrainConfig(goal=args.goal, reward="oracle")
    images, episode, actions = random_frames(frame_cfg, args.episodes, envs, args.seed)
    frames = torch.as_tensor(shrink_frames(images, args.pixel_size))
    model = KeypointAutoencoder(args.pixel_size, 16, args.pixel_stride, args.sigma)
    losses = train_autoencoder(model, frames, episode, actions, envs, args.steps, args.batch_size, args.inverse_weight,
                               args.seed, args.any_source)
    # the extractor a SAC run reads: an untrained VLM branch (seeded) beside the trained pixel branch
    cfg = TrainConfig(goal=args.goal, pixel_size=args.pixel_size, pixel_stride=args.pixel_stride)
    venv = make_vec(cfg, 1, args.seed)
    space = policy_view(venv, load_vlm(cfg.vlm), cfg).observation_space
    venv.close()
    extractor = keypoint_extractor(space, cfg.keypoints, args.pixel_stride)
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
    extractor = keypoint_extractor(space, settings["keypoints"], settings["pixel_stride"])
    extractor.load_state_dict(saved["state_dict"])
    return extractor.eval(), settings


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
