"""Can a policy deciding every 4 control steps finish push_close at all? Scripts on TRUE state, here only.

push_close's learnt policies stop near success 0.3 (docs/training.md), and zsrm trains at action
repeat 4 (a decision moves the pusher up to 10 cm). This plays three scripted policies on the same
seeded episodes and splits their success by how far (across the push) the pusher starts from its
puck's centre line:

* ``controller``: zsrm's own scripted controller (zsrm.envs.scripted.PushController), made for one
  decision per control step, at action repeat 1, 2 and 4;
* ``straight``: push straight at the other puck, never steering (what a policy that ignores the
  pusher's offset does);
* ``align``: a closed-loop script written for action repeat 4: move to a point behind the puck on
  its line to the other puck while more than 4 mm off it, then push at 0.3 while steering back.

    python probes/push_scripts.py --episodes 40 --out results/side/rl/push_scripts.json
"""
from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import zsrm.envs  # noqa: E402,F401
from zsrm.common.files import write_json  # noqa: E402
from zsrm.envs import EPISODE_STEPS, pushing  # noqa: E402
from zsrm.envs.scripted import PushController  # noqa: E402

OFFSET_BINS = ((0.0, 0.012), (0.012, 0.024), (0.024, 0.04))  # metres across the push (a puck's half width: 0.035)


def straight(env):
    def act(puck, other, pusher):
        return np.array([np.sign(other[0] - puck[0]), 0.0])
    return act


def align(env, tolerance: float = 0.004, push: float = 0.3):
    reach = pushing.MAX_MOVE * env.action_repeat  # metres a decision moves at |action| = 1

    def act(puck, other, pusher):
        line = (other - puck) / np.linalg.norm(other - puck)
        if np.linalg.norm(other - puck) < 0.075:
            return np.zeros(2)
        behind = puck - line * (pushing.PUCK_HALF + 0.03)
        across = np.dot(pusher - puck, np.array([-line[1], line[0]]))
        if abs(across) > tolerance or np.dot(puck - pusher, line) < pushing.PUCK_HALF + 0.01:
            return (behind - pusher) / reach
        return push * line + 0.5 * (behind + 0.02 * line - pusher) / reach
    return act


def controller(env):
    script = PushController(env)
    return lambda puck, other, pusher: script()


def play(script, action_repeat: int, episodes: int, seed: int) -> dict:
    env = gym.make("zsrm/Pushing-v0", task="push_close", image_size=16, action_repeat=action_repeat,
                   max_episode_steps=EPISODE_STEPS // action_repeat)
    rows = []
    for e in range(episodes):
        env.reset(seed=seed + e)
        scene = env.unwrapped
        mover, anchor = scene.task.objects[:2]
        offset = abs(scene.pusher_position[1] - scene.object_positions()[mover][1])
        act, done, steps, info = script(scene), False, 0, {}
        while not done:
            positions = scene.object_positions()
            action = act(positions[mover][:2], positions[anchor][:2], scene.pusher_position[:2])
            _, _, terminated, truncated, info = env.step(np.clip(action, -1, 1).astype(np.float32))
            steps, done = steps + info["oracle_steps"], terminated or truncated
        rows.append((offset, steps, bool(info["is_success"])))
    env.close()
    offsets, steps, success = (np.array(c, float) for c in zip(*rows))
    by_offset = {f"{lo:.3f}-{hi:.3f}": {"episodes": int(m.sum()), "success_rate": float(success[m].mean())}
                 for lo, hi in OFFSET_BINS if (m := (offsets >= lo) & (offsets < hi)).any()}
    return {"final_mean": float(steps.mean()), "final_success_rate": float(success.mean()), "by_start_offset_m": by_offset}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--episodes", type=int, default=40)
    p.add_argument("--seed", type=int, default=20_000)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    results = {f"controller-ar{ar}": play(controller, ar, args.episodes, args.seed) for ar in (1, 2, 4)}
    results["straight-ar4"] = play(straight, 4, args.episodes, args.seed)
    results["align-ar4"] = play(align, 4, args.episodes, args.seed)
    for name, r in results.items():
        print(f"{name}: {r['final_mean']:.1f}, success {r['final_success_rate']:.2f}")
    write_json(args.out, {**results, "meta": {
        "metric": "oracle episode reward (control steps of 100 in the goal relation) and final success, scripts on true "
                  "state (a probe: nothing here reaches a zsrm run)",
        "episodes": args.episodes, "command": "python probes/push_scripts.py " + " ".join(argv or [])}})


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
