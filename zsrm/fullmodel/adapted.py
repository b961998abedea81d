"""A VLM with two adapters for spatial captions: the model ``zsrm finetune`` trains by default.

The VLM stays whole (its trunk, head and text tower all train); two residual read-outs are
added, each starting at zero, so that before training the model *is* the VLM:

* image: where things are. CLIP's RN50 pools its last feature map with attention and
  positional embeddings, so its embedding can carry positions; the ``scene`` stand-in pools
  with mean and max, which throws positions away. The image adapter adds a linear read-out of
  the Grad-CAM layer's map pooled to a ``grid`` x ``grid`` layout.
* text: which relation, in which order. A text tower that learned which objects a scene
  holds gives "a yellow block on the left of a red block", "... on the right of ..." and "a red
  block on the left of a yellow block" nearly the same embedding; the text adapter adds an MLP
  of the whitened sentence embedding and the embeddings of its object phrases in order
  (:class:`~zsrm.fullmodel.text.RoleTextFeatures`), whitened on the training captions. Its
  input comes from a frozen copy of the VLM as it was before fine-tuning (``reference``,
  loaded again from its spec, not saved): whitening magnifies small directions of the
  embedding, and reading them off the text tower being trained would feed the adapter a
  moving input.

>>> import numpy as np, torch
>>> from zsrm.vlm import create_scene_vlm
>>> vlm = create_scene_vlm("tiny", seed=0, image_size=32)
>>> model = AdaptedVLM(vlm, grid=4, reference=create_scene_vlm("tiny", seed=0, image_size=32), reference_spec="tiny")
>>> x = np.zeros((2, 32, 32, 3), np.uint8)
>>> torch.equal(model.encode_images(x), vlm.encode_images(x))  # identical before training
True
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from zsrm.common.registry import build_model, load_folder, load_weights, read_config, register_kind, save_folder
from zsrm.fullmodel.text import RoleTextFeatures, load_frozen_reference, portable_spec, stored_spec
from zsrm.vlm.base import ImageBatch, VisionLanguageModel
from zsrm.vlm.text_cache import TextEmbeddingCache

BACKEND = "zsrm-adapted"
ADAPTERS_FILE = "adapters.safetensors"


@dataclass
class AdaptedFolder:
    """config.json of a saved adapted VLM (its base VLM is saved in base/, in its own format)."""

    backend: str
    grid: int  # image adapter: avg-pool grid of the trunk's map (0: none)
    text_hidden: int  # text adapter: hidden units (0: none)
    base_backend: str
    meta: dict | None = None
    reference: str | None = None  # spec of the frozen VLM the text adapter reads (with text_hidden)
    reference_is_folder: bool = False

    def __post_init__(self):
        if self.grid < 0 or self.text_hidden < 0:
            raise ValueError(f"grid and text_hidden must be >= 0, got {self.grid} and {self.text_hidden}")
        if self.text_hidden and self.reference is None:
            raise ValueError("a text adapter (text_hidden > 0) needs 'reference', the VLM it reads texts through")


class AdaptedVLM(VisionLanguageModel):
    """``image_head(f) = base.image_head(f) + W . flatten(avgpool_grid(f))`` (``grid`` 0: no image
    adapter) and ``text(t) = base.text(t) + MLP(role_features(t))`` (``text_hidden`` 0: none)."""

    backend = BACKEND

    def __init__(self, base: VisionLanguageModel, grid: int = 4, text_hidden: int = 256,
                 reference: VisionLanguageModel | None = None, reference_spec: str | None = None,
                 meta: dict | None = None):
        super().__init__()
        if grid < 0 or text_hidden < 0:
            raise ValueError(f"grid and text_hidden must be >= 0, got {grid} and {text_hidden}")
        self.base = base
        self.grid = int(grid)
        self.text_hidden = int(text_hidden)
        self.image_size = base.image_size
        self.gradcam_layer = f"base.{base.gradcam_layer}" if base.gradcam_layer else None
        self.meta: dict = dict(meta or {})
        self.spatial = None
        self.text_norm = self.text_adapter = None
        if self.text_hidden:
            if reference is None or reference_spec is None:
                raise ValueError("a text adapter needs the frozen reference VLM and its spec")
            # Frozen and kept out of this module's parameters and weights (loaded from its spec).
            self.__dict__["reference"] = reference.eval().requires_grad_(False)
            self.reference_spec = str(reference_spec)
            self._reference_cache = TextEmbeddingCache(lambda t: self.reference.encode_text_tokens(t).float().cpu())
            with torch.no_grad():
                text_dim = reference.encode_text_tokens(["a red block on the left of a blue block"]).shape[-1]
            self.text_norm = RoleTextFeatures(text_dim)
            self.text_adapter = nn.Sequential(nn.Linear(self.text_norm.out_dim, self.text_hidden), nn.ReLU(),
                                              nn.Linear(self.text_hidden, text_dim))
            nn.init.zeros_(self.text_adapter[-1].weight)
            nn.init.zeros_(self.text_adapter[-1].bias)
        if not self.grid:
            return
        try:
            with torch.no_grad():
                probe = base.image_trunk(base.preprocess(torch.zeros(1, base.image_size, base.image_size, 3,
                                                                     dtype=torch.uint8)))
                dim = base.image_head(probe).shape[-1]
        except (NotImplementedError, RuntimeError, ValueError) as err:
            raise ValueError(f"a spatial head needs the VLM's image trunk (a conv feature map), which this "
                             f"{base.backend} model does not expose ({err}); fine-tune with --spatial-grid 0") from None
        if probe.ndim != 4:
            raise ValueError(f"the VLM's trunk gives {probe.ndim}-D features, not a (N, C, h, w) map; "
                             "fine-tune with --spatial-grid 0")
        self.spatial = nn.Sequential(nn.AdaptiveAvgPool2d(self.grid), nn.Flatten(),
                                     nn.Linear(probe.shape[1] * self.grid * self.grid, dim))
        nn.init.zeros_(self.spatial[-1].weight)
        nn.init.zeros_(self.spatial[-1].bias)

    @property
    def logit_scale(self) -> nn.Parameter:
        return self.base.logit_scale

    def preprocess(self, images: ImageBatch) -> torch.Tensor:
        return self.base.preprocess(images)

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        return self.base.image_trunk(pixels)

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        out = self.base.image_head(features)
        return out + self.spatial(features) if self.spatial is not None else out

    def encode_images(self, images: ImageBatch, normalize: bool = True) -> torch.Tensor:
        if self.spatial is None:  # e.g. an open_clip ViT, whose trunk is not split off
            return self.base.encode_images(images, normalize)
        return super().encode_images(images, normalize)

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        e = self.base.encode_text_tokens(texts)
        if self.text_adapter is None:
            return e
        return e + self.text_adapter(self.text_norm(self.reference_texts, list(texts))).to(e.dtype)

    def reference_texts(self, texts: list[str]) -> torch.Tensor:
        """The frozen reference VLM's text embeddings, computed once per text."""
        return self._reference_cache(texts).to(self._device)

    @property
    def _device(self) -> torch.device:
        return self.logit_scale.device

    def fit_text_statistics(self, texts: list[str]) -> None:
        """Whiten the text adapter's input with the statistics of these (training) texts."""
        if self.text_norm is not None:
            self.text_norm.fit(self.reference_texts, list(texts))

    # --- persistence: the base VLM in its own format in base/, the read-out beside it ----
    def _adapters(self) -> nn.ModuleDict:
        return nn.ModuleDict({k: m for k, m in (("spatial", self.spatial), ("text_norm", self.text_norm),
                                                ("text_adapter", self.text_adapter)) if m is not None})

    def save(self, folder: str | Path) -> None:
        self.base.save(Path(folder) / "base")
        config = {"backend": BACKEND, "grid": self.grid, "text_hidden": self.text_hidden,
                  "base_backend": self.base.backend, "meta": self.meta}
        if self.text_hidden:
            spec, is_folder = portable_spec(self.reference_spec, folder)
            config.update(reference=spec, reference_is_folder=is_folder)
        save_folder(folder, config, {ADAPTERS_FILE: self._adapters()})

    @classmethod
    def from_folder(cls, folder: str | Path, device: str | torch.device = "cpu") -> "AdaptedVLM":
        cfg = read_config(folder, kind=BACKEND, schema=AdaptedFolder)
        reference = spec = None
        if cfg.text_hidden:
            spec = stored_spec(cfg.reference, cfg.reference_is_folder, folder)
            reference = load_frozen_reference(spec, device, f"the model in {folder} reads texts through")
        base = load_folder(Path(folder) / "base", device)
        model = build_model(folder, lambda: cls(base, grid=cfg.grid, text_hidden=cfg.text_hidden, reference=reference,
                                                reference_spec=spec, meta=cfg.meta))
        load_weights(model._adapters(), folder, ADAPTERS_FILE, device=device)
        return model.to(device).eval()


register_kind(BACKEND, AdaptedVLM.from_folder)
