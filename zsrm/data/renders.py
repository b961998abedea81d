"""Renders of random scenes with the count of each colour's visible pixels: the data the scene
VLM is pretrained (``zsrm pretrain-vlm``) and tested (``zsrm eval-vlm``) on.

Each scene is a tabletop (blocks) or pushing (pucks) exploration scene with a random subset
of the four colours, a random arm/pusher position and a few random actions, seen by all
three cameras. Visible pixels come from MuJoCo's segmentation render. Scenes come from two
disjoint seed streams, one for training and one held out. :func:`load_renders` renders the
training scenes once and caches them shard by shard, so a killed run keeps its shards.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable

import numpy as np

from zsrm.common.files import check_writable, read_json, write_json
from zsrm.data.shards import load_npz, save_npz
from zsrm.tasks.catalogue import SCENE_SHAPES
from zsrm.tasks.language import COLOURS
from zsrm.tasks.relations import CAMERAS

SCENES = tuple(SCENE_SHAPES)  # a render's "shape" is its scene's index here: 0 block, 1 puck
STREAMS = {"train": 0, "eval": 1}  # disjoint seed streams for training and held-out scenes


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
        for c in COLOURS + cls.containers:  # containers (the tabletop's box) are bodies named as they are
            name = c if c in cls.containers else f"{cls.shape}_{c}"
            body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
            self.geoms[c] = np.arange(m.body_geomadr[body], m.body_geomadr[body] + m.body_geomnum[body])
        self.geom_type = int(mujoco.mjtObj.mjOBJ_GEOM)

    def visible_pixels(self, camera: str, objects: tuple[str, ...] = COLOURS) -> np.ndarray:
        """Pixels of each object in a camera, in the order of ``objects`` (default: the colours')."""
        self.seg.update_scene(self.env.data, camera=camera, scene_option=self.option)
        seg = self.seg.render()
        ids = np.where(seg[..., 1] == self.geom_type, seg[..., 0], -1)
        return np.array([np.isin(ids, self.geoms[c]).sum() for c in objects])

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


def load_renders(folder: str | Path, scenes: int, shard_size: int, seed: int = 0, image_size: int = 64,
                 progress: bool = True) -> dict:
    """The first ``scenes`` training scenes, rendered once and cached in ``folder`` shard by shard
    (``shard-0000.npz``, ...); arrays as :func:`render_presence_scenes` returns them."""
    spec = {"seed": seed, "shard_size": shard_size, "image_size": image_size, "stream": "train"}
    return load_cached_shards(folder, spec, scenes, shard_size, "renders", "render scenes",
                              lambda indices, bar: render_presence_scenes(indices, seed=seed, size=image_size,
                                                                          progress=bar), progress)


def load_cached_shards(folder: str | Path, spec: dict, scenes: int, shard_size: int, what: str, desc: str,
                       render, progress: bool = True) -> dict:
    """The first ``scenes`` scenes of ``render(indices, progress)``, rendered once and cached in
    ``folder`` shard by shard under a manifest holding ``spec`` (a folder made with another spec
    is refused: ``what`` names its contents in the message), so a killed run keeps its shards."""
    from tqdm import tqdm

    folder = check_writable(folder, folder=True)
    manifest = folder / "manifest.json"
    if manifest.exists() and read_json(manifest, f"the settings of cached {what}") != spec:
        raise ValueError(f"{folder} holds {what} made with other settings ({manifest.read_text().strip()}); "
                         "use another --workdir or --fresh")
    write_json(manifest, spec, indent=None)
    shards = []
    n_shards = math.ceil(scenes / shard_size)
    with tqdm(total=n_shards * shard_size, desc=desc, unit="scene", disable=not progress) as bar:
        for s in range(n_shards):
            path = folder / f"shard-{s:04d}.npz"
            if path.exists():
                data = load_npz(path)
                bar.update(shard_size)
            else:  # always whole shards, so that a shard means the same scenes in every run
                data = render(range(s * shard_size, (s + 1) * shard_size), bar.update)
                save_npz(path, **data)
            keep = data["scene_index"] < min(scenes, (s + 1) * shard_size)
            shards.append({k: v[keep] for k, v in data.items()})
    return {k: np.concatenate([sh[k] for sh in shards]) for k in shards[0]}
