"""Renders of the double pendulum at random poses, each with its pose from the true state: the
data that teaches the scene VLM the pendulum's pose in words (``zsrm pretrain-vlm
--pendulum-scenes N``), as CLIP learned such words from web captions.

Scene ``index`` of a seed draws a pose class of :data:`zsrm.tasks.pendulum.POSES` uniformly
(so upright, leaning left, leaning right and fallen are equally common), a cart position and
hinge angles that give that class; the joints are set directly on the MuJoCo data of the
wrapped gymnasium env (velocities zero), and the env's own camera renders the frame the
agent would see. The class is read back from the rendered tip's true position
(:func:`zsrm.tasks.pendulum.pose_class`), never from the sampler's intent. Captions are drawn
from the class at training time (:func:`zsrm.tasks.pendulum.pendulum_caption`).
:func:`load_pendulum_renders` renders once and caches shard by shard, like
:func:`zsrm.data.renders.load_renders`.

>>> data = render_pendulum_scenes(range(2), seed=0, size=32)
>>> data["images"].shape, [POSES[p] for p in data["pose"]]
((2, 32, 32, 3), ['fallen', 'leaning_left'])
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable

import numpy as np

from zsrm.data.renders import load_cached_shards
from zsrm.tasks.pendulum import POSES, pose_class, tip_offset

STREAM = 2  # seed stream apart from the presence renders' (0 train, 1 eval)
CART_RANGE = 0.8  # |cart x| of the renders (the rail ends at 1)
# Where each class's hinge angles are drawn from (radians: first pole, second relative to it);
# a draw outside the class is redrawn.
PROPOSALS = {"upright": (0.45, 0.7), "leaning_left": (1.7, 1.3), "leaning_right": (1.7, 1.3),
             "fallen": (math.pi, math.pi)}


def pendulum_plan(index: int, seed: int = 0) -> dict:
    """What scene ``index`` of a seed shows: its pose class and the joint positions (cart x,
    first hinge, second hinge) that give it."""
    rng = np.random.default_rng([STREAM, seed, index])
    pose = POSES[int(rng.integers(len(POSES)))]
    x = float(rng.uniform(-CART_RANGE, CART_RANGE))
    a1, a2 = PROPOSALS[pose]
    for _ in range(10_000):
        theta1, theta2 = float(rng.uniform(-a1, a1)), float(rng.uniform(-a2, a2))
        if pose_class(*tip_offset(theta1, theta2)) == pose:
            return {"pose": pose, "qpos": (x, theta1, theta2)}
    raise RuntimeError(f"no {pose} pose drawn for scene {index}")  # pragma: no cover (p < 1e-30)


class PendulumPoser:
    """The pixel pendulum env, posed by writing its joints: ``render(qpos)`` -> (frame, dx, z)."""

    def __init__(self, size: int = 64):
        from zsrm.envs.pendulum import DoublePendulumPixelEnv

        self.env = DoublePendulumPixelEnv(image_size=size)
        self.env.reset(seed=0)  # the renderer needs a reset env
        inner = self.env._env.unwrapped
        self.model, self.data = inner.model, inner.data

    def render(self, qpos) -> tuple[np.ndarray, float, float]:
        import mujoco

        self.data.qpos[:] = qpos
        self.data.qvel[:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        tip, cart = self.data.site("tip").xpos, self.data.body("cart").xpos
        return self.env.render(), float(tip[0] - cart[0]), float(tip[2] - cart[2])

    def close(self):
        self.env.close()


def render_pendulum_scenes(indices: Iterable[int], seed: int = 0, size: int = 64, progress=None) -> dict:
    """Render scenes ``indices`` of a seed. Returns arrays, one row per image: ``images`` (N,
    size, size, 3) uint8, ``pose`` (N,) index into POSES (from the true tip position),
    ``qpos`` (N, 3) cart x and hinge angles, ``tip`` (N, 2) the tip's (dx, z) from the cart in
    metres, ``scene_index`` (N,). ``progress``: called once per scene."""
    indices = list(indices)
    n = len(indices)
    out = {"images": np.zeros((n, size, size, 3), np.uint8), "pose": np.zeros(n, np.uint8),
           "qpos": np.zeros((n, 3), np.float32), "tip": np.zeros((n, 2), np.float32),
           "scene_index": np.asarray(indices, np.int64)}
    poser = PendulumPoser(size)
    try:
        for j, index in enumerate(indices):
            plan = pendulum_plan(index, seed)
            frame, dx, z = poser.render(plan["qpos"])
            pose = pose_class(dx, z)
            if pose != plan["pose"]:  # the simulator disagrees with tip_offset: a model change
                raise RuntimeError(f"scene {index}: drawn as {plan['pose']}, rendered as {pose} "
                                   f"(dx {dx:.3f}, z {z:.3f})")
            out["images"][j] = frame
            out["pose"][j] = POSES.index(pose)
            out["qpos"][j] = plan["qpos"]
            out["tip"][j] = (dx, z)
            if progress is not None:
                progress(1)
    finally:
        poser.close()
    return out


def load_pendulum_renders(folder: str | Path, scenes: int, shard_size: int, seed: int = 0, image_size: int = 64,
                          progress: bool = True) -> dict:
    """The first ``scenes`` pendulum scenes, rendered once and cached in ``folder`` shard by shard
    (``shard-0000.npz``, ...); arrays as :func:`render_pendulum_scenes` returns them."""
    spec = {"kind": "pendulum", "seed": seed, "shard_size": shard_size, "image_size": image_size}
    return load_cached_shards(folder, spec, scenes, shard_size, "pendulum renders", "render pendulum",
                              lambda indices, bar: render_pendulum_scenes(indices, seed=seed, size=image_size,
                                                                          progress=bar), progress)


__all__ = ["pendulum_plan", "render_pendulum_scenes", "load_pendulum_renders", "PendulumPoser"]
