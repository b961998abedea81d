"""The VICE baseline's training frames: true goal images from scripted rollouts (privileged).

Scripted controllers (true state) reach the goal; every frame is labelled by the oracle, so
the goal frames are the positives and all the others (approach, random play) the negatives.
The classifier (:mod:`zsrm.rewards.vice`) is fitted once per run and kept in the run folder;
by default it keeps learning from the policy's frames, labelled by the oracle too.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from zsrm.envs.rollout import episode_steps, make_env, random_policy
from zsrm.envs.scripted import scripted_controller
from zsrm.rewards.vice import GoalClassifier, OnlineVICEReward, VICEReward, fit_goal_classifier
from zsrm.rl.config import TrainConfig
from zsrm.rl.goals import goal_camera, task_entry

VICE_SEED = 500_000  # scripted and random rollouts for the classifier: seeds apart from training and evaluation


def goal_frames(cfg: TrainConfig, episodes: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Frames of the goal's camera from ``episodes`` scripted and as many random episodes, with
    the oracle's verdict on each (the positives are the true goal images)."""
    camera = goal_camera(cfg.goal)
    env = make_env(task_entry(cfg.goal).goal, cameras=(camera,), image_size=cfg.image_size)
    frames, labels = [], []
    for policy in (scripted_controller, random_policy):
        for episode in range(episodes):
            for t, obs, info, _ in episode_steps(env, policy, seed=VICE_SEED + cfg.seed * 1000 + episode):
                if t:
                    frames.append(obs[camera])
                    labels.append(bool(info["is_success"]))
    env.close()
    return np.stack(frames), np.array(labels)


def vice_reward(cfg: TrainConfig, folder: Path, episodes: int = 20) -> VICEReward:
    """The VICE reward for ``cfg.goal``: the classifier in ``folder`` if there is one, else fitted
    on fresh goal frames and saved there. With ``cfg.vice_update_every`` it keeps learning from the
    policy's frames (:class:`~zsrm.rewards.vice.OnlineVICEReward`), its latest state kept beside
    ``folder`` (``vice_online/``), where a resumed run picks it up."""
    folder, frames = Path(folder), None
    if (folder / "config.json").is_file():
        classifier = GoalClassifier.from_folder(folder)
    else:
        frames, labels = goal_frames(cfg, episodes)
        classifier = fit_goal_classifier(frames, labels, image_size=cfg.image_size, seed=cfg.seed)
        classifier.save(folder, meta={"goal": task_entry(cfg.goal).goal, "frames": int(len(frames)),
                                      "goal_frames": int(labels.sum()), "episodes": 2 * episodes})
    if not cfg.vice_update_every:
        return VICEReward(classifier, goal_camera(cfg.goal))
    if frames is None:  # a resumed run: the same frames again (seeded rollouts)
        frames, labels = goal_frames(cfg, episodes)
    latest = folder.with_name("vice_online")
    if (latest / "config.json").is_file():
        classifier = GoalClassifier.from_folder(latest)
    meta = {"goal": task_entry(cfg.goal).goal, "update_every_env_steps": cfg.vice_update_every,
            "oracle_labels": cfg.vice_oracle_labels}
    return OnlineVICEReward(classifier, goal_camera(cfg.goal), frames[labels], frames[~labels],
                            update_every=max(1, cfg.vice_update_every // cfg.action_repeat), seed=cfg.seed,
                            oracle_labels=cfg.vice_oracle_labels, on_update=lambda model: model.save(latest, meta=meta))
