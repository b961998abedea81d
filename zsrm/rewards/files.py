"""Rewards of image files (``zsrm reward``), and a base reward built from command-line options.

Heavy imports (torch, the VLM) happen inside the functions.
"""
from __future__ import annotations

from pathlib import Path


def read_image(path: str | Path):
    """An image file as ``(H, W, 3) uint8`` RGB; FileNotFoundError / ValueError in one line."""
    import numpy as np
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such image file: {path}")
    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("RGB"), dtype=np.uint8)
    except (UnidentifiedImageError, OSError) as err:
        raise ValueError(f"cannot read {path} as an image ({type(err).__name__})") from None


def make_base_reward(vlm_spec: str, camera: str, mode: str, baseline: str | None, alpha: float):
    """A BaseReward, with its options checked before the (slow) VLM loads."""
    from zsrm.rewards.base import MODES, BaseReward
    from zsrm.rewards.interface import check_goal

    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    if mode == "projection":
        if baseline is None:
            raise ValueError("--mode projection needs --baseline TEXT (the scene without the goal)")
        check_goal(baseline)
    elif baseline is not None:
        raise ValueError("--baseline is used only with --mode projection")
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"--alpha must be in [0, 1], got {alpha}")
    from zsrm.vlm import load_vlm

    return BaseReward(load_vlm(vlm_spec), camera=camera, mode=mode, baseline=baseline, alpha=alpha)


def score_files(paths, goal: str, reward) -> list[float]:
    """The reward of each image file, batching images of the same size together."""
    import numpy as np

    from zsrm.rewards.interface import check_goal

    goal = check_goal(goal)
    if not paths:
        raise ValueError("give at least one image file")
    images = [read_image(p) for p in paths]  # all files checked before the model runs
    scores = [0.0] * len(images)
    by_shape: dict[tuple, list[int]] = {}
    for i, im in enumerate(images):
        by_shape.setdefault(im.shape, []).append(i)
    for idx in by_shape.values():
        r = reward.score(np.stack([images[i] for i in idx]), goal)
        for i, v in zip(idx, r):
            scores[i] = float(v)
    return scores
