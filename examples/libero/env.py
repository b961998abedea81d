"""A LIBERO task as a gymnasium env zsrm can read: robosuite's wrapper of
:mod:`examples.robosuite.env` on LIBERO's own scene (its BDDL file, its fixtures and its 50
shipped initial states), written as a user would, outside zsrm. Runs in ``.venv-bench``.

* Cameras added for Table 1's roles, looking at where LIBERO-Spatial puts its objects (its
  own cameras frame the whole kitchen: a bowl is 3 px at 64 px; the cabinet hides the table
  from a camera on the left at table height, so the left one looks down over it).
* Rendered without shadows, reflections or skybox: 4.9 -> 11.9 renders/s at 64 px on one
  core (726k mesh vertices and 4096 px textures on a software renderer).
* Exploration: one of the task's shipped initial states, then zsrm's layout (held objects
  dropped anywhere on the objects' area, with ``p_stack`` one dropped onto another), settled.
"""
from __future__ import annotations

import os

import numpy as np

from examples.robosuite.env import RobosuiteTableEnv, _robosuite

LIBERO_CAMERAS = {
    "libero_front": 'pos="0.32 0.1 1.0" xyaxes="0 1 0 -0.174 0 0.985" fovy="55"',  # 10 degrees down
    "libero_left": 'pos="-0.05 -0.3 1.45" xyaxes="1 0 0 0 0.766 0.643" fovy="45"',  # 50 degrees down, over the cabinet
    "libero_tilted": 'pos="0.4 0.1 1.4" xyaxes="0 1 0 -0.707 0 0.707" fovy="45"',  # 45 degrees down
}
LIBERO_XY = ((-0.2, 0.12), (-0.08, 0.3))  # where LIBERO-Spatial's objects lie (its initial states)


class LiberoTableEnv(RobosuiteTableEnv):
    """``task``: (suite, task index), e.g. ``("libero_spatial", 0)``; objects by LIBERO's names."""

    camera_xml = LIBERO_CAMERAS
    table_xy = LIBERO_XY
    reset_settle_steps = 150  # objects dropped from 5 cm come to rest (0.3 s)

    def __init__(self, task=("libero_spatial", 0), objects=(), all_objects=(), cameras=tuple(LIBERO_CAMERAS),
                 image_size: int = 64, p_stack: float = 0.25, task_layout: bool = False, plain_render: bool = True,
                 control_freq: int = 20):
        super().__init__(task, objects, all_objects, cameras, image_size, p_stack, task_layout, plain_render,
                         control_freq)

    def make_robosuite(self, task, control_freq: int, **kwargs):
        _robosuite()
        from libero.libero import get_libero_path
        from libero.libero.envs import OffScreenRenderEnv

        bench, t = libero_task(task)
        self.init_states = bench.get_task_init_states(task[1])
        self.language = t.language
        self.wrapper = OffScreenRenderEnv(
            bddl_file_name=os.path.join(get_libero_path("bddl_files"), t.problem_folder, t.bddl_file),
            has_offscreen_renderer=False, use_camera_obs=False, camera_heights=64, camera_widths=64,
            control_freq=control_freq, hard_reset=False, horizon=10**9)
        return self.wrapper.env

    def object(self, name: str):
        return self.rs.objects_dict[name]

    def _layout(self, rng: np.random.Generator) -> None:
        self.rs.sim.set_state_from_flattened(self.init_states[int(rng.integers(len(self.init_states)))])
        self.rs.sim.forward()
        top = self.rs.table_offset[2] + 0.1  # drop height: above every object's origin at rest
        spots = {o: np.array([rng.uniform(*self.table_xy[0]), rng.uniform(*self.table_xy[1]), top]) for o in self.held}
        if len(self.held) >= 2 and rng.random() < self.p_stack:
            upper, lower = (self.held[i] for i in rng.choice(len(self.held), 2, replace=False))
            spots[upper] = spots[lower] + np.array([*rng.uniform(-0.01, 0.01, 2), 0.07])
        for obj, xyz in spots.items():
            self._place(obj, xyz)

    def close(self):
        self.renderer.close()
        self.wrapper.close()


def libero_task(task):
    """LIBERO's benchmark and task record of ``task`` = (suite, index): its BDDL file, its
    instruction (``language``); read without building an env."""
    _robosuite()
    from libero.libero import benchmark

    suite, index = task
    bench = benchmark.get_benchmark_dict()[suite]()
    return bench, bench.get_task(index)
