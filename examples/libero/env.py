"""A LIBERO task as a gymnasium env zsrm can read: robosuite's wrapper of
:mod:`examples.robosuite.env` on LIBERO's own scene (its BDDL file, its fixtures and its 50
shipped initial states), written as a user would, outside zsrm. Runs in ``.venv-bench``.

* Cameras added for Table 1's roles, looking at where LIBERO-Spatial puts its objects (its
  own cameras frame the whole kitchen: a bowl is 3 px at 64 px; the cabinet hides the table
  from a camera on the left at table height, so the left one looks down over it).
* Rendered without shadows, reflections or skybox: 4.9 -> 11.9 renders/s at 64 px on one
  core (726k mesh vertices and 4096 px textures on a software renderer).
* Exploration: one of the task's shipped initial states, then zsrm's layout (held objects
  dropped anywhere on the objects' area, 10 cm apart, with ``p_stack`` one dropped onto
  another), settled; drawn again while an object came to rest off the area (thrown onto the
  cabinet or the floor, where no camera sees it but its presence caption says it is there).
"""
from __future__ import annotations

import os

import numpy as np

from examples.robosuite.env import RobosuiteTableEnv, _robosuite

LIBERO_CAMERAS = {
    # 28 degrees down from 26 cm over the table, wide enough for the whole objects' area (at 23
    # degrees and 50 degrees of view, 10-30% of objects fell outside it; from 10 cm up at 10
    # degrees, until 2026-12-07, they were slivers on the horizon under the robot).
    "libero_front": 'pos="0.42 0.11 1.16" xyaxes="0 1 0 -0.469 0 0.883" fovy="60"',
    "libero_left": 'pos="-0.05 -0.3 1.45" xyaxes="1 0 0 0 0.766 0.643" fovy="45"',  # 50 degrees down, over the cabinet
    "libero_tilted": 'pos="0.4 0.1 1.4" xyaxes="0 1 0 -0.707 0 0.707" fovy="45"',  # 45 degrees down
}
LIBERO_XY = ((-0.2, 0.12), (-0.08, 0.3))  # where LIBERO-Spatial's objects lie (its initial states)
MIN_GAP = 0.1  # metres between the centres of objects a layout drops (a bowl is 12 cm across)


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
        spots: dict = {}
        for o in self.held:  # apart: objects dropped onto each other were thrown off the table
            for _ in range(100):
                xy = np.array([rng.uniform(*self.table_xy[0]), rng.uniform(*self.table_xy[1])])
                if all(np.linalg.norm(xy - s[:2]) >= MIN_GAP for s in spots.values()):
                    break
            spots[o] = np.array([*xy, top])
        if len(self.held) >= 2 and rng.random() < self.p_stack:
            upper, lower = (self.held[i] for i in rng.choice(len(self.held), 2, replace=False))
            spots[upper] = spots[lower] + np.array([*rng.uniform(-0.01, 0.01, 2), 0.07])
        for obj, xyz in spots.items():
            self._place(obj, xyz)

    def reset(self, *, seed=None, options=None):
        """A layout whose held objects all came to rest on the objects' area (up to 10 draws)."""
        obs, info = super().reset(seed=seed, options=options)
        for _ in range(9):
            if self.task_layout or self.on_area():
                break
            obs, info = super().reset(options=options)
        return obs, info

    def on_area(self, margin: float = 0.05) -> bool:
        """Whether every held object rests on the objects' area (within ``margin`` metres), not
        on a fixture or the floor."""
        (x0, x1), (y0, y1) = self.table_xy
        z = self.rs.table_offset[2]
        for o in self.held:
            x, y, h = self.data.xpos[self.model.body(self.body_name(o)).id]
            if not (x0 - margin <= x <= x1 + margin and y0 - margin <= y <= y1 + margin and z - 0.02 <= h <= z + 0.1):
                return False
        return True

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
