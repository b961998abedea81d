"""``zsrm eval-reward``: the rewards against the oracle on held-out frames, per task.

Frames come from the task's own scene, from episodes none of the training data saw: scripted
episodes (a true-state controller carries the task out, so the goal is reached) and
random-action episodes (mostly not). The label of a frame is the oracle's ``is_success``.
Each reward is scored on the camera the goal's relation is read on.

Reported per task and reward: precision, recall and F1 of the binarised reward (1 when the
goal text beats its negatives), AUROC of the raw score (the cosine of the frame and the goal
text) and of the margin over the best negative. The base reward (the VLM before
fine-tuning) is binarised by the same argmax rule, so both are read the same way;
``f1_best_threshold`` is the F1 of the raw score at the threshold that is best *on these very
labels*: a privileged upper bound for any threshold, not something a user could tune.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from zsrm.envs.rollout import episode_steps, make_env, random_policy
from zsrm.envs.scripted import scripted_controller
from zsrm.evaluation.metrics import auroc, best_threshold_f1, binary_metrics
from zsrm.tasks.catalogue import REPORT_TASKS, SINGLE_TASKS
from zsrm.tasks.relations import RELATIONS

EVAL_TASKS = REPORT_TASKS
POLICIES = {"scripted": scripted_controller, "random": random_policy}


@dataclass
class EvalFrames:
    """Frames of one task's camera with the oracle's labels."""

    task: str
    goal: str
    camera: str
    images: np.ndarray  # (N, H, W, 3) uint8
    success: np.ndarray  # (N,) bool, info["is_success"]
    source: np.ndarray  # (N,) "scripted" or "random"
    episode: np.ndarray  # (N,) episode seed
    step: np.ndarray = field(default=None)  # (N,) step within the episode

    def __len__(self) -> int:
        return len(self.success)

    @classmethod
    def concat(cls, task: str, parts: list["EvalFrames"]) -> "EvalFrames":
        """The frames of several evaluations of one goal as one set named ``task``."""
        arrays = {k: np.concatenate([getattr(p, k) for p in parts])
                  for k in ("images", "success", "source", "episode", "step")}
        return cls(task, parts[0].goal, parts[0].camera, **arrays)


def task_camera(task: str) -> str:
    entry = _entry(task)
    return RELATIONS[entry.task.relation].camera


def _entry(task: str):
    if task not in SINGLE_TASKS or SINGLE_TASKS[task].task is None:
        known = [k for k, e in SINGLE_TASKS.items() if e.task is not None]
        raise ValueError(f"unknown spatial task {task!r}; known: {', '.join(known)}")
    return SINGLE_TASKS[task]


def rollout_frames(task: str, scripted_episodes: int = 10, random_episodes: int = 10, seed: int = 10_000,
                   every: int = 2, image_size: int = 64, progress: bool = True, distractors: tuple = ()) -> EvalFrames:
    """Frames every ``every`` steps (and the reset frame) of scripted and random episodes.

    Episode seeds are ``seed + i``; scripted and random episodes use different seeds.
    ``distractors``: colours of more objects in the scene, which the goal does not name.
    """
    from tqdm import tqdm

    if scripted_episodes < 0 or random_episodes < 0 or scripted_episodes + random_episodes == 0:
        raise ValueError("need at least one episode (scripted or random)")
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    entry = _entry(task)
    camera = task_camera(task)
    objects = entry.task.objects + tuple(distractors) if distractors else None
    env = make_env(task, cameras=(camera,), image_size=image_size, objects=objects)
    images, success, source, episodes, steps = [], [], [], [], []
    plan = [("scripted", seed + i) for i in range(scripted_episodes)]
    plan += [("random", seed + scripted_episodes + i) for i in range(random_episodes)]
    try:
        desc = f"eval frames {task}" + (f" + {', '.join(distractors)}" if distractors else "")
        for kind, ep_seed in tqdm(plan, desc=desc, unit="episode", disable=not progress):
            for t, obs, info, done in episode_steps(env, POLICIES[kind], ep_seed):
                if not done and t % every == 0:  # the frames an agent acts on: not the final one
                    images.append(obs[camera])
                    success.append(bool(info["is_success"]))
                    source.append(kind)
                    episodes.append(ep_seed)
                    steps.append(t)
    finally:
        env.close()
    return EvalFrames(task, entry.goal, camera, np.stack(images), np.array(success), np.array(source),
                      np.array(episodes), np.array(steps))


def distractor_frames(task: str, scripted_episodes: int = 10, random_episodes: int = 10, seed: int = 10_000,
                      every: int = 2, progress: bool = True) -> EvalFrames:
    """The task's evaluation frames with one distractor of each colour the goal does not name
    (the same episodes per colour), as one set named ``<task>_distractor``."""
    from zsrm.tasks.language import COLOURS

    entry = _entry(task)
    others = [c for c in COLOURS if c not in entry.task.objects]
    parts = [rollout_frames(task, scripted_episodes, random_episodes, seed, every, progress=progress,
                            distractors=(colour,)) for colour in others]
    return EvalFrames.concat(f"{task}_distractor", parts)


def scene_data_frames(folder, goal, labels=None) -> EvalFrames:
    """An own scene's collected frames (``zsrm collect --scene``, then ``zsrm label``) that hold
    the goal's objects (the goal's scene, as training sees it), of the camera its relation is
    read on, each labelled by the scene's oracle: whether the goal's sentence is among the
    image's true-coordinate captions, which ``zsrm label`` writes for evaluation from the
    privileged positions along each role camera's own axes, as
    :class:`~zsrm.envs.scene_task.SceneTask` judges goals. ``goal``: a SceneGoal."""
    from zsrm.data.dataset import LABELS, ExplorationData

    data = ExplorationData(folder)
    if not data.scene_adapter:
        raise ValueError(f"{folder} holds data of zsrm's scenes; the frames of zsrm's tasks come from their "
                         "rollouts (zsrm eval-reward without --scene)")
    camera = RELATIONS[goal.relation].camera
    if camera not in data.cameras:
        raise ValueError(f"{folder} has no {camera} images, which {goal.text!r} is read on (collect with that role)")
    truth = np.array([goal.text in caps for caps in data.captions(labels or LABELS, oracle="world")])
    parts = [data.shard(name, [f"images_{camera}", "episode", "step", "present"]) for name in data.shards]
    images = np.concatenate([p[f"images_{camera}"] for p in parts])
    if len(images) != len(truth):
        raise ValueError(f"{folder}: {len(truth)} labelled images but {len(images)} collected: label every shard first")
    present = np.concatenate([p["present"] for p in parts])[:, [data.objects.index(o) for o in goal.objects]]
    keep = present.all(axis=1)
    if not keep.any():
        raise ValueError(f"no image of {folder} holds {', '.join(goal.objects)}: collect scenes with them")
    return EvalFrames(goal.text, goal.text, camera, images[keep], truth[keep], np.full(int(keep.sum()), "random"),
                      np.concatenate([p["episode"] for p in parts])[keep], np.concatenate([p["step"] for p in parts])[keep])


def reward_metrics(binary, raw, margin, truth) -> dict:
    out = binary_metrics(np.asarray(binary) > 0.5, truth)
    out.update(auroc=auroc(raw, truth), auroc_margin=auroc(margin, truth),
               f1_best_threshold=best_threshold_f1(raw, truth))
    return out


def score_frames(reward, frames: EvalFrames) -> dict[str, np.ndarray]:
    """Binary, raw and margin outputs of a :class:`~zsrm.rewards.binarised.ZSRMReward` on the frames."""
    return reward.outputs(frames.images, frames.goal)


def evaluate_rewards(models: dict, frames_by_task: dict[str, EvalFrames], raw_scores: dict | None = None) -> dict:
    """``models``: name -> ZSRMReward. Returns name -> task -> metrics (plus frame counts).

    ``raw_scores``: name -> callable(EvalFrames) -> (N,) scores that replace a model's own raw
    score (the cosine with the goal text) for AUROC and ``f1_best_threshold``; e.g. the base
    reward of :mod:`zsrm.rewards.base` in its own mode.
    """
    raw_scores = raw_scores or {}
    out: dict[str, dict] = {name: {} for name in models}
    for task, frames in frames_by_task.items():
        truth = frames.success
        for name, reward in models.items():
            s = score_frames(reward, frames)
            raw = raw_scores[name](frames) if name in raw_scores else s["raw"]
            m = reward_metrics(s["binary"], raw, s["margin"], truth)
            m.update(frames=int(len(frames)), positives=int(truth.sum()),
                     f1_scripted=binary_metrics(s["binary"][frames.source == "scripted"] > 0.5,
                                                truth[frames.source == "scripted"])["f1"],
                     false_positive_rate_random=float((s["binary"][(frames.source == "random") & ~truth] > 0.5).mean())
                     if ((frames.source == "random") & ~truth).any() else float("nan"))
            out[name][task] = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in m.items()}
    return out


def write_curves(task: str, models: dict, folder, steps: int = 80, seed: int = 0, image_size: int = 64) -> tuple:
    """Reward along a scripted trajectory of ``task`` (the paper's Figure 5) for every model:
    ``FOLDER/<task>.csv`` and ``FOLDER/<task>.png``."""
    from pathlib import Path

    from zsrm.evaluation.curves import plot_curve, record_trajectory, reward_curve, write_csv

    entry = _entry(task)
    camera = task_camera(task)
    traj = record_trajectory(entry.goal, cameras=(camera,), steps=steps, seed=seed, image_size=image_size)
    rows = reward_curve(traj, models)
    folder = Path(folder)
    csv_path = write_csv(rows, folder / f"{task}.csv")
    png_path = plot_curve(rows, traj, folder / f"{task}.png", camera=camera,
                          title=f"{task}: {entry.goal!r} ({camera} camera, scripted, seed {seed}); "
                                "green: the oracle says the goal holds")
    return csv_path, png_path, rows
