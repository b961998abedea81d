"""Whitened text embeddings: what lets a small head tell "yellow left of red" from "red left of
yellow".

A sentence encoder trained for meaning, and even more a VLM text tower trained on which
objects a scene holds, put such captions almost on top of each other: they share most of
their embedding, and the relation and the word order live in low-variance directions (the
scene VLM's text embeddings of "left of" and "right of" have a cosine of 0.999). Whitening
with the captions' own statistics (PCA, each direction scaled to unit variance, with a floor)
turns those directions into the input, so that a small MLP on top separates them.

>>> import torch
>>> e = torch.tensor([[0.0, 0.0], [10.0, 0.1], [0.0, 0.2], [10.0, 0.3]])  # the 2nd column barely varies
>>> w = TextWhitener(2, eps=1e-8)
>>> w.fit(e)
>>> torch.cov(w(e).T).diagonal().round(decimals=2)  # after whitening both directions count the same
tensor([1., 1.])
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import torch
from torch import nn

from zsrm.tasks.language import GoalError
from zsrm.tasks.negatives import complement_of, read_caption
from zsrm.vlm.base import VisionLanguageModel
from zsrm.vlm.factory import load_vlm


class TextWhitener(nn.Module):
    """``(e - mean) @ W``, W the PCA whitening of a vocabulary's embeddings with eigenvalues
    floored at ``eps`` times the largest; fit once, saved as buffers. Unfit, it is the identity."""

    def __init__(self, dim: int, eps: float = 1e-4):
        super().__init__()
        self.eps = eps
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("matrix", torch.eye(dim))
        self.register_buffer("fitted", torch.tensor(False))

    @torch.no_grad()
    def fit(self, embeddings: torch.Tensor) -> None:
        e = embeddings.detach().double()
        if e.ndim != 2 or e.shape[1] != self.mean.shape[0] or len(e) < 2:
            raise ValueError(f"fit needs (M >= 2, {self.mean.shape[0]}) embeddings, got {tuple(e.shape)}")
        mean = e.mean(dim=0)
        cov = (e - mean).T @ (e - mean) / (len(e) - 1)
        eigval, eigvec = torch.linalg.eigh(cov)
        floor = self.eps * float(eigval.max().clamp(min=1e-12))
        self.mean.copy_(mean.float())
        self.matrix.copy_((eigvec / torch.sqrt(eigval.clamp(min=0) + floor)).float())
        self.fitted.fill_(True)

    def forward(self, e: torch.Tensor) -> torch.Tensor:
        return (e - self.mean) @ self.matrix


@lru_cache(maxsize=None)
def noun_phrases(text: str) -> tuple[str, ...]:
    """The object phrases of a caption or goal, in order ("red block", "blue block"; an own
    scene's "red mug", "blue plate"); () if the text is not one zsrm reads."""
    denied = complement_of(text)
    if denied is not None:
        return denied.phrases
    try:
        return read_caption(text).phrases
    except GoalError:
        return ()


class RoleTextFeatures(nn.Module):
    """Text features that say who is where in the sentence: the whitened sentence embedding,
    then the embeddings of its object phrases in order, one slot each (zeros if absent).

    Word order is what a mean-pooled sentence embedding keeps worst: "a red block on the left of
    a yellow block" and "a yellow block on the left of a red block" hold the same words. Putting
    the first object's phrase in the first slot makes the order explicit. Every embedding
    comes from the same text encoder ``encode`` (a VLM's text tower).
    """

    def __init__(self, dim: int, slots: int = 3):
        super().__init__()
        self.dim, self.slots = dim, slots
        self.whiten = TextWhitener(dim)

    @property
    def out_dim(self) -> int:
        return self.dim * (1 + self.slots)

    def fit(self, encode, texts: list[str]) -> None:
        with torch.no_grad():
            self.whiten.fit(encode(list(texts)))

    def forward(self, encode, texts: list[str], sentence: torch.Tensor | None = None) -> torch.Tensor:
        """(M, out_dim) features of M texts; ``sentence``: ``encode(texts)`` if already computed."""
        roles = [noun_phrases(t)[:self.slots] for t in texts]
        phrases = list(dict.fromkeys(p for r in roles for p in r))
        sentence = encode(list(texts)) if sentence is None else sentence
        out = [self.whiten(sentence)]
        slots = torch.zeros(len(texts), self.slots, self.dim, dtype=sentence.dtype, device=sentence.device)
        if phrases:
            p = nn.functional.normalize(encode(phrases), dim=-1)
            index = {ph: i for i, ph in enumerate(phrases)}
            rows = [(i, k, index[ph]) for i, r in enumerate(roles) for k, ph in enumerate(r)]
            i, k, j = (torch.tensor(v, device=sentence.device) for v in zip(*rows))
            slots = slots.index_put((i, k), p[j])
        return torch.cat(out + [slots.flatten(1)], dim=1)


def load_frozen_reference(spec: str, device, what: str) -> VisionLanguageModel:
    """The VLM a saved model reads texts through, loaded from its spec (FileNotFoundError saying
    which model needs it if it does not load)."""
    try:
        return load_vlm(spec, device=device)
    except (FileNotFoundError, ValueError) as err:
        raise FileNotFoundError(f"{what} the VLM {spec!r}, which does not load: {err}") from None


def portable_spec(spec: str, folder: str | Path) -> tuple[str, bool]:
    """(how a model saved in ``folder`` records the VLM ``spec`` it reads texts through, whether
    that is a folder): a folder is recorded relative to ``folder``, so both move together."""
    if not Path(spec).is_dir():
        return spec, False
    return os.path.relpath(Path(spec).resolve(), Path(folder).resolve()), True


def stored_spec(spec: str, is_folder: bool, folder: str | Path) -> str:
    """The spec :func:`portable_spec` recorded, usable from anywhere again."""
    return str((Path(folder) / spec).resolve()) if is_folder else spec
