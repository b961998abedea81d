"""Wrappers that replace an env's reward by a :class:`~zsrm.rewards.interface.RewardModel`'s.

* :class:`ZeroShotReward`: a gymnasium wrapper for one env.
* :class:`VecZeroShotReward`: a stable-baselines3 ``VecEnvWrapper`` that scores all envs of a
  step in one batched call (the fast way for PPO with many envs).

Both compute the goal's text embedding once (at construction), leave ``info["oracle_reward"]``
and ``info["is_success"]`` as the scene wrote them, and add the reward they return as
``info["zsrm_reward"]``. Observations pass through unchanged.
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from zsrm.rewards.interface import RewardModel, check_goal

INFO_KEY = "zsrm_reward"


def _check_setup(observation_space, reward_model, goal) -> str:
    if not isinstance(reward_model, RewardModel):
        raise TypeError(f"reward_model must be a zsrm RewardModel, got {type(reward_model).__name__}")
    if not isinstance(observation_space, gym.spaces.Dict):
        raise ValueError(f"zsrm reward wrappers need Dict image observations (camera -> image), "
                         f"got {type(observation_space).__name__}")
    cam = reward_model.camera
    if cam is not None and cam not in observation_space.spaces:
        raise ValueError(f"the {reward_model.name} reward reads camera {cam!r}, but the env observes "
                         f"{', '.join(observation_space.spaces)}; make the env with cameras=({cam!r}, ...)")
    goal = check_goal(goal)
    reward_model.prepare(goal)  # the goal's text embedding, computed once here
    return goal


class ZeroShotReward(gym.Wrapper):
    """Reward from a goal sentence: ``step`` returns ``reward_model(obs, goal, info)``.

    >>> import gymnasium as gym, zsrm.envs
    >>> from zsrm.rewards import OracleReward, ZeroShotReward
    >>> env = gym.make("zsrm/Pushing-v0", task="a yellow puck close to a blue puck")
    >>> env = ZeroShotReward(env, OracleReward(), goal="a yellow puck close to a blue puck")
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> reward == info["zsrm_reward"] == info["oracle_reward"]
    True

    Any reward model works the same way, e.g. the base reward of the paper::

        from zsrm.rewards import BaseReward
        from zsrm.vlm import load_vlm
        env = ZeroShotReward(env, BaseReward(load_vlm("scene"), camera="front"), goal)
    """

    def __init__(self, env: gym.Env, reward_model: RewardModel, goal: str, info_key: str = INFO_KEY):
        super().__init__(env)
        self.goal = _check_setup(env.observation_space, reward_model, goal)
        self.reward_model = reward_model
        self.info_key = info_key

    def step(self, action):
        obs, _, terminated, truncated, info = self.env.step(action)
        batch = {k: np.asarray(v)[None] for k, v in obs.items()}
        reward = float(self.reward_model(batch, self.goal, [info])[0])
        info[self.info_key] = reward
        return obs, reward, terminated, truncated, info


class VecZeroShotReward(VecEnvWrapper):
    """Reward from a goal sentence for all envs of a VecEnv, in one batched call per step.

    SB3 VecEnvs reset an env as soon as it is done, so the observation they return for it is
    the next episode's first; the reward of the last transition is computed on
    ``info["terminal_observation"]`` instead.

    >>> import gymnasium as gym, zsrm.envs
    >>> from stable_baselines3.common.env_util import make_vec_env
    >>> from zsrm.rewards import OracleReward, VecZeroShotReward
    >>> goal = "a yellow puck close to a blue puck"
    >>> venv = make_vec_env("zsrm/Pushing-v0", n_envs=2, env_kwargs={"task": goal})
    >>> venv = VecZeroShotReward(venv, OracleReward(), goal)
    >>> obs = venv.reset()
    >>> obs, rewards, dones, infos = venv.step(np.zeros((2, 2), np.float32))
    >>> rewards.shape, rewards.dtype
    ((2,), dtype('float32'))

    With PPO from pixels (PPO wraps this VecEnv in its own image transposition)::

        from stable_baselines3 import PPO
        venv = VecZeroShotReward(venv, BaseReward(load_vlm("scene"), camera="front"), goal)
        PPO("MultiInputPolicy", venv).learn(200_000)
    """

    def __init__(self, venv: VecEnv, reward_model: RewardModel, goal: str, info_key: str = INFO_KEY):
        super().__init__(venv)
        self.goal = _check_setup(venv.observation_space, reward_model, goal)
        self.reward_model = reward_model
        self.info_key = info_key

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, _, dones, infos = self.venv.step_wait()
        batch = dict(obs)
        done_idx = np.flatnonzero(dones)
        if len(done_idx):
            # Copy before writing: obs must stay the reset observations for the agent.
            batch = {k: np.array(v) for k, v in obs.items()}
            for i in done_idx:
                terminal = infos[i].get("terminal_observation")
                if terminal is None:
                    raise RuntimeError(f"env {i} is done but its info has no 'terminal_observation'")
                for k in batch:
                    batch[k][i] = terminal[k]
        rewards = self.reward_model(batch, self.goal, infos)
        for info, r in zip(infos, rewards):
            info[self.info_key] = float(r)
        return obs, rewards.astype(np.float32), dones, infos
