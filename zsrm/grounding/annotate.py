"""``zsrm label``: caption collected exploration images with Grad-CAM + Table 1 (paper 2.2).

For every shard of a dataset folder, the labels folder (``DATA/labels`` by default) gets:

* ``shard_XXXXX.npz``: per camera, the Grad-CAM heat maps, located pixel coordinates,
  heat-map peaks and target scores of every colour's phrase; in data collected with the box
  (``zsrm collect --p-box``), the same of the box's phrase "a box" apart (``gradcam_box_*``),
  on the images whose scene holds it;
* ``shard_XXXXX.json``: ``{"captions": [[...], ...]}``, the Grad-CAM captions of each image:
  what the reward model trains on. Only images and the scene's object list were read;
* ``oracle/shard_XXXXX.json``: the captions that the TRUE coordinates give, kept apart for
  evaluation only: ``"pixel"`` (true pixel coordinates through the same rules and pixel
  thresholds) and ``"world"`` (the oracle on true world positions).

Data of an own scene (``zsrm collect --scene``) are labelled the same way over its adapter's
phrases ("a red mug close to a blue plate", the own-scene goal grammar): Grad-CAM of each
phrase (the VLM must know them: ``zsrm pretrain-vlm --scene``, or real CLIP), pixel thresholds
from the adapter's ``object_width``, the tilted camera read on the table where the adapter gives
its ``table_height``, its points refined to their silhouettes uncalibrated (:func:`own_silhouettes`). The oracle's captions read the true positions
along the role cameras' own axes, as its SceneTask oracle does (:func:`own_scene_record`).

>>> import tempfile
>>> from zsrm.data.collect import CollectConfig, collect
>>> from zsrm.testing import ColourVLM
>>> folder = tempfile.mkdtemp()
>>> data = collect(CollectConfig(images=4, shard_size=4, episode_steps=2, record_every=1), folder, progress=False)
>>> _ = label_dataset(folder, LabelConfig(vlm="testing"), vlm=ColourVLM(64), progress=False)
>>> len(data.captions()), len(data.captions(oracle="pixel"))
(4, 4)
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from zsrm.data.dataset import LABELS, ORACLE, ExplorationData, with_box
from zsrm.data.shards import ShardFolder, save_json, save_npz
from zsrm.grounding.gradcam import GradCAM
from zsrm.grounding.labeler import OBJECT_WIDTH, SpatialLabeler, pixel_thresholds, world_table
from zsrm.grounding.silhouette import Silhouette, calibrate, refine_points, region_area
from zsrm.tasks.catalogue import SCENE_SHAPES
from zsrm.tasks.lexicon import BOX
from zsrm.tasks.relations import RELATIONS, TABLE_PLANE_CAMERAS, WORLD_THRESHOLDS, Thresholds
from zsrm.vlm.factory import DEFAULT_VLM
from zsrm.vlm.presence import BOX_PHRASE


# The shipped scene VLM was never shown the box; this one was (zsrm pretrain-vlm --box-scenes).
BOX_VLM = "scene-box"


@dataclass
class LabelConfig:
    """Options of ``zsrm label``. Thresholds are in metres (Table 1's, for 6 cm blocks); each
    camera's pixel thresholds are these times that camera's pixels per metre."""

    vlm: str = DEFAULT_VLM  # the VLM Grad-CAM reads: scene, a saved VLM folder, open_clip:MODEL[:TAG]
    target: Literal["contrast", "score"] = "contrast"  # Grad-CAM target: a phrase's score minus the other colours' mean, or the score
    locate: Literal["argmax", "peak_centroid", "fine"] = "fine"  # object position: the heat map's argmax cell, the centroid of its peak, or the peak centroid of LayerCAM at the VLM's finer layer (mirrored and shifted views averaged)
    cell_centres: Literal["grid", "receptive_field"] = "receptive_field"  # pixel position of each Grad-CAM cell: its geometric centre, or the peak of its measured input gradient
    template: str = "{}"  # how a phrase is written to the text tower, e.g. "a {}"
    batch_size: int = 64  # images per Grad-CAM batch
    refine: Literal["none", "silhouette"] = "silhouette"  # on the table-plane (tilted) camera, move each Grad-CAM point to its object's silhouette centre (zsrm.grounding.silhouette), or keep it
    box_vlm: str | None = None  # the VLM whose Grad-CAM finds the box, in data collected with it (a box-aware VLM); default: scene-box with the scene VLM (shipped: pretrained on box scenes), else --vlm itself
    thresholds: dict = field(default_factory=lambda: asdict(WORLD_THRESHOLDS), metadata={"cli": False})  # Table 1's, in metres
    on_top: Literal["solid", "front"] = "solid"  # an own scene with calibrated cameras (collected from 2026-12-07): on top of / below read in 3-D, on points triangulated from the tilted and left cameras (the oracle on true positions), or on the front camera as Table 1 (as before)

    def world_thresholds(self) -> Thresholds:
        return Thresholds(**self.thresholds)


def phrases_for(scene: str, colours) -> list[str]:
    """The Grad-CAM phrases of a scene's objects: "red block" in zsrm's scenes; an own scene's
    objects are their adapter's phrases already ("red mug")."""
    if scene not in SCENE_SHAPES:
        return list(colours)
    return [f"{c} {SCENE_SHAPES[scene]}" for c in colours]


def caption_shape(scene: str) -> str | None:
    """The shape zsrm's captions name in ``scene``; None for an own scene (its phrases)."""
    return SCENE_SHAPES.get(scene)


class Grounder:
    """Grad-CAM coordinates of every colour's phrase on every camera of a dataset's images."""

    def __init__(self, vlm, cfg: LabelConfig, data: ExplorationData, centres: list | None = None,
                 fine_centres: list | None = None, box_vlm=None, silhouettes: dict | None = None,
                 box_min_area: float = 0.0):
        self.cfg, self.data = cfg, data
        # On a table-plane camera, a box point whose silhouette covers less of the table than this
        # (square metres) sat on a block, not the box: the box goes unlocated there. 0: no check
        # (zsrm label's way).
        self.box_min_area = float(box_min_area)
        # Colours (an own scene's objects) the data can hold: each phrase contrasts with the others.
        self.allowed = [c for c in data.colours if c not in data.config["exclude"]]
        self.gradcam = {
            scene: GradCAM(vlm, target=cfg.target, contrast=phrases_for(scene, self.allowed), locate=cfg.locate,
                           cell_centres=cfg.cell_centres, presence_threshold=None, batch_size=cfg.batch_size,
                           template=cfg.template)
            for scene in data.scenes
        }
        size = data.config["image_size"]
        # Measured once, on the first shard's front images, so that a resumed run uses the
        # same centres as an uninterrupted one.
        first = data.shard(data.shards[0], [f"images_{data.cameras[0]}"])[f"images_{data.cameras[0]}"][:8]
        cam = next(iter(self.gradcam.values()))
        self.centres = np.asarray(cam.calibrate(first) if centres is None else centres, dtype=np.float64)
        self.fine_centres = None
        if cfg.locate == "fine":
            self.fine_centres = np.asarray(cam.calibrate(first, fine=True) if fine_centres is None else fine_centres,
                                           dtype=np.float64)
        # The box is named as the box-aware pretraining names it ("a box", whatever the colour
        # phrases' template), its score contrasted with the colours' phrases; the colours' own
        # Grad-CAM is untouched, so their coordinates are those of data without the box.
        self.box_gradcam = None
        if data.has_box:
            self.box_gradcam = GradCAM(vlm if box_vlm is None else box_vlm, target=cfg.target, locate=cfg.locate, cell_centres=cfg.cell_centres,
                                       contrast=[cfg.template.format(p) for p in phrases_for("tabletop", self.allowed)],
                                       presence_threshold=None, batch_size=cfg.batch_size)
        for g in list(self.gradcam.values()) + ([self.box_gradcam] if self.box_gradcam else []):
            g.set_centres(self.centres, (size, size))
            if self.fine_centres is not None:
                g.set_centres(self.fine_centres, (size, size), fine=True)
        # {scene: {camera: {"object": Silhouette, "box": Silhouette}}} of the table-plane cameras,
        # measured once (and kept in the labels manifest, so that a resumed run refines alike).
        self.silhouettes = {}
        if cfg.refine == "silhouette":
            if silhouettes is None:
                silhouettes = {scene: own_silhouettes(data, scene) if data.scene_adapter else calibrate_scene(data, scene)
                               for scene in data.scenes}
            self.silhouettes = {scene: {cam: {k: Silhouette.from_json(v) if isinstance(v, dict) else v
                                              for k, v in sils.items()} for cam, sils in cams.items()}
                                for scene, cams in silhouettes.items()}

    def silhouettes_json(self) -> dict:
        return {scene: {cam: {k: v.to_json() for k, v in sils.items()} for cam, sils in cams.items()}
                for scene, cams in self.silhouettes.items()}

    def shard(self, arrays: dict, colours=None) -> dict[str, np.ndarray]:
        """Per camera: ``gradcam_xy_<cam>`` (n, 4, 2), ``gradcam_score_<cam>``,
        ``gradcam_peak_<cam>`` (n, 4), ``gradcam_map_<cam>`` (n, 4, h, w) float16; NaN or
        0 for colours the data never holds (and for those not in ``colours``, where given: Grad-CAM
        of the others alone, which are the same, each phrase's map its own). With the box (``arrays`` holding ``box_present``):
        ``gradcam_box_xy_<cam>`` (n, 2), ``gradcam_box_score_<cam>``, ``gradcam_box_peak_<cam>``
        (n,), ``gradcam_box_map_<cam>`` (n, h, w), NaN or 0 where the scene has no box."""
        n, k = len(arrays["scene"]), len(self.data.colours)
        located = [c for c in self.allowed if colours is None or c in colours]
        cols = [self.data.colours.index(c) for c in located]
        out = {}
        for cam in self.data.cameras:
            xy = np.full((n, k, 2), np.nan, np.float32)
            score = np.full((n, k), np.nan, np.float32)
            peak = np.zeros((n, k), np.float32)
            maps = None
            for s, scene in enumerate(self.data.scenes):
                rows = np.nonzero(arrays["scene"] == s)[0]
                if not len(rows):
                    continue
                images = arrays[f"images_{cam}"][rows]
                res = self.gradcam[scene](images, phrases_for(scene, located))
                if maps is None:
                    maps = np.zeros((n, k) + res.maps.shape[-2:], np.float16)
                sil = self.silhouettes.get(scene, {}).get(cam)
                xy[rows[:, None], cols] = res.xy if sil is None else refine_points(images, res.xy, sil["object"])
                score[rows[:, None], cols] = res.score
                peak[rows[:, None], cols] = res.peak
                maps[rows[:, None], cols] = res.maps
            out.update({f"gradcam_xy_{cam}": xy, f"gradcam_score_{cam}": score, f"gradcam_peak_{cam}": peak,
                        f"gradcam_map_{cam}": maps})
            if self.box_gradcam is not None and "box_present" in arrays:
                out.update(self._box(arrays[f"images_{cam}"], arrays["box_present"], maps.shape[-2:], cam))
        return out

    def _box(self, images: np.ndarray, box_present: np.ndarray, grid, cam: str) -> dict[str, np.ndarray]:
        """Grad-CAM of the box's phrase on the images whose scene holds the box."""
        n = len(images)
        xy, score = np.full((n, 2), np.nan, np.float32), np.full(n, np.nan, np.float32)
        peak, maps = np.zeros(n, np.float32), np.zeros((n,) + tuple(grid), np.float16)
        rows = np.nonzero(box_present)[0]
        if len(rows):
            res = self.box_gradcam(images[rows], [BOX_PHRASE])
            xy[rows], score[rows], peak[rows], maps[rows] = res.xy[:, 0], res.score[:, 0], res.peak[:, 0], res.maps[:, 0]
            sil = self.silhouettes.get("tabletop", {}).get(cam)  # only tabletop scenes hold the box
            if sil is not None:
                xy[rows] = refine_points(images[rows], xy[rows], sil["box"])
                if self.box_min_area:
                    homography = self.data.table_homography["tabletop"][cam]
                    small = [i for i in rows if region_area(images[i], xy[i], sil["box"], homography) < self.box_min_area]
                    xy[small] = np.nan
        return {f"gradcam_box_xy_{cam}": xy, f"gradcam_box_score_{cam}": score, f"gradcam_box_peak_{cam}": peak,
                f"gradcam_box_map_{cam}": maps}


def calibrate_scene(data: ExplorationData, scene: str) -> dict[str, dict[str, Silhouette]]:
    """The silhouettes (:mod:`zsrm.grounding.silhouette`) of a scene's object, and of the box
    where the data can hold it, on each of its table-plane cameras, from calibration renders."""
    import gymnasium as gym

    import zsrm.envs  # noqa: F401  (registers the ids)
    from zsrm.envs.tabletop import BOX_HALF
    from zsrm.tasks.catalogue import SCENE_IDS

    cameras = list(data.table_homography.get(scene, {}))
    if not cameras:
        return {}
    box = data.has_box and scene == "tabletop"
    objects = tuple(data.colours) + ((BOX,) if box else ())
    size, shape = data.config["image_size"], SCENE_SHAPES[scene]
    env = gym.make(SCENE_IDS[scene], task=None, objects=objects, cameras=tuple(cameras), image_size=size).unwrapped
    try:
        env.reset(seed=0)
        out = {}
        for cam in cameras:
            width = data.block_width_px[scene][cam]
            out[cam] = {"object": calibrate(env, cam, size, objects[0], True, width)}
            if box:
                out[cam]["box"] = calibrate(env, cam, size, BOX, False, width * 2 * BOX_HALF / OBJECT_WIDTH[shape])
        return out
    finally:
        env.close()


def own_silhouettes(data: ExplorationData, scene: str) -> dict[str, dict[str, Silhouette]]:
    """An own scene's silhouettes on its table-plane cameras, uncalibrated: a window of one
    object width, no offset, never treated as partly hidden. zsrm measures offset and area on
    renders of each object alone at known table positions (:func:`calibrate_scene`), which an
    own scene's env does not offer; the images alone give the region's centroid."""
    return {cam: {"object": Silhouette(half_window=float(round(data.block_width_px[scene][cam])))}
            for cam in data.cameras if cam in TABLE_PLANE_CAMERAS}


def labelers(data: ExplorationData, cfg: LabelConfig, relations=tuple(RELATIONS)) -> dict[str, SpatialLabeler]:
    """The labeler of each scene: its shape's words, its cameras' pixel thresholds, and the
    tilted camera read on the table in metres when the data has its calibration. It relates
    the data's objects (:attr:`ExplorationData.objects`: the colours, and the box if the data
    can hold it; only tabletop scenes ever hold it), by ``relations`` (data of fewer cameras: theirs)."""
    out = {}
    world = world_thresholds(data, cfg)
    # An own scene: one width for all its objects (its adapter's), captions over its phrases (no shape).
    own_width = own_object_width(data) if data.scene_adapter else None
    for scene in data.scenes:
        table, shape = data.table_homography.get(scene, {}), caption_shape(scene)
        thresholds = pixel_thresholds(data.block_width_px[scene], shape, world, table, object_width=own_width)
        rays = data.pixel_rays.get(scene) if reads_solid(data, cfg) else None
        out[scene] = SpatialLabeler(thresholds, shape=shape, colours=data.objects, relations=relations,
                                    table_homography=table, rays=rays, solid_thresholds=world if rays else None)
    return out


def reads_solid(data: ExplorationData, cfg: LabelConfig) -> bool:
    """Do the labeler and the oracle read on top of / below in 3-D on this data (``cfg.on_top``
    "solid", an own scene whose collection recorded its cameras' rays)?"""
    return cfg.on_top == "solid" and bool(data.scene_adapter) and bool(data.pixel_rays)


def captions_from_pixels(data: ExplorationData, cfg: LabelConfig, pixels: dict, present: np.ndarray,
                         scene_index: np.ndarray) -> list[list[str]]:
    """Captions of N images from pixel coordinates ``{camera: (N, K, 2)}`` of the data's K
    objects (:meth:`ExplorationData.object_arrays`)."""
    out: list[list[str]] = [[] for _ in range(len(present))]
    for s, (scene, labeler) in enumerate(labelers(data, cfg).items()):
        rows = np.nonzero(scene_index == s)[0]
        if len(rows):
            caps = labeler.captions({c: xy[rows] for c, xy in pixels.items()}, present[rows])
            for r, cap in zip(rows, caps):
                out[r] = cap
    return out


def world_captions(data: ExplorationData, cfg: LabelConfig, positions, present, scene_index,
                   axes: dict | None = None) -> list[list[str]]:
    """The oracle's captions from true world positions (evaluation only); an own scene's read
    along its role cameras' ``axes`` (:func:`own_scene_record`), as its oracle reads them."""
    out: list[list[str]] = [[] for _ in range(len(present))]
    for s, scene in enumerate(data.scenes):
        rows = np.nonzero(scene_index == s)[0]
        if len(rows):
            table = world_table(positions[rows], present[rows], data.objects, world_thresholds(data, cfg), axes=axes,
                                solid=reads_solid(data, cfg))
            for r, cap in zip(rows, table.captions(caption_shape(scene))):
                out[r] = cap
    return out


def label_dataset(data_folder, cfg: LabelConfig, out: str | Path = LABELS, vlm=None, progress: bool = True) -> Path:
    """Label every finished shard of ``data_folder`` not labelled yet; returns the labels folder.
    ``vlm``: a loaded model (default: ``load_vlm(cfg.vlm)``)."""
    from tqdm import tqdm

    data = ExplorationData(data_folder)
    if not data.shards:
        raise ValueError(f"{data_folder} holds no finished shard: run zsrm collect first")
    folder = data.labels_folder(out)
    from zsrm.vlm import load_vlm

    if vlm is None:
        vlm = load_vlm(cfg.vlm)
    box_spec = cfg.box_vlm or (BOX_VLM if cfg.vlm == DEFAULT_VLM else None)
    box_vlm = load_vlm(box_spec) if box_spec is not None and data.has_box else None
    extra = {"data": str(Path(data_folder).resolve())}
    if data.scene_adapter:
        extra["own_scene"] = own_scene_record(data, cfg, vlm)
    shards = ShardFolder(folder, kind="labels", config=asdict(cfg), n_shards=data.manifest["n_shards"], extra=extra)
    axes = shards.manifest["own_scene"]["oracle_axes"] if data.scene_adapter else None
    grounder = Grounder(vlm, cfg, data, shards.manifest.get("centres"), shards.manifest.get("fine_centres"),
                        box_vlm=box_vlm, silhouettes=shards.manifest.get("silhouettes"))
    shards.manifest.setdefault("centres", grounder.centres.tolist())
    if grounder.silhouettes:
        shards.manifest.setdefault("silhouettes", grounder.silhouettes_json())
    if grounder.fine_centres is not None:
        shards.manifest.setdefault("fine_centres", grounder.fine_centres.tolist())
    todo = [i for i in shards.pending() if shard_done(data, i)]
    bar = tqdm(total=sum(data.manifest["shards"][f"shard_{i:05d}"]["images"] for i in todo), unit="img",
               desc="label", disable=not progress)
    try:
        for index in todo:
            name = f"shard_{index:05d}"
            arrays = data.shard(name)
            grad = grounder.shard({k: v for k, v in arrays.items()
                                   if k.startswith("images_") or k in ("scene", "box_present")})
            objects = data.object_arrays(arrays)  # the colours, and the box where the data has it
            # Training captions: from the Grad-CAM coordinates and the scene's object list only.
            captions = captions_from_pixels(data, cfg, gradcam_objects(data, grad), objects["present"], arrays["scene"])
            # Evaluation only: what the true coordinates say.
            truth_pixel = captions_from_pixels(data, cfg, {c: objects[f"pixels_{c}"] for c in data.cameras},
                                               objects["present"], arrays["scene"])
            truth_world = world_captions(data, cfg, objects["positions"], objects["present"], arrays["scene"], axes)
            save_npz(shards.path(index, ".npz"), **grad)
            save_json(shards.path(index, ".json", sub=ORACLE), {"pixel": truth_pixel, "world": truth_world})
            save_json(shards.path(index, ".json"), {"captions": captions})
            shards.finish(index, {"images": len(captions)})
            bar.update(len(captions))
    finally:
        bar.close()
    return folder


def gradcam_objects(data: ExplorationData, grad: dict) -> dict[str, np.ndarray]:
    """Grad-CAM coordinates ``{camera: (N, K, 2)}`` of the data's objects: the colours' and,
    where the data can hold the box, the box's as the last object."""
    if not data.has_box:
        return {c: grad[f"gradcam_xy_{c}"] for c in data.cameras}
    return {c: with_box(grad[f"gradcam_xy_{c}"], grad[f"gradcam_box_xy_{c}"]) for c in data.cameras}


def shard_done(data: ExplorationData, index: int) -> bool:
    return f"shard_{index:05d}" in data.manifest["shards"]


# --- an own scene (zsrm collect --scene) --------------------------------------------------------
def own_object_width(data: ExplorationData) -> float:
    """An own scene's object width in metres: as zsrm collect recorded it, else its adapter's."""
    info = data.manifest["scene_adapter"]
    if "object_width" in info:
        return float(info["object_width"])
    from zsrm.envs.adapter import load_adapter

    return float(load_adapter(info["name"]).object_width)


def world_thresholds(data: ExplorationData, cfg: LabelConfig) -> Thresholds:
    """Table 1's thresholds in metres for the data: the configured ones (set for zsrm's 6 cm
    blocks), scaled to an own scene's object width as its oracle scales them (scene_thresholds)."""
    if not data.scene_adapter:
        return cfg.world_thresholds()
    from zsrm.envs.scene_task import REFERENCE_WIDTH

    return cfg.world_thresholds().scaled(own_object_width(data) / REFERENCE_WIDTH)


def check_vlm_knows(vlm, phrases, spec: str, scene: str) -> None:
    """A scene stand-in VLM must have been taught the phrases (zsrm pretrain-vlm --scene); real
    CLIP knows the words. One line naming the first phrase it was not taught."""
    if getattr(vlm, "backend", None) != "scene":
        return
    meta = getattr(vlm, "meta", None) or {}
    known = meta.get("objects") or [f"{c} {s}" for c in meta.get("colours", ()) for s in ("block", "puck")]
    missing = [p for p in phrases if p not in known]
    if missing:
        learnt = f"it learnt {', '.join(known)}" if known else "it names no objects it learnt"
        raise ValueError(f"the VLM {spec} was never taught {missing[0]!r} ({learnt}): pretrain one on your scene "
                         f"with zsrm pretrain-vlm --scene {scene} --out FOLDER and label with --vlm FOLDER")


def own_scene_record(data: ExplorationData, cfg: LabelConfig, vlm) -> dict:
    """Before labelling an own scene's data: its adapter still names the data's objects and the
    VLM knows them. Returns what the labels manifest records: the object width, the oracle's
    axes of each role's camera (evaluation only: :func:`zsrm.envs.scene_task.role_axes`, read
    off the env's cameras as SceneTask's oracle reads them) and notes on what zsrm's own labeler
    has that this one lacks."""
    from zsrm.envs.adapter import SceneAdapterError, load_adapter
    from zsrm.envs.scene_task import role_axes

    adapter = load_adapter(data.scene_adapter)
    if tuple(adapter.objects) != data.colours:
        raise SceneAdapterError(f"{data.folder} holds {', '.join(data.colours)}, but {adapter.name}'s objects are now "
                                f"{', '.join(adapter.objects)}: collect the data again")
    phrases = [p for p in data.colours if p not in data.config["exclude"]]
    check_vlm_knows(vlm, phrases, cfg.vlm, adapter.name)
    env = adapter.make_env(tuple(adapter.roles[r] for r in data.cameras), data.config["image_size"], tuple(phrases))
    try:
        env.reset(seed=0)  # the cameras' poses; where the objects are is not read
        base = env.unwrapped
        axes = {r: role_axes(base.model, base.data, adapter.roles[r], r).tolist() for r in data.cameras}
    finally:
        env.close()
    tilted = [RELATIONS[r].name for r in RELATIONS if RELATIONS[r].camera == "tilted"]
    notes = ["one object width for every object (the adapter's object_width, "
             f"{own_object_width(data):g} m), where zsrm's scenes have one per shape"]
    if cfg.refine == "silhouette":
        notes.append("silhouette refinement uncalibrated: the tilted camera's points move to the centroid of the "
                     "object's colour region around them, with no offset (zsrm measures it on renders of each object "
                     "alone at known table positions, which an own scene's env does not offer) and one window for "
                     "every object")
    if not any(data.table_homography.get(s) for s in data.scenes):
        notes.append(f"the tilted camera ({', '.join(tilted)}) is read in pixels: the adapter gives no table_height, "
                     "so the data have no table calibration and pixel distances shrink with depth")
    return {"name": adapter.name, "object_width": own_object_width(data), "oracle_axes": axes, "notes": notes}
