"""Rewards from goal sentences and images, and the wrappers that give them to RL agents.

>>> from zsrm.rewards import BaseReward, OracleReward, ZSRMReward, ZeroShotReward, VecZeroShotReward
"""
from __future__ import annotations

import importlib

# Lazy: `zsrm` CLI start-up imports this package; torch and SB3 load only when used.
_EXPORTS = {
    "RewardModel": "zsrm.rewards.reward_model",
    "TextEmbeddingCache": "zsrm.rewards.reward_model",
    "check_goal": "zsrm.rewards.reward_model",
    "check_images": "zsrm.rewards.reward_model",
    "BaseReward": "zsrm.rewards.base",
    "projection_reward": "zsrm.rewards.base",
    "OracleReward": "zsrm.rewards.oracle",
    "ZSRMReward": "zsrm.rewards.zsrm",
    "ZeroShotReward": "zsrm.rewards.wrappers",
    "VecZeroShotReward": "zsrm.rewards.wrappers",
    "reward_curve": "zsrm.rewards.curve",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'zsrm.rewards' has no attribute {name!r}")
