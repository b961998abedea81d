"""Do the goal labeler's front check (``--zsrm-correct-front``) and height check
(``--zsrm-correct-height``) stop "inside of" where a block is held in the air in front of the box,
which the tilted camera reads as in it, and keep the true goal frames?

Plays place_inside's scene with the scripted controller (the block dropped in the box: the goal)
and with the same controller made to hold the block where it would let it go, moved ``dy`` metres
toward the front camera (``hover-0.03``: 3 cm in front of the box, 8 cm above the table), never
releasing it; labels every frame with the goal labeler (the box check on, as the runs use it)
without and with each check, and records where the front camera's block point sits above the
box's and how high the block's triangulated centre is (both in block widths) on the frames the
oracle calls the goal and on those the tilted camera alone calls it wrongly. The oracle reads
inside of on the table plane: a block held over the box's centre counts; the height check does not. The oracle's verdict is only
compared with, never read by the labeler.

    python probes/inside_front_check.py --out results/side/grounding/inside_front_check.json
"""
from __future__ import annotations

import argparse

import numpy as np

from inside_frames import GOAL, episode_frames, verdicts, write_rows
from zsrm.envs.rollout import make_env
from zsrm.envs.scripted import PickPlaceController, scripted_controller
from zsrm.grounding.goal_check import front_rise_ok, lift_ok
from zsrm.rl.config import TrainConfig
from zsrm.rl.corrected import goal_labeler


def held_in_front(dy: float):
    """A policy maker: the scripted controller, its drop point moved ``dy`` m along y, never letting go."""
    def make(env):
        script = PickPlaceController(env.unwrapped)
        goal = script._goal
        script._goal = lambda: goal() + (0.0, dy, 0.0)

        def act() -> np.ndarray:
            if script.phase in ("release", "retreat"):
                script.phase = "lower"  # hold it there
            return script()
        return act
    return make


def check(offsets, seeds, scripted_episodes: int, every: int, folder: str) -> dict:
    cfg = TrainConfig(goal="place_inside", reward="zsrm", zsrm_correct_every=10000, zsrm_correct_box_area=0.0115,
                      zsrm_correct_front=True, zsrm_correct_height=True)
    env = make_env(GOAL, cameras=("tilted", "front"), image_size=cfg.image_size)
    cameras = ("tilted", "front")
    runs = {f"hover{dy:+.2f}": episode_frames(env, held_in_front(dy), seeds, cameras, every=every) for dy in offsets}
    runs["scripted"] = episode_frames(env, scripted_controller, range(scripted_episodes), cameras, every=every)
    env.close()
    labeler = goal_labeler(cfg, folder)
    out = {}
    for name, (frames, oracle) in runs.items():
        tilted, front = frames["tilted"], frames["front"]
        unchecked, rise, lift = labeler.read(tilted, front)  # the tilted camera's verdict and the checks' quantities
        row = {"frames": len(tilted), "oracle_goal": int(oracle.sum())}
        for key, said in (("tilted_only", unchecked), ("front_check", unchecked & front_rise_ok(rise)),
                          ("height_check", unchecked & lift_ok(lift))):
            row[key] = verdicts(said, oracle)
        for key, where in (("oracle_goal", oracle), ("tilted_false_goal", unchecked & ~oracle)):
            for quantity, values in (("rise", rise), ("lift", lift)):
                if where.any():
                    row[f"{quantity}_{key}_p10_p50_p90"] = [round(float(v), 3)
                                                            for v in np.nanpercentile(values[where], [10, 50, 90])]
        out[name] = row
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--offsets", type=float, nargs="+", default=[-0.04, -0.03, -0.02, 0.0],
                        help="where the block is held: metres from the drop point along y (negative: toward the front)")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(900, 904)), help="episodes per offset")
    parser.add_argument("--scripted-episodes", type=int, default=6)
    parser.add_argument("--every", type=int, default=1, help="keep every n-th frame")
    parser.add_argument("--calibration", default="runs/inside_front_check", help="the labeler's calibration renders")
    parser.add_argument("--out", default="results/side/grounding/inside_front_check.json")
    args = parser.parse_args()
    out = check(args.offsets, args.seeds, args.scripted_episodes, args.every, args.calibration)
    out["meta"] = {"goal": GOAL, "cameras": ["tilted", "front"], "box_area_m2": 0.0115,
                   "command": f"python probes/inside_front_check.py --offsets {' '.join(map(str, args.offsets))} "
                              f"--seeds {' '.join(map(str, args.seeds))} --scripted-episodes "
                              f"{args.scripted_episodes} --every {args.every} --out {args.out}"}
    write_rows(args.out, out)


if __name__ == "__main__":
    main()
