"""What the MuJoCo scenes share: loading the MJCF, cameras, offscreen rendering, hidden objects,
seeded initial layouts and the oracle that reads the true state.

Agents see only ``observation[camera]`` images. ``info`` carries the true object positions,
``oracle_reward`` and ``is_success`` for evaluation and privileged baselines only; the reward
returned by ``step`` is always 0 (zsrm's reward wrappers supply the reward).
"""
from __future__ import annotations

import os
from importlib import resources

# Mesa's software renderer: small images render faster in the calling thread.
os.environ.setdefault("LP_NUM_THREADS", "0")

import gymnasium as gym
import mujoco
import numpy as np

from zsrm.tasks.catalogue import as_task
from zsrm.tasks.language import COLOURS, GoalError
from zsrm.tasks.relations import CAMERAS, WORLD_THRESHOLDS, holds_in_world

TABLE_TOP = 0.4
TABLE_HALF_X, TABLE_HALF_Y = 0.32, 0.24  # the table top's half extents (MJCF)
SPREADS = ("seen", "unseen")
# Objects never move faster than this (m/s): the gripper's top speed is 0.75 m/s, so only a
# contact glitch (fingers closing beside a block) could go faster, and it would throw the
# block off the table.
MAX_OBJECT_SPEED = 1.0


def load_model(asset: str) -> mujoco.MjModel:
    xml = resources.files("zsrm.envs").joinpath("assets", asset).read_text()
    return mujoco.MjModel.from_xml_string(xml)


def check_cameras(cameras) -> tuple[str, ...]:
    if isinstance(cameras, str):
        cameras = (cameras,)
    cameras = tuple(cameras)
    if not cameras:
        raise ValueError(f"give at least one camera of {', '.join(CAMERAS)}")
    for c in cameras:
        if c not in CAMERAS:
            raise ValueError(f"unknown camera {c!r}; known cameras: {', '.join(CAMERAS)}")
    return cameras


def check_colours(colours, containers=()) -> tuple[str, ...]:
    """Objects of a scene: colours, and the scene's ``containers`` ("box" on the tabletop)."""
    colours = tuple(colours or ())
    if not colours:
        raise ValueError("give a task, or the objects (colours) of an exploration scene")
    for c in colours:
        if c not in COLOURS and c not in containers:
            raise GoalError(f"unknown colour {c!r}; known colours: {', '.join(COLOURS + tuple(containers))}")
    if len(set(colours)) != len(colours):
        raise ValueError(f"objects must differ, got {', '.join(colours)}")
    return colours


class MujocoPixelEnv(gym.Env):
    """Base class of the tabletop and pushing scenes. Subclasses set the action space, apply
    actions (:meth:`_apply_action`) and lay out objects (:meth:`_initial_layout`)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 12}
    asset: str
    shape: str  # "block" or "puck": the object bodies are named f"{shape}_{colour}"
    object_half_size: float
    rest_height: float  # height of an object's centre above the table when it rests on it
    containers: tuple[str, ...] = ()  # objects named by noun, not colour (bodies named as they are)
    frame_skip = 8  # 8 x 5 ms = one 0.04 s control step
    # Raised whenever task scenes start differently: a run's config records it, so that a
    # result of the old layout is never taken for a finished run of the new one.
    layout_version = 1

    def __init__(self, task, cameras=("front",), image_size: int = 64, spread: str = "seen",
                 render_mode: str | None = None, objects=None, action_repeat: int = 1):
        if not isinstance(action_repeat, (int, np.integer)) or action_repeat < 1:
            raise ValueError(f"action_repeat must be an integer >= 1, got {action_repeat!r}")
        self.action_repeat = int(action_repeat)  # control steps per env step; only the last is rendered
        if spread not in SPREADS:
            raise ValueError(f"unknown spread {spread!r}; choose one of {', '.join(SPREADS)}")
        if not isinstance(image_size, (int, np.integer)) or not 16 <= image_size <= 512:
            raise ValueError(f"image_size must be an integer in [16, 512], got {image_size!r}")
        # task=None: exploration mode, ``objects`` (colours) at random places, no oracle. With a
        # task, ``objects`` that the goal does not name are distractors.
        self.task = None if task is None else as_task(task, self.shape)
        if self.task is None:
            self.objects, self.distractors = check_colours(objects, self.containers), ()
        else:
            extra = () if objects is None else tuple(
                c for c in check_colours(objects, self.containers) if c not in self.task.objects)
            self.objects, self.distractors = self.task.objects + extra, extra
        self.cameras = check_cameras(cameras)
        self.image_size = int(image_size)
        self.spread = spread
        self.render_mode = render_mode

        self.model = load_model(self.asset)
        self.data = mujoco.MjData(self.model)
        self._hide_unused_objects()
        self._renderer = None
        self._scene_option = mujoco.MjvOption()
        self._scene_option.geomgroup[3] = 0  # hidden objects
        self.observation_space = gym.spaces.Dict(
            {c: gym.spaces.Box(0, 255, (self.image_size, self.image_size, 3), np.uint8) for c in self.cameras}
        )

    # --- objects -------------------------------------------------------------------------
    def _body(self, colour: str) -> int:
        name = colour if colour in self.containers else f"{self.shape}_{colour}"
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)

    def _qpos_adr(self, colour: str) -> int:
        return self.model.jnt_qposadr[self.model.body_jntadr[self._body(colour)]]

    def _hide_unused_objects(self):
        for i, colour in enumerate(COLOURS + self.containers):
            if colour in self.objects:
                continue
            body = self._body(colour)
            for g in range(self.model.body_geomadr[body], self.model.body_geomadr[body] + self.model.body_geomnum[body]):
                self.model.geom_group[g] = 3
                self.model.geom_contype[g] = 0
                self.model.geom_conaffinity[g] = 0
            self.model.body_gravcomp[body] = 1.0
            self.model.body_pos[body] = (2.0 + i, 2.0, 0.1)

    def object_positions(self) -> dict[str, np.ndarray]:
        """True world positions of the task's objects, keyed by colour."""
        return {c: self.data.xpos[self._body(c)].copy() for c in self.objects}

    def _set_object(self, colour: str, xyz):
        adr = self._qpos_adr(colour)
        self.data.qpos[adr:adr + 3] = xyz
        self.data.qpos[adr + 3:adr + 7] = (1, 0, 0, 0)

    def _park_unused(self):
        for i, colour in enumerate(COLOURS):
            if colour not in self.objects:
                self._set_object(colour, (2.0 + i, 2.0, 0.1))

    # --- oracle ------------------------------------------------------------------------
    def oracle_success(self) -> bool:
        """Table 1 on the true positions; an object that left the table satisfies nothing."""
        if self.task is None:
            return False
        pos = self.object_positions()
        if not all(self.over_table(pos[c]) for c in self.task.objects):
            return False
        return bool(holds_in_world(self.task.relation, [pos[c] for c in self.task.objects], WORLD_THRESHOLDS))

    @staticmethod
    def over_table(p) -> bool:
        """Is this object centre above the table top (resting, held or stacked), not falling?"""
        return abs(p[0]) < TABLE_HALF_X and abs(p[1]) < TABLE_HALF_Y and p[2] > TABLE_TOP

    def fell_off(self) -> bool:
        return not all(self.over_table(p) for p in self.object_positions().values())

    def _info(self) -> dict:
        success = self.oracle_success()
        return {
            "object_positions": self.object_positions(),
            "oracle_reward": float(success),
            "is_success": success,
            "oracle_steps": int(success),
        }

    # --- layout ------------------------------------------------------------------------
    @property
    def spread_width(self) -> float:
        """Half-range of the uniform start noise: one object width in all (seen), two (unseen)."""
        return self.object_half_size * (1.0 if self.spread == "seen" else 2.0)

    def _sample_layout(self, options: dict | None = None) -> dict[str, np.ndarray]:
        """Initial positions that do not overlap and are not already in the goal relation."""
        if self.task is None:
            for _ in range(100):
                layout = self._random_layout(**(options or {}))
                if self._layout_ok(layout):
                    return layout
            raise RuntimeError(f"could not sample an exploration scene of {', '.join(self.objects)}")
        rel = self.task.relation
        for _ in range(1000):
            layout = self._initial_layout()
            for colour in self.distractors:
                if colour not in layout:  # a scene may lay its distractors out itself
                    layout[colour] = self._distractor_position()
            pts = list(layout.values())
            apart = all(np.linalg.norm(a[:2] - b[:2]) > 2.6 * self.object_half_size
                        for i, a in enumerate(pts) for b in pts[i + 1:])
            on_table = all(abs(p[0]) < 0.26 and abs(p[1]) < 0.18 for p in pts)
            if (apart and on_table and self._layout_ok(layout)
                    and not holds_in_world(rel, [layout[c] for c in self.task.objects])):
                return layout
        raise RuntimeError(f"could not sample a start state for {self.task.text!r}")

    def _distractor_position(self) -> np.ndarray:
        """A distractor starts at the back of the table, behind the strip where the task's
        objects start and move (y within about +-0.1 m), so it neither meets the goal's objects
        nor stands where they must go; the oracle reads the goal's objects only."""
        rng = self.np_random
        return np.array([rng.uniform(-0.2, 0.2), rng.uniform(0.13, 0.16), TABLE_TOP + self.rest_height])

    def _initial_layout(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _layout_ok(self, layout: dict[str, np.ndarray]) -> bool:
        """Scene-specific check of a start layout (the tabletop keeps blocks out of the box)."""
        return True

    def _random_layout(self, p_stack: float = 0.25, p_side: float = 0.0) -> dict[str, np.ndarray]:
        """Exploration: objects anywhere on the table; with probability ``p_stack`` a block
        starts stacked on another, with ``p_side`` an object starts beside another (centres 2
        to 3 half-widths apart). Random actions alone rarely bring two objects together, so
        without these, exploration data would hardly show "on top of" or touching objects.
        A container is never stacked nor placed beside; a block stacked on it falls in."""
        rng, h = self.np_random, self.object_half_size
        layout: dict[str, np.ndarray] = {}
        for colour in self.objects:
            if layout and self.shape == "block" and colour not in self.containers and rng.random() < p_stack:
                base = layout[list(layout)[rng.integers(len(layout))]]
                if not any(np.allclose(p[:2], base[:2]) and p[2] > base[2] for p in layout.values()):
                    layout[colour] = base + (*rng.uniform(-0.3 * h, 0.3 * h, 2), 2 * h)
                    continue
            if layout and colour not in self.containers and rng.random() < p_side:
                base = layout[list(layout)[rng.integers(len(layout))]]
                for _ in range(100):  # directions that stay on the table and clear of the others
                    angle, dist = rng.uniform(0, 2 * np.pi), rng.uniform(2.05 * h, 3.0 * h)
                    p = np.array([base[0] + dist * np.cos(angle), base[1] + dist * np.sin(angle),
                                  TABLE_TOP + self.rest_height])
                    if (abs(p[0]) < 0.22 and abs(p[1]) < 0.14
                            and all(np.linalg.norm(p[:2] - q[:2]) > 2.05 * h for q in layout.values())):
                        layout[colour] = p
                        break
                if colour in layout:
                    continue
            for _ in range(1000):
                p = np.array([rng.uniform(-0.22, 0.22), rng.uniform(-0.14, 0.14), TABLE_TOP + self.rest_height])
                if all(np.linalg.norm(p[:2] - q[:2]) > 2.6 * h for q in layout.values()):
                    break
            layout[colour] = p
        return layout

    # --- gym API -----------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        self._park_unused()
        # options (exploration scenes only): p_stack, p_side of :meth:`_random_layout`
        for colour, xyz in self._sample_layout(options).items():
            self._set_object(colour, xyz)
        self._reset_agent()
        mujoco.mj_forward(self.model, self.data)
        # Let objects settle onto the table before the first frame.
        for _ in range(5):
            mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        return self._observation(), self._info()

    def step(self, action):
        """Apply ``action`` for ``action_repeat`` control steps and render the last one.

        ``info["oracle_steps"]`` counts the control steps in the goal relation (the oracle
        metric sums it over an episode); ``oracle_reward`` and ``is_success`` are the verdict
        after the last one.
        """
        action = np.asarray(action, dtype=np.float64)
        if action.shape != self.action_space.shape:
            raise ValueError(f"action must have shape {self.action_space.shape}, got {action.shape}")
        in_goal, terminated = 0, False
        for _ in range(self.action_repeat):
            self._apply_action(np.clip(action, -1.0, 1.0))
            in_goal += int(self.oracle_success())
            terminated = self.fell_off()
            if terminated:
                break
        info = self._info()
        info["oracle_steps"] = in_goal
        return self._observation(), 0.0, terminated, False, info

    def _reset_agent(self):
        raise NotImplementedError

    def _simulate(self):
        """One control step of physics, then the object speed limit."""
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        for colour in self.objects:
            if colour in self.containers:  # fixed to the world: no velocity to limit
                continue
            adr = self.model.jnt_dofadr[self.model.body_jntadr[self._body(colour)]]
            v = self.data.qvel[adr:adr + 3]
            speed = float(np.linalg.norm(v))
            if speed > MAX_OBJECT_SPEED:
                v *= MAX_OBJECT_SPEED / speed

    def _apply_action(self, action: np.ndarray):
        raise NotImplementedError

    # --- rendering ---------------------------------------------------------------------
    def _render_camera(self, camera: str, size: int | None = None) -> np.ndarray:
        size = size or self.image_size
        if self._renderer is None or self._renderer.height != size:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = mujoco.Renderer(self.model, size, size)
            for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
                self._renderer.scene.flags[flag] = False
        self._renderer.update_scene(self.data, camera=camera, scene_option=self._scene_option)
        return self._renderer.render().copy()

    def _observation(self) -> dict[str, np.ndarray]:
        return {c: self._render_camera(c) for c in self.cameras}

    def render_cameras(self, cameras=CAMERAS, size: int | None = None) -> dict[str, np.ndarray]:
        """Images of any cameras, whatever the observation holds (for reports and data)."""
        return {c: self._render_camera(c, size) for c in check_cameras(cameras)}

    def render(self):
        """The observed cameras side by side (rgb_array)."""
        return np.concatenate([self._render_camera(c) for c in self.cameras], axis=1)

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
