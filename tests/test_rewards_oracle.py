"""The oracle reward reads the scene's true-state verdict from info."""
import gymnasium as gym
import numpy as np
import pytest

import zsrm.envs  # noqa: F401
from zsrm.rewards import OracleReward


def test_reads_oracle_reward_from_infos():
    r = OracleReward()(None, "a red block on top of a blue block", [{"oracle_reward": 1.0}, {"oracle_reward": 0}])
    np.testing.assert_array_equal(r, [1.0, 0.0])
    assert r.dtype == np.float32
    assert OracleReward.camera is None


def test_matches_the_scene_oracle():
    env = gym.make("zsrm/Pushing-v0", task="a yellow puck close to a blue puck", image_size=32)
    obs, info = env.reset(seed=0)
    batch = {k: v[None] for k, v in obs.items()}
    assert OracleReward()(batch, "a yellow puck close to a blue puck", [info])[0] == info["oracle_reward"]


def test_bad_input():
    with pytest.raises(ValueError, match="pass infos"):
        OracleReward()({"front": np.zeros((1, 8, 8, 3), np.uint8)}, "a goal")
    with pytest.raises(ValueError, match="no 'oracle_reward'"):
        OracleReward()(None, "a goal", [{"oracle_reward": 1.0}, {}])
    with pytest.raises(ValueError, match="non-empty sentence"):
        OracleReward()(None, "", [{"oracle_reward": 1.0}])
