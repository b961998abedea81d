"""Subcommands for rewards: ``zsrm reward`` (score image files) and ``zsrm reward-curve``
(the base reward along a scripted trajectory, the paper's Figure 5).

Heavy imports (torch, the VLM) happen inside the commands, so ``zsrm --help`` stays fast.
"""
from __future__ import annotations

import json
from pathlib import Path

FIGURE5_GOAL = "a yellow puck close to a blue puck"


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
    from zsrm.rewards.reward_model import check_goal

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

    from zsrm.rewards.reward_model import check_goal

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


def _cmd_reward(args):
    from zsrm.rewards.reward_model import check_goal

    goal = check_goal(args.goal)
    for p in args.images:  # fail on a bad path before loading the model
        read_image(p)
    reward = make_base_reward(args.vlm, "image", args.mode, args.baseline, args.alpha)
    scores = score_files(args.images, goal, reward)
    if args.json:
        print(json.dumps({"goal": goal, "vlm": args.vlm, "mode": args.mode,
                          "scores": dict(zip(map(str, args.images), scores))}, indent=2))
    else:
        for path, s in zip(args.images, scores):
            print(f"{s:.6f}\t{path}")


def _cmd_reward_curve(args):
    from zsrm.rewards.curve import plot_curve, record_trajectory, reward_curve, summarise, write_csv
    from zsrm.rewards.reward_model import check_goal

    goal = check_goal(args.goal)
    reward = make_base_reward(args.vlm, args.camera, args.mode, args.baseline, args.alpha)
    traj = record_trajectory(goal, cameras=(args.camera,), steps=args.steps, seed=args.seed,
                             image_size=args.image_size)
    rows = reward_curve(traj, {"base": reward})
    out = Path(args.out)
    csv_path = write_csv(rows, out.with_suffix(".csv"))
    title = (f"base reward ({args.mode}, vlm {args.vlm}) for {goal!r}, {args.camera} camera, "
             f"seed {args.seed}\ngreen: oracle says the goal holds")
    png_path = plot_curve(rows, traj, out.with_suffix(".png"), camera=args.camera, title=title)
    print(json.dumps(summarise(rows), indent=2))
    print(f"wrote {csv_path} and {png_path}")


def add_command(sub):
    p = sub.add_parser("reward", help="score image files (PNG/JPG) for a goal sentence with the base reward")
    p.add_argument("images", nargs="+", metavar="IMAGE", help="image files")
    p.add_argument("--goal", required=True, help="the goal sentence, e.g. 'a yellow block on top of a red block'")
    _add_reward_options(p)
    p.add_argument("--json", action="store_true", help="print JSON instead of 'score<TAB>path' lines")
    p.set_defaults(func=_cmd_reward)

    p = sub.add_parser("reward-curve",
                       help="base reward along a scripted trajectory: CSV + PNG (the paper's Figure 5)")
    p.add_argument("--goal", default=FIGURE5_GOAL,
                   help=f"a goal with a scripted controller (default {FIGURE5_GOAL!r}: the first object is pushed "
                        "toward the second)")
    p.add_argument("--camera", default="tilted", choices=("front", "left", "tilted"))
    p.add_argument("--steps", type=int, default=30, help="control steps after the reset frame (default 30)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--image-size", type=int, default=64)
    p.add_argument("--out", default="results/figure5", help="output prefix: writes PREFIX.csv and PREFIX.png")
    _add_reward_options(p)
    p.set_defaults(func=_cmd_reward_curve)


def _add_reward_options(p):
    p.add_argument("--vlm", default="scene", help="VLM spec: scene (default), open_clip:RN50, a model folder, ...")
    p.add_argument("--mode", default="dot", choices=("dot", "cosine", "projection"),
                   help="dot: E_I(image) . E_L(goal) (paper 2.1); cosine: normalised; projection: VLM-RMs "
                        "goal-baseline regularisation")
    p.add_argument("--baseline", help="baseline sentence for --mode projection, e.g. 'two pucks on a table'")
    p.add_argument("--alpha", type=float, default=0.5, help="projection strength in [0, 1] (default 0.5)")
