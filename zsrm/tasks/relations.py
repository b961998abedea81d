"""The spatial relations of Table 1 of the paper: one table for the oracle and the labeler.

Every predicate reads 2-D coordinates in a camera's plane, x to the right and y up:

* the oracle passes true world positions through :func:`camera_plane`;
* the labeler (grounding stage) passes Grad-CAM pixel coordinates, with the row flipped
  so that y points up.

Only the thresholds differ between the two (metres against pixels), so both read the
same :data:`RELATIONS` table and can be compared one to one.
All predicates are vectorised: coordinates are arrays of shape ``(..., 2)``.

An own scene whose cameras are calibrated reads on top of / below in 3-D instead
(:attr:`Relation.solid`, world points ``(..., 3)``, z up, in metres): the oracle from true positions,
the labeler from Grad-CAM points triangulated on the two cameras that look down most
(:data:`SOLID_CAMERAS`). Table 1's front reading asks the upper object's point to sit a gap higher
in the image; a bowl on a plate sits 1 cm over the plate's base, and from the front the bowl
hides the plate.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

CAMERAS = ("front", "left", "tilted")


@dataclass(frozen=True)
class Thresholds:
    """Named thresholds of Table 1, in the units of the coordinates they are used with.

    gap:    margin for every strict ordering (``a.x > b.x + gap``); 0 is Table 1 verbatim.
    eps_x:  on top of / below: the largest horizontal offset (Table 1's epsilon_1).
    eps_y:  on top of / below: the largest vertical offset (Table 1's epsilon_2).
    close:  close to: the largest centre distance.
    inside: inside of: the largest centre distance (much smaller than ``close``).
    """

    gap: float
    eps_x: float
    eps_y: float
    close: float
    inside: float

    def scaled(self, factor: float) -> "Thresholds":
        """The same thresholds in units ``factor`` times smaller (e.g. metres -> pixels)."""
        return replace(self, **{k: v * factor for k, v in self.__dict__.items()})


# Metres, for the tabletop's 6 cm blocks and the pushing scene's 7 cm pucks; a block in the
# tabletop's open box is at most 1.7 cm from the box's centre (inside < 2 cm).
WORLD_THRESHOLDS = Thresholds(gap=0.01, eps_x=0.03, eps_y=0.09, close=0.10, inside=0.02)


def _x(p: np.ndarray) -> np.ndarray:
    return np.asarray(p, dtype=np.float64)[..., 0]


def _y(p: np.ndarray) -> np.ndarray:
    return np.asarray(p, dtype=np.float64)[..., 1]


def _dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=-1)


def left_of(a, b, t: Thresholds):
    return _x(b) - _x(a) > t.gap


def right_of(a, b, t: Thresholds):
    return _x(a) - _x(b) > t.gap


def on_top_of(a, b, t: Thresholds):
    dy = _y(a) - _y(b)
    return (np.abs(_x(a) - _x(b)) < t.eps_x) & (dy > t.gap) & (dy < t.eps_y)


def below(a, b, t: Thresholds):
    return on_top_of(b, a, t)


def on_top_of_solid(a, b, t: Thresholds):
    """World points (..., 3), z up: a over b's footprint (within ``eps_x`` on the table plane),
    higher, by at most ``eps_y`` (resting on it, not held above it). No gap: a thin plate lifts
    what rests on it by less than one."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    dz = a[..., 2] - b[..., 2]
    return (np.linalg.norm(a[..., :2] - b[..., :2], axis=-1) < t.eps_x) & (dz > 0) & (dz < t.eps_y)


def below_solid(a, b, t: Thresholds):
    return on_top_of_solid(b, a, t)


def in_between(a, b, c, t: Thresholds):
    lo, hi = np.minimum(_x(b), _x(c)), np.maximum(_x(b), _x(c))
    return (_x(a) > lo + t.gap) & (_x(a) < hi - t.gap)


def in_front_of(a, b, t: Thresholds):
    # Left-camera coordinates: x points toward the front camera.
    return _x(a) - _x(b) > t.gap


def behind(a, b, t: Thresholds):
    return _x(b) - _x(a) > t.gap


def close_to(a, b, t: Thresholds):
    return _dist(a, b) < t.close


def inside_of(a, b, t: Thresholds):
    return _dist(a, b) < t.inside


@dataclass(frozen=True)
class Relation:
    name: str  # identifier, e.g. "left_of"
    phrase: str  # canonical words in goal text, e.g. "on the left of"
    arity: int  # number of objects (2, or 3 for in between)
    camera: str  # the camera whose coordinates the predicate reads
    holds: Callable[..., np.ndarray]
    # The relation seen in the camera's image flipped left to right (None: not a flip of its image).
    mirror: str | None = None
    # Its reading on world points (..., 3), z up, where an own scene's cameras are calibrated.
    solid: Callable[..., np.ndarray] | None = None

    def __call__(self, *coords, thresholds: Thresholds) -> np.ndarray:
        if len(coords) != self.arity:
            raise ValueError(f"{self.name} relates {self.arity} objects, got {len(coords)}")
        return self.holds(*coords, thresholds)


RELATIONS: dict[str, Relation] = {
    r.name: r
    for r in (
        Relation("left_of", "on the left of", 2, "front", left_of, "right_of"),
        Relation("right_of", "on the right of", 2, "front", right_of, "left_of"),
        Relation("on_top_of", "on top of", 2, "front", on_top_of, "on_top_of", on_top_of_solid),
        Relation("below", "below", 2, "front", below, "below", below_solid),
        Relation("in_between", "in between", 3, "front", in_between, "in_between"),
        Relation("in_front_of", "in front of", 2, "left", in_front_of),
        Relation("behind", "behind", 2, "left", behind),
        Relation("close_to", "close to", 2, "tilted", close_to),
        Relation("inside_of", "inside of", 2, "tilted", inside_of),
    )
}


# The cameras a 3-D reading triangulates objects from: the two that look down most, 90 degrees
# apart, and see an object under another (a plate's rim around a bowl) that the front camera does not.
SOLID_CAMERAS = ("tilted", "left")

# Cameras whose plane is the table top (see camera_plane): the labeler can map their pixel
# coordinates onto the table with the camera's calibration and read them in metres.
TABLE_PLANE_CAMERAS = frozenset({"tilted"})


def camera_plane(xyz, camera: str) -> np.ndarray:
    """World positions ``(..., 3)`` (x right, y away from the front camera, z up) to the
    2-D coordinates of a camera's plane as the oracle reads them.

    front: (x, z). left: (-y, z), its x axis points toward the front camera.
    tilted: (x, y), the table plane the 45-degree camera sees in two directions at once.
    """
    p = np.asarray(xyz, dtype=np.float64)
    if camera == "front":
        return p[..., [0, 2]]
    if camera == "left":
        return np.stack([-p[..., 1], p[..., 2]], axis=-1)
    if camera == "tilted":
        return p[..., [0, 1]]
    raise ValueError(f"unknown camera {camera!r}; known cameras: {', '.join(CAMERAS)}")


def holds_in_world(relation: str, positions, thresholds: Thresholds = WORLD_THRESHOLDS):
    """Oracle: does ``relation`` hold for these true world positions (one per object)?"""
    rel = RELATIONS[relation]
    return rel(*(camera_plane(p, rel.camera) for p in positions), thresholds=thresholds)
