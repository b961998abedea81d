"""The example's gymnasium env, written the way a user writes one, knowing nothing of zsrm.

A planar pusher moves over a wooden table with three cylinders (red, purple, orange) and a
shallow bowl. Observations are camera images only (a dict, one entry per camera asked for);
actions are ``(dx, dy)`` of the pusher in [-1, 1]; the reward is always 0. The objects' true
positions are not in the observation nor in ``info``: only :meth:`OwnSceneEnv.body_position`
reads them, for whoever is allowed to (the adapter's privileged accessor).
"""
from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym
import mujoco
import numpy as np

XML = Path(__file__).with_name("scene.xml")
CAMERAS = ("cam_front", "cam_side", "cam_high")
OBJECT_BODIES = ("red_cylinder", "purple_cylinder", "orange_cylinder", "bowl")
TABLE_TOP = 0.30
REST_Z = {"bowl": TABLE_TOP + 0.004}  # a body's origin height when it rests on the table
CYLINDER_REST_Z = TABLE_TOP + 0.03
PLACE_X, PLACE_Y = 0.19, 0.12  # objects start within these half extents of the table's centre
# start="compact": the objects within these half extents, 1 cm or more apart, and the pusher
# just in front of one of them, so that a few pushes change which object is where.
COMPACT_X, COMPACT_Y = 0.08, 0.06
# start="column": the objects one behind the other (x within 3 mm, 2 to 6 cm between edges), so
# that neither is left or right of another, and the pusher beside the front one (or the one reset's
# options name), on either side: a sideways push of the right object changes which is left of which.
COLUMN_DX, COLUMN_GAP = 0.003, (0.02, 0.06)
PUSHER_RADIUS = 0.02
RADIUS = {"bowl": 0.049}  # other objects: the cylinders' 0.025
MAX_MOVE = 0.02  # the default step_size
HIDDEN_GROUP = 3
STARTS = ("anywhere", "compact", "column")
SIDES = {"left": -1.0, "right": 1.0}  # reset(options={"side": ...}): which side of the object the pusher starts


class OwnSceneEnv(gym.Env):
    """Pixels in, pusher motion out.

    cameras: which of ``CAMERAS`` to observe; image_size: square image side;
    objects: which of ``OBJECT_BODIES`` are on the table (the others are hidden away);
    start: "anywhere" (objects anywhere on the table, the pusher anywhere along the front edge),
    "compact" (objects near the centre, the pusher just in front of one of them) or "column"
    (objects one behind the other near the centre, the pusher just beside the front one);
    step_size: metres of pusher target motion per step at |action| = 1;
    reach: metres between the pusher's edge and the object's it starts by (compact, column).
    ``reset(options=...)``: "beside" (a body) starts the pusher by that object instead; "side"
    ("left" or "right") puts it on that side of it in a column.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 12}
    frame_skip = 10  # 10 x 4 ms per step

    def __init__(self, cameras=CAMERAS, image_size: int = 64, objects=OBJECT_BODIES, render_mode=None,
                 start: str = "anywhere", step_size: float = MAX_MOVE, reach: float = 0.015):
        if start not in STARTS:
            raise ValueError(f"start must be one of {', '.join(map(repr, STARTS))}, got {start!r}")
        self.start, self.step_size, self.reach = start, float(step_size), float(reach)
        self.cameras = tuple(cameras)
        for cam in self.cameras:
            if cam not in CAMERAS:
                raise ValueError(f"no camera {cam!r} in this scene; its cameras: {', '.join(CAMERAS)}")
        self.objects = tuple(objects)
        for name in self.objects:
            if name not in OBJECT_BODIES:
                raise ValueError(f"no object {name!r} in this scene; its objects: {', '.join(OBJECT_BODIES)}")
        self.image_size, self.render_mode = int(image_size), render_mode
        self.model = mujoco.MjModel.from_xml_path(str(XML))
        self.data = mujoco.MjData(self.model)
        self._hide_absent()
        self.observation_space = gym.spaces.Dict(
            {c: gym.spaces.Box(0, 255, (self.image_size, self.image_size, 3), np.uint8) for c in self.cameras})
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._renderer = None
        self._option = mujoco.MjvOption()
        self._option.geomgroup[HIDDEN_GROUP] = 0

    def _body(self, name: str) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)

    def _hide_absent(self):
        """Absent objects: not drawn, not touched, weightless, parked far from the table."""
        for name in OBJECT_BODIES:
            if name in self.objects:
                continue
            body = self._body(name)
            geoms = range(self.model.body_geomadr[body], self.model.body_geomadr[body] + self.model.body_geomnum[body])
            for g in geoms:
                self.model.geom_group[g] = HIDDEN_GROUP
                self.model.geom_contype[g] = self.model.geom_conaffinity[g] = 0
            self.model.body_gravcomp[body] = 1.0

    def _park_absent(self):
        """Absent objects off the table, each at its own spot."""
        for i, name in enumerate(OBJECT_BODIES):
            if name not in self.objects:
                self._place(name, (3.0 + i, 3.0, 0.1))

    def _place(self, name: str, xyz):
        adr = self.model.jnt_qposadr[self.model.body_jntadr[self._body(name)]]
        self.data.qpos[adr:adr + 3] = xyz
        self.data.qpos[adr + 3:adr + 7] = (1, 0, 0, 0)

    def body_position(self, name: str) -> np.ndarray:
        """True world position of a body (privileged: not part of what the env observes)."""
        return self.data.xpos[self._body(name)].copy()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        placed = self._column() if self.start == "column" else self._scatter(self.start == "compact")
        start = self.np_random.uniform((-0.2, -0.14), (0.2, -0.11))  # the pusher starts along the front edge
        if self.start != "anywhere":  # ... or just in front of (beside) one of the objects, if nothing is in its way
            xy, r = self._next_to(placed, options or {})
            gap = r + PUSHER_RADIUS + self.reach
            if self.start == "column":  # on the side options name, else either
                side = self._side(options or {})
                ready = xy + (side * gap, self.np_random.uniform(-0.01, 0.01))
            else:
                ready = xy + (self.np_random.uniform(-0.01, 0.01), -gap)
            if all(np.linalg.norm(ready - q) >= rq + PUSHER_RADIUS + 0.01 for q, rq in placed.values() if q is not xy):
                start = ready
        self.data.qpos[:2] = start
        self.data.ctrl[:] = start
        mujoco.mj_forward(self.model, self.data)
        for _ in range(5):  # settle onto the table
            mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        return self._observation(), {}

    def _next_to(self, placed: dict, options: dict) -> tuple:
        """(xy, radius) of the placed object the pusher starts by: ``options["beside"]`` (a body)
        if given; in a column the front one, which the front camera sees whole; else any of them."""
        if options.get("beside"):
            if options["beside"] not in placed:
                raise ValueError(f"beside: {options['beside']!r} is not on the table; it holds {', '.join(placed)}")
            return placed[options["beside"]]
        if self.start == "column":
            return min(placed.values(), key=lambda p: p[0][1])
        return list(placed.values())[self.np_random.integers(len(placed))]

    def _side(self, options: dict) -> float:
        """-1 (left) or +1 (right): ``options["side"]`` if given, else drawn."""
        if options.get("side") is None:
            return float(self.np_random.choice((-1.0, 1.0)))
        if options["side"] not in SIDES:
            raise ValueError(f"side must be 'left' or 'right', got {options['side']!r}")
        return SIDES[options["side"]]

    def _scatter(self, compact: bool) -> dict:
        """Place the held objects at random: anywhere, centres 9 cm apart (the bowl's width), or
        compact, 1 cm or more between edges. Returns {body: (xy, radius)} of the placed objects."""
        half, placed = (COMPACT_X, COMPACT_Y) if compact else (PLACE_X, PLACE_Y), {}
        self._park_absent()
        for name in OBJECT_BODIES:
            if name not in self.objects:
                continue
            radius = RADIUS.get(name, 0.025)
            for _ in range(200):
                xy = self.np_random.uniform(np.negative(half), half)
                if all(np.linalg.norm(xy - q) > (radius + r + 0.01 if compact else 0.09) for q, r in placed.values()):
                    break
            placed[name] = (xy, radius)
            self._place(name, (*xy, REST_Z.get(name, CYLINDER_REST_Z)))
        return placed

    def _column(self) -> dict:
        """Place the held objects one behind the other in a random order near the table's centre."""
        rng, placed = self.np_random, {}
        x, y = rng.uniform(-COMPACT_X, COMPACT_X), rng.uniform(-COMPACT_Y, -COMPACT_Y / 2)
        self._park_absent()
        for name in map(str, rng.permutation([n for n in OBJECT_BODIES if n in self.objects])):
            radius = RADIUS.get(name, 0.025)
            if placed:  # edge to edge behind the one before
                y += list(placed.values())[-1][1] + radius + rng.uniform(*COLUMN_GAP)
            placed[name] = (np.array([x + rng.uniform(-COLUMN_DX, COLUMN_DX), y]), radius)
            self._place(name, (*placed[name][0], REST_Z.get(name, CYLINDER_REST_Z)))
        return placed

    def step(self, action):
        action = np.clip(np.asarray(action, np.float64), -1.0, 1.0)
        lo, hi = self.model.actuator_ctrlrange[:, 0], self.model.actuator_ctrlrange[:, 1]
        self.data.ctrl[:] = np.clip(self.data.ctrl + self.step_size * action, lo, hi)
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        fell = any(self.body_position(n)[2] < TABLE_TOP - 0.05 for n in self.objects)
        return self._observation(), 0.0, bool(fell), False, {}

    def _render(self, camera: str) -> np.ndarray:
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.image_size, self.image_size)
        self._renderer.update_scene(self.data, camera=camera, scene_option=self._option)
        return self._renderer.render().copy()

    def _observation(self) -> dict:
        return {c: self._render(c) for c in self.cameras}

    def render(self):
        return self._render(self.cameras[0])

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
