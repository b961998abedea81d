"""Gymnasium's InvertedDoublePendulum-v5, observed through rendered pixels only."""
from __future__ import annotations

import gymnasium as gym
import numpy as np

GOAL = "an inverted pendulum standing upright"


class DoublePendulumPixelEnv(gym.Env):
    """The double inverted pendulum with image observations ``{"front": HxWx3 uint8}``.

    The environment's own reward (alive bonus minus distance and velocity penalties) is the
    oracle: it goes to ``info["oracle_reward"]``, never to the agent; ``step`` returns 0.
    ``info["is_success"]`` is True while the pendulum has not fallen.

    ``action_repeat``: control steps (of gymnasium's 0.05 s) per ``step``, only the last one
    rendered; ``info["oracle_reward"]`` is then the sum of the env's rewards over them, and the
    step stops early when the pendulum falls.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, task=GOAL, image_size: int = 64, render_mode: str | None = None, cameras=("front",),
                 action_repeat: int = 1):
        if tuple([cameras] if isinstance(cameras, str) else cameras) != ("front",):
            raise ValueError("the double pendulum has one camera: 'front'")
        if not isinstance(image_size, (int, np.integer)) or not 16 <= image_size <= 512:
            raise ValueError(f"image_size must be an integer in [16, 512], got {image_size!r}")
        if not isinstance(action_repeat, (int, np.integer)) or action_repeat < 1:
            raise ValueError(f"action_repeat must be an integer >= 1, got {action_repeat!r}")
        self.action_repeat = int(action_repeat)
        self.goal = task
        self.cameras = ("front",)
        self.image_size = int(image_size)
        self.render_mode = render_mode
        # A fixed side view framing the rail and both poles (the default one is far away).
        camera = {"trackbodyid": -1, "distance": 2.8, "lookat": np.array([0.0, 0.0, 0.5]),
                  "elevation": 0.0, "azimuth": 90.0}
        self._env = gym.make("InvertedDoublePendulum-v5", render_mode="rgb_array", width=self.image_size,
                             height=self.image_size, default_camera_config=camera)
        self.action_space = self._env.action_space
        self.observation_space = gym.spaces.Dict(
            {"front": gym.spaces.Box(0, 255, (self.image_size, self.image_size, 3), np.uint8)}
        )

    def _obs(self):
        return {"front": np.ascontiguousarray(self._env.render())}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        state, info = self._env.reset(seed=seed, options=options)
        return self._obs(), {"state": state, "oracle_reward": 0.0, "is_success": True}

    def step(self, action):
        total = 0.0
        for _ in range(self.action_repeat):
            state, reward, terminated, truncated, _ = self._env.step(action)
            total += float(reward)
            if terminated or truncated:
                break
        info = {"state": state, "oracle_reward": total, "is_success": not terminated}
        return self._obs(), 0.0, terminated, truncated, info

    def render(self):
        return self._obs()["front"]

    def render_cameras(self, cameras=("front",), size=None):
        return self._obs()

    def close(self):
        self._env.close()
