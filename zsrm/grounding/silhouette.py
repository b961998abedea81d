"""Refine a Grad-CAM point to the centre of its object's silhouette (the table-plane camera).

The tilted camera's relations, "close to" and "inside of", are read in table metres, where one
pixel is about 9 mm and "inside of" allows 2 cm (Table 1). Grad-CAM puts a block within about
a pixel, and the box within several (its peak sits on the box's front wall). Around the
Grad-CAM point this finds the object's pixels without the VLM:

* the pixels unlike the table around them (the median colour of the window's border), in the
  connected region nearest the point;
* for a block, of these only the ones of the point's colour (chromaticity, so that shaded faces
  stay in), unless fewer than ``min_visible`` of the block's silhouette shows: a block partly
  hidden behind another (stacked, or in the box) keeps the whole region, whose centroid is
  pulled toward what hides it rather than away;
* the box (colourless, and holding blocks) keeps the whole region.

The refined point is the region's centroid less the offset that calibration renders of the
object alone on the table measure (:func:`calibrate`): a silhouette's centroid is not its
projected centre (the box's front wall shows, its back wall does not). Calibration, like the
camera's table homography, reads the scene's geometry, never a collected image's state.

>>> image = np.zeros((16, 16, 3), np.float32); image[4:8, 6:10] = (255, 0, 0)
>>> refine_point(image, np.array([9.0, 7.0]), Silhouette(half_window=6)).round(2).tolist()
[7.5, 5.5]
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage

# Colour distance (RGB, 0-255) from the table's colour that makes a pixel part of an object,
# and chromaticity distance from the point's colour that keeps it in a block's region.
BACKGROUND_TOLERANCE = 50.0
CHROMA_TOLERANCE = 0.08
MIN_VISIBLE = 0.8  # a block showing less of its silhouette than this is treated as partly hidden


@dataclass(frozen=True)
class Silhouette:
    """How one kind of object is refined on one camera (pixels of that camera's images).

    half_window: the search window's half-size (about the object's width).
    offset:      the silhouette centroid minus the projected centre, measured alone on the table.
    area:        the silhouette's area alone on the table (0: never treated as hidden).
    by_colour:   keep only the pixels of the point's colour (blocks, pucks), or every pixel unlike
                 the table (the box).
    """

    half_window: float
    offset: tuple[float, float] = (0.0, 0.0)
    area: float = 0.0
    by_colour: bool = True

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> "Silhouette":
        return cls(float(d["half_window"]), tuple(d["offset"]), float(d["area"]), bool(d["by_colour"]))


def _chromaticity(image: np.ndarray) -> np.ndarray:
    return image / (image.sum(-1, keepdims=True) + 30.0)  # +30: dark pixels' noise stays small


def _nearest_region(mask: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """The connected region of ``mask`` holding the pixel nearest the point."""
    labels, n = ndimage.label(mask)
    if not n:
        return mask
    return labels == labels.flat[np.argmin(np.where(mask, d2, np.inf))]


def region(image: np.ndarray, seed, sil: Silhouette) -> np.ndarray:
    """Boolean mask (H, W) of the object's pixels around ``seed`` (x, row): see the module."""
    img = np.asarray(image, np.float32)
    h, w = img.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w]
    dx, dy = np.abs(xs - seed[0]), np.abs(ys - seed[1])
    window = (dx <= sil.half_window) & (dy <= sil.half_window)
    border = window & ~((dx <= sil.half_window - 2) & (dy <= sil.half_window - 2))
    if not border.any():
        return np.zeros((h, w), bool)
    table = np.median(img[border], axis=0)
    fg = window & (np.linalg.norm(img - table, axis=-1) > BACKGROUND_TOLERANCE)
    if not fg.any():
        return fg
    d2 = (xs - seed[0]) ** 2 + (ys - seed[1]) ** 2
    whole = _nearest_region(fg, d2)
    if not sil.by_colour:
        return whole
    chroma = _chromaticity(img)
    near = fg & (d2 <= 2.25)
    if not near.any():
        near = fg & (d2 == d2[fg].min())
    same = fg & (np.linalg.norm(chroma - np.median(chroma[near], axis=0), axis=-1) < CHROMA_TOLERANCE)
    part = _nearest_region(same, d2)
    return part if part.sum() >= MIN_VISIBLE * sil.area else whole


def refine_point(image: np.ndarray, seed, sil: Silhouette) -> np.ndarray:
    """The refined pixel coordinates (x, row) of the object Grad-CAM put at ``seed``; ``seed``
    itself where it is NaN (not found) or no object pixel lies in the window."""
    seed = np.asarray(seed, np.float64)
    if not np.isfinite(seed).all():
        return seed
    mask = region(image, seed, sil)
    if not mask.any():
        return seed
    rows, cols = np.nonzero(mask)
    return np.array([cols.mean() - sil.offset[0], rows.mean() - sil.offset[1]])


def region_area(image: np.ndarray, seed, sil: Silhouette, homography) -> float:
    """The area on the table, in square metres, of the region :func:`region` finds around ``seed``:
    each pixel's corners through the camera's table ``homography``
    (:func:`zsrm.envs.cameras.table_homography`); 0 where no region is found. Tells the box (about
    0.013-0.016 alone on the tilted camera) from a block (0.007-0.010, lying turned or not) a box
    point landed on."""
    from zsrm.envs.cameras import apply_homography

    seed = np.asarray(seed, np.float64)
    if not np.isfinite(seed).all():
        return 0.0
    mask = region(image, seed, sil)
    rows, cols = np.nonzero(mask)
    corner = np.stack([cols, rows], axis=1).astype(np.float64) - 0.5  # each pixel's top-left corner
    origin, right, down = (apply_homography(homography, corner + d) for d in ((0, 0), (1, 0), (0, 1)))
    across, along = right - origin, down - origin
    return float(np.abs(across[:, 0] * along[:, 1] - across[:, 1] * along[:, 0]).sum())


def refine_points(images: np.ndarray, xy: np.ndarray, sil: Silhouette) -> np.ndarray:
    """:func:`refine_point` of every point: images (N, H, W, 3), xy (N, 2) or (N, P, 2)."""
    xy = np.asarray(xy, np.float64)
    flat = xy.reshape(len(xy), -1, 2)
    out = np.array([[refine_point(images[i], p, sil) for p in flat[i]] for i in range(len(xy))]).reshape(xy.shape)
    return out.astype(np.float32)


def calibrate(env, camera: str, size: int, obj: str, by_colour: bool, width_px: float,
              grid=(5, 4)) -> Silhouette:
    """Measure an object's silhouette offset and area on ``camera``: render it alone (the other
    objects moved off the table) at a grid of table positions, seed the region at its projected
    centre and average. ``env``: the scene's env (unwrapped), holding ``obj``."""
    import mujoco

    from zsrm.data.collect import box_reference_point
    from zsrm.envs.base import TABLE_TOP
    from zsrm.envs.cameras import project

    base = getattr(env, "unwrapped", env)
    sil = Silhouette(half_window=float(round(width_px)), by_colour=by_colour)
    objects = list(base.objects)
    offsets, areas = [], []
    for x in np.linspace(-0.2, 0.2, grid[0]):
        for y in np.linspace(-0.12, 0.12, grid[1]):
            for i, other in enumerate(objects):
                base._set_object(other, (2.0 + i, 2.0, 0.1))
            if obj in base.containers:
                base._set_object(obj, (x, y, 0.0))
                centre = box_reference_point((x, y, 0.0))
            else:
                centre = np.array([x, y, TABLE_TOP + base.rest_height])
                base._set_object(obj, centre)
            mujoco.mj_forward(base.model, base.data)
            image = base.render_cameras((camera,), size)[camera]
            truth = project(base, camera, centre, size)
            mask = region(image, truth, sil)
            if not mask.any():
                continue
            rows, cols = np.nonzero(mask)
            offsets.append((cols.mean() - truth[0], rows.mean() - truth[1]))
            areas.append(mask.sum())
    if not offsets:
        raise RuntimeError(f"calibration found no pixel of the {obj} on the {camera} camera")
    off = np.median(offsets, axis=0)  # median: the gripper may hide the object at a grid point
    return Silhouette(sil.half_window, (float(off[0]), float(off[1])), float(np.median(areas)) if by_colour else 0.0,
                      by_colour)
