"""A tiny hand-wired VLM whose Grad-CAM answer is known: for doctests and tests.

:class:`ColourVLM` detects the four block colours with a fixed 1x1 convolution and a ReLU
(the Grad-CAM layer, pooled to a coarser grid), averages the detector maps into an
embedding, and embeds a text as the one-hot vector of the colour it names. Grad-CAM of
"red block" on it is the red detector's map, so a test can say exactly where it must point.

>>> import numpy as np
>>> vlm = ColourVLM()
>>> image = np.zeros((32, 32, 3), np.uint8); image[:8, :8] = (30, 60, 230)
>>> (vlm.encode_images(image[None]) @ vlm.encode_texts(["a blue block", "a red block"]).T).argmax().item()
0
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from zsrm.common.registry import save_folder
from zsrm.tasks.language import COLOURS
from zsrm.vlm.base import VisionLanguageModel, pixels_from_images

# Linear colour detectors on RGB in [0, 1] (rows: red, green, yellow, blue) and biases: each
# is positive on its block colour and negative on the others, the table, floor and walls.
_DETECTORS = [(2.0, -2.0, -1.0), (-2.0, 2.0, -1.0), (1.0, 1.0, -3.0), (-1.0, -1.0, 2.0)]
_BIASES = [-0.3, -0.3, -0.9, -0.6]
_BACKGROUND = 0.1  # a constant channel, so that an image without any colour still has an embedding


class ColourVLM(VisionLanguageModel):
    backend = "testing"
    gradcam_layer = "detect"
    fine_layer = "detect.1"  # the detectors' ReLU at full resolution, before the pooling

    def __init__(self, image_size: int = 32, stride: int = 4):
        super().__init__()
        self.image_size = image_size
        self.stride = stride
        self.logit_scale = nn.Parameter(torch.tensor(np.log(100.0), dtype=torch.float32))
        self.detect = nn.Sequential(nn.Conv2d(3, len(COLOURS) + 1, 1), nn.ReLU())
        with torch.no_grad():
            self.detect[0].weight.zero_()
            self.detect[0].weight[: len(COLOURS), :, 0, 0] = torch.tensor(_DETECTORS)
            self.detect[0].bias.copy_(torch.tensor(_BIASES + [_BACKGROUND]))
        self.pool = nn.AvgPool2d(stride)

    def preprocess(self, images) -> torch.Tensor:
        return pixels_from_images(images, self.image_size, mean=(0.0, 0.0, 0.0), std=(1.0, 1.0, 1.0))

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        return self.pool(self.detect(pixels))

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        return features.mean(dim=(-2, -1))

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        out = torch.zeros(len(texts), len(COLOURS) + 1)
        for k, text in enumerate(texts):
            named = [i for i, c in enumerate(COLOURS) if c in text.lower().split()]
            out[k, named if named else [len(COLOURS)]] = 1.0
        return out

    def save(self, folder: str | Path) -> None:
        """Its config only: the weights are fixed by construction."""
        save_folder(folder, {"backend": self.backend, "image_size": self.image_size, "stride": self.stride}, {})
