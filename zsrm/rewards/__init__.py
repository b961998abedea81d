"""Rewards from goal sentences and images, and the wrappers that give them to RL agents.

>>> from zsrm.rewards import BaseReward, OracleReward, ZSRMReward, ZeroShotReward, VecZeroShotReward
"""
from __future__ import annotations

import importlib

# Lazy: torch and SB3 load only when a reward is used.
_EXPORTS = {
    "RewardModel": "zsrm.rewards.interface",
    "check_goal": "zsrm.rewards.interface",
    "check_images": "zsrm.rewards.interface",
    "TextEmbeddingCache": "zsrm.vlm.text_cache",
    "BaseReward": "zsrm.rewards.base",
    "projection_reward": "zsrm.rewards.base",
    "OracleReward": "zsrm.rewards.oracle",
    "ZSRMReward": "zsrm.rewards.binarised",
    "ZeroShotReward": "zsrm.rewards.wrappers",
    "VecZeroShotReward": "zsrm.rewards.wrappers",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'zsrm.rewards' has no attribute {name!r}")
