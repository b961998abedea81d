"""Several reward models as one: an image-text score is the mean of its members' scores.

Students trained with different seeds on the same data err apart; averaging their scores lifts
the binarised reward a little (``zsrm own-scene --students``, docs/own-scene.md). An ensemble
folder holds only ``config.json``: its kind and its members' folders, written relative to it
(:func:`write_ensemble`), so that a chain folder moves as a whole. Each member scores with its
own towers, as it was trained; the texts are free sentences, so members need not share a
vocabulary (nor a text VLM, nor an image size).

The embeddings are the members' unit embeddings side by side, each scaled by ``1/sqrt(N)``: unit
vectors whose dot product is the members' mean cosine. So every reward that scores with
``encode_images`` and ``encode_texts`` (the binarised reward's argmax and margin, the raw
cosine, the base reward) reads the mean score, with no change of its own; with
``normalize=False`` the embeddings are the same unit vectors (an ensemble's dot product is its
mean cosine).

>>> import numpy as np
>>> from zsrm.testing import ColourVLM
>>> pair = StudentEnsemble([ColourVLM(), ColourVLM(stride=8)])
>>> images, texts = np.zeros((2, 32, 32, 3), np.uint8), ["a red block", "a blue block"]
>>> bool(torch.allclose(pair.similarity(images, texts), ColourVLM().similarity(images, texts)))
True
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from zsrm.common.files import ZsrmFileError
from zsrm.common.registry import CONFIG_FILE, folder_kind, load_folder, read_config, register_kind, save_folder
from zsrm.vlm.base import ImageBatch, VisionLanguageModel

KIND = "zsrm-ensemble"


@dataclass
class EnsembleFolder:
    """config.json of an ensemble."""

    kind: str
    members: tuple[str, ...]  # member folders, relative to the ensemble's folder (or absolute)
    meta: dict | None = None


class StudentEnsemble(VisionLanguageModel):
    """The mean image-text score of ``members`` (any VisionLanguageModels, usually students)."""

    backend = KIND
    gradcam_layer = "none"  # no one image tower: Grad-CAM reads a single model

    def __init__(self, members, meta: dict | None = None):
        super().__init__()
        if not len(members):
            raise ValueError("an ensemble needs at least one member model")
        self.members = nn.ModuleList(members)
        self.meta: dict = dict(meta or {})
        scales = [float(getattr(m, "logit_scale", torch.tensor(math.log(1 / 0.07))).detach().exp()) for m in members]
        # the temperature a loss on the mean cosine reads (zsrm.rewards.corrected); not learnt
        self.logit_scale = nn.Parameter(torch.tensor(math.log(sum(scales) / len(scales))), requires_grad=False)
        self.image_size = max(int(getattr(m, "image_size", 0)) for m in members)  # the largest member input

    @property
    def device(self) -> torch.device:
        return self.logit_scale.device

    def _side_by_side(self, parts: list[torch.Tensor]) -> torch.Tensor:
        return torch.cat([p.float() for p in parts], dim=-1) / math.sqrt(len(parts))

    def encode_images(self, images: ImageBatch, normalize: bool = True) -> torch.Tensor:
        return self._side_by_side([m.encode_images(images, normalize=True) for m in self.members])

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        return self._side_by_side([m.encode_texts(texts, normalize=True) for m in self.members])

    def preprocess(self, images: ImageBatch) -> torch.Tensor:
        raise NotImplementedError(f"an ensemble of {len(self.members)} models has no one image tower: each member "
                                  "preprocesses its own (encode_images); Grad-CAM reads a single model")

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        return self.preprocess(pixels)

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        return self.preprocess(features)

    # --- persistence ---------------------------------------------------------------------
    def save(self, folder: str | Path) -> None:
        """Each member saved in ``folder/member-I``, then the config listing them."""
        folder = Path(folder)
        for i, member in enumerate(self.members):
            member.save(folder / f"member-{i}")
        write_ensemble(folder, [folder / f"member-{i}" for i in range(len(self.members))], self.meta)

    @classmethod
    def from_folder(cls, folder: str | Path, device: str | torch.device = "cpu") -> "StudentEnsemble":
        cfg = read_config(folder, kind=KIND, schema=EnsembleFolder)
        shared: dict = {}  # one text VLM for the students that read texts through the same one
        return cls([load_member(p, device, shared) for p in member_paths(folder, cfg.members)],
                   meta=cfg.meta).to(device).eval()


def member_paths(folder: str | Path, members) -> list[Path]:
    """The member folders an ensemble's config lists, checked: at least one, no repeats, each a
    saved model that is not itself an ensemble (one line each)."""
    where = Path(folder) / CONFIG_FILE
    if not members:
        raise ZsrmFileError(f"{where} lists no members: an ensemble averages one or more saved models")
    paths = [(Path(folder) / m).resolve() for m in members]
    if len(set(paths)) < len(paths):
        raise ZsrmFileError(f"{where} lists a member twice: {', '.join(map(str, members))}")
    for name, path in zip(members, paths):
        kind = folder_kind(path)
        if kind is None:
            raise FileNotFoundError(f"{where} lists the member {name!r}, but {path} holds no saved model "
                                    f"({CONFIG_FILE}): train it (zsrm finetune --student --seed N --out {path}), "
                                    "or list the members that are there")
        if kind == KIND:
            raise ZsrmFileError(f"{where}: the member {name!r} is itself an ensemble; list its members instead")
    return paths


def load_member(path: Path, device, shared: dict):
    """A member model; students reading texts through the same VLM share one copy of it
    (``shared``: spec -> the loaded text VLM)."""
    from zsrm.fullmodel.student import BACKEND, StudentFolder, StudentRewardNet
    from zsrm.fullmodel.text import load_frozen_reference, stored_spec

    if folder_kind(path) != BACKEND:
        return load_folder(path, device)
    cfg = read_config(path, kind=BACKEND, schema=StudentFolder)
    spec = stored_spec(cfg.text_vlm, cfg.text_vlm_is_folder, path)
    if spec not in shared:
        shared[spec] = load_frozen_reference(spec, device, f"the student in {path} embeds texts with")
    return StudentRewardNet.from_folder(path, device, text_vlm=shared[spec])


def write_ensemble(folder: str | Path, members, meta: dict | None = None) -> Path:
    """Write the ensemble ``folder`` (its config.json) of the saved models in ``members``, each
    recorded relative to ``folder``; every member must be there already."""
    folder = Path(folder)
    names = [os.path.relpath(Path(m).resolve(), folder.resolve()) for m in members]
    member_paths(folder, names)
    save_folder(folder, {"kind": KIND, "members": names, "meta": dict(meta or {})}, {})
    return folder


def is_ensemble_folder(spec) -> bool:
    return folder_kind(spec) == KIND


register_kind(KIND, StudentEnsemble.from_folder)
