"""Vision-language models: an image tower, a text tower and a dot product (paper section 2.1).

>>> from zsrm.vlm import load_vlm
>>> vlm = load_vlm("scene")  # doctest: +SKIP
>>> reward = vlm.similarity(obs["front"], ["a yellow block on top of a red block"])  # doctest: +SKIP

Saved models of every kind load through one registry (:mod:`zsrm.common.registry`), which
:func:`load_vlm` reads for a folder or a shipped model's name.
Backends: ``scene`` (offline stand-in for CLIP, trained by ``zsrm pretrain-vlm``) and
``open_clip`` (RN50 with OpenAI's weights is the paper's model). The ``open_clip`` package
itself is imported only when an open_clip model is asked for (it takes seconds).
"""
from zsrm.vlm.base import VisionLanguageModel, image_batch, pixels_from_images
from zsrm.vlm.factory import load_vlm
from zsrm.vlm.losses import multi_positive_contrastive_loss
from zsrm.vlm.openclip import OpenClipVLM, WeightsUnavailableError, create_open_clip_vlm
from zsrm.vlm.scene import SCENE_PRESETS, SHIPPED_SCENE_DIR, SceneConfig, SceneVLM, create_scene_vlm
from zsrm.vlm.text_cache import TextEmbeddingCache

__all__ = [
    "VisionLanguageModel", "SceneVLM", "SceneConfig", "SCENE_PRESETS", "OpenClipVLM", "WeightsUnavailableError",
    "load_vlm", "create_scene_vlm", "create_open_clip_vlm", "multi_positive_contrastive_loss",
    "image_batch", "pixels_from_images", "SHIPPED_SCENE_DIR", "TextEmbeddingCache",
]
