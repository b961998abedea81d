"""The ``open_clip`` backend: any open_clip model, RN50 with OpenAI's weights by default (the paper's).

Weights come from open_clip's pretrained tags (downloaded once, then read from the cache) or
from a local file. Loading never runs code from a file: safetensors, or ``torch.load`` with
``weights_only=True`` (OpenAI's original TorchScript ``.pt`` files are refused; use the
safetensors copy on the Hugging Face hub instead).

Grad-CAM reads the last convolutional ReLU: for open_clip's ResNets (RN50, RN101, RN50x4,
...) the output of ``visual.layer4``; the head is the attention pool (which ends with the
projection to the joint space). Vision transformers have no such layer: they encode images
but refuse the trunk/head split.

>>> vlm = create_open_clip_vlm("RN50", pretrained="none")  # doctest: +SKIP
>>> vlm.gradcam_layer  # doctest: +SKIP
'visual.layer4'
"""
from __future__ import annotations

import json
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from zsrm.common.registry import WEIGHTS_FILE, build_model, read_config, register_kind, save_folder
from zsrm.common.registry import load_weights as load_folder_weights
from zsrm.vlm.base import ImageBatch, VisionLanguageModel, pixels_from_images

CHECKPOINT_SUFFIXES = (".safetensors", ".pt", ".pth", ".bin")
HF_SAFE_WEIGHTS = "open_clip_model.safetensors"
HF_WEIGHTS = "open_clip_pytorch_model.bin"


class WeightsUnavailableError(FileNotFoundError):
    """Pretrained weights are neither cached nor downloadable; the message says how to pass a file."""


def _offline() -> bool:
    return os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on")


def looks_like_path(pretrained: str) -> bool:
    return os.sep in pretrained or "/" in pretrained or pretrained.lower().endswith(CHECKPOINT_SUFFIXES)


@dataclass
class OpenClipFolder:
    """config.json of a saved open_clip model (``model_cfg`` carries a custom architecture)."""

    backend: str
    model_name: str
    quick_gelu: bool = False
    preprocess_cfg: dict | None = None
    model_cfg: dict | None = None
    meta: dict | None = None


class OpenClipVLM(VisionLanguageModel):
    """An open_clip model behind zsrm's VLM interface. ``clip`` is the open_clip model itself."""

    backend = "open_clip"

    def __init__(self, clip: nn.Module, model_name: str, pretrained: str | None = None,
                 quick_gelu: bool = False, model_cfg: dict | None = None):
        super().__init__()
        open_clip = _open_clip()
        self.clip = clip
        self.model_name = model_name
        self.pretrained = pretrained  # tag or file the weights came from (provenance only)
        self.quick_gelu = quick_gelu
        self.model_cfg = model_cfg or open_clip.get_model_config(model_name)
        self.tokenizer = open_clip.get_tokenizer(model_name)
        size = clip.visual.image_size
        self.image_size = int(size if isinstance(size, int) else size[0])
        self.preprocess_cfg = dict(getattr(clip.visual, "preprocess_cfg", {}) or {})
        self.splittable = type(clip.visual).__name__ == "ModifiedResNet"
        self.gradcam_layer = "visual.layer4" if self.splittable else None

    @property
    def visual(self) -> nn.Module:
        return self.clip.visual

    @property
    def logit_scale(self) -> nn.Parameter:
        return self.clip.logit_scale

    @property
    def device(self) -> torch.device:
        return self.clip.logit_scale.device

    def preprocess(self, images: ImageBatch) -> torch.Tensor:
        from open_clip.constants import OPENAI_DATASET_MEAN, OPENAI_DATASET_STD

        cfg = self.preprocess_cfg
        return pixels_from_images(images, self.image_size, cfg.get("mean", OPENAI_DATASET_MEAN),
                                  cfg.get("std", OPENAI_DATASET_STD),
                                  crop=cfg.get("resize_mode", "shortest") != "squash", device=self.device)

    def _require_split(self):
        if not self.splittable:
            raise NotImplementedError(
                f"{self.model_name} ({type(self.clip.visual).__name__}) has no last convolutional ReLU to split at "
                "for Grad-CAM; use an open_clip ResNet such as RN50 (encode_images works on any model)"
            )

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        self._require_split()
        v = self.clip.visual
        return v.layer4(v.layer3(v.layer2(v.layer1(v.stem(pixels)))))

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        self._require_split()
        return self.clip.visual.attnpool(features)

    def encode_images(self, images: ImageBatch, normalize: bool = True) -> torch.Tensor:
        if self.splittable:
            return super().encode_images(images, normalize)
        return self.clip.encode_image(self.preprocess(images), normalize=normalize)

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        return self.clip.encode_text(self.tokenizer(texts).to(self.device))

    # --- persistence ---------------------------------------------------------------------
    def save(self, folder: str | Path) -> None:
        """``model.safetensors`` holds open_clip's own state dict, so open_clip can read it too."""
        config = {
            "backend": self.backend,
            "model_name": self.model_name,
            "quick_gelu": self.quick_gelu,
            "preprocess_cfg": _jsonable(self.preprocess_cfg),
            "model_cfg": self.model_cfg,
            "meta": {"pretrained": self.pretrained},
        }
        save_folder(folder, config, {WEIGHTS_FILE: self.clip})

    @classmethod
    def from_folder(cls, folder: str | Path, device: str | torch.device = "cpu") -> "OpenClipVLM":
        cfg = read_config(folder, kind=cls.backend, schema=OpenClipFolder)

        def make():
            _register_model_cfg(cfg.model_name, cfg.model_cfg)
            return create_open_clip_vlm(cfg.model_name, "none", quick_gelu=cfg.quick_gelu,
                                        preprocess_cfg=cfg.preprocess_cfg, provenance=(cfg.meta or {}).get("pretrained"))

        vlm = build_model(folder, make)
        load_folder_weights(vlm.clip, folder, device=device)
        return vlm.to(device).eval()


def _jsonable(d: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def _open_clip():
    from zsrm.vlm.compat import import_open_clip

    return import_open_clip()


def _register_model_cfg(model_name: str, model_cfg: dict | None):
    """Saved folders carry their architecture, so custom open_clip configs load anywhere."""
    open_clip = _open_clip()
    if model_name in open_clip.list_models() or not model_cfg:
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{model_name}.json"
        path.write_text(json.dumps(model_cfg))
        open_clip.add_model_config(path)


def default_tag(model_name: str) -> str:
    """open_clip's first listed pretrained tag of a model (RN50 -> "openai")."""
    tags = _open_clip().list_pretrained_tags_by_model(model_name)
    if not tags:
        raise ValueError(f"open_clip knows no pretrained weights for {model_name}; "
                         f"pass a local file (open_clip:{model_name}:/path/to/weights.safetensors) or open_clip:{model_name}:none")
    return tags[0]


def _unavailable(model_name: str, tag: str, cfg: dict, reason: str) -> WeightsUnavailableError:
    open_clip = _open_clip()
    name = model_name
    if cfg.get("quick_gelu") and not name.endswith("-quickgelu") and f"{name}-quickgelu" in open_clip.list_models():
        name = f"{name}-quickgelu"  # these weights were trained with QuickGELU
    hub = cfg.get("hf_hub", "")
    if hub:
        repo, filename = os.path.split(hub)
        where = f"{filename or HF_SAFE_WEIGHTS} from https://huggingface.co/{repo}"
        fname = filename or HF_SAFE_WEIGHTS
    else:
        where = cfg.get("url", "the weights file")
        fname = os.path.basename(cfg.get("url", "weights.safetensors"))
    return WeightsUnavailableError(
        f"open_clip {model_name} weights {tag!r} are not cached here and cannot be downloaded ({reason}); "
        f"download {where} on a machine with internet, then pass the file: open_clip:{name}:/path/to/{fname}"
    )


def fetch_pretrained(model_name: str, tag: str) -> str:
    """Path of a pretrained tag's weights file: from the cache, else downloaded.

    Offline (``HF_HUB_OFFLINE=1``) a missing file raises :class:`WeightsUnavailableError`
    at once instead of trying the network.
    """
    open_clip = _open_clip()
    cfg = open_clip.get_pretrained_cfg(model_name, tag)
    hub, url = cfg.get("hf_hub", ""), cfg.get("url", "")
    if cfg.get("file"):
        return cfg["file"]
    if hub:
        from huggingface_hub import try_to_load_from_cache

        repo, filename = os.path.split(hub)
        filename = filename or HF_WEIGHTS
        for name in (filename[:-4] + ".safetensors" if filename.endswith((".bin", ".pth")) else None,
                     HF_SAFE_WEIGHTS if filename == HF_WEIGHTS else None, filename):
            if name:
                cached = try_to_load_from_cache(repo, name)
                if isinstance(cached, str) and os.path.isfile(cached):
                    return cached
    if url:
        cached = os.path.join(os.path.expanduser("~/.cache/clip"), os.path.basename(url))
        if os.path.isfile(cached):
            return cached
    if _offline():
        raise _unavailable(model_name, tag, cfg, "HF_HUB_OFFLINE is set")
    try:
        return open_clip.download_pretrained(cfg)
    except Exception as err:  # any network or hub failure means the same thing to the user
        raise _unavailable(model_name, tag, cfg, f"download failed with {type(err).__name__}") from None


def load_weights(clip: nn.Module, path: str) -> None:
    """Load a checkpoint file into an open_clip model without running code from it."""
    open_clip = _open_clip()
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such checkpoint file: {path}")
    try:
        open_clip.load_checkpoint(clip, path, strict=True, weights_only=True)
    except RuntimeError as err:
        msg = str(err)
        if "TorchScript" in msg:
            raise ValueError(f"{path} is a TorchScript archive, which would run code to load; use the "
                             "safetensors weights instead (e.g. open_clip_model.safetensors from the model's "
                             "Hugging Face hub page)") from None
        first = msg.strip().splitlines()[0] if msg.strip() else type(err).__name__
        raise ValueError(f"{path} does not fit open_clip model: {first[:300]}") from None
    except Exception as err:  # weights_only unpickling refuses anything but tensors and containers
        raise ValueError(f"cannot read {path} as weights only: {str(err).splitlines()[0][:200]}") from None


def create_open_clip_vlm(model_name: str = "RN50", pretrained: str | None = "default", device="cpu",
                         quick_gelu: bool | None = None, preprocess_cfg: dict | None = None,
                         provenance: str | None = None) -> OpenClipVLM:
    """An open_clip model as a zsrm VLM.

    ``pretrained``: ``"default"`` (open_clip's first tag for the model, "openai" for RN50), a
    tag, a local checkpoint file (``.safetensors``, or ``.pt``/``.pth``/``.bin`` state dicts),
    or ``"none"`` for random weights (tests and speed benchmarks).
    """
    open_clip = _open_clip()
    if model_name not in open_clip.list_models():
        raise ValueError(f"unknown open_clip model {model_name!r}; e.g. RN50, RN101, ViT-B-32 "
                         "(open_clip.list_models() lists them all)")
    pretrained = "none" if pretrained is None else str(pretrained)
    checkpoint, tag_cfg = None, {}
    if pretrained.lower() == "none":
        pass
    elif looks_like_path(pretrained) or os.path.isfile(pretrained):
        checkpoint = os.path.expanduser(pretrained)
        if not os.path.isfile(checkpoint):
            raise FileNotFoundError(f"no such checkpoint file: {checkpoint}")
    else:
        tag = default_tag(model_name) if pretrained == "default" else pretrained
        tags = open_clip.list_pretrained_tags_by_model(model_name)
        if tag not in tags:
            raise ValueError(f"open_clip has no weights {tag!r} for {model_name}; known: {', '.join(tags) or 'none'}"
                             " (or pass a local checkpoint file)")
        tag_cfg = open_clip.get_pretrained_cfg(model_name, tag)
        checkpoint = fetch_pretrained(model_name, tag)
        pretrained = tag
    if quick_gelu is None:
        quick_gelu = bool(tag_cfg.get("quick_gelu", False))
    force_pp = preprocess_cfg or {k: tag_cfg[k] for k in ("mean", "std", "interpolation", "resize_mode") if k in tag_cfg}
    # Never let open_clip fetch tower weights itself: every download goes through fetch_pretrained.
    logging.disable(logging.WARNING)  # open_clip warns that weights are random before we load them
    try:
        clip = open_clip.create_model(model_name, pretrained=None, force_quick_gelu=quick_gelu,
                                      force_preprocess_cfg=force_pp or None,
                                      pretrained_image=False, pretrained_text=False)
    finally:
        logging.disable(logging.NOTSET)
    if checkpoint:
        load_weights(clip, checkpoint)
    vlm = OpenClipVLM(clip, model_name, provenance or pretrained, quick_gelu)
    return vlm.to(device).eval()


register_kind(OpenClipVLM.backend, OpenClipVLM.from_folder)
