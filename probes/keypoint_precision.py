"""How exactly do a policy's keypoints say where the pusher and the pucks are? (push_close; TRUE
state read here only, to score the keypoints, never by a policy.)

SAC on true state finishes push_close (success 0.80-0.88); with 0.5 cm of noise on each position it
falls to 0.60 (``probes/push_state_ppo.py --noise``). This probe asks how far from that the
keypoints a SAC policy reads are. push_close frames (half from zsrm's scripted controller, which
walks the pusher round and behind its puck and pushes, half random actions; 25 decisions an
episode at action repeat 4) go through each extractor named, frozen; a small MLP (two layers of 256)
is fitted on the training episodes' keypoints to the pusher's and both pucks' table (x, y), and
scored on held-out episodes: the mean absolute error in cm of each position and of the puck's
place from the pusher (what steering reads). ``random`` is an untrained extractor; ``--supervised
SETTINGS`` trains a fresh extractor of those settings (zsrm train's, e.g. ``pixel_size=64,pixel_stride=2``;
``default``: v3's) together with the MLP: the most its architecture can hold.

    python probes/keypoint_precision.py --extractors random results/rl/pilots/v3-push_close-oracle-pixels64-200k-0/policy \\
        --supervised default pixel_size=64,pixel_stride=2 --out results/side/rl/keypoint_precision.json
"""
from __future__ import annotations

import argparse
import os
import runpy
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch import nn  # noqa: E402
from tqdm import tqdm  # noqa: E402

from zsrm.common.files import write_json  # noqa: E402
from zsrm.envs.scripted import scripted_controller  # noqa: E402
from zsrm.pipeline.learn import parse_settings  # noqa: E402
from zsrm.rl.config import TrainConfig  # noqa: E402
from zsrm.rl.envs import make_vec  # noqa: E402
from zsrm.rl.features import KeypointExtractor, policy_view  # noqa: E402
from zsrm.rl.goals import goal_camera  # noqa: E402
from zsrm.rl.policy import PolicyBundle  # noqa: E402
from zsrm.vlm import load_vlm  # noqa: E402

TARGETS = ("pusher x", "pusher y", "puck x", "puck y", "other x", "other y")


def collect(venv, cfg: TrainConfig, episodes: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames of the goal camera (N, 64, 64, 3), true (pusher, puck, other) table (x, y) (N, 6) in
    metres and each frame's episode."""
    scene, camera = venv.envs[0].unwrapped, goal_camera(cfg.goal)
    rng = np.random.default_rng(seed)
    frames, targets, episode = [], [], []
    for e in tqdm(range(episodes), desc="frames", unit="episode"):
        obs = venv.reset()
        script = scripted_controller(venv.envs[0]) if e % 2 == 0 else None
        for _ in range(cfg.episode_decisions):
            positions = scene.object_positions()
            frames.append(obs[camera][0])
            targets.append([*scene.pusher_position[:2], *(positions[c][:2] for c in scene.task.objects)])
            episode.append(e)
            action = script() if script is not None else rng.uniform(-1, 1, 2).astype(np.float32)
            obs, _, dones, _ = venv.step(action[None])
            if dones[0]:
                break
    flat = [np.concatenate([np.ravel(t) for t in row]) for row in targets]
    return np.stack(frames), np.array(flat, np.float32), np.array(episode)


def observations(venv, vlm, cfg: TrainConfig, images: np.ndarray, size: int = 256) -> tuple[dict, object]:
    """What a policy of ``cfg``'s settings sees of each frame (converted ``size`` at a time) and its space."""
    view = policy_view(venv, vlm, cfg)
    parts = [view.convert(images[i:i + size]) for i in range(0, len(images), size)]
    return {k: torch.as_tensor(np.concatenate([part[k] for part in parts])) for k in parts[0]}, view.observation_space


def extractor_for(name: str, venv, vlm, images: np.ndarray, seed: int) -> tuple[KeypointExtractor, dict, TrainConfig]:
    """The extractor ``name`` says (``random``: untrained; ``supervised:SETTINGS``: untrained, of those
    settings; a folder of ``keypoint_autoencoder.py``'s; else a trained policy's folder), the frames as
    it sees them, and its settings."""
    if name == "random" or name.startswith("supervised:"):
        settings = name.removeprefix("supervised:")
        items = [] if settings in ("random", "default") else settings.split(",")
        cfg = TrainConfig(goal="push_close", **parse_settings(items))
        obs, space = observations(venv, vlm, cfg, images)
        torch.manual_seed(seed)
        return KeypointExtractor(space, keypoints=cfg.keypoints, pixels=cfg.pixels,
                                 pixel_stride=cfg.pixel_stride), obs, cfg
    if (Path(name) / "extractor.pt").is_file():  # probes/keypoint_autoencoder.py's
        load = runpy.run_path(str(Path(__file__).with_name("keypoint_autoencoder.py")))["load_extractor"]
        settings = load(name, None, settings_only=True)
        cfg = TrainConfig(goal="push_close", **settings)
        obs, space = observations(venv, vlm, cfg, images)
        return load(name, space)[0], obs, cfg
    bundle = PolicyBundle.load(name)
    return bundle.policy.features_extractor.eval(), observations(venv, vlm, bundle.cfg, images)[0], bundle.cfg


def fit(points_of, targets: torch.Tensor, train: np.ndarray, params: list, steps: int, seed: int) -> torch.Tensor:
    """Fit ``points_of(index) -> head`` on the training frames; the held-out frames' predictions (m)."""
    torch.manual_seed(seed)
    mu, sd = targets[train].mean(0), targets[train].std(0) + 1e-6
    idx_train = np.flatnonzero(train)
    head = None
    for step in range(steps):
        batch = torch.as_tensor(np.random.default_rng(seed + step).choice(idx_train, 256))
        points = points_of(batch)
        if head is None:
            head = nn.Sequential(nn.Linear(points.shape[1], 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(),
                                 nn.Linear(256, targets.shape[1]))
            optimiser = torch.optim.Adam([*head.parameters(), *params], lr=1e-3)
        loss = (head(points) - (targets[batch] - mu) / sd).abs().mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        held = torch.as_tensor(np.flatnonzero(~train))
        return head(points_of(held)) * sd + mu


def errors_cm(pred: torch.Tensor, true: torch.Tensor) -> dict:
    err = (pred - true).abs().mean(0).numpy() * 100
    rel_pred, rel_true = pred[:, 2:4] - pred[:, 0:2], true[:, 2:4] - true[:, 0:2]
    return {**{name: round(float(e), 2) for name, e in zip(TARGETS, err)},
            "puck from pusher": round(float((rel_pred - rel_true).norm(dim=1).mean()) * 100, 2),
            "mean": round(float(err.mean()), 2)}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--extractors", nargs="+", default=["random"], help="random, or trained policy folders")
    p.add_argument("--supervised", nargs="*", default=[], metavar="SETTINGS",
                   help="a fresh extractor of these zsrm train settings (KEY=VALUE,KEY=VALUE or default) trained "
                        "with the MLP: the most the architecture holds")
    p.add_argument("--episodes", type=int, default=80, help="half scripted, half random actions")
    p.add_argument("--steps", type=int, default=3000, help="Adam steps of each fit")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    start = time.time()
    venv = make_vec(TrainConfig(goal="push_close"), 1, args.seed)
    images, targets, episode = collect(venv, TrainConfig(goal="push_close"), args.episodes, args.seed)
    targets = torch.as_tensor(targets)
    train = episode < int(0.75 * args.episodes)
    vlm = load_vlm("scene")

    results = {}
    for name in args.extractors + [f"supervised:{s}" for s in args.supervised]:
        extractor, obs, cfg = extractor_for(name, venv, vlm, images, args.seed)
        if name.startswith("supervised:"):  # the extractor learns with the MLP
            pred = fit(lambda i: extractor.points({k: v[i] for k, v in obs.items()}), targets, train,
                       list(extractor.parameters()), args.steps, args.seed)
        else:
            with torch.no_grad():
                points = extractor.points(obs)
            pred = fit(lambda i: points[i], targets, train, [], args.steps, args.seed)
        results[name] = {"error_cm": errors_cm(pred, targets[~train]), "trunk_size": cfg.trunk_size,
                         "pixel_size": cfg.pixel_size, "pixel_stride": cfg.pixel_stride}
        print(name, results[name])
    venv.close()
    write_json(args.out, {"extractors": results, "frames": {"train": int(train.sum()), "held_out": int((~train).sum())},
                          "meta": {"wall_s": round(time.time() - start, 1), "machine": "x86_64, 2 cores, no GPU",
                                   "command": "python probes/keypoint_precision.py " + " ".join(argv or [])}})


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
