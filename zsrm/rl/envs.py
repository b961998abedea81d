"""Vectorised envs for training and evaluation: the goal's scene, seen through the camera its
relation is read on, with the reward (oracle or zsrm) in one batched call per step.

The double pendulum (goal ``pendulum``, Figure 4) is one of them: its one camera (front), no
start spread, episodes capped at 100 control steps like the other scenes (the env ends one
earlier when the pendulum falls; gymnasium's own cap of 1000 never comes).

A user's own scene (``cfg.scene``, a :class:`zsrm.envs.SceneAdapter`) is made by its adapter and
wrapped in :class:`zsrm.envs.scene_task.SceneTask` (the goal's role camera, the action repeat, the
oracle in ``info``), so that the user's env needs no change."""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

import zsrm.envs  # noqa: F401  (registers the scenes)
from zsrm.rl.config import TrainConfig
from zsrm.rl.goals import goal_camera, is_pendulum, scene_goal, task_entry
from zsrm.tasks.catalogue import PENDULUM_ID, PUSHING_ID, TABLETOP_ID, choice_colour

EPISODE_STEPS = 100


def make_vec(cfg: TrainConfig, n_envs: int, seed: int, spread: str = "seen",
             distractors: tuple[str, ...] = (), workers: int = 1, training: bool = False) -> VecEnv:
    """``n_envs`` scenes of the goal, seeded ``seed, seed + 1, ...``, in this process or split over
    ``workers`` processes (:class:`~zsrm.rl.workers.WorkerVecEnv`: the same numbers); with
    ``distractors``, colours the goal does not name are in the scene too (at the back of the
    table; with ``cfg.choice``, the one distractor in line, :func:`choice_colour`'s by default).
    ``training`` envs start as ``cfg.near_start`` says (a curriculum); evaluation's never do."""
    if cfg.scene:
        return make_scene_vec(cfg, n_envs, seed, spread, distractors, workers)
    entry = task_entry(cfg.goal)
    # the front camera for the corrected reward's labeler alone (the policy and the reward read the goal's)
    labels_front = cfg.zsrm_correct_front or cfg.zsrm_correct_height
    front = ("front",) if training and labels_front and goal_camera(cfg.goal) != "front" else ()
    kwargs = dict(task=entry.goal, cameras=(goal_camera(cfg.goal), *front), image_size=cfg.image_size,
                  action_repeat=cfg.action_repeat)
    if cfg.choice:
        distractors = tuple(distractors) or (choice_colour(entry.task),)
        kwargs["distractor_place"] = "line"
    if distractors:
        kwargs["objects"] = tuple(distractors)
    if entry.env_id == PENDULUM_ID:
        if spread != "seen":
            raise ValueError(f"the pendulum has no start spread to widen (got {spread!r}); it starts as "
                             "gymnasium's does")
    else:
        kwargs["spread"] = spread
    if cfg.start != "above":
        if entry.env_id != TABLETOP_ID:
            raise ValueError(f"start {cfg.start!r} is for the tabletop's blocks; {cfg.goal!r} is not a tabletop task")
        kwargs["start"] = cfg.start
    if cfg.lift_ceiling:
        if entry.env_id != TABLETOP_ID:
            raise ValueError(f"lift_ceiling is for the tabletop's gripper; {cfg.goal!r} is not a tabletop task")
        kwargs["lift_ceiling"] = cfg.lift_ceiling
    if cfg.near_start:  # checked for evaluation's envs too: a run's config is wrong whichever env reads it
        if entry.env_id != PUSHING_ID:
            raise ValueError(f"near_start is for the pushing scene's pucks; {cfg.goal!r} is not a pushing task")
        if training:
            kwargs["near_start"] = cfg.near_start
    decisions = EPISODE_STEPS // cfg.action_repeat
    return vec_of([lambda: gym.make(entry.env_id, max_episode_steps=decisions, **kwargs)] * n_envs, seed, workers)


def vec_of(env_fns: list, seed: int, workers: int = 1) -> VecEnv:
    """A DummyVecEnv of ``env_fns`` (a WorkerVecEnv with ``workers`` > 1), seeded from ``seed``."""
    if workers > 1:
        from zsrm.rl.workers import WorkerVecEnv

        venv = WorkerVecEnv(env_fns, workers)
    else:
        venv = DummyVecEnv(env_fns)
    venv.seed(seed)
    return venv


def make_scene_vec(cfg: TrainConfig, n_envs: int, seed: int, spread: str = "seen",
                   distractors: tuple[str, ...] = (), workers: int = 1) -> VecEnv:
    """:func:`make_vec` on a user's own scene: its adapter's task env (``task_env_kwargs``)
    observing the goal's role camera and holding the goal's objects (all of them where the env
    cannot hold fewer), as zsrm's own task scenes do, laid out by the env's own reset."""
    from zsrm.envs.adapter import check_env, load_adapter
    from zsrm.envs.scene_task import SceneTask

    if spread != "seen":
        raise ValueError(f"spread {spread!r}: your own scene ({cfg.scene}) starts as its env does, with no spread "
                         "to widen")
    if distractors:
        raise ValueError(f"your own scene ({cfg.scene}) holds the objects its env holds; it takes no distractors")
    adapter, goal = load_adapter(cfg.scene), scene_goal(cfg.goal, cfg.scene)
    role = goal_camera(cfg.goal, cfg.scene)

    def make():
        env = check_env(adapter, adapter.make_env((adapter.roles[role],), cfg.image_size, goal.objects, task=True),
                        roles=(role,))
        return gym.wrappers.TimeLimit(SceneTask(env, adapter, goal, cfg.action_repeat),
                                      max_episode_steps=EPISODE_STEPS // cfg.action_repeat)

    return vec_of([make] * n_envs, seed, workers)


def make_reward(cfg: TrainConfig, run_folder=None):
    """The RewardModel that ``cfg.reward`` names: oracle, zsrm, base (the VLM ``cfg.vlm``'s cosine
    of the frame and the goal, paper 2.1; for the pendulum binarised: 1 when the goal beats the
    other poses' sentences, :data:`zsrm.tasks.pendulum.NEGATIVES`) or vice (a goal classifier
    fitted on true goal images, kept in ``run_folder/vice``); None for the rewards that are not a
    RewardModel (random, curiosity). The zsrm reward with ``cfg.zsrm_correct_every`` keeps its
    labeler and latest model in ``run_folder`` too (:mod:`zsrm.rl.corrected`)."""
    from zsrm.rewards import BaseReward, OracleReward, ZSRMReward

    if cfg.reward == "oracle":
        return OracleReward()
    if cfg.reward == "zsrm":
        from zsrm.envs.adapter import load_adapter
        from zsrm.fullmodel import load_reward_backbone

        if cfg.zsrm_correct_every:
            from zsrm.rl.corrected import corrected_reward

            if run_folder is None:
                raise ValueError("the corrected zsrm reward needs a run folder to keep its model and labeler in")
            return corrected_reward(cfg, run_folder)
        objects = load_adapter(cfg.scene).objects if cfg.scene else None
        return ZSRMReward(load_reward_backbone(cfg.reward_model), output=cfg.zsrm_output, objects=objects)
    if cfg.reward == "base":
        from zsrm.vlm import load_vlm

        if is_pendulum(cfg.goal, cfg.scene):
            from zsrm.tasks.pendulum import NEGATIVES

            return BaseReward(load_vlm(cfg.vlm), camera="front", mode="binary", negatives=NEGATIVES)
        return BaseReward(load_vlm(cfg.vlm), camera=goal_camera(cfg.goal, cfg.scene), mode="cosine")
    if cfg.reward == "vice":
        from zsrm.rl.vice import vice_reward

        if run_folder is None:
            raise ValueError("the vice reward needs a run folder to keep its goal classifier in")
        return vice_reward(cfg, Path(run_folder) / "vice")
    return None
