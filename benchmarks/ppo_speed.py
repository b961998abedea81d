"""PPO speed with the zsrm reward against the oracle reward, same configuration both ways.

Prints and writes (``--out``): env steps/s of PPO with each reward, ``ratio`` = zsrm / oracle
(the reward model's cost in the RL loop), env-only steps/s (the same vectorised scenes
stepped with random actions, no reward, no policy) and ``env_fraction`` = PPO with the zsrm
reward / env-only. One process, one torch thread, measured in one run.

    python benchmarks/ppo_speed.py --out results/ppo_speed.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402


def ppo_steps_per_s(cfg, steps: int) -> float:
    from zsrm.rewards import VecZeroShotReward
    from zsrm.rl.envs import goal_camera, make_reward, make_vec, task_entry
    from zsrm.rl.features import VecImageFeatures
    from zsrm.rl.ppo import build_ppo
    from zsrm.vlm import load_vlm

    venv = make_vec(cfg, cfg.n_envs, cfg.seed)
    venv = VecImageFeatures(VecZeroShotReward(venv, make_reward(cfg), task_entry(cfg.goal).goal),
                            load_vlm(cfg.vlm), goal_camera(cfg.goal))
    model = build_ppo(cfg, venv)
    model.learn(cfg.n_envs * cfg.n_steps)  # warm-up: first rollout and update
    t = time.perf_counter()
    model.learn(steps // cfg.action_repeat, reset_num_timesteps=False)
    return steps / (time.perf_counter() - t)


def env_steps_per_s(cfg, steps: int) -> float:
    from zsrm.rl.envs import make_vec

    venv = make_vec(cfg, cfg.n_envs, cfg.seed)
    venv.reset()
    rng = np.random.default_rng(0)
    decisions = steps // cfg.action_repeat // cfg.n_envs
    t = time.perf_counter()
    for _ in range(decisions):
        venv.step(rng.uniform(-1, 1, (cfg.n_envs, *venv.action_space.shape)).astype(np.float32))
    return decisions * cfg.n_envs * cfg.action_repeat / (time.perf_counter() - t)


def main(argv=None):
    from zsrm.rl.config import TrainConfig

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal", default="stack")
    parser.add_argument("--steps", type=int, default=16_384, help="env steps timed per reward")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    speeds = {}
    for reward in ("oracle", "zsrm"):
        speeds[reward] = ppo_steps_per_s(TrainConfig(goal=args.goal, reward=reward), args.steps)
        print(f"PPO with the {reward} reward: {speeds[reward]:.0f} env steps/s", flush=True)
    env_only = env_steps_per_s(TrainConfig(goal=args.goal), args.steps)
    print(f"env only: {env_only:.0f} env steps/s")
    cfg = TrainConfig(goal=args.goal)
    result = {
        "ratio": speeds["zsrm"] / speeds["oracle"],
        "env_fraction": speeds["zsrm"] / env_only,
        "ppo_zsrm_steps_per_s": speeds["zsrm"], "ppo_oracle_steps_per_s": speeds["oracle"],
        "env_only_steps_per_s": env_only,
        "meta": {"goal": args.goal, "steps_timed": args.steps, "n_envs": cfg.n_envs, "action_repeat": cfg.action_repeat,
                 "zsrm_reward": cfg.reward_model, "policy_vision": f"frozen {cfg.vlm} VLM trunk + keypoints",
                 "torch_threads": 1, "machine": f"{platform.machine()}, {os.cpu_count()} cores, no GPU",
                 "command": "python benchmarks/ppo_speed.py --out results/ppo_speed.json"},
    }
    print(f"ratio zsrm/oracle {result['ratio']:.2f}, env_fraction {result['env_fraction']:.2f}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")
    return result


if __name__ == "__main__":
    main()
