"""The double pendulum's pose in words: what the scene VLM learns about the pendulum.

CLIP knows "an inverted pendulum standing upright" from web captions; the offline scene VLM
learns it from renders of the pendulum at random poses (:mod:`zsrm.data.pendulum`) captioned
here from the true pose. A pose is one of :data:`POSES`, read from the tip of the second pole
relative to the cart (``dx`` to the right of the image, ``z`` up, metres; the upright tip is
1.2 m above the cart):

* ``upright``: the tip near the top, ``z >= 1.10`` (a straight pole within 24 degrees of
  vertical; the env ends an episode once ``z <= 1.0``);
* ``leaning_left`` / ``leaning_right``: ``0.25 <= z <= 1.02`` and the tip at least 0.15 m to
  that side of the cart, as the camera sees it (image left is the world's -x);
* ``fallen``: the tip at or below the cart, ``z <= 0.1`` (lying or hanging down).

Poses between these bands have no caption (:func:`pose_class` returns None): the renders
avoid them, so no caption is ever half true. Each pose has a few phrasings
(:data:`CAPTIONS`); the first is its canonical text, and the upright one is the pendulum's
goal sentence. The base reward ranks the goal against the other poses' canonical texts
(:data:`NEGATIVES`).

>>> pose_class(0.0, 1.2), pose_class(-0.5, 0.8), pose_class(0.9, -0.4), pose_class(0.0, 1.05)
('upright', 'leaning_left', 'fallen', None)
>>> mirrored("leaning_left")
'leaning_right'
>>> GOAL
'an inverted pendulum standing upright'
"""
from __future__ import annotations

import numpy as np

from zsrm.tasks.catalogue import SINGLE_TASKS

POLE_LENGTH = 0.6  # each of the two poles (gymnasium's inverted_double_pendulum.xml)
FULL_HEIGHT = 2 * POLE_LENGTH  # the tip's height above the cart when both poles stand straight up

UPRIGHT_MIN_Z = 1.10
LEAN_Z = (0.25, 1.02)
LEAN_MIN_DX = 0.15
FALLEN_MAX_Z = 0.10

POSES = ("upright", "leaning_left", "leaning_right", "fallen")

GOAL = SINGLE_TASKS["pendulum"].goal  # "an inverted pendulum standing upright"

CAPTIONS: dict[str, tuple[str, ...]] = {
    "upright": (GOAL, "an upright pendulum", "a pendulum balanced straight up"),
    "leaning_left": ("an inverted pendulum leaning to the left", "a pendulum tilting to the left",
                     "a pendulum falling over to the left"),
    "leaning_right": ("an inverted pendulum leaning to the right", "a pendulum tilting to the right",
                      "a pendulum falling over to the right"),
    "fallen": ("an inverted pendulum that has fallen over", "a fallen pendulum", "a pendulum that has fallen down"),
}
assert tuple(CAPTIONS) == POSES and CAPTIONS["upright"][0] == GOAL

# What the goal is ranked against by the binarised base reward: every other pose's canonical text.
NEGATIVES = tuple(CAPTIONS[p][0] for p in POSES if p != "upright")


def pose_class(dx: float, z: float) -> str | None:
    """The pose of a tip ``dx`` metres right of the cart (as the camera sees it) and ``z`` above
    it, or None for a pose between the captioned bands."""
    if z >= UPRIGHT_MIN_Z:
        return "upright"
    if z <= FALLEN_MAX_Z:
        return "fallen"
    if LEAN_Z[0] <= z <= LEAN_Z[1] and abs(dx) >= LEAN_MIN_DX:
        return "leaning_right" if dx > 0 else "leaning_left"
    return None


def tip_offset(theta1: float, theta2: float) -> tuple[float, float]:
    """``(dx, z)`` of the tip relative to the cart for hinge angles ``theta1`` (first pole from
    vertical, positive toward +x) and ``theta2`` (second pole relative to the first)."""
    dx = POLE_LENGTH * (np.sin(theta1) + np.sin(theta1 + theta2))
    z = POLE_LENGTH * (np.cos(theta1) + np.cos(theta1 + theta2))
    return float(dx), float(z)


def mirrored(pose: str) -> str:
    """The pose of the left-right mirrored image."""
    return {"leaning_left": "leaning_right", "leaning_right": "leaning_left"}.get(_check(pose), pose)


def pendulum_caption(pose: str, rng: np.random.Generator) -> str:
    """One of the pose's phrasings, drawn by ``rng``.

    >>> pendulum_caption("fallen", np.random.default_rng(0)) in CAPTIONS["fallen"]
    True
    """
    phrases = CAPTIONS[_check(pose)]
    return phrases[int(rng.integers(len(phrases)))]


def all_pendulum_captions() -> list[str]:
    """Every caption :func:`pendulum_caption` can write (to pre-encode with the frozen text encoder)."""
    return [c for p in POSES for c in CAPTIONS[p]]


def _check(pose: str) -> str:
    if pose not in CAPTIONS:
        raise ValueError(f"unknown pendulum pose {pose!r}; known: {', '.join(POSES)}")
    return pose


__all__ = ["POSES", "CAPTIONS", "GOAL", "NEGATIVES", "pose_class", "tip_offset", "mirrored", "pendulum_caption",
           "all_pendulum_captions"]
