"""What the scene VLM learns and is tested on: which objects an image shows, never where.

The images are renders made by a data stage (:mod:`zsrm.data.renders`) with the count of
each colour's visible pixels; an object counts as visible when at least
:data:`MIN_VISIBLE_PIXELS` of its pixels show, so blocks hidden by the gripper or fallen off
the table are not named.

Captions say *what* is visible, never *where*: a random non-empty subset of the visible
objects in random order ("a blue block and a red block"). A caption never lists everything
that is absent, so "a red block" means "there is a red block", not "only a red block" (a
prototype whose captions named exactly the visible set learnt the latter and lost presence).

The tabletop's open box has no colour: renders that show it (:mod:`zsrm.data.box_renders`) may
name it too, as "a box" (``presence_caption(..., box=True)``); captions of renders without the
box are unchanged, draw for draw.
"""
from __future__ import annotations

from typing import Iterable

import numpy as np
import torch

from zsrm.tasks.catalogue import SCENE_SHAPES
from zsrm.tasks.language import COLOURS
from zsrm.tasks.lexicon import CONTAINERS

MIN_VISIBLE_PIXELS = 5  # at 64 px; scaled with image area for other sizes
BOX_PHRASE = f"a {CONTAINERS[0]}"  # the box has no colour: its noun alone names it, as in goals


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


def presence_caption(colours: Iterable[str], shape: str, rng: np.random.Generator, box: bool = False) -> str:
    """A caption naming a random non-empty subset of ``colours`` (the visible objects), in random
    order; with ``box`` (the tabletop's box is visible too), the box is one of the objects to pick from.

    >>> presence_caption(["red", "blue"], "block", np.random.default_rng(2))
    'a blue block and a red block'
    >>> presence_caption([], "block", np.random.default_rng(2), box=True)
    'a box'
    """
    if box and shape != SCENE_SHAPES["tabletop"]:
        raise ValueError(f"the box stands on the tabletop, with blocks, not with {shape}s")
    # The box goes last, so that without it the draws (and captions) are those of before.
    phrases = [probe_text(c, shape) for c in colours] + ([BOX_PHRASE] if box else [])
    if not phrases:
        raise ValueError("a presence caption needs at least one visible object")
    k = int(rng.integers(1, len(phrases) + 1))
    chosen = rng.permutation(len(phrases))[:k]
    return join_phrases([phrases[i] for i in chosen])


def phrase_probe(phrase: str) -> str:
    """The presence probe of an object of a user's own scene, named by its noun phrase.

    >>> phrase_probe("red mug"), phrase_probe("orange plate")
    ('a red mug', 'an orange plate')
    """
    return f"{'an' if phrase[:1] in 'aeiou' else 'a'} {phrase}"


def phrases_caption(phrases: Iterable[str], rng: np.random.Generator) -> str:
    """:func:`presence_caption` for a user's own scene: a random non-empty subset of the visible
    objects' ``phrases``, in random order, never where they are.

    >>> phrases_caption(["red mug", "blue plate"], np.random.default_rng(2))
    'a blue plate and a red mug'
    """
    probes = [phrase_probe(p) for p in phrases]
    if not probes:
        raise ValueError("a presence caption needs at least one visible object")
    k = int(rng.integers(1, len(probes) + 1))
    return join_phrases([probes[i] for i in rng.permutation(len(probes))[:k]])


def all_phrases_captions(phrases: Iterable[str], limit: int = 5000) -> list[str]:
    """Every caption :func:`phrases_caption` can write for these objects (their ordered
    subsets), or none when there would be more than ``limit`` (they are then encoded as drawn)."""
    from itertools import permutations
    from math import perm

    probes = [phrase_probe(p) for p in phrases]
    if sum(perm(len(probes), k) for k in range(1, len(probes) + 1)) > limit:
        return []
    return [join_phrases(list(p)) for k in range(1, len(probes) + 1) for p in permutations(probes, k)]


def visible_names(visible_row: np.ndarray, names, image_size: int = 64) -> list[str]:
    """The ``names`` (in order with ``visible_row``) whose objects show enough pixels to be named."""
    threshold = min_visible_pixels(image_size)
    return [c for c, n in zip(names, visible_row) if n >= threshold]


def all_presence_captions(shape: str) -> list[str]:
    """Every caption :func:`presence_caption` can write for a shape (ordered subsets of COLOURS)."""
    from itertools import permutations

    return [join_phrases([probe_text(c, shape) for c in perm])
            for k in range(1, len(COLOURS) + 1) for perm in permutations(COLOURS, k)]


def all_box_captions() -> list[str]:
    """Every caption :func:`presence_caption` can write with ``box=True`` that names the box
    (ordered subsets of the four blocks and the box that hold the box); the others are
    :func:`all_presence_captions` of blocks."""
    from itertools import permutations

    phrases = [probe_text(c, SCENE_SHAPES["tabletop"]) for c in COLOURS] + [BOX_PHRASE]
    return [join_phrases(list(perm)) for k in range(1, len(phrases) + 1)
            for perm in permutations(phrases, k) if BOX_PHRASE in perm]


def box_visible(pixels: int, image_size: int = 64) -> bool:
    """Does the box show enough pixels to be named (the colours' threshold)?"""
    return int(pixels) >= min_visible_pixels(image_size)


def visible_colours(visible_row: np.ndarray, image_size: int = 64) -> list[str]:
    """Colours whose objects show enough pixels to be named."""
    return visible_names(visible_row, COLOURS, image_size)


def presence_scores(vlm, images: np.ndarray, shapes: np.ndarray, batch_size: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(relative scores, raw cosine similarities), both (N, 4) in COLOURS order.

    ``shapes[i]`` is the index of image i's scene in ``SCENE_SHAPES`` (0: tabletop, block
    probes; 1: pushing, puck probes). The relative score of colour c is its probe's cosine
    minus the mean cosine of the other colours' probes.
    """
    probes = {k: vlm.encode_texts([probe_text(c, shape) for c in COLOURS])
              for k, shape in enumerate(SCENE_SHAPES.values())}
    sims = np.zeros((len(images), len(COLOURS)), np.float32)
    with torch.no_grad():
        for lo in range(0, len(images), batch_size):
            emb = vlm.encode_images(images[lo:lo + batch_size])
            for k in probes:
                rows = np.flatnonzero(shapes[lo:lo + batch_size] == k)
                if len(rows):
                    sims[lo + rows] = (emb[rows] @ probes[k].T).cpu().numpy()
    others = (sims.sum(axis=1, keepdims=True) - sims) / (len(COLOURS) - 1)
    return sims - others, sims
