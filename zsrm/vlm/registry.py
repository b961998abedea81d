"""Saved models: one folder format, one registry of model kinds, one way to read and write them.

A saved model is a folder holding ``config.json``, whose ``"backend"`` field (or ``"kind"``)
names the model's *kind*, and its weights as safetensors (never pickle, so loading runs no code from a file).
Each kind registers the function that loads it (:func:`register_kind`); :func:`load_folder`
reads the kind and calls it. Models that ship with zsrm are registered by name
(:func:`register_shipped`: ``"scene"``, and ``"student"`` once :mod:`zsrm.fullmodel` is
imported), so a spec string can name them.

Every loader reads its folder through :func:`read_config` and :func:`load_weights`, and every
``save`` writes through :func:`save_folder`.

>>> import tempfile, torch
>>> folder = tempfile.mkdtemp()
>>> save_folder(folder, {"backend": "example", "width": 2}, {WEIGHTS_FILE: torch.nn.Linear(2, 1)})
>>> read_config(folder, kind="example")["width"]
2
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"

# kind -> loader(folder, device) -> VisionLanguageModel
KINDS: dict[str, Callable] = {}
# name -> folder of a model shipped with zsrm
SHIPPED: dict[str, Path] = {}


def register_kind(kind: str, loader: Callable) -> None:
    """Let :func:`load_folder` load folders whose config names ``kind`` with ``loader(folder, device)``."""
    KINDS[kind] = loader


def register_shipped(name: str, folder: Path) -> None:
    """A model shipped with zsrm, loadable by ``name`` (see :func:`zsrm.vlm.load_vlm`)."""
    SHIPPED[name] = Path(folder)


def read_config(folder: str | Path, kind: str | None = None) -> dict:
    """A saved model folder's config.json; with ``kind``, checks the folder holds that kind."""
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no {CONFIG_FILE} in {folder}: not a saved zsrm model folder")
    try:
        config = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path} is not valid JSON: {err}") from None
    if kind is not None and kind_of(config) != kind:
        raise ValueError(f"{folder} holds a {kind_of(config)!r} model, not a {kind!r} model")
    return config


def kind_of(config: dict) -> str | None:
    """The kind a saved model's config names."""
    return config.get("kind", config.get("backend")) if isinstance(config, dict) else None


def folder_kind(spec) -> str | None:
    """The kind a saved model folder names, or None if ``spec`` is not such a folder."""
    try:
        return kind_of(read_config(Path(str(spec)).expanduser()))
    except (FileNotFoundError, ValueError, OSError):
        return None


def load_weights(module, folder: str | Path, file: str = WEIGHTS_FILE, device="cpu") -> None:
    """Load ``folder/file`` (safetensors) into ``module``, every key matching."""
    from safetensors.torch import load_model

    path = Path(folder) / file
    if not path.is_file():
        raise FileNotFoundError(f"no {file} in {folder}")
    load_model(module, str(path), strict=True, device=str(device))


def save_weights(module, folder: str | Path, file: str = WEIGHTS_FILE) -> None:
    """Write ``module``'s weights to ``folder/file`` as safetensors (the folder is made)."""
    from safetensors.torch import save_model

    Path(folder).mkdir(parents=True, exist_ok=True)
    save_model(module, str(Path(folder) / file))


def save_tensors(tensors: dict, path: str | Path) -> None:
    """A flat ``name -> tensor`` dict as a safetensors file (e.g. an optimiser's state)."""
    from safetensors.torch import save_file

    save_file({k: v.detach().contiguous() for k, v in tensors.items()}, str(path))


def load_tensors(path: str | Path) -> dict:
    from safetensors.torch import load_file

    return load_file(str(path))


def save_folder(folder: str | Path, config: dict, weights: dict) -> None:
    """Write ``config`` as config.json and each ``file -> module`` of ``weights`` as safetensors."""
    for file, module in weights.items():
        save_weights(module, folder, file)
    Path(folder).mkdir(parents=True, exist_ok=True)
    (Path(folder) / CONFIG_FILE).write_text(json.dumps(config, indent=2) + "\n")


def load_folder(folder: str | Path, device="cpu"):
    """The model saved in ``folder``, by the loader its kind registered."""
    kind = kind_of(read_config(folder))
    if kind not in KINDS:
        raise ValueError(f"{Path(folder) / CONFIG_FILE} names an unknown model kind {kind!r}; known: "
                         f"{', '.join(KINDS)} (zsrm.fullmodel registers its kinds when imported)")
    return KINDS[kind](Path(folder), device)
