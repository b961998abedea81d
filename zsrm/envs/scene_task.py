"""A user's own scene as a zsrm task: a goal over its objects, judged by an oracle from the true
state, without any change to the user's env.

:class:`SceneTask` wraps an env a :class:`~zsrm.envs.SceneAdapter` made. It observes the
adapter's cameras by their Table 1 roles (``{"front": image}``, as zsrm's own scenes do), repeats
each action ``action_repeat`` control steps, and writes the oracle into ``info`` as zsrm's scenes
do (:mod:`zsrm.envs.base`): ``oracle_reward`` and ``is_success``, the goal's verdict after the
last control step, and ``oracle_steps``, the control steps in the goal relation (the oracle
episode reward sums it). As zsrm's scenes never start in the goal relation, a reset whose scene
already holds it is drawn again by the env's own reset (up to :data:`MAX_REDRAWS` times).

The oracle reads the adapter's privileged accessor (:meth:`~zsrm.envs.SceneAdapter.object_positions`)
and judges Table 1's relation in the plane of the role's camera, taken from the MuJoCo camera
itself (:func:`role_axes`): zsrm's :func:`~zsrm.tasks.relations.camera_plane` assumes zsrm's world
frame, a user's scene has its own. The thresholds are zsrm's, scaled to the adapter's
``object_width`` (:func:`scene_thresholds`). Only evaluation and the oracle reward read it; the
policy and every other reward see the images.
"""
from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

from zsrm.envs.adapter import SceneAdapter, SceneAdapterError
from zsrm.tasks.relations import RELATIONS, WORLD_THRESHOLDS, Thresholds

# WORLD_THRESHOLDS are set for zsrm's 6 cm blocks.
REFERENCE_WIDTH = 0.06
# Resets drawn again at most this many times while the goal already holds (then the start is kept).
MAX_REDRAWS = 20


def scene_thresholds(object_width: float) -> Thresholds:
    """zsrm's world thresholds for objects ``object_width`` metres wide.

    >>> round(scene_thresholds(0.03).close, 3), round(scene_thresholds(0.06).inside, 3)
    (0.05, 0.02)
    """
    return WORLD_THRESHOLDS.scaled(object_width / REFERENCE_WIDTH)


def role_axes(model: mujoco.MjModel, data: mujoco.MjData, camera: str, role: str) -> np.ndarray:
    """The two world directions ``(2, 3)`` whose coordinates Table 1 reads on ``camera`` in ``role``.

    Right is the camera's image x axis laid flat; up is against gravity. front and left: (right,
    up), so that "on top of" means higher, however the camera tilts. tilted: (right, forward),
    the table plane, forward being the camera's view direction laid flat. For zsrm's own
    cameras this is :func:`~zsrm.tasks.relations.camera_plane` (front (x, z), left (-y, z),
    tilted (x, y)).
    """
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if cam < 0:
        raise SceneAdapterError(f"the {role!r} role's camera {camera!r} is not a camera of the model")
    gravity = np.asarray(model.opt.gravity, np.float64)
    up = -gravity / np.linalg.norm(gravity) if np.linalg.norm(gravity) > 0 else np.array([0.0, 0.0, 1.0])
    image_x = data.cam_xmat[cam].reshape(3, 3)[:, 0]  # the columns of cam_xmat: image right, image up, backward
    right = image_x - image_x.dot(up) * up
    if np.linalg.norm(right) < 1e-6:
        raise SceneAdapterError(f"camera {camera!r} (the {role!r} role) is rolled so that its image x axis is "
                                "vertical: Table 1 reads left and right on it")
    right /= np.linalg.norm(right)
    if role in ("front", "left"):
        return np.stack([right, up])
    return np.stack([right, np.cross(up, right)])


def holds_in_scene(relation: str, positions, axes: np.ndarray, thresholds: Thresholds, solid: bool = True) -> bool:
    """Table 1's ``relation`` over the objects' world ``positions``, read along ``axes`` (role_axes);
    on top of and below read on the positions themselves (z up) unless ``solid`` is False
    (:attr:`~zsrm.tasks.relations.Relation.solid`, as the labeler reads them from 2026-12-07)."""
    rel = RELATIONS[relation]
    if solid and rel.solid is not None:
        return bool(rel.solid(*[np.asarray(p, np.float64) for p in positions], thresholds))
    coords = [np.asarray(p, np.float64) @ axes.T for p in positions]
    return bool(rel(*coords, thresholds=thresholds))


class SceneTask(gym.Wrapper):
    """An adapter's env with a goal: observations by role, action repeat, the oracle in ``info``.

    ``goal`` is a :class:`~zsrm.tasks.scene_goals.SceneGoal` over the adapter's phrases. The
    env's own reward passes through (summed over the repeated steps); zsrm's reward wrappers
    replace it.
    """

    def __init__(self, env: gym.Env, adapter: SceneAdapter, goal, action_repeat: int = 1):
        super().__init__(env)
        self.adapter, self.goal, self.action_repeat = adapter, goal, int(action_repeat)
        missing = [p for p in goal.objects if p not in adapter.objects]
        if missing:
            raise SceneAdapterError(f"{adapter.name}: unknown object {missing[0]!r}; this scene's objects: "
                                    f"{', '.join(adapter.objects)}")
        spaces = env.observation_space.spaces
        self.observation_space = gym.spaces.Dict(
            {role: spaces[cam] for role, cam in adapter.roles.items() if cam in spaces})
        self.role = RELATIONS[goal.relation].camera
        self.thresholds = scene_thresholds(adapter.object_width)

    def oracle_success(self) -> bool:
        """The goal on the true positions (privileged)."""
        positions = self.adapter.object_positions(self.env)
        missing = [p for p in self.goal.objects if p not in positions]
        if missing:
            raise SceneAdapterError(f"{self.adapter.name}: object_positions holds no {missing[0]!r}, which the goal "
                                    f"names; it holds: {', '.join(positions) or 'nothing'}")
        base = self.env.unwrapped
        axes = role_axes(base.model, base.data, self.adapter.roles[self.role], self.role)
        return holds_in_scene(self.goal.relation, [positions[p] for p in self.goal.objects], axes, self.thresholds)

    def _verdict(self, info: dict, steps_in_goal: int, success: bool) -> dict:
        return {**info, "oracle_reward": float(success), "is_success": success, "oracle_steps": steps_in_goal}

    def reset(self, *, seed=None, options=None):
        start = self.adapter.task_reset_options(self.goal)  # the adapter's start for this goal, if any
        options = {**start, **(options or {})} if start else options
        obs, info = self.env.reset(seed=seed, options=options)
        success = self.oracle_success()
        for _ in range(MAX_REDRAWS):  # the env's generator goes on from the seed: the same seed, the same start
            if not success:
                break
            obs, info = self.env.reset(options=options)
            success = self.oracle_success()
        return self.adapter.observe(obs), self._verdict(info, int(success), success)

    def step(self, action):
        total, in_goal = 0.0, 0
        for _ in range(self.action_repeat):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            success = self.oracle_success()
            in_goal += int(success)
            if terminated or truncated:
                break
        return self.adapter.observe(obs), total, terminated, truncated, self._verdict(info, in_goal, success)


__all__ = ["MAX_REDRAWS", "REFERENCE_WIDTH", "SceneTask", "holds_in_scene", "role_axes", "scene_thresholds"]
