"""What the policy's vision can read (diagnostic for issue 11; prints, writes nothing).

Random tabletop episodes (front camera, 64 px); a probe (the policy's keypoint extractor and a
linear layer) is trained by regression on TRUE state, here only, to ask whether the features
hold it: gripper x/z, the two blocks' x/z and the grip's open/closed state. Once with the
frozen scene-VLM map alone, once with the small pixel CNN beside it. Mean absolute error on
held-out frames (metres; 0-1 for the grip).

    python probes/policy_vision_probe.py --episodes 40
"""
import argparse

import gymnasium as gym
import numpy as np
import torch
from torch import nn

import zsrm.envs  # noqa: F401
from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY, KeypointExtractor
from zsrm.vlm import load_vlm

NAMES = ("gripper x", "gripper z", "yellow x", "yellow z", "red x", "red z", "grip closed")


def frames(episodes: int):
    env = gym.make("zsrm/Tabletop-v0", task="stack", image_size=64)
    base = env.unwrapped
    images, targets = [], []
    for ep in range(episodes):
        env.reset(seed=ep)
        rng = np.random.default_rng(ep)
        for _ in range(50):
            obs, _, terminated, _, info = env.step(rng.uniform(-1, 1, 3))
            p = info["object_positions"]
            images.append(obs["front"])
            targets.append([*base.gripper_position[[0, 2]], *p["yellow"][[0, 2]], *p["red"][[0, 2]], float(base.closed)])
            if terminated:
                break
    return np.stack(images), torch.tensor(np.array(targets), dtype=torch.float32)


def probe(maps, images, targets, pixels: bool, steps: int = 1500) -> np.ndarray:
    torch.manual_seed(0)
    space = gym.spaces.Dict({FEATURES_KEY: gym.spaces.Box(0, np.inf, tuple(maps.shape[1:]), np.float32),
                             IMAGE_KEY: gym.spaces.Box(0, 255, tuple(images.shape[1:]), np.uint8)})
    extractor, head = KeypointExtractor(space, pixels=pixels), nn.Linear(256, targets.shape[1])
    opt = torch.optim.Adam([*extractor.parameters(), *head.parameters()], lr=1e-3)
    mu, sd = targets.mean(0), targets.std(0) + 1e-6
    train = int(0.8 * len(targets))
    for _ in range(steps):
        idx = torch.randint(0, train, (128,))
        loss = (head(extractor({FEATURES_KEY: maps[idx], IMAGE_KEY: images[idx]})) - (targets[idx] - mu) / sd).pow(2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        pred = head(extractor({FEATURES_KEY: maps[train:], IMAGE_KEY: images[train:]})) * sd + mu
    return (pred - targets[train:]).abs().mean(0).numpy()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    raw, targets = frames(args.episodes)
    vlm = load_vlm("scene")
    with torch.no_grad():
        maps = torch.cat([vlm.image_trunk(vlm.preprocess(raw[i:i + 256])) for i in range(0, len(raw), 256)])
    images = torch.tensor(raw).permute(0, 3, 1, 2).contiguous()
    print(f"{len(raw)} frames; held-out mean absolute error of: " + ", ".join(NAMES))
    for pixels in (False, True):
        err = probe(maps, images, targets, pixels)
        print(("VLM map + pixel CNN: " if pixels else "VLM map alone:       ") + " ".join(f"{e:.3f}" for e in err))


if __name__ == "__main__":
    main()
