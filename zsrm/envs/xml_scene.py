"""A gymnasium env made from nothing but a MuJoCo XML: what a :class:`zsrm.envs.SceneAdapter`
builds when it gives ``xml`` and no ``env_id``.

Observations are the asked cameras' images (a dict by camera name); the reward is always 0 and
nothing ends an episode but a time limit.

* **Actions** are in [-1, 1] per actuator (``actions="normalised"``): without ``step_size``, -1
  and 1 are the ends of the actuator's ``ctrlrange``; with it, each step moves the control by up
  to ``step_size`` (for a position actuator on a slide joint: its target, in metres), which is
  how a policy makes small motions. ``actions="raw"`` takes the ``ctrlrange`` values themselves
  (the only mode before 2026-12-05; PPO's unit-scale actions saturate a range of +-0.25 m).
* **Objects**: ``objects`` names the bodies a scene holds (each with a free joint); the other
  free bodies are parked far away, unseen and untouched. ``None``: every body.
* **Starts**: a reset restores the model's first keyframe (or its default pose) and moves every
  held free body's x and y by up to ``jitter`` metres, keeping them apart. ``start="beside"``
  then puts the body the actuators drive (through slide joints) beside one held object, drawn at
  random, on a random side: the start zsrm's own task scenes use, where a few pushes change
  which object is where. The scene then settles for a few steps.

What an XML alone cannot give is refused in one line (:class:`XmlSceneError`): no actuators,
an object that is not a body with a free joint, ``start="beside"`` with actuators that do not
drive slide joints of one body.

>>> from pathlib import Path
>>> xml = Path(__file__).with_name("assets") / "pushing.xml"
>>> env = XmlSceneEnv(xml, cameras=("front",), image_size=32)
>>> obs, info = env.reset(seed=0)
>>> obs["front"].shape, info, env.action_space.low.tolist()
((32, 32, 3), {}, [-1.0, -1.0])
"""
from __future__ import annotations

import os
from pathlib import Path


import gymnasium as gym
import mujoco
import numpy as np

SETTLE_STEPS = 5
HIDDEN_GROUP = 5  # geom group of parked bodies: the renderer leaves it out
PARK = np.array([50.0, 50.0, 1.0])  # where absent bodies wait (one metre apart along x)
MARGIN = 0.005  # metres between the surfaces of objects placed at a reset
TRIES = 100  # draws of a body's place before it is kept where it overlaps least


class XmlSceneError(ValueError):
    """What a bare XML cannot do, in one line."""


class XmlSceneEnv(gym.Env):
    """Pixels of a MuJoCo XML's cameras in, actuator controls out (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 12}

    def __init__(self, xml: str | Path, cameras, image_size: int = 64, frame_skip: int = 10, jitter: float = 0.0,
                 render_mode: str | None = None, objects=None, actions: str = "normalised",
                 step_size: float | None = None, start: str = "keyframe"):
        self.model = mujoco.MjModel.from_xml_path(str(xml))
        self.data = mujoco.MjData(self.model)
        self.xml = str(xml)
        names = [self.model.camera(i).name for i in range(self.model.ncam)]
        self.cameras = tuple(cameras)
        for cam in self.cameras:
            if cam not in names:
                raise XmlSceneError(f"{xml} has no camera {cam!r}; its cameras: {', '.join(names) or 'none'}")
        if actions not in ("normalised", "raw"):
            raise XmlSceneError(f"actions must be 'normalised' or 'raw', got {actions!r}")
        if start not in ("keyframe", "beside"):
            raise XmlSceneError(f"start must be 'keyframe' or 'beside', got {start!r}")
        if step_size is not None and (actions == "raw" or not step_size > 0):
            raise XmlSceneError(f"step_size takes a positive size with normalised actions, got {step_size!r} "
                                f"with actions={actions!r}")
        if self.model.nu == 0:
            raise XmlSceneError(f"{xml} has no actuators: zsrm's bare-XML env acts through them (add an "
                                "<actuator>, or give the adapter an env_id of your own env)")
        self.image_size, self.frame_skip, self.jitter = int(image_size), int(frame_skip), float(jitter)
        self.actions, self.step_size, self.start = actions, step_size, start
        self.render_mode = render_mode
        self.observation_space = gym.spaces.Dict(
            {c: gym.spaces.Box(0, 255, (self.image_size, self.image_size, 3), np.uint8) for c in self.cameras})
        limited = self.model.actuator_ctrllimited.astype(bool)
        self._low = np.where(limited, self.model.actuator_ctrlrange[:, 0], -1.0)
        self._high = np.where(limited, self.model.actuator_ctrlrange[:, 1], 1.0)
        if actions == "raw":
            self.action_space = gym.spaces.Box(self._low.astype(np.float32), self._high.astype(np.float32),
                                               dtype=np.float32)
        else:
            self.action_space = gym.spaces.Box(-1.0, 1.0, (self.model.nu,), np.float32)
        self._free = self._free_bodies()
        self.held_bodies = tuple(self._free) if objects is None else tuple(objects)
        for body in self.held_bodies:
            if body not in self._free:
                raise XmlSceneError(f"{xml}: {body!r} is not a body with a free joint; the bodies zsrm can place "
                                    f"or leave out: {', '.join(self._free) or 'none'}")
        self._park_absent()
        self._effector = self._driven_body() if start == "beside" else None
        self._option = mujoco.MjvOption()
        self._option.geomgroup[HIDDEN_GROUP] = 0
        self._renderer = None

    # --- the model ------------------------------------------------------------------------
    def _free_bodies(self) -> dict[str, int]:
        """Body name -> its free joint's qpos address, for every body with a free joint."""
        out = {}
        for j in np.flatnonzero(self.model.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
            out[self.model.body(self.model.jnt_bodyid[j]).name] = int(self.model.jnt_qposadr[j])
        return out

    def _body_geoms(self, body: int) -> range:
        adr = self.model.body_geomadr[body]
        return range(adr, adr + self.model.body_geomnum[body])

    def _park_absent(self) -> None:
        """Absent bodies: drawn in a hidden group, touching nothing; held still where they wait."""
        self._parked = []  # (qpos address, dof address, where) of each absent body
        for k, (body, adr) in enumerate(self._free.items()):
            if body in self.held_bodies:
                continue
            b = self.model.body(body).id
            for g in self._body_geoms(b):
                self.model.geom_group[g] = HIDDEN_GROUP
                self.model.geom_contype[g] = self.model.geom_conaffinity[g] = 0
            dof = int(self.model.jnt_dofadr[self.model.body_jntadr[b]])
            self._parked.append((adr, dof, PARK + [k, 0.0, 0.0]))

    def _hold_parked(self) -> None:
        for adr, dof, where in self._parked:
            self.data.qpos[adr:adr + 3] = where
            self.data.qvel[dof:dof + 6] = 0.0

    def _driven_body(self) -> tuple[int, list[int]]:
        """The body the actuators move through slide joints, and those joints (start="beside")."""
        joints = []
        for a in range(self.model.nu):
            j = int(self.model.actuator_trnid[a, 0])
            if self.model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or \
                    self.model.jnt_type[j] != mujoco.mjtJoint.mjJNT_SLIDE:
                raise XmlSceneError(f"{self.xml}: start='beside' moves the body the actuators drive through slide "
                                    f"joints; actuator {self.model.actuator(a).name or a!r} does not drive a slide "
                                    "joint (give your own env with an env_id for other arms)")
            joints.append(j)
        bodies = {int(self.model.jnt_bodyid[j]) for j in joints}
        if len(bodies) != 1:
            raise XmlSceneError(f"{self.xml}: start='beside' needs the actuators to drive one body; they drive "
                                f"{', '.join(sorted(self.model.body(b).name for b in bodies))}")
        return bodies.pop(), joints

    def _radius(self, body: int) -> float:
        """A body's horizontal reach from its origin (its geoms' bounding spheres)."""
        reach = [np.linalg.norm(self.model.geom_pos[g][:2]) + self.model.geom_rbound[g] for g in self._body_geoms(body)]
        return float(max(reach, default=0.0))

    # --- gymnasium ------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if self.model.nkey:
            mujoco.mj_resetDataKeyframe(self.model, self.data, 0)
        else:
            mujoco.mj_resetData(self.model, self.data)
        self._hold_parked()
        self._place_objects()
        mujoco.mj_forward(self.model, self.data)
        if self._effector is not None:
            self._place_beside()
        self.data.ctrl[:] = self._hold_controls()
        for _ in range(SETTLE_STEPS):
            self._physics_step()
        return self._observation(), {}

    def _physics_step(self) -> None:
        mujoco.mj_step(self.model, self.data, nstep=self.frame_skip)
        if self._parked:
            self._hold_parked()
            mujoco.mj_forward(self.model, self.data)

    def _place_objects(self) -> None:
        """Every held body's x and y moved by up to ``jitter``, apart from those placed before it."""
        placed: list[tuple[np.ndarray, float]] = []
        for body in self.held_bodies:
            adr, r = self._free[body], self._radius(self.model.body(body).id)
            home = self.data.qpos[adr:adr + 2].copy()
            best, best_gap = home, -np.inf
            for _ in range(TRIES if self.jitter > 0 else 1):
                xy = home + self.np_random.uniform(-self.jitter, self.jitter, 2)
                gap = min((np.linalg.norm(xy - p) - r - q for p, q in placed), default=np.inf)
                if gap > best_gap:
                    best, best_gap = xy, gap
                if gap >= MARGIN:
                    break
            self.data.qpos[adr:adr + 2] = best
            placed.append((best, r))

    def _place_beside(self) -> None:
        """The driven body beside one held object, on a random side, its slide joints solved for it."""
        body, joints = self._effector
        if not self.held_bodies:
            return
        axes = np.stack([self.data.xaxis[j][:2] for j in joints], axis=1)  # (2, n joints): world xy per unit slide
        reach = self._radius(body)
        others = [(self.data.xpos[self.model.body(b).id][:2].copy(), self._radius(self.model.body(b).id))
                  for b in self.held_bodies]
        qpos0, start = self.data.qpos.copy(), self.data.xpos[body][:2].copy()
        for _ in range(TRIES):
            centre, r = others[int(self.np_random.integers(len(others)))]
            angle = self.np_random.uniform(0, 2 * np.pi)
            target = centre + (r + reach + MARGIN) * np.array([np.cos(angle), np.sin(angle)])
            move = np.linalg.lstsq(axes, target - start, rcond=None)[0]
            self.data.qpos[:] = qpos0
            for j, d in zip(joints, move):
                adr = self.model.jnt_qposadr[j]
                q = self.data.qpos[adr] + d
                if self.model.jnt_limited[j]:
                    q = np.clip(q, *self.model.jnt_range[j])
                self.data.qpos[adr] = q
            mujoco.mj_forward(self.model, self.data)
            here = self.data.xpos[body][:2]
            if np.linalg.norm(here - target) < 1e-3 and \
                    all(np.linalg.norm(here - p) >= q + reach for p, q in others):
                return
        self.data.qpos[:] = qpos0  # nowhere free within reach: the keyframe's place
        mujoco.mj_forward(self.model, self.data)

    def _hold_controls(self) -> np.ndarray:
        """Controls that hold the actuators where they are: a position actuator's target is its
        joint's position; any other's control is zero (clipped to its range)."""
        ctrl = np.zeros(self.model.nu)
        for a in range(self.model.nu):
            j = int(self.model.actuator_trnid[a, 0])
            position = self.model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE and \
                self.model.actuator_biasprm[a, 1] < 0
            if position and self.model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
                ctrl[a] = self.data.qpos[self.model.jnt_qposadr[j]]
        return np.clip(ctrl, self._low, self._high)

    def step(self, action):
        action = np.asarray(action, np.float64)
        if self.actions == "raw":
            ctrl = action
        elif self.step_size is None:
            ctrl = self._low + (np.clip(action, -1, 1) + 1) / 2 * (self._high - self._low)
        else:
            ctrl = self.data.ctrl + np.clip(action, -1, 1) * self.step_size
        self.data.ctrl[:] = np.clip(ctrl, self._low, self._high)
        self._physics_step()
        return self._observation(), 0.0, False, False, {}

    def body_position(self, body: str) -> np.ndarray:
        """PRIVILEGED: a body's world position (what an adapter's ``bodies`` read)."""
        return self.data.xpos[self.model.body(body).id].copy()

    def _render(self, camera: str) -> np.ndarray:
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.image_size, self.image_size)
        self._renderer.update_scene(self.data, camera=camera, scene_option=self._option)
        return self._renderer.render().copy()

    def _observation(self) -> dict[str, np.ndarray]:
        return {c: self._render(c) for c in self.cameras}

    def render(self):
        return self._render(self.cameras[0])

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
