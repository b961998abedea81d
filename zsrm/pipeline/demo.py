"""``zsrm demo``: a tour of the scenes (the main job is ``zsrm reproduce``). Writes a report folder.

It shows the scenes, a random-policy episode per scene, how often the goal holds under a
random policy and under the true-state scripted controller (the oracle's view), and along
scripted trajectories (the paper's Figure 5) the base reward of the shipped offline ``scene`` VLM
beside the binarised full reward of the shipped student reward model.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from zsrm.common.files import atomic_path, check_writable, write_json, write_text
from zsrm.envs.rollout import camera_strip, episode_steps, make_env, random_policy, run_episode
from zsrm.envs.scripted import scripted_controller
from zsrm.evaluation.plots import pyplot, save_figure
from zsrm.tasks.catalogue import REPORT_TASKS
from zsrm.vlm.factory import DEFAULT_VLM

SCENES = {"tabletop": "stack", "pushing": "push_close", "pendulum": "pendulum"}


def _label(image: np.ndarray, text: str) -> np.ndarray:
    from PIL import Image, ImageDraw

    img = Image.fromarray(image)
    ImageDraw.Draw(img).text((4, 2), text, fill=(0, 0, 0))
    return np.asarray(img)


def write_scenes(out: Path, size: int = 128) -> Path:
    """One row per scene: its cameras side by side, labelled with the goal."""
    from PIL import Image

    rows = []
    for scene, task in SCENES.items():
        env = make_env(task, image_size=size)
        env.reset(seed=0)
        strip = camera_strip(env, size)
        env.close()
        row = np.full((size, 3 * size, 3), 255, np.uint8)
        row[:, : strip.shape[1]] = strip
        rows.append(_label(row, f"{scene}: {env.unwrapped.task if scene != 'pendulum' else env.unwrapped.goal}"))
    path = out / "scenes.png"
    with atomic_path(path) as tmp:
        Image.fromarray(np.concatenate(rows, axis=0)).save(tmp)
    return path


def write_random_gifs(out: Path, steps: int = 40, size: int = 64) -> list[Path]:
    import imageio.v3 as iio

    paths = []
    for scene, task in SCENES.items():
        env = make_env(task, image_size=size)
        frames = [camera_strip(env, size) for t, *_ in episode_steps(env, random_policy, seed=0, max_steps=steps) if t]
        env.close()
        path = out / f"random_episode_{scene}.gif"
        with atomic_path(path) as tmp:
            iio.imwrite(tmp, np.stack(frames), duration=80, loop=0)
        paths.append(path)
    return paths


def policy_table(episodes: int) -> list[dict]:
    """Oracle metrics of a random and a scripted policy on the report tasks."""
    from tqdm import tqdm

    rows = []
    for task in tqdm(REPORT_TASKS, desc="policies"):
        env = make_env(task)
        for name, policy in (("random", random_policy), ("scripted", scripted_controller)):
            results = [run_episode(env, policy, seed=seed) for seed in range(episodes)]
            rows.append({
                "task": task,
                "goal": str(env.unwrapped.task),
                "policy": name,
                "episodes": episodes,
                "success_rate": float(np.mean([r["success"] for r in results])),
                "mean_steps_in_goal": float(np.mean([r["steps_in_goal"] for r in results])),
            })
        env.close()
    return rows


def plot_policy_table(rows: list[dict], path: Path) -> Path:
    plt = pyplot()

    tasks = list(dict.fromkeys(r["task"] for r in rows))
    fig, ax = plt.subplots(figsize=(6, 3.2))
    width = 0.38
    for i, policy in enumerate(("random", "scripted")):
        vals = [next(r["mean_steps_in_goal"] for r in rows if r["task"] == t and r["policy"] == policy) for t in tasks]
        ax.bar(np.arange(len(tasks)) + (i - 0.5) * width, vals, width, label=policy)
    ax.set_xticks(np.arange(len(tasks)), tasks)
    ax.set_ylabel("steps in goal per 100-step episode\n(oracle metric)")
    ax.legend()
    return save_figure(fig, path)


REWARD_CURVES = {  # goal -> the camera its relation is read from
    "a yellow puck close to a blue puck": "tilted",
    "a yellow block on top of a red block": "front",
}


def write_reward_curves(out: Path, vlm_spec: str = DEFAULT_VLM, zsrm_spec: str = "student") -> tuple[list[Path], list[dict]]:
    """Base reward (paper 2.1) and the binarised ZSRM reward (paper 2.2, the shipped student)
    along scripted trajectories: CSV + PNG per goal, and how often each agrees with the oracle."""
    from zsrm.evaluation.curves import plot_curve, record_trajectory, reward_curve, write_csv
    from zsrm.fullmodel import load_reward_backbone
    from zsrm.rewards import BaseReward, OracleReward, ZSRMReward
    from zsrm.vlm import load_vlm

    vlm = load_vlm(vlm_spec)
    zsrm = ZSRMReward(load_reward_backbone(zsrm_spec))
    paths, agreement = [], []
    for goal, camera in REWARD_CURVES.items():
        traj = record_trajectory(goal, cameras=(camera,), steps=40, seed=0)
        rows = reward_curve(traj, {"base": BaseReward(vlm, camera=camera), "zsrm": zsrm, "oracle": OracleReward()})
        stem = out / ("reward_" + "_".join(goal.split()[1:3] + goal.split()[-2:-1]))
        title = (f"base reward ({vlm_spec} VLM) and zsrm reward ({zsrm_spec}) for {goal!r}, {camera} camera; "
                 "green: oracle says the goal holds")
        paths += [write_csv(rows, stem.with_suffix(".csv")), plot_curve(rows, traj, stem.with_suffix(".png"), camera, title)]
        oracle = np.array([r["oracle"] for r in rows])
        zsrm_says = np.array([r["zsrm_reward"] for r in rows])
        agreement.append({"goal": goal, "frames": len(rows), "oracle_frames": int(oracle.sum()),
                          "zsrm_frames": int(zsrm_says.sum()), "zsrm_agrees": float((zsrm_says == oracle).mean())})
    return paths, agreement


def run_demo(out: Path, episodes: int = 5) -> Path:
    check_writable(out, folder=True)
    curve_files, agreement = write_reward_curves(out)
    files = [write_scenes(out), *write_random_gifs(out), *curve_files]
    rows = policy_table(episodes)
    with atomic_path(out / "policies.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    write_json(out / "policies.json", rows)
    files += [out / "policies.csv", out / "policies.json", plot_policy_table(rows, out / "policies.png")]
    lines = ["# zsrm demo report", "", "Written by `zsrm demo` (offline).", ""]
    lines += ["| task | policy | success rate | mean steps in goal |", "|---|---|---|---|"]
    lines += [f"| {r['task']} | {r['policy']} | {r['success_rate']:.2f} | {r['mean_steps_in_goal']:.1f} |" for r in rows]
    lines += ["", "Binarised zsrm reward (shipped student) along one scripted episode, against the oracle:", "",
              "| goal | frames | oracle: goal holds | zsrm reward 1 | zsrm agrees with oracle |", "|---|---|---|---|---|"]
    lines += [f"| {a['goal']} | {a['frames']} | {a['oracle_frames']} | {a['zsrm_frames']} | {a['zsrm_agrees']:.2f} |"
              for a in agreement]
    lines += ["", "Files:", *[f"- `{p.name}`" for p in files]]
    write_text(out / "README.md", "\n".join(lines) + "\n")
    print("\n".join(lines[4:4 + 2 + len(rows)]))
    print(f"\nreport written to {out.resolve()}")
    return out


@dataclass
class Demo:
    """A tour of the scenes: renders, random episodes, an oracle table, reward curves."""

    out: str = "reports/scenes"  # report folder (zsrm reproduce writes reports/demo)
    episodes: int = 5  # episodes per task and policy for the table

    def run(self) -> int:
        run_demo(Path(self.out), episodes=self.episodes)
        return 0
