"""Renders of a user's own scene with the count of each object's visible pixels: the data the
``scene`` stand-in VLM learns the scene's object names from (``zsrm pretrain-vlm --scene``).

This is the one step that reads the simulator's object list: which objects a render shows
comes from the adapter's privileged :meth:`~zsrm.envs.SceneAdapter.object_positions` (and
MuJoCo's segmentation render). The captions made from it name only which objects are present,
never where. With real CLIP weights this step is skipped: CLIP already knows the words.

Each object's pixels are those of the body whose position the accessor returns (and the
bodies below it), so an accessor that reads body positions, as the example's does, is all it
takes. Scenes come from seeded streams apart from :mod:`zsrm.data.renders`' (train and
held-out), and are cached shard by shard like them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable

import mujoco
import numpy as np

from zsrm.data.renders import load_cached_shards
from zsrm.envs.adapter import ROLES, SceneAdapter, check_env, check_phrases_known

STREAMS = {"train": 2, "eval": 3}  # seed streams, apart from zsrm's renders' (0, 1)


def own_scene_plan(adapter: SceneAdapter, index: int, seed: int, stream: str = "train", max_actions: int = 10) -> dict:
    """What scene ``index`` of a seeded stream holds: which objects (one to all, where the env
    can leave some out), the env's seed, the exploration actions' generator and their number."""
    rng = np.random.default_rng([STREAMS[stream], seed, index])
    objects = tuple(adapter.objects)
    if adapter.holds_subsets:
        k = int(rng.integers(1, len(objects) + 1))
        chosen = set(rng.choice(len(objects), k, replace=False).tolist())
        objects = tuple(o for i, o in enumerate(adapter.objects) if i in chosen)
    return {"objects": objects, "env_seed": int(rng.integers(2**31 - 1)), "actions_rng": rng,
            "n_actions": int(rng.integers(0, max_actions + 1))}


class _Segmenter:
    """Visible pixels of each object of an env, from MuJoCo's segmentation render."""

    def __init__(self, env, size: int):
        self.model, self.data = env.unwrapped.model, env.unwrapped.data
        self.renderer = mujoco.Renderer(self.model, size, size)
        self.renderer.enable_segmentation_rendering()
        self.geom_type = int(mujoco.mjtObj.mjOBJ_GEOM)

    def _body_of(self, xyz) -> int:
        """The body at ``xyz`` (the nearest body origin but the world)."""
        d = np.linalg.norm(self.data.xpos[1:] - np.asarray(xyz)[None], axis=1)
        return int(np.argmin(d)) + 1

    def _subtree(self, body: int) -> np.ndarray:
        """The geoms of ``body`` and of every body below it."""
        bodies, ids = {body}, []
        for b in range(body + 1, self.model.nbody):
            if self.model.body_parentid[b] in bodies:
                bodies.add(b)
        for b in sorted(bodies):
            ids += range(self.model.body_geomadr[b], self.model.body_geomadr[b] + self.model.body_geomnum[b])
        return np.array(ids, np.int64)

    def mask(self, camera: str, positions: dict[str, np.ndarray], objects: tuple[str, ...]) -> np.ndarray:
        """(size, size) uint8: which of ``objects`` each pixel of ``camera`` shows (1-based; 0: none)."""
        self.renderer.update_scene(self.data, camera=camera)
        seg = self.renderer.render()
        ids = np.where(seg[..., 1] == self.geom_type, seg[..., 0], -1)
        out = np.zeros(ids.shape, np.uint8)
        for j, o in enumerate(objects):
            if o in positions:
                out[np.isin(ids, self._subtree(self._body_of(positions[o])))] = j + 1
        return out

    def close(self):
        self.renderer.close()


def render_own_scenes(adapter: SceneAdapter, indices: Iterable[int], seed: int = 0, stream: str = "train",
                      size: int = 64, max_actions: int = 10, progress=None, masks: bool = False) -> dict:
    """Render scenes ``indices`` of a seeded stream from every camera role.

    Returns one row per image (scene-major, roles in Table 1's order): ``images`` (N, size,
    size, 3) uint8, ``visible`` (N, K) visible pixels of each of the adapter's K objects,
    ``in_scene`` (N, K) bool, ``camera`` (N,) index into the roles, ``scene_index`` (N,); with
    ``masks``, ``masks`` (N, size, size) uint8, each pixel's object (1-based, 0: none).
    """
    indices, objects = list(indices), tuple(adapter.objects)
    plans = [own_scene_plan(adapter, i, seed, stream, max_actions) for i in indices]
    n, k = len(indices) * len(ROLES), len(objects)
    out = {"images": np.zeros((n, size, size, 3), np.uint8), "visible": np.zeros((n, k), np.int32),
           "in_scene": np.zeros((n, k), bool), "camera": np.tile(np.arange(len(ROLES), dtype=np.uint8), len(indices)),
           "scene_index": np.repeat(np.asarray(indices, np.int64), len(ROLES))}
    if masks:
        out["masks"] = np.zeros((n, size, size), np.uint8)
    env = seg = None
    current = None
    try:
        # scenes that hold the same objects share an env; one env alive at a time
        for j in sorted(range(len(plans)), key=lambda j: plans[j]["objects"]):
            plan = plans[j]
            if plan["objects"] != current:
                if env is not None:
                    seg.close()
                    env.close()
                env = check_env(adapter, adapter.make_env(tuple(adapter.roles.values()), size, plan["objects"]))
                seg, current = _Segmenter(env, size), plan["objects"]
            _render_one(adapter, env, seg, plan, out, slice(j * len(ROLES), (j + 1) * len(ROLES)), objects)
            if progress is not None:
                progress(1)
    finally:
        if env is not None:
            seg.close()
            env.close()
    return out


def _render_one(adapter: SceneAdapter, env, seg: _Segmenter, plan: dict, out: dict, rows: slice, objects) -> None:
    obs, _ = env.reset(seed=plan["env_seed"])
    for _ in range(plan["n_actions"]):
        obs, _, terminated, truncated, _ = env.step(adapter.exploration_action(env, plan["actions_rng"]))
        if terminated or truncated:  # an object fell: keep the frame, it is still a scene
            break
    images = adapter.observe(obs)
    positions = adapter.object_positions(env)  # privileged: which objects there are, for the captions
    check_phrases_known(adapter, positions)
    out["images"][rows] = np.stack([images[r] for r in ROLES])
    role_masks = np.stack([seg.mask(adapter.roles[r], positions, objects) for r in ROLES])
    out["visible"][rows] = [np.bincount(m.ravel(), minlength=len(objects) + 1)[1:] for m in role_masks]
    if "masks" in out:
        out["masks"][rows] = role_masks
    out["in_scene"][rows] = [o in positions for o in objects]


def disc_radius(areas) -> float:
    """The radius of a disc of the median of ``areas`` (an object's visible pixels in renders that
    show it): its size in pixels, whatever its shape."""
    return float(np.sqrt(np.median(areas) / np.pi))


def check_captions_vary(renders: dict, adapter: SceneAdapter, image_size: int = 64) -> None:
    """Refuse renders whose presence captions cannot teach the objects' names: an object shown in
    every render (or in none) is a word no caption ever contrasts, and the VLM trains at chance."""
    from zsrm.vlm.presence import min_visible_pixels

    shown = renders["visible"] >= min_visible_pixels(image_size)
    always = [o for j, o in enumerate(adapter.objects) if shown[:, j].all()]
    never = [o for j, o in enumerate(adapter.objects) if not shown[:, j].any()]
    if always or never:
        what = "; ".join(part for part in (
            f"{', '.join(always)} {'is' if len(always) == 1 else 'are'} shown in every render" if always else "",
            f"{', '.join(never)} in none" if never else "") if part)
        fix = ("let its scenes hold subsets of the objects (a bare XML: name each object's body in bodies; your own "
               "env: an objects= keyword)" if always else "check the cameras see the objects and bodies names them")
        raise ValueError(f"{adapter.name}: the presence captions never vary ({what}): the VLM could not learn which "
                         f"word is which object; {fix}")


def load_own_renders(folder: str | Path, adapter: SceneAdapter, scenes: int, shard_size: int, seed: int = 0,
                     image_size: int = 64, progress: bool = True, masks: bool = False) -> dict:
    """The first ``scenes`` training scenes of the adapter's scene, rendered once and cached in
    ``folder`` shard by shard; arrays as :func:`render_own_scenes` returns them."""
    spec = {"scene": adapter.name, "objects": list(adapter.objects), "seed": seed, "shard_size": shard_size,
            "image_size": image_size, "stream": "train"}
    if masks:  # renders made before masks existed keep their spec
        spec["masks"] = True
    return load_cached_shards(folder, spec, scenes, shard_size, "renders", "render own scenes",
                              lambda indices, bar: render_own_scenes(adapter, indices, seed=seed, size=image_size,
                                                                     progress=bar, masks=masks), progress)
