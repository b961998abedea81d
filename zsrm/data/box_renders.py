"""Renders of tabletop scenes with the open box, each with the visible pixels of every block and
of the box: the data that teaches the scene VLM the word "box" (``zsrm pretrain-vlm
--box-scenes N``), which the presence renders never show (their scenes have no box).

Scene ``index`` of a seed is an exploration scene of the tabletop with a random non-empty
subset of the four colours and the box; in about a third of the scenes one of its blocks is
put in the box, resting on its floor (random exploration almost never drops one in, and a
block in the box is what "inside of" needs the VLM to find). Then a few random actions, and
all three cameras render. Visible pixels come from MuJoCo's segmentation render, as in
:mod:`zsrm.data.renders`; ``inside`` (a block is in the box by the oracle's world rule) is
for inspection only. Captions are drawn at training time
(:func:`zsrm.vlm.presence.presence_caption` with ``box``). :func:`load_box_renders` renders once
and caches shard by shard, like :func:`zsrm.data.renders.load_renders`.

>>> data = render_box_scenes(range(2), seed=0, size=32)
>>> data["images"].shape, data["visible"].shape, data["box_visible"].shape
((6, 32, 32, 3), (6, 4), (6,))
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from zsrm.data.renders import _SceneRenderer, load_cached_shards
from zsrm.tasks.language import COLOURS
from zsrm.tasks.lexicon import BOX
from zsrm.tasks.relations import CAMERAS, WORLD_THRESHOLDS, holds_in_world

STREAM = 3  # seed stream apart from the presence renders' (0 train, 1 eval) and the pendulum's (2)
P_INSIDE = 1 / 3  # scenes that start with a block in the box
MAX_ACTIONS = 10  # random actions after the reset, as in the presence renders
SETTLE_STEPS = 5  # control steps a block put in the box settles for (as a reset settles its layout)


def box_plan(index: int, seed: int = 0) -> dict:
    """What scene ``index`` of a seed holds: colours, the block put in the box (or None) and its
    offset from the box's centre, env seed, actions."""
    from zsrm.envs.tabletop import BLOCK_HALF, BOX_INNER_HALF

    rng = np.random.default_rng([STREAM, seed, index])
    k = int(rng.integers(1, len(COLOURS) + 1))
    colours = tuple(COLOURS[i] for i in sorted(rng.choice(len(COLOURS), k, replace=False)))
    into_box = colours[int(rng.integers(k))] if rng.random() < P_INSIDE else None
    slack = BOX_INNER_HALF - BLOCK_HALF - 0.002  # a 2 mm gap to the walls at most offset
    return {"colours": colours, "into_box": into_box, "offset": rng.uniform(-slack, slack, 2),
            "env_seed": int(rng.integers(2**31 - 1)), "n_actions": int(rng.integers(0, MAX_ACTIONS + 1)),
            "actions_rng": rng}


def block_inside(env) -> bool:
    """Is some block in the box, by the oracle's world rule (centres within ``inside``)?"""
    pos = env.object_positions()
    return any(holds_in_world("inside_of", [pos[c], pos[BOX]], WORLD_THRESHOLDS) for c in pos if c != BOX)


def put_in_box(env, colour: str, offset) -> None:
    """Put block ``colour`` on the box's floor, ``offset`` (x, y) from its centre, and let it
    settle; nothing moves if a block is in the box already (stacked on it at reset, it fell in)."""
    import mujoco

    from zsrm.envs.tabletop import BLOCK_HALF

    if block_inside(env):
        return
    box = env.object_positions()[BOX]
    floor = env.model.geom(f"{BOX}_floor")
    z = box[2] + floor.pos[2] + floor.size[2] + BLOCK_HALF + 0.001  # 1 mm above the floor
    env._set_object(colour, (box[0] + offset[0], box[1] + offset[1], z))
    mujoco.mj_step(env.model, env.data, nstep=env.frame_skip * SETTLE_STEPS)


def render_box_scenes(indices: Iterable[int], seed: int = 0, size: int = 64, cameras: tuple[str, ...] = CAMERAS,
                      progress=None) -> dict:
    """Render scenes ``indices`` of a seed from every camera.

    Returns arrays, one row per image (scene-major, cameras in order): ``images`` (N, size,
    size, 3) uint8, ``visible`` (N, 4) visible pixel counts of the blocks in COLOURS order,
    ``box_visible`` (N,) the box's visible pixels, ``inside`` (N,) bool a block is in the box
    (world rule; informational), ``camera`` (N,) index into ``cameras``, ``scene_index`` (N,).
    ``progress``: called once per scene.
    """
    indices = list(indices)
    plans = [box_plan(i, seed) for i in indices]
    n = len(indices) * len(cameras)
    out = {
        "images": np.zeros((n, size, size, 3), np.uint8),
        "visible": np.zeros((n, len(COLOURS)), np.int32),
        "box_visible": np.zeros(n, np.int32),
        "inside": np.zeros(n, bool),
        "camera": np.tile(np.arange(len(cameras), dtype=np.uint8), len(indices)),
        "scene_index": np.repeat(np.asarray(indices, np.int64), len(cameras)),
    }
    renderer, renderer_colours = None, None
    # Scenes with the same colours share an env (building one takes ~80 ms).
    order = sorted(range(len(plans)), key=lambda j: plans[j]["colours"])
    try:
        for j in order:
            plan = plans[j]
            if plan["colours"] != renderer_colours:
                if renderer is not None:  # keep one env alive at a time
                    renderer.close()
                renderer = _SceneRenderer("tabletop", plan["colours"] + (BOX,), size, tuple(cameras))
                renderer_colours = plan["colours"]
            env, rng = renderer.env, plan["actions_rng"]
            env.reset(seed=plan["env_seed"])
            if plan["into_box"] is not None:
                put_in_box(env, plan["into_box"], plan["offset"])
            for _ in range(plan["n_actions"]):
                *_, terminated, _, _ = env.step(rng.uniform(-1, 1, env.action_space.shape))
                if terminated:  # a block fell off the table: keep the frame, it is still a scene
                    break
            frames = env.render_cameras(cameras)
            pixels = np.stack([renderer.visible_pixels(c, COLOURS + (BOX,)) for c in cameras])
            rows = slice(j * len(cameras), (j + 1) * len(cameras))
            out["images"][rows] = np.stack([frames[c] for c in cameras])
            out["visible"][rows] = pixels[:, :len(COLOURS)]
            out["box_visible"][rows] = pixels[:, len(COLOURS)]
            out["inside"][rows] = block_inside(env)
            if progress is not None:
                progress(1)
    finally:
        if renderer is not None:
            renderer.close()
    return out


def load_box_renders(folder: str | Path, scenes: int, shard_size: int, seed: int = 0, image_size: int = 64,
                     progress: bool = True) -> dict:
    """The first ``scenes`` box scenes, rendered once and cached in ``folder`` shard by shard
    (``shard-0000.npz``, ...); arrays as :func:`render_box_scenes` returns them."""
    spec = {"kind": "box", "seed": seed, "shard_size": shard_size, "image_size": image_size}
    return load_cached_shards(folder, spec, scenes, shard_size, "box renders", "render box scenes",
                              lambda indices, bar: render_box_scenes(indices, seed=seed, size=image_size,
                                                                     progress=bar), progress)


__all__ = ["box_plan", "render_box_scenes", "load_box_renders", "put_in_box", "block_inside"]
