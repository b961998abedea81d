"""Environment steps per second (physics + rendering) in one process, random actions.

    python benchmarks/env_speed.py --out results/env_speed.json

Compares one 64 px camera against three (the ratio shows what each extra camera costs).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym

import zsrm.envs  # noqa: F401


def steps_per_second(cameras, image_size=64, seconds=10.0, env_id="zsrm/Tabletop-v0", task="stack") -> float:
    env = gym.make(env_id, task=task, cameras=cameras, image_size=image_size)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(20):  # warm up the renderer
        env.step(env.action_space.sample())
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        steps += 1
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="timing window per setting")
    parser.add_argument("--out", default="results/env_speed.json")
    args = parser.parse_args()
    one = steps_per_second(("front",), 64, args.seconds)
    three = steps_per_second(("front", "left", "tilted"), 64, args.seconds)
    result = {
        "steps_per_s_1cam_64": round(one, 1),
        "steps_per_s_3cam_64": round(three, 1),
        "ratio_1cam_over_3cam": round(one / three, 2),
        "meta": {
            "env": "zsrm/Tabletop-v0, task stack, random actions, resets included",
            "renderer": f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}",
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {platform.platform()}",
            "command": "python benchmarks/env_speed.py --out results/env_speed.json",
        },
    }
    print(json.dumps(result, indent=2))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
