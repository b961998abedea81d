"""Does a push_close policy's success depend on which side of the other puck its puck starts?

A policy that ignores the layout and pushes one way would succeed from one side only. Plays a
trained policy (by its mean action) on seeded episodes and splits the oracle's steps in the goal
relation by the side the moved puck started on, and says how far apart the pucks end (and the
nearest they came) in the episodes that never succeed: a push that stops short or goes astray.

    python probes/push_sides.py runs/rl-v3/push_close-oracle-1/policy --episodes 30 \
        --out results/side/rl/push_close_sides.json
"""
from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from zsrm.common.files import write_json  # noqa: E402
from zsrm.rl.envs import make_vec  # noqa: E402
from zsrm.rl.evaluate import eval_seed  # noqa: E402
from zsrm.rl.features import policy_view  # noqa: E402
from zsrm.rl.policy import PolicyBundle  # noqa: E402
from zsrm.vlm import load_vlm  # noqa: E402


def start_side(env) -> int:
    """-1 when the moved puck starts left of the other, +1 right of it."""
    mover, anchor = (env.data.qpos[env._qpos_adr(c)] for c in env.task.objects[:2])
    return int(np.sign(mover - anchor))


def play(policy: str, episodes: int, seed: int) -> dict:
    bundle = PolicyBundle.load(policy)
    cfg = bundle.cfg
    venv = policy_view(make_vec(cfg, 1, eval_seed(seed)), load_vlm(cfg.vlm), cfg)
    objects = venv.venv.envs[0].unwrapped.task.objects[:2]
    steps, apart = {-1: [], 1: []}, []  # apart: (end, nearest) centre distance of failed episodes
    for _ in range(episodes):
        obs, done, in_goal, distances = venv.reset(), False, 0, []
        side = start_side(venv.venv.envs[0].unwrapped)
        while not done:
            obs, _, dones, infos = venv.step(bundle.act(obs, deterministic=True))
            in_goal, done = in_goal + infos[0]["oracle_steps"], bool(dones[0])
            a, b = (infos[0]["object_positions"][c][:2] for c in objects)
            distances.append(float(np.linalg.norm(a - b)))
        steps[side].append(in_goal)
        if not in_goal:
            apart.append((distances[-1], min(distances)))
    venv.close()
    sides = {("left" if side < 0 else "right"): {"episodes": len(v), "succeeded": int(sum(s > 0 for s in v)),
                                                 "mean_oracle_steps": float(np.mean(v)) if v else None}
             for side, v in steps.items()}
    end, nearest = np.array(apart).T if apart else ([], [])
    failed = {"episodes": len(apart), "median_end_distance_m": float(np.median(end)) if apart else None,
              "median_nearest_distance_m": float(np.median(nearest)) if apart else None}
    return {"by_start_side": sides, "never_succeeded": failed}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy")
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    result = {**play(args.policy, args.episodes, args.seed),
              "meta": {"close_to_threshold_m": 0.10, "policy": args.policy, "episodes": args.episodes, "actions": "mean",
                       "command": f"python probes/push_sides.py {args.policy} --episodes {args.episodes} "
                                  f"--seed {args.seed}" + (f" --out {args.out}" if args.out else "")}}
    print(result["by_start_side"], result["never_succeeded"])
    if args.out:
        write_json(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
