"""The spatial labeler of Table 1: object coordinates from three cameras -> captions.

The front camera decides left of / right of / on top of / below / in between, the left
camera in front of / behind, the 45-degree camera close to / inside of (paper 2.2). The
predicates and the thresholds' meaning come from :mod:`zsrm.tasks.relations`, the module
the oracle uses, so Grad-CAM captions and true-coordinate captions compare one to one.

Pixel coordinates are ``(x, row)`` with the row pointing down; the labeler flips the row
(``y = -row``) so that y points up, as Table 1 reads them. Every caption is the canonical
goal sentence (:attr:`zsrm.tasks.language.Task.text`), so captions match goal texts exactly.

>>> labeler = SpatialLabeler.from_block_widths({"front": 6.0, "left": 6.0, "tilted": 7.0})
>>> coords = {"front": {"red": (20, 40), "yellow": (44, 40)},
...           "left": {"red": (31, 40), "yellow": (31, 40)},
...           "tilted": {"red": (20, 30), "yellow": (44, 30)}}
>>> labeler(coords)
['a red block on the left of a yellow block', 'a yellow block on the right of a red block']
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations
from typing import Mapping, Sequence

import numpy as np

from zsrm.tasks.language import COLOURS, Task
from zsrm.tasks.lexicon import CONTAINERS
from zsrm.tasks.relations import CAMERAS, RELATIONS, SOLID_CAMERAS, WORLD_THRESHOLDS, Thresholds, camera_plane
from zsrm.tasks.scene_goals import SceneGoal

# Object widths (metres) of the scenes' shapes: the world thresholds are in metres.
OBJECT_WIDTH = {"block": 0.06, "puck": 0.07}
# The relations a container (the tabletop's box) takes part in, always as the last object: "a
# red block inside of a box". Its centre is that of a large open box, so its other relations
# (a block "on top of" the box it lies in, "a box inside of a block") would say little or the
# wrong thing.
CONTAINER_RELATIONS = frozenset({"inside_of"})


def pixel_thresholds(block_width_px: Mapping[str, float], shape: str = "block",
                     world: Thresholds = WORLD_THRESHOLDS, table_cameras=(),
                     object_width: float | None = None) -> dict[str, Thresholds]:
    """Per-camera pixel thresholds: the world thresholds scaled by pixels per metre, measured
    as an object's width in pixels on that camera over its width in metres (the shape's, or
    ``object_width``: an own scene's adapter's). Cameras in ``table_cameras`` are read in table
    metres (see :class:`SpatialLabeler`) and keep ``world``."""
    if object_width is None and shape not in OBJECT_WIDTH:
        raise ValueError(f"unknown shape {shape!r}; known shapes: {', '.join(OBJECT_WIDTH)}")
    metres = OBJECT_WIDTH[shape] if object_width is None else object_width
    out = {}
    for camera, width in block_width_px.items():
        if not width > 0:
            raise ValueError(f"block width on camera {camera!r} must be positive, got {width}")
        out[camera] = world if camera in table_cameras else world.scaled(width / metres)
    return out


def object_tuples(arity: int, k: int) -> np.ndarray:
    """All ordered tuples of ``arity`` different object indices out of ``k``: (T, arity)."""
    tuples = list(permutations(range(k), arity))
    return np.array(tuples, dtype=np.int64).reshape(len(tuples), arity)


def relation_tuples(relation: str, objects: Sequence[str]) -> np.ndarray:
    """The ordered object tuples (T, arity) a relation is read for: every tuple of different
    objects (:func:`object_tuples`), except that a container appears only as the last object of
    :data:`CONTAINER_RELATIONS`, and those relations are read only with a container there
    (Table 1's "Obj1 inside of Obj2" needs Obj2 to hold it: two blocks whose centres are 2 cm
    apart are stacked, not one inside the other). Without a container, exactly
    :func:`object_tuples` for every other relation.

    >>> relation_tuples("inside_of", ("red", "green", "box")).tolist()
    [[0, 2], [1, 2]]
    >>> len(relation_tuples("left_of", ("red", "green", "box"))), len(relation_tuples("inside_of", ("red", "green")))
    (2, 0)
    """
    tuples = object_tuples(RELATIONS[relation].arity, len(objects))
    is_container = np.isin(tuples, [i for i, o in enumerate(objects) if o in CONTAINERS])
    if relation in CONTAINER_RELATIONS:
        return tuples[is_container[:, -1] & ~is_container[:, :-1].any(axis=1)]
    return tuples[~is_container.any(axis=1)]


def pixel_planes(pixels: Mapping[str, np.ndarray], table_homography: Mapping[str, np.ndarray] | None = None
                 ) -> dict[str, np.ndarray]:
    """Pixel coordinates (x, row) -> Table 1's plane (x right, y up): flip the row. Cameras
    with a table homography (:func:`zsrm.envs.cameras.table_homography`) are mapped onto the
    table instead, in metres, the plane :func:`zsrm.tasks.relations.camera_plane` gives them."""
    from zsrm.envs.cameras import apply_homography

    out = {}
    for camera, xy in pixels.items():
        xy = np.asarray(xy, dtype=np.float64)
        if table_homography and camera in table_homography:
            out[camera] = apply_homography(table_homography[camera], xy)
        else:
            out[camera] = np.stack([xy[..., 0], -xy[..., 1]], axis=-1)
    return out


def world_planes(positions: np.ndarray, cameras: Sequence[str] = CAMERAS,
                 axes: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """True world positions (..., 3) -> each camera's plane, as the oracle reads them: zsrm's
    :func:`~zsrm.tasks.relations.camera_plane`, or along ``axes`` (camera -> (2, 3) world
    directions: an own scene's :func:`zsrm.envs.scene_task.role_axes`)."""
    if axes is not None:
        return {camera: np.asarray(positions, np.float64) @ np.asarray(axes[camera], np.float64).T
                for camera in cameras}
    return {camera: camera_plane(positions, camera) for camera in cameras}


@dataclass(frozen=True)
class RelationTable:
    """Which relations hold for which objects in N images.

    ``holds[relation]`` is a bool array (N, T) over the ordered object tuples
    ``tuples[relation]`` (T, arity) of indices into ``colours``.
    """

    colours: tuple[str, ...]
    tuples: dict[str, np.ndarray]
    holds: dict[str, np.ndarray]

    def captions(self, shape: str | None = "block") -> list[list[str]]:
        """Every caption that holds, per image, as canonical goal sentences: of zsrm's ``shape``,
        or with ``shape=None`` over an own scene's phrases (:class:`~zsrm.tasks.scene_goals.SceneGoal`)."""
        n = next(iter(self.holds.values())).shape[0] if self.holds else 0
        out: list[list[str]] = [[] for _ in range(n)]
        for relation, holds in self.holds.items():
            # Texts only of tuples that hold: a tuple with the box never holds in a puck scene,
            # where its text would be no goal at all.
            texts: dict[int, str] = {}
            for img, t in zip(*np.nonzero(holds)):
                if t not in texts:
                    objects = [self.colours[i] for i in self.tuples[relation][t]]
                    texts[t] = (SceneGoal(relation, objects) if shape is None else Task(relation, objects, shape)).text
                out[img].append(texts[t])
        return out


def relation_table(planes: Mapping[str, np.ndarray], present: np.ndarray, thresholds: Mapping[str, Thresholds],
                   colours: Sequence[str] = COLOURS, relations: Sequence[str] = tuple(RELATIONS),
                   solid: np.ndarray | None = None, solid_thresholds: Thresholds | None = None) -> RelationTable:
    """Evaluate Table 1 on N images of K objects.

    planes:     camera -> (N, K, 2) coordinates in that camera's plane (y up); NaN for an object
                that was not located (it then takes part in no relation).
    present:    (N, K) bool, the objects in each image.
    thresholds: camera -> the :class:`Thresholds` in that camera's units.
    colours:    the K objects: colours, and the box (see :func:`relation_tuples`).
    solid:      (N, K, 3) world points (z up, metres): the relations with a 3-D reading
                (:attr:`~zsrm.tasks.relations.Relation.solid`) read them, with ``solid_thresholds``.
    """
    present = np.asarray(present, dtype=bool)
    if present.ndim != 2 or present.shape[1] != len(colours):
        raise ValueError(f"present must have shape (N, {len(colours)}), got {present.shape}")
    tuples, holds = {}, {}
    for name in relations:
        if name not in RELATIONS:
            raise ValueError(f"unknown relation {name!r}; known relations: {', '.join(RELATIONS)}")
        rel = RELATIONS[name]
        in_3d = solid is not None and rel.solid is not None
        xy = _coordinates(name, planes, thresholds, present, solid if in_3d else None)
        t = relation_tuples(name, colours)
        args = [xy[:, t[:, i]] for i in range(rel.arity)]  # each (N, T, 2) or (N, T, 3)
        with np.errstate(invalid="ignore"):  # NaN coordinates compare False: no relation
            ok = (rel.solid(*args, solid_thresholds) if in_3d else rel(*args, thresholds=thresholds[rel.camera]))
        ok &= present[:, t].all(axis=-1)
        ok &= np.all([np.isfinite(a).all(-1) for a in args], axis=0)
        tuples[name], holds[name] = t, ok
    return RelationTable(tuple(colours), tuples, holds)


def _coordinates(name: str, planes, thresholds, present: np.ndarray, solid: np.ndarray | None) -> np.ndarray:
    """The coordinates ``name`` reads, checked: its camera's plane, or the 3-D points ``solid``."""
    if solid is not None:
        xyz = np.asarray(solid, dtype=np.float64)
        if xyz.shape != present.shape + (3,):
            raise ValueError(f"3-D points must have shape {present.shape + (3,)}, got {xyz.shape}")
        return xyz
    camera = RELATIONS[name].camera
    if camera not in planes:
        raise ValueError(f"{name} needs the {camera!r} camera's coordinates")
    if camera not in thresholds:
        raise ValueError(f"{name} needs thresholds for the {camera!r} camera")
    xy = np.asarray(planes[camera], dtype=np.float64)
    if xy.shape != present.shape + (2,):
        raise ValueError(f"{camera} coordinates must have shape {present.shape + (2,)}, got {xy.shape}")
    return xy


class SpatialLabeler:
    """Captions from object pixel coordinates on the front, left and tilted cameras.

    thresholds: camera -> pixel :class:`Thresholds` (see :func:`pixel_thresholds`).
    shape: zsrm's shape the captions name (``None``: an own scene's phrases, ``colours``).
    table_homography: camera -> 3x3 pixel-to-table map. Those cameras' coordinates are read
    in metres on the table, so their thresholds must be in metres: on the tilted camera a
    pixel distance means twice as much at the far edge of the table as at the near one, and
    with one pixel threshold "close to" labels had precision 0.29 even from true coordinates.
    """

    def __init__(self, thresholds: Mapping[str, Thresholds], shape: str | None = "block",
                 colours: Sequence[str] = COLOURS, relations: Sequence[str] = tuple(RELATIONS),
                 table_homography: Mapping[str, np.ndarray] | None = None, rays: Mapping[str, dict] | None = None,
                 solid_thresholds: Thresholds | None = None):
        missing = {RELATIONS[r].camera for r in relations} - set(thresholds)
        if missing:
            raise ValueError(f"no thresholds for camera(s) {', '.join(sorted(missing))}")
        if rays is not None and (solid_thresholds is None or set(SOLID_CAMERAS) - set(rays)):
            raise ValueError(f"a 3-D reading needs the rays of the {' and '.join(SOLID_CAMERAS)} cameras and "
                             "thresholds in metres")
        self.thresholds = dict(thresholds)
        self.table_homography = {c: np.asarray(h, np.float64) for c, h in (table_homography or {}).items()}
        self.shape = shape
        self.colours = tuple(colours)
        self.relations = tuple(relations)
        self.rays, self.solid_thresholds = rays, solid_thresholds

    @classmethod
    def from_block_widths(cls, block_width_px: Mapping[str, float], shape: str = "block", **kwargs):
        return cls(pixel_thresholds(block_width_px, shape), shape=shape, **kwargs)

    def table(self, pixels: Mapping[str, np.ndarray], present: np.ndarray) -> RelationTable:
        """pixels: camera -> (N, K, 2) pixel coordinates (x, row); present: (N, K) bool."""
        return relation_table(pixel_planes(pixels, self.table_homography), present, self.thresholds, self.colours,
                              self.relations, self.points(pixels), self.solid_thresholds)

    def points(self, pixels: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """(N, K, 3): each object's world point, triangulated from its pixels on :data:`SOLID_CAMERAS`
        (None without rays: no 3-D reading)."""
        if self.rays is None or any(c not in pixels for c in SOLID_CAMERAS):
            return None
        from zsrm.envs.cameras import triangulate  # mujoco, imported when used

        (a, b) = SOLID_CAMERAS
        return triangulate(self.rays[a], pixels[a], self.rays[b], pixels[b])

    def captions(self, pixels: Mapping[str, np.ndarray], present: np.ndarray) -> list[list[str]]:
        """Every caption that holds, for each of N images."""
        return self.table(pixels, present).captions(self.shape)

    def __call__(self, coords: Mapping[str, Mapping[str, Sequence[float]]]) -> list[str]:
        """One image: ``{camera: {colour: (x, row)}}`` -> its captions. Objects missing from a
        camera's mapping, or with NaN coordinates, take part in no relation that camera reads."""
        named = {c for cam in coords.values() for c in cam}
        unknown = named - set(self.colours)
        if unknown:
            raise ValueError(f"unknown colour(s) {', '.join(sorted(unknown))}; known: {', '.join(self.colours)}")
        present = np.array([[c in named for c in self.colours]])
        pixels = {}
        for camera in CAMERAS:
            xy = np.full((1, len(self.colours), 2), np.nan)
            for i, c in enumerate(self.colours):
                if c in coords.get(camera, {}):
                    xy[0, i] = coords[camera][c]
            pixels[camera] = xy
        return self.captions(pixels, present)[0]


def world_table(positions: np.ndarray, present: np.ndarray, colours: Sequence[str] = COLOURS,
                thresholds: Thresholds = WORLD_THRESHOLDS, relations: Sequence[str] = tuple(RELATIONS),
                axes: Mapping[str, np.ndarray] | None = None, solid: bool = False) -> RelationTable:
    """The oracle's table from true world positions (N, K, 3), in metres (read along ``axes``
    where given, see :func:`world_planes`; ``solid``: the relations with a 3-D reading read the
    positions themselves)."""
    positions = np.asarray(positions, dtype=np.float64)
    planes = world_planes(positions, axes=axes)
    return relation_table(planes, present, {c: thresholds for c in CAMERAS}, colours, relations,
                          positions if solid else None, thresholds)
