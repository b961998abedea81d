"""Vectorised envs for training and evaluation: the goal's scene, seen through the camera its
relation is read on, with the reward (oracle or zsrm) in one batched call per step."""
from __future__ import annotations

import gymnasium as gym
from stable_baselines3.common.vec_env import DummyVecEnv

import zsrm.envs  # noqa: F401  (registers the scenes)
from zsrm.rl.config import TrainConfig
from zsrm.tasks.catalogue import PENDULUM_ID, TABLETOP_ID, CatalogueEntry, resolve
from zsrm.tasks.relations import RELATIONS

EPISODE_STEPS = 100


def task_entry(goal: str) -> CatalogueEntry:
    entry = resolve(goal)
    if entry.env_id == PENDULUM_ID:
        raise ValueError("zsrm train runs the spatial tasks; the pendulum has no relation to read")
    return entry


def goal_camera(goal: str) -> str:
    """The camera the goal's relation is read on (Table 1): front, left or tilted."""
    return RELATIONS[task_entry(goal).task.relation].camera


def make_vec(cfg: TrainConfig, n_envs: int, seed: int, spread: str = "seen") -> DummyVecEnv:
    """``n_envs`` scenes of the goal in one process, seeded ``seed, seed + 1, ...``."""
    entry = task_entry(cfg.goal)
    kwargs = dict(task=entry.goal, cameras=(goal_camera(cfg.goal),), image_size=cfg.image_size,
                  spread=spread, action_repeat=cfg.action_repeat)
    if cfg.start != "above":
        if entry.env_id != TABLETOP_ID:
            raise ValueError(f"start {cfg.start!r} is for the tabletop's blocks; {cfg.goal!r} is a pushing task")
        kwargs["start"] = cfg.start
    decisions = EPISODE_STEPS // cfg.action_repeat
    venv = DummyVecEnv([lambda: gym.make(entry.env_id, max_episode_steps=decisions, **kwargs)
                        for _ in range(n_envs)])
    venv.seed(seed)
    return venv


def make_reward(cfg: TrainConfig, folder=None):
    """The RewardModel that ``cfg.reward`` names: oracle, zsrm, base (the scene VLM's cosine of
    the frame and the goal, paper 2.1) or vice (a goal classifier fitted on true goal images,
    kept in ``folder``); None for the rewards that are not a RewardModel (random, curiosity)."""
    from zsrm.rewards import BaseReward, OracleReward, ZSRMReward

    if cfg.reward == "oracle":
        return OracleReward()
    if cfg.reward == "zsrm":
        from zsrm.fullmodel import load_reward_backbone

        return ZSRMReward(load_reward_backbone(cfg.reward_model), output=cfg.zsrm_output)
    if cfg.reward == "base":
        from zsrm.vlm import load_vlm

        return BaseReward(load_vlm(cfg.vlm), camera=goal_camera(cfg.goal), mode="cosine")
    if cfg.reward == "vice":
        from zsrm.rl.vice import vice_reward

        if folder is None:
            raise ValueError("the vice reward needs a folder to keep its goal classifier in")
        return vice_reward(cfg, folder)
    return None
