"""The one interface every vision-language model in zsrm implements.

A VLM is an image tower, a text tower and a dot product (paper section 2.1). The image tower
is split at the layer Grad-CAM reads (the last convolutional ReLU) into ``image_trunk`` and
``image_head`` so that grounding runs the trunk once per image and sends every phrase's
gradient through the head alone.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from torch import nn

ImageBatch = "np.ndarray | Sequence[np.ndarray] | Sequence[PIL.Image.Image] | torch.Tensor"


class VisionLanguageModel(nn.Module, ABC):
    backend: str  # "open_clip" or "scene"
    gradcam_layer: str  # name of the module whose output Grad-CAM reads

    @abstractmethod
    def preprocess(self, images: ImageBatch) -> torch.Tensor:
        """uint8 HWC arrays (one, a list, or an NHWC batch) or PIL images -> model input NCHW float.
        Raises ValueError naming the problem for a wrong shape or dtype."""

    @abstractmethod
    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        """Preprocessed pixels -> the Grad-CAM layer's activations (N, C, h, w)."""

    @abstractmethod
    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        """Grad-CAM layer activations -> image embeddings (N, D), not normalised."""

    @abstractmethod
    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        """Texts -> text embeddings (M, D), not normalised."""

    @abstractmethod
    def save(self, folder: str | Path) -> None:
        """Weights as safetensors plus a JSON config, in one folder."""

    def encode_images(self, images: ImageBatch, normalize: bool = True) -> torch.Tensor:
        pixels = self.preprocess(images)
        emb = self.image_head(self.image_trunk(pixels))
        return nn.functional.normalize(emb, dim=-1) if normalize else emb

    def encode_texts(self, texts: Sequence[str], normalize: bool = True) -> torch.Tensor:
        if isinstance(texts, str):
            texts = [texts]
        texts = list(texts)
        for t in texts:
            if not isinstance(t, str) or not t.strip():
                raise ValueError("texts must be non-empty strings")
        emb = self.encode_text_tokens(texts)
        return nn.functional.normalize(emb, dim=-1) if normalize else emb
