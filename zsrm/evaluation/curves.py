"""``zsrm reward-curve``: reward along a scripted trajectory (the paper's Figure 5), for any reward models.

A true-state scripted controller (:mod:`zsrm.envs.scripted`) carries out the goal, e.g. in
the pushing scene it pushes the first puck of "a yellow puck close to a blue puck" (yellow)
toward the second (blue). Every frame, from the reset frame on, is scored by each reward
model; the table also holds the distance between the goal's first two objects (true state,
metres) and the oracle's verdict.

>>> from zsrm.rewards import OracleReward
>>> from zsrm.evaluation.curves import record_trajectory, reward_curve
>>> traj = record_trajectory("a yellow puck close to a blue puck", cameras=("tilted",), steps=5)
>>> rows = reward_curve(traj, [OracleReward()])
>>> list(rows[0]), len(rows)
(['step', 'distance', 'oracle_reward', 'oracle'], 6)
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from zsrm.envs.rollout import episode_steps, make_env
from zsrm.envs.scripted import scripted_controller
from zsrm.evaluation.plots import pyplot, save_figure
from zsrm.rewards.interface import RewardModel, check_goal

FIGURE5_GOAL = "a yellow puck close to a blue puck"  # the paper's Figure 5: the first puck is pushed to the second


@dataclass
class Trajectory:
    """Frames ``camera -> (T, H, W, 3)`` (frame 0 = the reset frame), the T infos, the goal."""

    goal: str
    observations: dict[str, np.ndarray]
    infos: list[dict]
    seed: int = 0
    objects: tuple[str, ...] = field(default_factory=tuple)

    def __len__(self) -> int:
        return len(self.infos)

    @property
    def distances(self) -> np.ndarray:
        """Distance (m) between the centres of the goal's first two objects, per frame."""
        if len(self.objects) < 2:
            return np.full(len(self), np.nan)
        a, b = self.objects[:2]
        return np.array([np.linalg.norm(i["object_positions"][a] - i["object_positions"][b]) for i in self.infos])


def record_trajectory(goal: str, cameras: Sequence[str] = ("tilted",), steps: int = 30, seed: int = 0,
                      image_size: int = 64) -> Trajectory:
    """Run the scene's scripted controller for ``goal`` and keep every frame and info."""
    goal = check_goal(goal)
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    env = make_env(goal, cameras=tuple(cameras), image_size=image_size)
    frames, infos = [], []
    try:
        for _, obs, info, _ in episode_steps(env, scripted_controller, seed, max_steps=steps):
            frames.append(obs)
            infos.append(info)
    except (TypeError, NotImplementedError) as err:
        raise ValueError(f"no scripted trajectory for {goal!r}: {err}") from None
    finally:
        env.close()
    task = env.unwrapped.task
    observations = {c: np.stack([f[c] for f in frames]) for c in frames[0]}
    return Trajectory(goal, observations, infos, seed, tuple(task.objects) if task else ())


def _named(models) -> dict[str, RewardModel]:
    if isinstance(models, RewardModel):
        models = [models]
    if isinstance(models, Mapping):
        named = dict(models)
    else:
        named = {}
        for m in models:
            name, k = m.name, 2
            while name in named:  # two models of one kind: base, base_2, ...
                name, k = f"{m.name}_{k}", k + 1
            named[name] = m
    if not named:
        raise ValueError("give at least one reward model")
    for name, m in named.items():
        if not isinstance(m, RewardModel):
            raise TypeError(f"{name!r} is not a zsrm RewardModel: {type(m).__name__}")
    return named


def reward_curve(trajectory: Trajectory, models) -> list[dict]:
    """One row per frame: step, distance, ``<name>_reward`` per model, oracle.

    ``models``: a RewardModel, a list of them (named by ``model.name``) or a dict name -> model.
    Each model scores all frames of the trajectory in one call.
    """
    named = _named(models)
    scores = {f"{name}_reward": m(trajectory.observations, trajectory.goal, trajectory.infos)
              for name, m in named.items()}
    dist = trajectory.distances
    rows = []
    for t, info in enumerate(trajectory.infos):
        row = {"step": t, "distance": float(dist[t])}
        row.update({k: float(v[t]) for k, v in scores.items()})
        row["oracle"] = float(info["oracle_reward"])
        rows.append(row)
    return rows


def spearman(a, b) -> float:
    """Rank correlation (no ties correction needed for continuous values)."""
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def summarise(rows: list[dict]) -> dict:
    """For each reward column: rank correlation with closeness (-distance) and with the oracle."""
    dist = np.array([r["distance"] for r in rows])
    oracle = np.array([r["oracle"] for r in rows])
    out = {}
    for key in [k for k in rows[0] if k.endswith("_reward")]:
        r = np.array([row[key] for row in rows])
        out[key] = {
            "spearman_with_closeness": spearman(r, -dist) if np.isfinite(dist).all() else float("nan"),
            "mean_when_goal_holds": float(r[oracle > 0].mean()) if (oracle > 0).any() else float("nan"),
            "mean_otherwise": float(r[oracle == 0].mean()) if (oracle == 0).any() else float("nan"),
            "argmax_step": int(r.argmax()),
        }
    return out


def write_csv(rows: list[dict], path: str | Path) -> Path:
    from zsrm.common.files import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp, tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
    return path


def plot_curve(rows: list[dict], trajectory: Trajectory, path: str | Path, camera: str | None = None,
               title: str | None = None, n_frames: int = 8) -> Path:
    """Each reward vs frame (one panel per model, the distance dashed on a second axis, frames
    where the oracle says the goal holds shaded), above a strip of frames."""
    plt = pyplot()

    camera = camera or next(iter(trajectory.observations))
    frames = trajectory.observations[camera]
    keys = [k for k in rows[0] if k.endswith("_reward")]
    steps = np.array([r["step"] for r in rows])
    dist = np.array([r["distance"] for r in rows])
    oracle = np.array([r["oracle"] for r in rows])
    shown = np.unique(np.linspace(0, len(rows) - 1, min(n_frames, len(rows))).round().astype(int))

    fig = plt.figure(figsize=(1.4 * len(shown) + 1, 2.2 * len(keys) + 1.9))
    grid = fig.add_gridspec(len(keys) + 1, len(shown), height_ratios=[2.2] * len(keys) + [1.6])
    for i, key in enumerate(keys):
        ax = fig.add_subplot(grid[i, :])
        r = np.array([row[key] for row in rows])
        ax.plot(steps, r, "o-", color="C0", ms=3, label=key.replace("_", " "))
        ax.plot(steps[shown], r[shown], "s", color="C3", ms=6, mfc="none", label="frames shown below")
        for t in steps[oracle > 0]:
            ax.axvspan(t - 0.5, t + 0.5, color="C2", alpha=0.15, lw=0)
        ax.set_ylabel(key.replace("_", " "))
        ax.set_xlim(-0.5, steps[-1] + 0.5)
        if np.isfinite(dist).all():
            ax2 = ax.twinx()
            ax2.plot(steps, dist, "--", color="0.4", lw=1, label="object distance (m)")
            ax2.set_ylabel("distance (m)", color="0.4")
            lines = ax.get_legend_handles_labels()
            lines2 = ax2.get_legend_handles_labels()
            ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=7, loc="upper left")
        if i == 0:
            ax.set_title(title or f"{trajectory.goal!r} ({camera} camera); green: oracle says goal holds",
                         fontsize=9)
        if i == len(keys) - 1:
            ax.set_xlabel("frame")
    for j, t in enumerate(shown):
        ax = fig.add_subplot(grid[-1, j])
        ax.imshow(frames[t])
        ax.set_title(f"frame {t}", fontsize=8)
        ax.axis("off")
    return save_figure(fig, path)
