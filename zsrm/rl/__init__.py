"""Reinforcement learning from a goal sentence: PPO (or SAC) from pixels with zsrm's rewards.

>>> from zsrm.rl import TrainConfig, train  # doctest: +SKIP
>>> train(TrainConfig(goal="stack", reward="zsrm", steps=300_000), "runs/rl/stack-zsrm-0")  # doctest: +SKIP
"""
from zsrm.rl.config import PRESETS, REWARDS, TrainConfig, preset

__all__ = ["PRESETS", "REWARDS", "TrainConfig", "preset", "train"]


def __getattr__(name):
    if name == "train":
        from zsrm.rl.learners import train

        return train
    raise AttributeError(f"module 'zsrm.rl' has no attribute {name!r}")
