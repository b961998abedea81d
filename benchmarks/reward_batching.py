"""Rewards per second for 8 envs: the batched VecEnv wrapper vs the simple way, in one run.

* batched: ``VecZeroShotReward`` over a ``DummyVecEnv`` of N envs: one image forward for all N
  frames of a step, the goal's text embedding computed once;
* simple: each env wrapped in ``ZeroShotReward`` with the text cache off: N image forwards of
  one frame per step, and the goal re-encoded at every call.

Both step the same seeded envs (zsrm/Tabletop-v0, "stack", front camera, 64 px frames, resized
to the VLM's 224 px input) with the same random actions, alternating step by step so that load
from other processes hits both alike, and must give the same rewards.

    .venv/bin/python benchmarks/reward_batching.py --out results/reward_batching.json
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
from stable_baselines3.common.vec_env import DummyVecEnv

from zsrm.envs.rollout import make_env
from zsrm.rewards import BaseReward, VecZeroShotReward, ZeroShotReward
from zsrm.vlm import load_vlm

TASK = "stack"


def make_envs(n_envs: int, image_size: int, wrap=None):
    def make():
        env = make_env(TASK, image_size=image_size, cameras=("front",))
        return wrap(env) if wrap else env

    venv = DummyVecEnv([make] * n_envs)
    venv.seed(0)
    return venv


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--vlm", default="open_clip:RN50:none", help="VLM spec (default: RN50, random weights)")
    p.add_argument("--n-envs", type=int, default=8)
    p.add_argument("--steps", type=int, default=3, help="timed vec-env steps per way (after 1 warm-up)")
    p.add_argument("--image-size", type=int, default=64)
    p.add_argument("--out", default="results/reward_batching.json")
    args = p.parse_args(argv)

    from zsrm.tasks.catalogue import SINGLE_TASKS

    goal = SINGLE_TASKS[TASK].goal
    load_before = os.getloadavg()[0]
    vlm = load_vlm(args.vlm)
    batched = VecZeroShotReward(make_envs(args.n_envs, args.image_size), BaseReward(vlm, camera="front"), goal)
    simple = make_envs(args.n_envs, args.image_size,
                       wrap=lambda env: ZeroShotReward(env, BaseReward(vlm, camera="front", cache_texts=False), goal))
    batched.reset()
    simple.reset()
    rng = np.random.default_rng(0)
    times = {"batched": 0.0, "simple": 0.0}
    max_diff = 0.0
    for step in range(args.steps + 1):
        actions = rng.uniform(-1, 1, (args.n_envs, *batched.action_space.shape)).astype(np.float32)
        rewards = {}
        for name, venv in (("batched", batched), ("simple", simple)):
            t0 = time.perf_counter()
            _, rewards[name], _, _ = venv.step(actions)
            if step > 0:  # step 0 warms up both (allocations, first renders)
                times[name] += time.perf_counter() - t0
        max_diff = max(max_diff, float(np.abs(rewards["batched"] - rewards["simple"]).max()))
        print(f"step {step}{' (warm-up)' if step == 0 else ''}: batched {times['batched']:.1f} s, "
              f"simple {times['simple']:.1f} s so far", file=sys.stderr)
    n = args.n_envs * args.steps
    rates = {k: n / v for k, v in times.items()}
    result = {
        "ratio": rates["batched"] / rates["simple"],
        "batched_rewards_per_s": rates["batched"],
        "simple_rewards_per_s": rates["simple"],
        "n_envs": args.n_envs,
        "timed_steps": args.steps,
        "rewards_timed_per_way": n,
        "max_abs_reward_difference": max_diff,
        "env": f"zsrm/Tabletop-v0, task {TASK!r}, real rendered 'front' frames of {args.image_size} px, DummyVecEnv",
        "vlm": f"{args.vlm} (input {getattr(vlm, 'image_size', 'n/a')} px, fp32)",
        "reward": "BaseReward mode 'dot' (paper 2.1)",
        "batched_way": "VecZeroShotReward: one image forward of all envs per step, goal text embedded once",
        "simple_way": "ZeroShotReward per env, text cache off: one image forward and one text forward per env per step",
        "timing": "wall clock of vec-env steps (env step + reward), the two ways alternating step by step",
        "machine": f"{platform.platform()}, {os.cpu_count()} CPUs, torch {torch.__version__} "
                   f"({torch.get_num_threads()} threads)",
        # Other processes share the 2 cores: the 1-minute load average tells how busy they were.
        "load_average_1min": {"start": round(load_before, 2), "end": round(os.getloadavg()[0], 2)},
        "command": "python benchmarks/reward_batching.py " + " ".join(argv if argv is not None else sys.argv[1:]),
    }
    print(json.dumps(result, indent=2))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
        print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
