"""Contrastive losses for training and fine-tuning the VLMs.

Captions repeat within a batch (many images are "a red block"; many later are "a yellow
block on top of a red block"). CLIP's loss treats every other pair in the batch as a
negative, so it would push an image away from a text identical to its own caption. The
multi-positive loss here makes every pair whose labels are equal a positive instead.

A note on when this matters: if identical captions also get identical text embeddings (a
deterministic text tower), CLIP's push of image i away from text j and its pull towards
text i cancel through the shared embedding, and the total gradient equals this loss's.
The two differ per image-text logit, and in total whenever items share a label without
sharing an embedding: paraphrases given one label id, or a text tower with dropout.
"""
from __future__ import annotations

from typing import Hashable, Sequence

import torch
from torch import nn


def label_ids(labels: Sequence[Hashable] | torch.Tensor, device=None) -> torch.Tensor:
    """Labels (captions, or any hashables) -> int64 ids, equal ids for equal labels.

    >>> label_ids(["a red block", "a blue block", "a red block"]).tolist()
    [0, 1, 0]
    """
    if isinstance(labels, torch.Tensor):
        if labels.ndim != 1:
            raise ValueError(f"labels must be one per batch item, got shape {tuple(labels.shape)}")
        return labels.to(device=device, dtype=torch.long)
    index: dict[Hashable, int] = {}
    return torch.tensor([index.setdefault(x, len(index)) for x in labels], dtype=torch.long, device=device)


def multi_positive_contrastive_loss(image_features: torch.Tensor, text_features: torch.Tensor,
                                    labels: Sequence[Hashable] | torch.Tensor,
                                    logit_scale: torch.Tensor | float) -> torch.Tensor:
    """Symmetric InfoNCE in which all batch items sharing a label are positives of each other.

    ``image_features`` and ``text_features`` are (N, D), row i of each a training pair, and
    normalised by the caller; ``labels[i]`` is pair i's caption (or any id); ``logit_scale``
    is the multiplier of the cosine similarities (CLIP's ``logit_scale.exp()``). Each row's
    target is uniform over the items with the same label, so identical captions are never
    negatives; with all labels distinct this is exactly CLIP's loss.

    >>> f = nn.functional.normalize(torch.eye(3), dim=-1)
    >>> loss = multi_positive_contrastive_loss(f, f, ["a", "b", "c"], 100.0)
    >>> abs(round(float(loss), 4))
    0.0
    """
    if image_features.shape != text_features.shape or image_features.ndim != 2:
        raise ValueError(f"image and text features must both be (N, D), got {tuple(image_features.shape)} "
                         f"and {tuple(text_features.shape)}")
    ids = label_ids(labels, device=image_features.device)
    if len(ids) != len(image_features):
        raise ValueError(f"need one label per pair: {len(ids)} labels for {len(image_features)} pairs")
    logits = logit_scale * image_features @ text_features.T
    positives = (ids[:, None] == ids[None, :]).to(logits.dtype)
    targets = positives / positives.sum(dim=1, keepdim=True)
    # Positives are symmetric, so the same targets serve both directions.
    loss_images = -(targets * nn.functional.log_softmax(logits, dim=1)).sum(dim=1).mean()
    loss_texts = -(targets * nn.functional.log_softmax(logits.T, dim=1)).sum(dim=1).mean()
    return (loss_images + loss_texts) / 2
