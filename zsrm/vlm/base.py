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
    """Image tower, text tower and a dot product; see :func:`zsrm.vlm.load_vlm`.

    ``logit_scale`` is the learnable log temperature of contrastive training (CLIP's), so
    ``logit_scale.exp() * image @ text.T`` are the logits of a batch.
    """

    backend: str  # "open_clip" or "scene"
    gradcam_layer: str  # name of the module whose output Grad-CAM reads
    # An earlier module on a finer grid whose LayerCAM refines where Grad-CAM's coarse map
    # points (zsrm.grounding's locate="fine"); None: the Grad-CAM layer itself.
    fine_layer: str | None = None
    image_size: int  # side of the square input that preprocess produces
    logit_scale: nn.Parameter

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

    def similarity(self, images: ImageBatch, texts: Sequence[str]) -> torch.Tensor:
        """Cosine similarities (N images, M texts): the base reward of paper section 2.1."""
        return self.encode_images(images) @ self.encode_texts(texts).T

    def encode_texts(self, texts: Sequence[str], normalize: bool = True) -> torch.Tensor:
        if isinstance(texts, str):
            texts = [texts]
        texts = list(texts)
        if not texts:
            raise ValueError("no texts given: pass one or more non-empty strings")
        for t in texts:
            if not isinstance(t, str) or not t.strip():
                raise ValueError("texts must be non-empty strings")
        emb = self.encode_text_tokens(texts)
        return nn.functional.normalize(emb, dim=-1) if normalize else emb


def image_batch(images: ImageBatch) -> list[np.ndarray]:
    """Check images and return them as a list of uint8 (H, W, 3) arrays.

    Accepts one uint8 HWC array, an NHWC batch, a list of such arrays, PIL images (converted
    to RGB) or uint8 torch tensors laid out the same way. Anything else raises ValueError
    with the reason, because a float or CHW image silently rescaled would give wrong rewards.

    >>> [a.shape for a in image_batch(np.zeros((2, 64, 64, 3), np.uint8))]
    [(64, 64, 3), (64, 64, 3)]
    >>> image_batch(np.zeros((64, 64), np.uint8))
    Traceback (most recent call last):
    ...
    ValueError: images must be uint8 RGB arrays of shape (H, W, 3) or (N, H, W, 3), got a 2-D array of shape (64, 64)
    """
    if isinstance(images, torch.Tensor):
        images = images.detach().cpu().numpy()
    if isinstance(images, np.ndarray):
        if images.ndim == 4:
            return [_check_image(im, f"image {i}") for i, im in enumerate(_check_dtype(images))]
        return [_check_image(images, "image")]
    if _is_pil(images):
        return [np.asarray(images.convert("RGB"))]
    if isinstance(images, (str, bytes)) or not isinstance(images, Sequence):
        raise ValueError(f"images must be uint8 arrays, PIL images or a list of them, got {type(images).__name__}")
    if len(images) == 0:
        raise ValueError("no images given")
    out = []
    for i, im in enumerate(images):
        if _is_pil(im):
            out.append(np.asarray(im.convert("RGB")))
        elif isinstance(im, (np.ndarray, torch.Tensor)):
            im = im.detach().cpu().numpy() if isinstance(im, torch.Tensor) else im
            out.append(_check_image(im, f"image {i}"))
        else:
            raise ValueError(f"image {i} must be a uint8 array or a PIL image, got {type(im).__name__}")
    return out


def _is_pil(obj) -> bool:
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - pillow is a dependency
        return False
    return isinstance(obj, Image.Image)


def _check_dtype(a: np.ndarray) -> np.ndarray:
    if a.dtype != np.uint8:
        raise ValueError(
            f"images must be uint8 with values 0-255, got dtype {a.dtype}; "
            "convert with (img * 255).round().astype(np.uint8) if yours are floats in [0, 1]"
        )
    return a


def _check_image(a: np.ndarray, what: str) -> np.ndarray:
    if a.ndim != 3:
        raise ValueError(
            f"images must be uint8 RGB arrays of shape (H, W, 3) or (N, H, W, 3), got a {a.ndim}-D array of shape {a.shape}"
        )
    if a.shape[-1] != 3:
        hint = " (channels first? pass H, W, 3)" if a.shape[0] == 3 else ""
        raise ValueError(f"{what} must have 3 colour channels (RGB) last, got shape {a.shape}{hint}")
    if min(a.shape[:2]) < 8:
        raise ValueError(f"{what} is too small: {a.shape[0]}x{a.shape[1]} pixels")
    return _check_dtype(a)


def pixels_from_images(images: ImageBatch, size: int, mean, std, crop: bool = True,
                       device: torch.device | str = "cpu") -> torch.Tensor:
    """uint8 images -> normalised float pixels (N, 3, size, size).

    Square images are resized; others are resized on their short side and centre-cropped
    (``crop=True``, CLIP's "shortest" mode) or squashed (``crop=False``).
    """
    if isinstance(images, np.ndarray) and images.ndim == 4 and len(images):
        _check_image(_check_dtype(images)[0], "image 0")  # one batch, one shape: no list to split and stack
        arrays, by_shape = images if images.flags.writeable else images.copy(), {images.shape[1:]: slice(None)}
    else:
        arrays = image_batch(images)
        by_shape = {}
        for i, a in enumerate(arrays):  # resize images of one shape together
            by_shape.setdefault(a.shape, []).append(i)
    mean_t = torch.tensor(mean, dtype=torch.float32, device=device).view(1, 3, 1, 1)
    std_t = torch.tensor(std, dtype=torch.float32, device=device).view(1, 3, 1, 1)
    out = torch.empty(len(arrays), 3, size, size, device=device)
    for shape, idx in by_shape.items():
        x = torch.from_numpy(np.ascontiguousarray(arrays[idx]) if isinstance(idx, slice)
                             else np.stack([arrays[i] for i in idx])).to(device).permute(0, 3, 1, 2).float() / 255.0
        h, w = shape[:2]
        if (h, w) != (size, size):
            if crop and h != w:
                scale = size / min(h, w)
                nh, nw = max(size, round(h * scale)), max(size, round(w * scale))
                x = nn.functional.interpolate(x, (nh, nw), mode="bicubic", antialias=True, align_corners=False)
                top, left = (nh - size) // 2, (nw - size) // 2
                x = x[:, :, top:top + size, left:left + size]
            else:
                x = nn.functional.interpolate(x, (size, size), mode="bicubic", antialias=True, align_corners=False)
            x = x.clamp(0.0, 1.0)
        out[idx] = (x - mean_t) / std_t
    return out


def check_image_tower(config, stages: int, multiple: int) -> None:
    """Normalise and check a conv image tower's config in place (JSON gives lists, not tuples):
    ``widths`` must have ``stages`` entries and ``image_size`` be a multiple of ``multiple``."""
    config.widths = tuple(int(w) for w in config.widths)
    config.mean, config.std = tuple(config.mean), tuple(config.std)
    if len(config.widths) != stages:
        raise ValueError(f"widths must have {stages} entries, got {config.widths}")
    if config.image_size % multiple or config.image_size < multiple:
        raise ValueError(f"image_size must be a positive multiple of {multiple}, got {config.image_size}")
    if min(config.widths) < 1 or config.embed_dim < 1:
        raise ValueError(f"widths and embed_dim must be positive, got {config.widths} and {config.embed_dim}")
