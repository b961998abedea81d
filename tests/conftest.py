"""Shared test doubles: a tiny, deterministic vision-language model.

``ToyVLM`` implements the real :class:`~zsrm.vlm.base.VisionLanguageModel` interface with
embeddings one can reason about: an image embeds to its mean (R, G, B) in [0, 1]; a text
embeds to the sum of the RGB vectors of the colour words it contains (plus a small constant,
so that no text embeds to zero). It counts encoder calls so tests can check caching.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import pytest
import torch

from zsrm.vlm.base import VisionLanguageModel

COLOUR_VECTORS = {"red": (1.0, 0.0, 0.0), "green": (0.0, 1.0, 0.0), "blue": (0.0, 0.0, 1.0),
                  "yellow": (1.0, 1.0, 0.0)}


class ToyVLM(VisionLanguageModel):
    backend = "toy"
    gradcam_layer = "trunk"

    def __init__(self, size: int = 16):
        super().__init__()
        self.size = size
        self.text_calls = 0  # calls of the text tower
        self.image_calls = 0  # forwards of the image tower

    def preprocess(self, images):
        images = np.asarray(images)
        if images.ndim == 3:
            images = images[None]
        if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
            raise ValueError(f"expected uint8 (N, H, W, 3), got {images.dtype} {images.shape}")
        x = torch.from_numpy(images).permute(0, 3, 1, 2).float() / 255.0
        return torch.nn.functional.interpolate(x, size=(self.size, self.size), mode="area")

    def image_trunk(self, pixels):
        self.image_calls += 1
        return torch.relu(pixels)

    def image_head(self, features):
        return features.mean(dim=(2, 3))

    def encode_text_tokens(self, texts):
        self.text_calls += 1
        out = torch.full((len(texts), 3), 0.1)
        for i, text in enumerate(texts):
            for word in text.lower().replace(",", " ").split():
                if word in COLOUR_VECTORS:
                    out[i] += torch.tensor(COLOUR_VECTORS[word])
        return out

    def save(self, folder):
        Path(folder).mkdir(parents=True, exist_ok=True)
        (Path(folder) / "config.json").write_text(json.dumps({"backend": self.backend, "size": self.size}))


@pytest.fixture
def toy_vlm() -> ToyVLM:
    return ToyVLM()


def _solid_frames(colours, size: int = 16) -> np.ndarray:
    return np.stack([np.full((size, size, 3), c, np.uint8) for c in colours])


@pytest.fixture
def solid_frames():
    """``solid_frames([(255, 0, 0), ...], size=16)``: one-colour frames, (N, size, size, 3) uint8."""
    return _solid_frames
