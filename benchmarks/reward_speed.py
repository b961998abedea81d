"""Rewards per second on 64 frames: the student network vs the fine-tuned VLM, in one run.

Both compute the same thing, the binarised ZSRM reward (:class:`zsrm.rewards.binarised.ZSRMReward`)
of "a yellow block on top of a red block" for a batch of 64 real rendered front-camera frames
(64 px), with the goal and negative texts embedded once beforehand. The fine-tuned VLM is the
simple way (the model the rewards come from); the student is the small network for the RL
loop. The two alternate repeat by repeat, so load from other processes hits both alike.
``ratio`` = student rewards/s / fine-tuned VLM rewards/s. Also reported: how often the two
binarised rewards agree on these frames.

    .venv/bin/python benchmarks/reward_speed.py --vlm runs/zsrm/vlm --student runs/zsrm/student \\
        --out results/reward_speed.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import torch

TASK = "stack"


def frames(n: int, seed: int = 0) -> np.ndarray:
    """n front frames of the stack scene, half from the scripted controller (goal reached), half random."""
    from zsrm.evaluation.reward_quality import rollout_frames

    f = rollout_frames(TASK, scripted_episodes=2, random_episodes=2, seed=seed, every=1, progress=False)
    rng = np.random.default_rng(seed)
    return f.images[np.sort(rng.choice(len(f), n, replace=False))]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vlm", default="runs/zsrm/vlm", help="fine-tuned VLM folder (zsrm finetune)")
    p.add_argument("--student", default="runs/zsrm/student", help="student folder (zsrm finetune --student)")
    p.add_argument("--images", type=int, default=64)
    p.add_argument("--repeats", type=int, default=20, help="timed batches per model (after 2 warm-ups)")
    p.add_argument("--out", default="results/reward_speed.json")
    args = p.parse_args(argv)

    from zsrm.fullmodel import load_reward_backbone
    from zsrm.rewards.binarised import ZSRMReward
    from zsrm.tasks.catalogue import SINGLE_TASKS

    for path in (args.vlm, args.student):
        if not Path(path).is_dir():
            print(f"reward_speed: error: no model folder {path}: train it with zsrm finetune", file=sys.stderr)
            return 2
    goal = SINGLE_TASKS[TASK].goal
    rewards = {"student": ZSRMReward(load_reward_backbone(args.student)),
               "vlm": ZSRMReward(load_reward_backbone(args.vlm))}
    x = {"front": frames(args.images)}
    for r in rewards.values():
        r.prepare(goal)  # texts embedded once, as in the RL loop
    load_before = os.getloadavg()[0]
    times = {k: [] for k in rewards}
    out = {}
    with torch.inference_mode():
        for rep in range(args.repeats + 2):
            for name, r in rewards.items():
                t0 = time.perf_counter()
                out[name] = r(x, goal)
                if rep >= 2:  # two warm-ups each
                    times[name].append(time.perf_counter() - t0)
    per_s = {k: args.images / float(np.median(v)) for k, v in times.items()}
    result = {
        "ratio": per_s["student"] / per_s["vlm"],
        "student_rewards_per_s": per_s["student"],
        "vlm_rewards_per_s": per_s["vlm"],
        "images": args.images,
        "timed_batches_per_model": args.repeats,
        "binary_agreement": float((out["student"] == out["vlm"]).mean()),
        "student": {"folder": args.student,
                    "parameters": sum(p.numel() for p in rewards["student"].model.parameters())},
        "vlm": {"folder": args.vlm, "backend": rewards["vlm"].model.backend,
                "parameters": sum(p.numel() for p in rewards["vlm"].model.parameters()),
                "input_px": rewards["vlm"].model.image_size},
        "reward": f"binarised ZSRM reward of {goal!r}: goal vs {len(rewards['vlm'].candidates(goal)) - 1} "
                  "negative texts, text embeddings cached",
        "frames": f"{args.images} real rendered front-camera frames (64 px) of the {TASK!r} scene",
        "timing": "median wall clock of one batched reward call per model, the two alternating",
        "machine": f"{platform.platform()}, {os.cpu_count()} CPUs, torch {torch.__version__} "
                   f"({torch.get_num_threads()} threads), load average {load_before:.1f} before timing",
        "command": "python benchmarks/reward_speed.py " + " ".join(argv if argv is not None else sys.argv[1:]),
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"student {per_s['student']:.0f} rewards/s, fine-tuned VLM {per_s['vlm']:.0f} rewards/s: "
          f"ratio {result['ratio']:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
