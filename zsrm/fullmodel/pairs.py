"""Image-caption pairs for training the full reward model.

A labelled exploration image holds one frame per camera and a list of captions (every
relation the labeler found). Each caption becomes one training pair with the frame of the
camera its relation is read on (Table 1: front for left/right/on top/below/in between, left
for in front/behind, tilted for close to/inside of).

:class:`CaptionedImages` is the in-memory form; :meth:`CaptionedImages.from_dataset` reads a
folder written by ``zsrm collect`` and ``zsrm label``, taking the Grad-CAM captions only: the
true-coordinate captions are evaluation data and never reach training.

>>> import numpy as np
>>> frames = {"front": np.zeros((2, 16, 16, 3), np.uint8)}
>>> data = CaptionedImages(frames, [["a red block on the left of a blue block"], []], groups=[0, 1])
>>> len(data), data.n_pairs, data.pair_texts()
(2, 1, ['a red block on the left of a blue block'])
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from zsrm.data.dataset import LABELS, ExplorationData
from zsrm.grounding.labeler import relation_tuples
from zsrm.tasks.catalogue import SCENE_SHAPES
from zsrm.tasks.language import Task
from zsrm.tasks.scene_goals import SceneGoal
from zsrm.tasks.negatives import COMPLEMENTS, caption_candidates, caption_relation_camera, complement_text


@lru_cache(maxsize=None)
def caption_camera(caption: str) -> str:
    """The camera a caption's relation is read on."""
    return caption_relation_camera(caption)[1]


@lru_cache(maxsize=None)
def caption_relation(caption: str) -> str:
    return caption_relation_camera(caption)[0]


def complement_captions(captions: Sequence[str], objects: Sequence[str], shape: str | None) -> list[str]:
    """Complement captions of one image (see :data:`~zsrm.tasks.negatives.COMPLEMENTS`): for each
    complemented relation, every object tuple the labeler reads it for
    (:func:`~zsrm.grounding.labeler.relation_tuples`) that it did not caption: "a far from b" for
    coloured objects not found close to each other, and where ``objects`` holds the box, "a
    outside of a box" for coloured objects not found inside of it. ``shape`` None: ``objects`` are
    an own scene's phrases."""
    have = set(captions)
    goal = SceneGoal if shape is None else (lambda relation, objs: Task(relation, objs, shape))
    tasks = (goal(relation, [objects[i] for i in t])
             for relation in COMPLEMENTS for t in relation_tuples(relation, objects))
    return [complement_text(t) for t in tasks if t.text not in have]


class CaptionedImages:
    """N multi-camera frames with their captions; one pair per (image, caption).

    images:   camera -> (N, H, W, 3) uint8.
    captions: N lists of canonical goal sentences (may be empty).
    groups:   (N,) ints; images of one group (an exploration episode) are never split
              between training and validation, as consecutive frames look alike.
    objects:  optional (shape, objects) of each image's scene: its colours, and the box where it holds
              it (what the labeler reads too); with it, complement captions are added
              (:func:`complement_captions`).
    """

    def __init__(self, images: Mapping[str, np.ndarray], captions: Sequence[Sequence[str]],
                 groups: Sequence[int] | None = None, objects: Sequence[tuple[str, Sequence[str]]] | None = None):
        self.images = {c: np.asarray(v) for c, v in images.items()}
        sizes = {len(v) for v in self.images.values()}
        if len(sizes) != 1:
            raise ValueError(f"every camera needs the same number of frames, got {sorted(sizes)}")
        n = sizes.pop()
        if len(captions) != n:
            raise ValueError(f"{len(captions)} caption lists for {n} images")
        for c, v in self.images.items():
            if v.ndim != 4 or v.shape[-1] != 3 or v.dtype != np.uint8:
                raise ValueError(f"images[{c!r}] must be (N, H, W, 3) uint8, got {v.dtype} {v.shape}")
        self.captions = [list(c) for c in captions]
        if objects is not None:
            if len(objects) != n:
                raise ValueError(f"{len(objects)} object lists for {n} images")
            self.captions = [caps + complement_captions(caps, colours, shape)
                             for caps, (shape, colours) in zip(self.captions, objects)]
        self.groups = np.arange(n) if groups is None else np.asarray(groups, dtype=np.int64)
        if self.groups.shape != (n,):
            raise ValueError(f"groups must have shape ({n},), got {self.groups.shape}")
        # Pairs: (row, caption) for every caption whose camera this data holds.
        rows, texts = [], []
        for r, caps in enumerate(self.captions):
            for cap in dict.fromkeys(caps):
                if caption_camera(cap) in self.images:
                    rows.append(r)
                    texts.append(cap)
        self.pair_rows = np.asarray(rows, dtype=np.int64)
        self._pair_texts = texts

    def __len__(self) -> int:
        return len(self.captions)

    @property
    def n_pairs(self) -> int:
        return len(self.pair_rows)

    @property
    def cameras(self) -> tuple[str, ...]:
        return tuple(self.images)

    def pair_texts(self, index: np.ndarray | None = None) -> list[str]:
        if index is None:
            return list(self._pair_texts)
        return [self._pair_texts[i] for i in np.asarray(index).reshape(-1)]

    def pair_images(self, index: np.ndarray) -> np.ndarray:
        """The frame of each pair's caption camera: (len(index), H, W, 3) uint8."""
        index = np.asarray(index).reshape(-1)
        texts = self.pair_texts(index)
        first = next(iter(self.images.values()))
        out = np.empty((len(index),) + first.shape[1:], np.uint8)
        for k, (i, t) in enumerate(zip(index, texts)):
            out[k] = self.images[caption_camera(t)][self.pair_rows[i]]
        return out

    def holds(self, pair: int) -> set[str]:
        """Every caption of the pair's image: texts that must not serve as its negatives."""
        return set(self.captions[self.pair_rows[pair]])

    def subset(self, rows: np.ndarray) -> "CaptionedImages":
        rows = np.asarray(rows, dtype=np.int64)
        # Captions already hold their complements: none are added again.
        return CaptionedImages({c: v[rows] for c, v in self.images.items()},
                               [self.captions[r] for r in rows], self.groups[rows])

    def split(self, val_fraction: float, seed: int = 0) -> tuple["CaptionedImages", "CaptionedImages"]:
        """(train, validation), whole groups to one side, ``val_fraction`` of the groups held out."""
        if not 0.0 <= val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in [0, 1), got {val_fraction}")
        groups = np.unique(self.groups)
        rng = np.random.default_rng([seed, 7])
        n_val = int(round(val_fraction * len(groups)))
        if val_fraction > 0 and n_val == 0 and len(groups) > 1:
            n_val = 1
        val_groups = rng.choice(groups, n_val, replace=False) if n_val else np.array([], np.int64)
        is_val = np.isin(self.groups, val_groups)
        return self.subset(np.nonzero(~is_val)[0]), self.subset(np.nonzero(is_val)[0])

    def relation_counts(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for t in self._pair_texts:
            rel = caption_relation(t)
            counts[rel] = counts.get(rel, 0) + 1
        return counts

    def sampling_weights(self, balance: float = 1.0) -> np.ndarray:
        """Probability of drawing each pair: ``count(relation) ** -balance``, normalised.

        balance 0 draws pairs uniformly; 1 draws each relation equally often (on top of is
        rare in random exploration, left/right of are in almost every image).
        """
        if self.n_pairs == 0:
            raise ValueError("no image-caption pairs: are the images labelled, with the captions' cameras?")
        counts = self.relation_counts()
        w = np.array([counts[caption_relation(t)] ** -float(balance) for t in self._pair_texts])
        return w / w.sum()

    def vocabulary(self) -> list[str]:
        """Every caption and every negative of every caption, each once."""
        seen: dict[str, None] = {}
        for t in dict.fromkeys(self._pair_texts):
            seen.update(dict.fromkeys(caption_candidates(t)))
        return list(seen)

    @classmethod
    def from_dataset(cls, folder: str | Path, labels: str | Path = LABELS) -> "CaptionedImages":
        """A collected and labelled dataset folder (of zsrm's scenes or an own scene's): its images,
        the Grad-CAM captions of ``labels`` and, for the complements, each scene's object list
        (what the labeler reads: an own scene's phrases)."""
        data = ExplorationData(folder)
        captions = data.captions(labels)  # Grad-CAM captions only (oracle=None)
        images, groups, objects = {c: [] for c in data.cameras}, [], []
        for s, name in enumerate(data.shards):
            arrays = data.shard(name, [f"images_{c}" for c in data.cameras] + ["episode", "present", "scene"]
                                + (["box_present"] if data.has_box else []))
            for c in data.cameras:
                images[c].append(arrays[f"images_{c}"])
            # Episodes are numbered within a shard: make the group ids unique across shards.
            groups.append(s * 1_000_000 + arrays["episode"].astype(np.int64))
            present = data.object_arrays(arrays)["present"]  # over data.objects: the box last, where it can be
            objects += [(SCENE_SHAPES.get(data.scenes[sc]), [o for o, p in zip(data.objects, row) if p])
                        for sc, row in zip(arrays["scene"], present)]
        return cls({c: np.concatenate(v) for c, v in images.items()}, captions, np.concatenate(groups), objects)
