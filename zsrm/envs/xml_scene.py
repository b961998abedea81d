"""A gymnasium env made from nothing but a MuJoCo XML: what a :class:`zsrm.envs.SceneAdapter`
builds when it gives ``xml`` and no ``env_id``.

Observations are the asked cameras' images (a dict by camera name); actions set the model's
actuator controls directly, within their ``ctrlrange`` ([-1, 1] for an actuator without one);
the reward is always 0 and nothing ends an episode but a time limit. A reset restores the
model's first keyframe (or its default pose) and moves every free body's x and y by up to
``jitter`` metres, so that exploration scenes differ; then the scene settles for a few steps.

>>> from pathlib import Path
>>> xml = Path(__file__).with_name("assets") / "pushing.xml"
>>> env = XmlSceneEnv(xml, cameras=("front",), image_size=32)
>>> obs, info = env.reset(seed=0)
>>> obs["front"].shape, info
((32, 32, 3), {})
"""
from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym
import mujoco
import numpy as np

SETTLE_STEPS = 5


class XmlSceneEnv(gym.Env):
    """Pixels of a MuJoCo XML's cameras in, actuator controls out."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 12}

    def __init__(self, xml: str | Path, cameras, image_size: int = 64, frame_skip: int = 10, jitter: float = 0.0,
                 render_mode: str | None = None):
        self.model = mujoco.MjModel.from_xml_path(str(xml))
        self.data = mujoco.MjData(self.model)
        names = [self.model.camera(i).name for i in range(self.model.ncam)]
        self.cameras = tuple(cameras)
        for cam in self.cameras:
            if cam not in names:
                raise ValueError(f"{xml} has no camera {cam!r}; its cameras: {', '.join(names) or 'none'}")
        self.image_size, self.frame_skip, self.jitter = int(image_size), int(frame_skip), float(jitter)
        self.render_mode = render_mode
        self.observation_space = gym.spaces.Dict(
            {c: gym.spaces.Box(0, 255, (self.image_size, self.image_size, 3), np.uint8) for c in self.cameras})
        limited = self.model.actuator_ctrllimited.astype(bool)
        low = np.where(limited, self.model.actuator_ctrlrange[:, 0], -1.0).astype(np.float32)
        high = np.where(limited, self.model.actuator_ctrlrange[:, 1], 1.0).astype(np.float32)
        self.action_space = gym.spaces.Box(low, high, dtype=np.float32)
        self._renderer = None

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if self.model.nkey:
            mujoco.mj_resetDataKeyframe(self.model, self.data, 0)
        else:
            mujoco.mj_resetData(self.model, self.data)
        free = np.flatnonzero(self.model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
        for j in free:  # every free body's x and y, by up to jitter
            adr = self.model.jnt_qposadr[j]
            self.data.qpos[adr:adr + 2] += self.np_random.uniform(-self.jitter, self.jitter, 2)
        mujoco.mj_forward(self.model, self.data)
        for _ in range(SETTLE_STEPS):
            mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        return self._observation(), {}

    def step(self, action):
        self.data.ctrl[:] = np.clip(np.asarray(action, np.float64), self.action_space.low, self.action_space.high)
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        return self._observation(), 0.0, False, False, {}

    def _render(self, camera: str) -> np.ndarray:
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.image_size, self.image_size)
        self._renderer.update_scene(self.data, camera=camera)
        return self._renderer.render().copy()

    def _observation(self) -> dict[str, np.ndarray]:
        return {c: self._render(c) for c in self.cameras}

    def render(self):
        return self._render(self.cameras[0])

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
