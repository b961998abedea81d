"""``load_vlm(spec)``: every way to get a vision-language model, from one string.

Specs (open_clip style: factory functions, architectures as data):

* ``"scene"``: the pretrained scene VLM shipped in ``zsrm/vlm/weights/scene/`` (built by
  ``zsrm pretrain-vlm``);
* a folder saved by ``vlm.save(folder)``: its ``config.json`` names the backend;
* ``"open_clip:MODEL"``: open_clip's default weights for MODEL (``open_clip:RN50`` is OpenAI's
  RN50, the paper's model); ``"open_clip"`` alone means ``open_clip:RN50``;
* ``"open_clip:MODEL:TAG"``: a pretrained tag, e.g. ``open_clip:RN50:yfcc15m``;
* ``"open_clip:MODEL:/path/to/file.safetensors"`` (or ``.pt``/``.pth``/``.bin`` state dicts);
* ``"open_clip:MODEL:none"``: random weights, for tests and speed benchmarks.

>>> vlm = load_vlm("scene")  # doctest: +SKIP
>>> vlm.similarity(images, ["a red block", "a blue block"])  # doctest: +SKIP
"""
from __future__ import annotations

from pathlib import Path

import torch

from zsrm.vlm.base import VisionLanguageModel
from zsrm.vlm.scene import CONFIG_FILE, WEIGHTS_FILE, SceneVLM, read_config

SHIPPED_SCENE_DIR = Path(__file__).resolve().parent / "weights" / "scene"
DEFAULT_OPEN_CLIP_MODEL = "RN50"
SPEC_HELP = ("'scene', a saved model folder, 'open_clip:MODEL' (e.g. open_clip:RN50), 'open_clip:MODEL:TAG', "
             "'open_clip:MODEL:/path/to/checkpoint.safetensors' or 'open_clip:MODEL:none'")


def load_vlm(spec: str | Path = "scene", device: str | torch.device = "cpu") -> VisionLanguageModel:
    """A VLM from a spec string (see the module docstring), in eval mode."""
    if isinstance(spec, Path):
        return load_folder(spec, device)
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"give a VLM spec: {SPEC_HELP}")
    spec = spec.strip()
    if spec == "scene":
        if not (SHIPPED_SCENE_DIR / WEIGHTS_FILE).is_file():
            raise FileNotFoundError(f"the pretrained scene VLM is missing from {SHIPPED_SCENE_DIR}; "
                                    "build it with `zsrm pretrain-vlm` (about 15 minutes on 2 CPU cores)")
        return SceneVLM.from_folder(SHIPPED_SCENE_DIR, device)
    if spec == "open_clip" or spec.startswith("open_clip:"):
        from zsrm.vlm.openclip import create_open_clip_vlm

        parts = spec.split(":", 2)
        model = parts[1] if len(parts) > 1 and parts[1] else DEFAULT_OPEN_CLIP_MODEL
        pretrained = parts[2] if len(parts) > 2 and parts[2] else "default"
        return create_open_clip_vlm(model, pretrained, device=device)
    path = Path(spec).expanduser()
    if path.is_dir():
        return load_folder(path, device)
    raise ValueError(f"unknown VLM spec {spec!r}: expected {SPEC_HELP}"
                     + (f" ({path} does not exist)" if "/" in spec else ""))


def load_folder(folder: str | Path, device: str | torch.device = "cpu") -> VisionLanguageModel:
    """A VLM saved with ``vlm.save(folder)``."""
    folder = Path(folder)
    backend = read_config(folder).get("backend")
    if backend == "scene":
        return SceneVLM.from_folder(folder, device)
    if backend == "open_clip":
        from zsrm.vlm.openclip import OpenClipVLM

        return OpenClipVLM.from_folder(folder, device)
    raise ValueError(f"{folder / CONFIG_FILE} names an unknown backend {backend!r}; known: scene, open_clip")
