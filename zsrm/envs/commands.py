"""Subcommands for the scenes: ``zsrm render`` and ``zsrm scripted-eval``."""
from __future__ import annotations

import json
import platform
from pathlib import Path

import numpy as np

REPORT_TASKS = ("stack", "place_left", "place_right", "push_close")


def make_env(name_or_goal: str, **kwargs):
    """A registered env for a catalogue name or a goal sentence."""
    import gymnasium as gym

    import zsrm.envs  # noqa: F401  (registers the ids)
    from zsrm.tasks.catalogue import PENDULUM_ID, resolve

    entry = resolve(name_or_goal)
    if entry.env_id == PENDULUM_ID:
        kwargs.pop("cameras", None)
        kwargs.pop("spread", None)
    return gym.make(entry.env_id, task=entry.goal, **kwargs)


def camera_strip(env, size: int) -> np.ndarray:
    """All cameras of a scene side by side, as one image."""
    return np.concatenate(list(env.unwrapped.render_cameras(size=size).values()), axis=1)


def render_task(task: str, out: Path, size: int = 128, seed: int = 0) -> Path:
    from PIL import Image

    env = make_env(task, image_size=size)
    env.reset(seed=seed)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(camera_strip(env, size)).save(out)
    env.close()
    return out


def run_episode(env, policy, seed: int, frames: list | None = None, size: int = 64) -> dict:
    """One episode; returns the oracle's verdict at the end and the steps the goal held."""
    obs, info = env.reset(seed=seed)
    steps_in_goal, steps = 0, 0
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy())
        steps += 1
        steps_in_goal += int(info["is_success"])
        done = terminated or truncated
        if frames is not None:
            frames.append(camera_strip(env, size))
    return {"success": bool(info["is_success"]), "steps_in_goal": steps_in_goal, "steps": steps}


def scripted_success(tasks=REPORT_TASKS, episodes: int = 20, progress: bool = True) -> dict:
    """Success rate of the scripted controller over seeded episodes (seeds 0..episodes-1)."""
    from tqdm import tqdm

    from zsrm.envs.scripted import scripted_controller

    rates = {}
    for task in tasks:
        env = make_env(task)
        wins = 0
        for seed in tqdm(range(episodes), desc=f"scripted {task}", disable=not progress):
            env.reset(seed=seed)
            controller = scripted_controller(env)
            wins += run_episode(env, controller, seed=seed)["success"]
        rates[task] = wins / episodes
        env.close()
    return rates


def _cmd_render(args):
    out = Path(args.out or f"{args.task.replace(' ', '_')}.png")
    render_task(args.task, out, args.size, args.seed)
    print(f"wrote {out}")


def _cmd_scripted_eval(args):
    rates = scripted_success(args.tasks, args.episodes)
    result = dict(rates)
    result["meta"] = {
        "episodes": args.episodes,
        "seeds": f"0-{args.episodes - 1}",
        "metric": "fraction of episodes whose last step satisfies the oracle (true state)",
        "command": f"zsrm scripted-eval --episodes {args.episodes} --out {args.out}",
        "machine": platform.platform(),
    }
    print(json.dumps(rates, indent=2))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
        print(f"wrote {args.out}")


def add_command(sub):
    p = sub.add_parser("render", help="write a PNG of the three cameras side by side for a task")
    p.add_argument("task", help="a catalogue name (stack, place_left, place_right, push_close, pendulum) or a goal sentence")
    p.add_argument("--out", help="PNG path (default: TASK.png)")
    p.add_argument("--size", type=int, default=128, help="image size in pixels (default 128)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_render)

    p = sub.add_parser("scripted-eval", help="success of the true-state scripted controllers")
    p.add_argument("--tasks", nargs="+", default=list(REPORT_TASKS))
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--out", help="JSON path, e.g. results/scripted_success.json")
    p.set_defaults(func=_cmd_scripted_eval)
