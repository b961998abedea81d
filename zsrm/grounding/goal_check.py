"""Does one goal hold in a frame? The labeler of Table 1 (Grad-CAM + the relation's rule) asked
about one goal, for frames a policy reaches (:class:`zsrm.rewards.corrected.CorrectedZSRMReward`).

It is the labeler ``zsrm label`` runs, read on the goal's camera only: the VLM's Grad-CAM points
of the scene's objects (contrasted with the other colours' phrases), refined to their silhouettes
on the table-plane camera, and the relation's rule with that camera's thresholds. What it reads:
the frames, and which objects the goal's scene holds (the goal names them); never the state.
Its calibration (Grad-CAM cell centres, object widths in pixels, the table's homography) comes from
a few exploration renders (:func:`zsrm.data.collect.collect`), as ``zsrm label``'s does.
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from zsrm.data.collect import CollectConfig, camera_rays, collect
from zsrm.grounding.annotate import Grounder, LabelConfig, gradcam_objects, labelers
from zsrm.grounding.labeler import SpatialLabeler
from zsrm.tasks.catalogue import SCENE_IDS
from zsrm.tasks.language import Task
from zsrm.tasks.relations import RELATIONS

CALIBRATION_IMAGES = 16  # exploration renders the labeler is calibrated on (zsrm label: a dataset's first 8)
# The front check of "inside of" (``front_check``): on the front camera the block's Grad-CAM point in
# the box sits this far above the box's, in block widths (the walls hide its lower part: scripted
# goal frames read 0.25 to 0.68, 10th to 90th percentile); a block held in the air in front of the
# box, which the tilted camera reads as in it, reads outside (the box's point then lands on the
# held block or the gripper) (probes/inside_front_check.py).
FRONT_RISE = (0.15, 0.85)
# The height check of "inside of" (``height_check``): the block's centre, triangulated from its
# Grad-CAM points on the goal's camera and the front camera, at most this many block widths above a
# resting block's centre. Dropped in the box it reads -0.1 to 0.4 (10th to 90th percentile); held 8 cm
# up in front of the box, which the tilted camera reads as in it, 0.6 to 1.05 (probes/inside_front_check.py).
# 0.67 (``--zsrm-correct-lift-max``) also counts a block held low in the box, as the oracle does.
LIFT_MAX = 0.5


class Reading(NamedTuple):
    """:meth:`GoalLabeler.read`: the relation on the goal's camera alone, and with the front
    camera's frames the front check's rise and the height check's lift (block widths; NaN: not located)."""
    holds: np.ndarray
    rise: np.ndarray | None = None
    lift: np.ndarray | None = None


class GoalLabeler:
    """``labeler(frames)``: (N,) bool, the goal's relation read by Grad-CAM on frames (N, H, W, 3)
    of the goal's camera of its task scene, which holds the goal's objects.

    Build it with :meth:`calibrated`; ``folder`` keeps the calibration renders (a rerun reads them).
    ``front_check`` and ``height`` (the scene's :func:`~zsrm.data.collect.camera_rays`), inside of
    only: called with the front camera's frames of the same steps too (``labeler(frames,
    front=...)``), it says inside of only where the front check (:data:`FRONT_RISE`) and the height
    check (:data:`LIFT_MAX`) agree."""

    def __init__(self, task: Task, grounder: Grounder, labeler: SpatialLabeler, front_check: bool = False,
                 height: dict | None = None, lift_max: float = LIFT_MAX):
        self.task, self.grounder, self.camera = task, grounder, RELATIONS[task.relation].camera
        self.labeler, self.front_check, self.height, self.lift_max = labeler, bool(front_check), height, float(lift_max)
        if self.needs_front and (task.relation != "inside_of" or "front" not in grounder.data.cameras):
            raise ValueError(f"the front and height checks read inside of on calibration data with the front "
                             f"camera; {task.text!r} is {task.relation}, the data has {', '.join(grounder.data.cameras)}")
        objects = grounder.data.objects  # the colours, then the box where the data can hold it
        missing = set(task.objects) - set(objects)
        if missing:
            raise ValueError(f"the labeler's calibration data hold no {', '.join(sorted(missing))}")
        self.present = np.isin(np.array(objects, dtype=object), list(task.objects))

    @property
    def needs_front(self) -> bool:
        """Does it read the front camera's frames too?"""
        return self.front_check or self.height is not None

    @classmethod
    def calibrated(cls, task: Task, scene: str, image_size: int, folder: str | Path, vlm, vlm_spec: str = "scene",
                   box_vlm=None, box_min_area: float = 0.0, front_check: bool = False,
                   height_check: bool = False, lift_max: float = LIFT_MAX) -> "GoalLabeler":
        """Calibrated on ``CALIBRATION_IMAGES`` exploration renders of ``scene`` (a zsrm scene name:
        tabletop or pushing) at ``image_size``, collected into ``folder`` (once). ``box_min_area``:
        a box point whose silhouette covers less of the table (square metres) is not the box (see
        :class:`~zsrm.grounding.annotate.Grounder`); ``front_check``, ``height_check`` (with
        ``lift_max``, block widths): see the class."""
        if scene not in SCENE_IDS:
            raise ValueError(f"unknown scene {scene!r}; the goal labeler reads zsrm's scenes: {', '.join(SCENE_IDS)}")
        camera = RELATIONS[task.relation].camera
        p_box = 0.5 if task.has_container else 0.0
        cameras = (camera, "front") if (front_check or height_check) and camera != "front" else (camera,)
        collect_cfg = CollectConfig(images=CALIBRATION_IMAGES, shard_size=CALIBRATION_IMAGES, scenes=(scene,),
                                    cameras=cameras, image_size=image_size, p_box=p_box)
        data = collect(collect_cfg, folder, progress=False)
        cfg = LabelConfig(vlm=vlm_spec)
        grounder = Grounder(vlm, cfg, data, box_vlm=box_vlm, box_min_area=box_min_area)
        height = camera_rays(collect_cfg)[scene] if height_check else None
        return cls(task, grounder, labelers(data, cfg, relations=(task.relation,))[scene], front_check, height,
                   lift_max)

    def __call__(self, frames: np.ndarray, front: np.ndarray | None = None) -> np.ndarray:
        if self.needs_front and (front is None or len(front) != len(frames)):
            raise ValueError(f"the front and height checks need the front camera's frames of the same {len(frames)} steps")
        reading = self.read(frames, front)
        holds = reading.holds & front_rise_ok(reading.rise) if self.front_check else reading.holds
        return holds & lift_ok(reading.lift, self.lift_max) if self.height is not None else holds

    def read(self, frames: np.ndarray, front: np.ndarray | None = None) -> Reading:
        """One Grad-CAM pass: the relation on the goal's camera alone, and with ``front`` the block's
        front point above the box's and (with ``height``) the block's lift, in block widths."""
        frames = np.asarray(frames)  # checked by Grad-CAM (zsrm.grounding.gradcam)
        n = len(frames)
        arrays = {"scene": np.zeros(n, np.int64), f"images_{self.camera}": frames,
                  **({"images_front": np.asarray(front)} if front is not None else {})}
        if self.grounder.data.has_box:
            arrays["box_present"] = np.full(n, self.present[-1])
        pixels = gradcam_objects(self.grounder.data, self.grounder.shard(arrays, colours=self.task.objects))
        present = np.broadcast_to(self.present, (n, len(self.present)))
        captions = self.labeler.captions({self.camera: pixels[self.camera]}, present)
        holds = np.array([self.task.text in c for c in captions], dtype=bool)
        if front is None:
            return Reading(holds)
        lift = self.lift(pixels[self.camera], pixels["front"]) if self.height is not None else None
        return Reading(holds, self.front_rise(pixels["front"]), lift)

    def front_rise(self, front: np.ndarray) -> np.ndarray:
        """(N,): the block's front Grad-CAM point (N, K, 2) above the box's, in block widths."""
        block, box = (front[:, self._index(o)] for o in self.task.objects[:2])
        width = self.grounder.data.block_width_px[self.grounder.data.scenes[0]]["front"]
        return (box[:, 1] - block[:, 1]) / width  # rows grow down

    def lift(self, goal_camera: np.ndarray, front: np.ndarray) -> np.ndarray:
        """(N,): the block's centre, triangulated from its Grad-CAM points (N, K, 2) on the goal's
        camera and the front camera, above a resting block's centre, in block widths."""
        from zsrm.envs.cameras import triangulate  # mujoco, imported when used

        rays, block = self.height["rays"], self._index(self.task.objects[0])
        xyz = triangulate(rays[self.camera], goal_camera[:, block], rays["front"], front[:, block])
        return (xyz[:, 2] - self.height["rest_z"]) / self.height["width"]

    def _index(self, obj: str) -> int:
        return list(self.grounder.data.objects).index(obj)


def front_rise_ok(rise: np.ndarray) -> np.ndarray:
    """(N,) bool: the front check holds (a rise within :data:`FRONT_RISE`; NaN, not located: False)."""
    with np.errstate(invalid="ignore"):
        return (rise > FRONT_RISE[0]) & (rise < FRONT_RISE[1])


def lift_ok(lift: np.ndarray, lift_max: float = LIFT_MAX) -> np.ndarray:
    """(N,) bool: the height check holds (a lift below ``lift_max``; NaN, not located: False)."""
    with np.errstate(invalid="ignore"):
        return lift < lift_max
