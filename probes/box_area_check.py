"""Does the goal labeler's box check (``--zsrm-correct-box-area``) stop "inside of" where the
box's Grad-CAM point lands on a block resting away from the box, and keep the true goal frames?

Plays place_inside's scene with scripted motions that carry the yellow block away from the box and
let it go on the table, then move the gripper toward the box (``box``), hover above the block
(``hover``) or wander (``wander``), and the scripted controller's episodes (the goal reached); labels
every frame of the tilted camera with the goal labeler without and with the check. The oracle's
verdict is only compared with, never read by the labeler.

    python probes/box_area_check.py --out results/side/grounding/box_area_check.json
"""
from __future__ import annotations

import argparse

import numpy as np

from inside_frames import GOAL, episode_frames, verdicts, write_rows
from zsrm.envs.rollout import make_env
from zsrm.envs.scripted import scripted_controller
from zsrm.rl.config import TrainConfig
from zsrm.rl.corrected import goal_labeler

KINDS = ("box", "hover", "wander")


def away_from_box(kind: str):
    """A policy maker: carry the block away from the box for 3 steps, let it go, then ``kind``."""
    def make(env):
        base, steps, rng = env.unwrapped, [0], np.random.default_rng(KINDS.index(kind))

        def act() -> np.ndarray:
            steps[0] += 1
            box, block = base.object_positions()["box"], base.object_positions()["yellow"]
            if steps[0] < 4:
                return np.array([np.sign(block[0] - box[0]) or 1.0, 0.0, -0.3, 1.0])
            target = {"box": box + (0, 0, 0.12), "hover": block + (0, 0, 0.2)}.get(kind)
            move = rng.uniform(-2, 2, 3) if target is None else (target - base.gripper_position) / 0.025
            return np.array([*np.clip(move, -1, 1), -1.0])
        return act
    return make


def check(area: float, seeds, kinds, scripted_episodes: int, every: int, folder: str) -> dict:
    cfg = TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=10000, zsrm_correct_box_area=area)
    env = make_env(GOAL, cameras=("tilted",), image_size=cfg.image_size)
    runs = {kind: episode_frames(env, away_from_box(kind), seeds, every=every) for kind in kinds}
    runs["scripted"] = episode_frames(env, scripted_controller, range(scripted_episodes), every=every)
    env.close()
    labeler = goal_labeler(cfg, folder)
    out = {}
    for name, (frames, oracle) in runs.items():
        frames = frames["tilted"]
        labeler.grounder.box_min_area = area
        checked = labeler(frames)
        labeler.grounder.box_min_area = 0.0  # the labeler as zsrm label's
        unchecked = labeler(frames)
        row = {"frames": len(frames), "oracle_goal": int(oracle.sum())}
        for key, said in (("unchecked", unchecked), ("checked", checked)):
            row[key] = verdicts(said, oracle)
        out[name] = row
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--area", type=float, default=0.0115, help="the check's least box area (square metres)")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(900, 906)), help="episodes per motion")
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    parser.add_argument("--scripted-episodes", type=int, default=6)
    parser.add_argument("--every", type=int, default=1, help="keep every n-th frame")
    parser.add_argument("--calibration", default="runs/box_area_check", help="the labeler's calibration renders")
    parser.add_argument("--out", default="results/side/grounding/box_area_check.json")
    args = parser.parse_args()
    out = check(args.area, args.seeds, args.kinds, args.scripted_episodes, args.every, args.calibration)
    out["meta"] = {"area_m2": args.area, "goal": GOAL, "camera": "tilted",
                   "command": f"python probes/box_area_check.py --area {args.area} --seeds "
                              f"{' '.join(map(str, args.seeds))} --kinds {' '.join(args.kinds)} --scripted-episodes "
                              f"{args.scripted_episodes} --every {args.every} --out {args.out}"}
    write_rows(args.out, out)


if __name__ == "__main__":
    main()
