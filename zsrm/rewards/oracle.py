"""The oracle reward: the scene's true-state verdict, ``info["oracle_reward"]``.

Privileged (it reads the true state through ``info``): for baselines and evaluation only,
never a zero-shot reward.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from zsrm.rewards.interface import RewardModel


class OracleReward(RewardModel):
    """Reads ``info[key]`` of each env (default ``"oracle_reward"``); ignores images and goal.

    >>> OracleReward()(None, "a yellow block on top of a red block",
    ...                [{"oracle_reward": 1.0}, {"oracle_reward": 0.0}])
    array([1., 0.], dtype=float32)
    """

    name = "oracle"
    camera = None

    def __init__(self, key: str = "oracle_reward"):
        self.key = key

    def compute(self, observations: Mapping[str, np.ndarray] | None, goal: str,
                infos: Sequence[dict] | None) -> np.ndarray:
        if infos is None:
            raise ValueError("the oracle reward reads info dicts; pass infos")
        missing = [i for i, info in enumerate(infos) if self.key not in info]
        if missing:
            raise ValueError(f"info of env(s) {missing} has no {self.key!r}: is this a zsrm scene?")
        return np.array([float(info[self.key]) for info in infos], dtype=np.float32)
