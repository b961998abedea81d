"""A small reward network trained from scratch on the generated pairs, for the RL inner loop.

The paper reports that training on the generated data from scratch works well. The student
is a four-layer CNN at 64 px whose last feature map is flattened (not pooled), so where an
object is stays in the embedding; its text side is a frozen VLM's text embeddings of the
sentence and of its object phrases in order (:class:`~zsrm.fullmodel.text.RoleTextFeatures`,
computed once per text and cached) through a small trainable MLP. It implements the
:class:`~zsrm.vlm.base.VisionLanguageModel` interface, so it trains with the same loop as
the VLM and plugs into the same rewards.

>>> import numpy as np
>>> from zsrm.testing import ColourVLM
>>> net = StudentRewardNet(StudentConfig(image_size=32, widths=(8, 8, 8, 8), embed_dim=8), ColourVLM(), "testing")
>>> net.encode_images(np.zeros((2, 32, 32, 3), np.uint8)).shape
torch.Size([2, 8])
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np  # noqa: F401  (doctest)
import torch
from torch import nn

from zsrm.common.registry import (WEIGHTS_FILE, build_model, folder_kind, load_weights, read_config, register_kind,
                                  register_shipped, save_folder)
from zsrm.fullmodel.text import RoleTextFeatures, load_frozen_reference, portable_spec, stored_spec
from zsrm.vlm.base import ImageBatch, VisionLanguageModel, check_image_tower, pixels_from_images
from zsrm.vlm.text_cache import TextEmbeddingCache

BACKEND = "zsrm-student"
# The student trained by `make results` (results/reward_eval.json), shipped so that the ZSRM
# reward works offline without training first: load it with the spec "student".
SHIPPED_STUDENT_DIR = Path(__file__).resolve().parent / "weights" / "student"


@dataclass
class StudentConfig:
    image_size: int = 64
    widths: tuple[int, int, int, int] = (32, 64, 64, 128)  # four stride-2 convs: 64 px -> 4x4 map
    embed_dim: int = 128
    text_hidden: int = 256
    mean: tuple[float, float, float] = (0.5, 0.5, 0.5)
    std: tuple[float, float, float] = (0.25, 0.25, 0.25)

    def __post_init__(self):
        check_image_tower(self, stages=4, multiple=16)


@dataclass
class StudentFolder:
    """config.json of a saved student."""

    backend: str
    config: StudentConfig
    text_vlm: str  # spec of the VLM whose frozen text tower it reads through
    text_vlm_is_folder: bool = False
    meta: dict | None = None


class StudentRewardNet(VisionLanguageModel):
    """CNN image tower + (frozen VLM text embedding -> MLP) text tower.

    ``text_vlm`` is any VisionLanguageModel; only its text tower is used, frozen, and it is
    not part of this model's weights (``text_vlm_spec`` says how to load it again).
    """

    backend = BACKEND
    gradcam_layer = "features"

    def __init__(self, config: StudentConfig, text_vlm: VisionLanguageModel, text_vlm_spec: str,
                 meta: dict | None = None):
        super().__init__()
        self.config = config
        self.image_size = config.image_size
        w = config.widths
        layers, cin = [], 3
        for cout in w:
            layers += [nn.Conv2d(cin, cout, 3, stride=2, padding=1), nn.ReLU()]
            cin = cout
        self.features = nn.Sequential(*layers)
        side = config.image_size // 16
        self.image_proj = nn.Sequential(nn.Flatten(), nn.Linear(w[-1] * side * side, config.embed_dim))
        # The text vlm is frozen and saved elsewhere: keep it out of this module's parameters.
        self.__dict__["text_vlm"] = text_vlm.eval().requires_grad_(False)
        self.text_vlm_spec = str(text_vlm_spec)
        with torch.no_grad():
            text_dim = text_vlm.encode_texts(["a red block on the left of a blue block"]).shape[-1]
        self.text_features = RoleTextFeatures(text_dim)
        self.text_proj = nn.Sequential(nn.Linear(self.text_features.out_dim, config.text_hidden), nn.ReLU(),
                                       nn.Linear(config.text_hidden, config.embed_dim))
        self.logit_scale = nn.Parameter(torch.tensor(math.log(1 / 0.07)))
        self.meta: dict = dict(meta or {})
        self._frozen_text = TextEmbeddingCache(lambda t: self.text_vlm.encode_texts(t).float().cpu())

    @property
    def device(self) -> torch.device:
        return self.logit_scale.device

    def preprocess(self, images: ImageBatch) -> torch.Tensor:
        return pixels_from_images(images, self.image_size, self.config.mean, self.config.std, device=self.device)

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        return self.features(pixels)

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        return self.image_proj(features)

    def frozen_text_features(self, texts: list[str]) -> torch.Tensor:
        """The text VLM's normalised embeddings, computed once per text."""
        return self._frozen_text(texts).to(self.device)

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        return self.text_proj(self.text_features(self.frozen_text_features, list(texts)))

    def fit_text_statistics(self, texts: list[str]) -> None:
        """Whiten the frozen text embeddings with the statistics of these (training) texts."""
        self.text_features.fit(self.frozen_text_features, list(texts))

    # --- persistence ---------------------------------------------------------------------
    def save(self, folder: str | Path) -> None:
        spec, is_folder = portable_spec(self.text_vlm_spec, folder)
        config = {"backend": BACKEND, "config": asdict(self.config), "text_vlm": spec,
                  "text_vlm_is_folder": is_folder, "meta": self.meta}
        save_folder(folder, config, {WEIGHTS_FILE: self})

    @classmethod
    def from_folder(cls, folder: str | Path, device: str | torch.device = "cpu",
                    text_vlm: VisionLanguageModel | None = None) -> "StudentRewardNet":
        cfg = read_config(folder, kind=BACKEND, schema=StudentFolder)
        spec = stored_spec(cfg.text_vlm, cfg.text_vlm_is_folder, folder)
        if text_vlm is None:
            text_vlm = load_frozen_reference(spec, device, f"the student in {folder} embeds texts with")
        model = build_model(folder, lambda: cls(cfg.config, text_vlm, spec, meta=cfg.meta))
        load_weights(model, folder, device=device)
        return model.to(device).eval()


def is_student_folder(spec) -> bool:
    return folder_kind(spec) == BACKEND


register_kind(BACKEND, StudentRewardNet.from_folder)
register_shipped("student", SHIPPED_STUDENT_DIR)
