"""Do the distilled policies see the blue block? (Why Table 2's test tasks fail.)

On the "left of" / "right of" scenes (both blocks on the table), moves one block a block width
in a random direction, renders the frame again, and measures how far the policy's image
keypoints and its action move: on the test scenes when the blue block moves and when the
training-colour block moves, and on the training scenes for comparison. A policy blind to
blue would barely respond when the blue block moves.

    OMP_NUM_THREADS=1 python probes/distill_blue_sensitivity.py \
        --out results/side/multitask/blue_sensitivity.json
"""
from __future__ import annotations

import argparse

import mujoco
import numpy as np
import torch

from zsrm.common.files import write_json
from zsrm.envs.tabletop import BLOCK_HALF
from zsrm.evaluation.multitask import EVAL_SEED, split_goals
from zsrm.policy.models import embed_goals, view_frames
from zsrm.policy.training import load_distilled
from zsrm.rl.config import TrainConfig
from zsrm.rl.envs import make_vec
from zsrm.rl.evaluate import mean_se
from zsrm.tasks.language import parse_goal
from zsrm.vlm import load_vlm


@torch.no_grad()
def responses(policy, embedding, env, camera: str, colour: str, rng) -> tuple[float, float]:
    """Mean keypoint shift (image units, [-1, 1] across) and action change when ``colour``'s
    block moves one block width."""
    def read():
        frame = torch.as_tensor(env._render_camera(camera)).permute(2, 0, 1)[None]
        seen = view_frames(frame, policy.cfg.keypoint_view)  # what the policy's tower reads
        keypoints = policy.encoder(seen)[0, :2 * policy.cfg.keypoints].view(-1, 2)
        return keypoints, policy.act(frame.permute(0, 2, 3, 1), embedding)[0]

    before_k, before_a = read()
    start = env.object_positions()[colour]
    angle = rng.uniform(0, 2 * np.pi)
    env._set_object(colour, start + 2 * BLOCK_HALF * np.array([np.cos(angle), np.sin(angle), 0.0]))
    mujoco.mj_forward(env.model, env.data)
    after_k, after_a = read()
    env._set_object(colour, start)
    mujoco.mj_forward(env.model, env.data)
    return float((after_k - before_k).norm(dim=1).mean()), float((after_a - before_a).norm())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", default="runs/multitask/distill", help="the folder zsrm distill wrote")
    parser.add_argument("--scenes", type=int, default=10, help="seeded scenes per test goal")
    parser.add_argument("--out", default="results/side/multitask/blue_sensitivity.json")
    args = parser.parse_args()

    summary, policies = load_distilled(args.policies)
    # The paper's three: the grounded policy finds the goal's objects through the VLM's Grad-CAM,
    # not through keypoints of its own (with its default view it has none).
    policies = {name: policy for name, policy in policies.items() if name != "grounded"}
    vlm = load_vlm(summary["vlm"])
    rng = np.random.default_rng(0)
    # Per policy and moved block (blue; a training colour in a test scene; in a training scene):
    # keypoint shifts and action changes.
    moved = ("blue", "test_other", "train")
    shifts = {name: {key: ([], []) for key in moved} for name in policies}
    every = split_goals()
    splits = {split: [g for g in every[split] if parse_goal(g).relation in ("left_of", "right_of")]
              for split in ("test", "train")}
    for split, goals in splits.items():
        for goal in goals:
            for name, policy in policies.items():
                embedding = embed_goals(vlm, [goal], policy.cfg.text_embedding)
                venv = make_vec(TrainConfig(goal=goal, image_size=policy.cfg.image_size,
                                            action_repeat=policy.cfg.action_repeat), args.scenes, EVAL_SEED)
                venv.reset()
                for wrapped in venv.envs:
                    for colour in parse_goal(goal).objects:
                        key = "train" if split == "train" else ("blue" if colour == "blue" else "test_other")
                        k, a = responses(policy, embedding, wrapped.unwrapped, policy.cfg.camera, colour, rng)
                        shifts[name][key][0].append(k)
                        shifts[name][key][1].append(a)
                venv.close()
    result = {"scenes_per_split": len(splits["test"]) * args.scenes, "goals": splits, "policies": args.policies,
              "moved": {"blue": "the blue block, test scenes", "test_other": "the training-colour block, test "
                        "scenes", "train": "either block, training scenes"},
              "metric": "mean over keypoints of |keypoint shift| (image spans [-1, 1]) and |action change| "
                        "when one block moves a block width; mean and s.e. over scenes"}
    for name, by in shifts.items():
        result[name] = {}
        for key, (k, a) in by.items():
            (km, kse), (am, ase) = mean_se(k), mean_se(a)
            result[name][key] = {"keypoint_shift": {"mean": km, "se": kse}, "action_change": {"mean": am, "se": ase}}
        print(f"{name}: keypoints / action move " + ", ".join(
            f"{result[name][key]['keypoint_shift']['mean']:.3f} / {result[name][key]['action_change']['mean']:.3f} "
            f"({key})" for key in moved))
    write_json(args.out, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
