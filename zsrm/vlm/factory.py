"""``load_vlm(spec)``: every way to get a vision-language model, from one string.

Specs (open_clip style: factory functions, architectures as data):

* ``"scene"``: the pretrained scene VLM shipped in ``zsrm/vlm/weights/scene/`` (built by
  ``zsrm pretrain-vlm``); likewise ``"student"``, the reward student shipped with
  :mod:`zsrm.fullmodel` (see :mod:`zsrm.common.registry`); ``"student@DIGEST"`` that model only
  if its weights are that version (what training runs record, see :func:`pinned`);
* a folder saved by ``vlm.save(folder)``: its ``config.json`` names the model's kind;
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

from zsrm.common.registry import SHIPPED, WEIGHTS_FILE, load_folder
from zsrm.vlm.base import VisionLanguageModel

DEFAULT_VLM = "scene"  # the VLM every stage uses unless told otherwise
DEFAULT_OPEN_CLIP_MODEL = "RN50"
SPEC_HELP = ("'scene', a saved model folder, 'open_clip:MODEL' (e.g. open_clip:RN50), 'open_clip:MODEL:TAG', "
             "'open_clip:MODEL:/path/to/checkpoint.safetensors' or 'open_clip:MODEL:none'")
HOW_TO_BUILD = {"scene": "build it with `zsrm pretrain-vlm` (about 15 minutes on 2 CPU cores)",
                "scene-pendulum": "build it with `zsrm pretrain-vlm --pendulum-scenes 3000 --init zsrm/vlm/weights/scene "
                                  "--steps 1000 --out zsrm/vlm/weights/scene-pendulum` (about 10 minutes on a CPU core)",
                "scene-box": "build it with `zsrm pretrain-vlm --box-scenes 2000 --init zsrm/vlm/weights/scene "
                             "--steps 600 --out zsrm/vlm/weights/scene-box` (about 5 minutes on a CPU core)",
                "student": "reinstall zsrm or train one with `zsrm reward-data --images 8000 --shard-size 250 --p-box 0.3 "
                           "--out data/zsrm/box-8k --labels labels-sil` then `zsrm finetune --student --data "
                           "data/zsrm/box-8k --labels labels-sil --steps 4000`"}


def weights_digest(folder: Path) -> str:
    """The first 12 hex digits of the SHA-256 of a model folder's weights (which version it is)."""
    import hashlib

    return hashlib.sha256((folder / WEIGHTS_FILE).read_bytes()).hexdigest()[:12]


def shipped_digest(name: str) -> str:
    """:func:`weights_digest` of a shipped model."""
    return weights_digest(shipped_folder(name))


def pinned(spec: str) -> str:
    """``spec`` with a shipped model's name pinned to its version (``student@<digest>``), so that
    a run records which weights it used and a later, retrained shipped model does not pass for
    them; other specs unchanged."""
    return f"{spec}@{shipped_digest(spec)}" if isinstance(spec, str) and spec in SHIPPED else spec


def shipped_folder(name: str) -> Path:
    """The folder of a model shipped with zsrm; FileNotFoundError saying how to build it if missing."""
    folder = SHIPPED[name]
    if not (folder / WEIGHTS_FILE).is_file():
        raise FileNotFoundError(f"the shipped {name} model is missing from {folder}; {HOW_TO_BUILD.get(name, '')}")
    return folder


def retired_folder(name: str, digest: str) -> Path | None:
    """The folder of an earlier version of a shipped model, kept beside it as
    ``retired/<name>@<digest>`` so that runs pinned to it still load it; None if not kept."""
    folder = SHIPPED[name].parent / "retired" / f"{name}@{digest}"
    return folder if (folder / WEIGHTS_FILE).is_file() and weights_digest(folder) == digest else None


def load_vlm(spec: str | Path = DEFAULT_VLM, device: str | torch.device = "cpu") -> VisionLanguageModel:
    """A VLM from a spec string (see the module docstring), in eval mode."""
    if isinstance(spec, Path):
        return load_folder(spec, device)
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"give a VLM spec: {SPEC_HELP}")
    spec = spec.strip()
    name, _, digest = spec.partition("@")
    if digest and name in SHIPPED:  # a pinned version (see pinned): only those weights will do
        if shipped_digest(name) != digest:
            retired = retired_folder(name, digest)
            if retired is not None:
                return load_folder(retired, device)
            raise ValueError(f"{spec!r} is the shipped {name} model of version {digest}, but the installed one is "
                             f"{shipped_digest(name)} (retrained since); install that zsrm version, or retrain "
                             f"with the installed model")
        spec = name
    if spec in SHIPPED:
        return load_folder(shipped_folder(spec), device)
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
