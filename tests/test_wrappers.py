"""Reward wrappers: single env, batched VecEnv, terminal observations, SB3 PPO."""
import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

import zsrm.envs  # noqa: F401  (registers the scenes)
from zsrm.rewards import BaseReward, OracleReward, VecZeroShotReward, ZeroShotReward

GOAL = "a yellow puck close to a blue puck"
RED, BLUE = (255, 0, 0), (0, 0, 255)


@pytest.fixture
def one_torch_thread():
    """PPO's tiny CNN at 36 px runs many times faster on one thread than on two busy cores."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


class ColourEnv(gym.Env):
    """Frames are blue, except the last frame of an episode, which is red; info says which."""

    def __init__(self, length=3, size=8):
        self.length, self.size = length, size
        self.observation_space = gym.spaces.Dict({"front": gym.spaces.Box(0, 255, (size, size, 3), np.uint8)})
        self.action_space = gym.spaces.Discrete(2)

    def _frame(self, colour):
        return {"front": np.full((self.size, self.size, 3), colour, np.uint8)}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self._frame(BLUE), {"oracle_reward": 0.0, "is_success": False}

    def step(self, action):
        self.t += 1
        last = self.t == self.length
        info = {"oracle_reward": float(last), "is_success": last}
        return self._frame(RED if last else BLUE), 0.0, last, False, info


def test_single_env_wrapper(toy_vlm):
    env = ZeroShotReward(ColourEnv(), BaseReward(toy_vlm, mode="cosine"), goal="a red block")
    env.reset(seed=0)
    rewards, infos = [], []
    for _ in range(3):
        _, r, term, trunc, info = env.step(0)
        rewards.append(r)
        infos.append(info)
    assert rewards[2] > 0.9 > rewards[0]  # the red last frame matches "red"
    assert [i["zsrm_reward"] for i in infos] == rewards
    assert [i["oracle_reward"] for i in infos] == [0.0, 0.0, 1.0]
    assert [i["is_success"] for i in infos] == [False, False, True]
    assert toy_vlm.text_calls == 1  # the goal's embedding, at construction


def test_vec_wrapper_uses_the_terminal_observation(toy_vlm):
    # Episodes of 2 and 3 steps, so the envs finish at different steps.
    venv = DummyVecEnv([lambda: ColourEnv(length=2), lambda: ColourEnv(length=3)])
    venv = VecZeroShotReward(venv, BaseReward(toy_vlm, mode="cosine"), goal="a red block")
    venv.reset()
    dones_seen, rewards_seen = [], []
    for _ in range(6):
        obs, rewards, dones, infos = venv.step(np.zeros(2, int))
        dones_seen.append(dones.copy())
        rewards_seen.append(rewards.copy())
        # The agent still gets the reset (blue) frame of a finished env ...
        assert np.all(obs["front"][..., 2] == 255)
        for i in np.flatnonzero(dones):
            assert infos[i]["terminal_observation"]["front"][0, 0, 0] == 255  # ... the red one stays in info
        np.testing.assert_allclose(rewards, [info["zsrm_reward"] for info in infos])
    dones_seen, rewards_seen = np.array(dones_seen), np.array(rewards_seen)
    # ... and the reward at done is the red terminal frame's, elsewhere the blue frames'.
    assert np.all(rewards_seen[dones_seen] > 0.9)
    assert np.all(rewards_seen[~dones_seen] < 0.2)
    assert dones_seen[:, 0].sum() == 3 and dones_seen[:, 1].sum() == 2


def test_vec_wrapper_batches_and_caches(toy_vlm):
    venv = DummyVecEnv([ColourEnv] * 4)
    venv = VecZeroShotReward(venv, BaseReward(toy_vlm, mode="cosine"), goal="a red block")
    venv.reset()
    for _ in range(5):
        venv.step(np.zeros(4, int))
    assert toy_vlm.image_calls == 5  # one image forward per step for all 4 envs
    assert toy_vlm.text_calls == 1  # one text forward, ever


def test_single_and_vec_wrappers_agree(toy_vlm):
    model = BaseReward(toy_vlm, mode="dot")
    single = ZeroShotReward(ColourEnv(length=3), model, "a red block")
    single.reset(seed=0)
    venv = VecZeroShotReward(DummyVecEnv([lambda: ColourEnv(length=3)]), model, "a red block")
    venv.reset()
    for _ in range(7):
        _, r, term, trunc, _ = single.step(0)
        if term or trunc:
            single.reset()
        _, vr, _, _ = venv.step(np.zeros(1, int))
        assert vr[0] == pytest.approx(r, abs=1e-6)


def test_oracle_through_the_vec_wrapper_on_a_scene():
    venv = make_vec_env("zsrm/Pushing-v0", n_envs=2, env_kwargs={"task": GOAL, "image_size": 32,
                                                                "max_episode_steps": 3})
    venv = VecZeroShotReward(venv, OracleReward(), GOAL)
    venv.reset()
    all_dones = []
    for _ in range(4):
        _, rewards, dones, infos = venv.step(np.zeros((2, 2), np.float32))
        assert rewards.tolist() == [info["oracle_reward"] for info in infos]
        assert all("is_success" in info for info in infos)
        all_dones.append(dones.tolist())
    assert all_dones == [[False, False], [False, False], [True, True], [False, False]]  # 3-step episodes


def test_bad_setup(toy_vlm):
    with pytest.raises(ValueError, match="non-empty sentence"):
        ZeroShotReward(ColourEnv(), BaseReward(toy_vlm), goal=" ")
    with pytest.raises(ValueError, match="camera 'tilted'"):
        ZeroShotReward(ColourEnv(), BaseReward(toy_vlm, camera="tilted"), goal="red")
    with pytest.raises(TypeError, match="RewardModel"):
        ZeroShotReward(ColourEnv(), lambda obs, goal, infos: 0.0, goal="red")
    box_env = gym.make("CartPole-v1")
    with pytest.raises(ValueError, match="Dict image observations"):
        ZeroShotReward(box_env, OracleReward(), goal="balance the pole")


class _RecordRewards(BaseCallback):
    """Checks, at every step of PPO's rollouts, that the rewards PPO stores are the wrapper's."""

    def _on_step(self) -> bool:
        infos, rewards = self.locals["infos"], self.locals["rewards"]
        assert all("oracle_reward" in i and "is_success" in i for i in infos)
        np.testing.assert_allclose(rewards, [i["zsrm_reward"] for i in infos], atol=1e-6)
        return True


def test_ppo_learns_from_the_vec_wrapper(toy_vlm, one_torch_thread):
    # 36 px: the smallest image NatureCNN (SB3's default image extractor) accepts.
    venv = make_vec_env("zsrm/Pushing-v0", n_envs=2, seed=0, env_kwargs={"task": GOAL, "image_size": 36})
    venv = VecZeroShotReward(venv, BaseReward(toy_vlm, camera="front", mode="cosine"), GOAL)
    model = PPO("MultiInputPolicy", venv, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=256, callback=_RecordRewards())
    assert model.num_timesteps >= 256
    rewards = model.rollout_buffer.rewards
    # The scene's own reward is always 0: non-zero rewards come from the wrapper.
    # (SB3 adds gamma * V(terminal obs) to the reward at time-limit truncations.)
    assert np.all(rewards != 0)
    assert toy_vlm.text_calls == 1


def test_ppo_with_the_single_env_wrapper(toy_vlm, one_torch_thread):
    env = ZeroShotReward(gym.make("zsrm/Pushing-v0", task=GOAL, image_size=36),
                         BaseReward(toy_vlm, camera="front", mode="dot"), GOAL)
    check_env(env, warn=False)
    model = PPO("MultiInputPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=64, callback=_RecordRewards())
    assert np.all(model.rollout_buffer.rewards > 0)
