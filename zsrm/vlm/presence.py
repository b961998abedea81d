"""Renders labelled with which objects they show: the scene VLM's pretraining and test data.

Each scene is a tabletop (blocks) or pushing (pucks) exploration scene with a random subset
of the four colours, a random arm/pusher position and a few random actions, seen by all
three cameras. An object counts as visible in an image when at least
:data:`MIN_VISIBLE_PIXELS` of its pixels show (MuJoCo's segmentation render), so blocks hidden
by the gripper or fallen off the table are not named.

Captions say *what* is visible, never *where*: a random non-empty subset of the visible
objects in random order ("a blue block and a red block"). A caption never lists everything
that is absent, so "a red block" means "there is a red block", not "only a red block" (a
prototype whose captions named exactly the visible set learnt the latter and lost presence).
"""
from __future__ import annotations

from typing import Iterable

import numpy as np

from zsrm.tasks.language import COLOURS
from zsrm.tasks.relations import CAMERAS

SCENES = ("tabletop", "pushing")
SHAPES = {"tabletop": "block", "pushing": "puck"}
MIN_VISIBLE_PIXELS = 5  # at 64 px; scaled with image area for other sizes
STREAMS = {"train": 0, "eval": 1}  # disjoint seed streams for training and held-out scenes


def min_visible_pixels(image_size: int) -> int:
    return max(1, round(MIN_VISIBLE_PIXELS * (image_size / 64) ** 2))


def join_phrases(phrases: list[str]) -> str:
    """ "a red block", "a red block and a blue block", "a red block, a green block and a blue block"."""
    if not phrases:
        raise ValueError("nothing to name")
    if len(phrases) == 1:
        return phrases[0]
    return ", ".join(phrases[:-1]) + " and " + phrases[-1]


def probe_text(colour: str, shape: str) -> str:
    """The zero-shot presence probe of one object, e.g. "a red block"."""
    return f"a {colour} {shape}"


def presence_caption(colours: Iterable[str], shape: str, rng: np.random.Generator) -> str:
    """A caption naming a random non-empty subset of ``colours`` (the visible objects), in random order.

    >>> presence_caption(["red", "blue"], "block", np.random.default_rng(2))
    'a blue block and a red block'
    """
    colours = list(colours)
    if not colours:
        raise ValueError("a presence caption needs at least one visible object")
    k = int(rng.integers(1, len(colours) + 1))
    chosen = rng.permutation(len(colours))[:k]
    return join_phrases([probe_text(colours[i], shape) for i in chosen])


def all_presence_captions(shape: str) -> list[str]:
    """Every caption :func:`presence_caption` can write for a shape (ordered subsets of COLOURS)."""
    from itertools import permutations

    return [join_phrases([probe_text(c, shape) for c in perm])
            for k in range(1, len(COLOURS) + 1) for perm in permutations(COLOURS, k)]


def scene_plan(index: int, seed: int, stream: str = "train", max_actions: int = 10) -> dict:
    """What scene ``index`` of a seeded stream holds: scene kind, colours, env seed, actions."""
    rng = np.random.default_rng([STREAMS[stream], seed, index])
    scene = SCENES[int(rng.integers(len(SCENES)))]
    k = int(rng.integers(1, len(COLOURS) + 1))
    colours = tuple(COLOURS[i] for i in sorted(rng.choice(len(COLOURS), k, replace=False)))
    n_actions = int(rng.integers(0, max_actions + 1))
    return {"scene": scene, "colours": colours, "env_seed": int(rng.integers(2**31 - 1)),
            "actions_rng": rng, "n_actions": n_actions}


class _SceneRenderer:
    """One exploration env per (scene, colours), with a segmentation renderer to count visible pixels."""

    def __init__(self, scene: str, colours: tuple[str, ...], size: int, cameras: tuple[str, ...]):
        import mujoco

        from zsrm.envs.pushing import PushingEnv
        from zsrm.envs.tabletop import TabletopEnv

        cls = TabletopEnv if scene == "tabletop" else PushingEnv
        self.env = cls(task=None, objects=colours, cameras=cameras, image_size=size)
        self.cameras = cameras
        m = self.env.model
        self.seg = mujoco.Renderer(m, size, size)
        self.seg.enable_segmentation_rendering()
        self.option = mujoco.MjvOption()
        self.option.geomgroup[3] = 0  # the env's hidden (unused) objects
        self.geoms = {}
        for c in COLOURS:
            body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{cls.shape}_{c}")
            self.geoms[c] = np.arange(m.body_geomadr[body], m.body_geomadr[body] + m.body_geomnum[body])
        self.geom_type = int(mujoco.mjtObj.mjOBJ_GEOM)

    def visible_pixels(self, camera: str) -> np.ndarray:
        """Pixels of each colour's object in a camera, in COLOURS order."""
        self.seg.update_scene(self.env.data, camera=camera, scene_option=self.option)
        seg = self.seg.render()
        ids = np.where(seg[..., 1] == self.geom_type, seg[..., 0], -1)
        return np.array([np.isin(ids, self.geoms[c]).sum() for c in COLOURS])

    def close(self):
        self.seg.close()
        self.env.close()


def render_presence_scenes(indices: Iterable[int], seed: int = 0, stream: str = "train", size: int = 64,
                           cameras: tuple[str, ...] = CAMERAS, max_actions: int = 10, progress=None) -> dict:
    """Render scenes ``indices`` of a seeded stream from every camera.

    Returns arrays, one row per image (scene-major, cameras in order): ``images`` (N, size,
    size, 3) uint8, ``visible`` (N, 4) visible pixel counts in COLOURS order, ``in_scene``
    (N, 4) bool (the object is in the scene, visible or not), ``shape`` (N,) 0 block / 1 puck,
    ``camera`` (N,) index into ``cameras``, ``scene_index`` (N,). ``progress``: a callable
    called once per scene (e.g. a tqdm bar's ``update``).
    """
    indices = list(indices)
    plans = [scene_plan(i, seed, stream, max_actions) for i in indices]
    renderers: dict[tuple, _SceneRenderer] = {}
    n = len(indices) * len(cameras)
    out = {
        "images": np.zeros((n, size, size, 3), np.uint8),
        "visible": np.zeros((n, len(COLOURS)), np.int32),
        "in_scene": np.zeros((n, len(COLOURS)), bool),
        "shape": np.zeros(n, np.uint8),
        "camera": np.tile(np.arange(len(cameras), dtype=np.uint8), len(indices)),
        "scene_index": np.repeat(np.asarray(indices, np.int64), len(cameras)),
    }
    # Scenes that share a kind and colours share an env (building one takes ~80 ms).
    order = sorted(range(len(plans)), key=lambda j: (plans[j]["scene"], plans[j]["colours"]))
    try:
        for j in order:
            plan = plans[j]
            key = (plan["scene"], plan["colours"])
            if key not in renderers:
                for r in renderers.values():  # keep one env alive at a time
                    r.close()
                renderers = {key: _SceneRenderer(*key, size, tuple(cameras))}
            r = renderers[key]
            env, rng = r.env, plan["actions_rng"]
            env.reset(seed=plan["env_seed"])
            for _ in range(plan["n_actions"]):
                *_, terminated, _, _ = env.step(rng.uniform(-1, 1, env.action_space.shape))
                if terminated:  # an object fell off the table: keep the frame, it is still a scene
                    break
            frames = env.render_cameras(cameras)
            rows = slice(j * len(cameras), (j + 1) * len(cameras))
            out["images"][rows] = np.stack([frames[c] for c in cameras])
            out["visible"][rows] = np.stack([r.visible_pixels(c) for c in cameras])
            out["in_scene"][rows] = [c in plan["colours"] for c in COLOURS]
            out["shape"][rows] = SCENES.index(plan["scene"])
            if progress is not None:
                progress(1)
    finally:
        for r in renderers.values():
            r.close()
    return out


def visible_colours(visible_row: np.ndarray, image_size: int = 64) -> list[str]:
    """Colours whose objects show enough pixels to be named."""
    threshold = min_visible_pixels(image_size)
    return [c for c, n in zip(COLOURS, visible_row) if n >= threshold]
