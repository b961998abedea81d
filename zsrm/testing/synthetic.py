"""Synthetic captioned frames whose true captions are known: for tests and doctests.

Coloured squares on a grey background, seen "from the front": each frame is captioned by the
real spatial labeler (Table 1) from the squares' true pixel centres, with the front camera's
relations only (left of, right of, on top of, below, in between).

>>> data = synthetic_pairs(8, size=32, seed=0)
>>> len(data), data.cameras
(8, ('front',))
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from zsrm.grounding.labeler import SpatialLabeler, pixel_thresholds
from zsrm.fullmodel.pairs import CaptionedImages
from zsrm.tasks.language import COLOURS, parse_goal
from zsrm.tasks.relations import RELATIONS
from zsrm.vlm.base import VisionLanguageModel, pixels_from_images

RGB = {"red": (220, 30, 30), "green": (30, 200, 40), "yellow": (230, 220, 30), "blue": (30, 60, 230)}
FRONT_RELATIONS = tuple(r for r, rel in RELATIONS.items() if rel.camera == "front")


def render_squares(centres: dict[str, tuple[float, float]], size: int, width: int) -> np.ndarray:
    """A (size, size, 3) uint8 frame with a ``width``-pixel square per colour at (x, row)."""
    frame = np.full((size, size, 3), 120, np.uint8)
    half = width // 2
    for colour, (x, row) in centres.items():
        x0, r0 = int(round(x)) - half, int(round(row)) - half
        frame[max(r0, 0):max(r0 + width, 0), max(x0, 0):max(x0 + width, 0)] = RGB[colour]
    return frame


def synthetic_pairs(n: int, size: int = 32, width: int | None = None, colours=("red", "yellow", "green"),
                    p_stack: float = 0.3, seed: int = 0) -> CaptionedImages:
    """``n`` frames of two or three squares, a third of them stacked, captioned by Table 1."""
    rng = np.random.default_rng(seed)
    width = width or max(3, size // 8)
    labeler = SpatialLabeler(pixel_thresholds({"front": float(width)}), relations=FRONT_RELATIONS)
    frames, pixels, present = [], np.full((n, len(COLOURS), 2), np.nan), np.zeros((n, len(COLOURS)), bool)
    ground = size * 0.75
    for i in range(n):
        k = int(rng.integers(2, len(colours) + 1))
        chosen = list(rng.choice(colours, k, replace=False))
        centres: dict[str, tuple[float, float]] = {}
        for colour in chosen:
            centres[colour] = (float(rng.uniform(width, size - width)), ground)
        if rng.random() < p_stack:  # put the first square on top of the second
            x = centres[chosen[1]][0] + rng.uniform(-0.2, 0.2) * width
            centres[chosen[0]] = (x, ground - width)
        frames.append(render_squares(centres, size, width))
        for colour, xy in centres.items():
            pixels[i, COLOURS.index(colour)] = xy
            present[i, COLOURS.index(colour)] = True
    captions = labeler.captions({"front": pixels}, present)
    return CaptionedImages({"front": np.stack(frames)}, captions, groups=np.arange(n) // 2)


class TaskTextVLM(VisionLanguageModel):
    """A test double whose text tower knows the task structure and whose image tower is the
    mean colour: the student's frozen text side in fast tests. A text embeds to one-hots of
    its relation and of the colour of each of its (up to three) objects; an object phrase
    ("red block") to the one-hot of its colour."""

    backend = "testing-task-text"
    gradcam_layer = "none"

    def __init__(self):
        super().__init__()
        self.image_size = 16
        self.logit_scale = nn.Parameter(torch.tensor(float(np.log(10.0))))
        self.text_calls = 0

    def preprocess(self, images) -> torch.Tensor:
        return pixels_from_images(images, self.image_size, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        return pixels

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        return features.mean(dim=(2, 3))

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        self.text_calls += 1
        relations, k = list(RELATIONS), len(COLOURS)
        out = torch.zeros(len(texts), len(relations) + 3 * k)
        for i, text in enumerate(texts):
            words = text.split()
            if len(words) == 2 and words[0] in COLOURS:  # an object phrase, "red block"
                out[i, len(relations) + COLOURS.index(words[0])] = 1.0
                continue
            task = parse_goal(text)
            out[i, relations.index(task.relation)] = 1.0
            for j, colour in enumerate(task.objects):
                out[i, len(relations) + j * k + COLOURS.index(colour)] = 1.0
        return out

    def save(self, folder) -> None:
        raise NotImplementedError("TaskTextVLM is a test double and is not saved")
