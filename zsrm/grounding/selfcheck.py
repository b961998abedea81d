"""Does a VLM's Grad-CAM point at the object it names? A check that reads no position.

For each image and each object it holds (beside at least one other), every present object's
Grad-CAM point is hidden in turn under a disc painted with the image's median colour, and the
VLM scores the phrases again. The point of phrase ``p`` *agrees* when hiding it lowers ``p``'s
score more than hiding any other present object's point does: the VLM's own evidence for ``p``
sits where Grad-CAM says ``p`` is. The check reads the images and which objects each one holds
(what the scene VLM's presence captions already read), never where an object is; so it can
choose among pretraining seeds without the privileged positions that evaluation alone may read.

>>> import numpy as np
>>> disc_mask(5, np.array([[2.0, 2.0]]), 1.0)[0].astype(int)
array([[0, 0, 0, 0, 0],
       [0, 0, 1, 0, 0],
       [0, 1, 1, 1, 0],
       [0, 0, 1, 0, 0],
       [0, 0, 0, 0, 0]])
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

from zsrm.grounding.gradcam import GradCAM
from zsrm.vlm.presence import phrase_probe


def disc_mask(size: int, centres: np.ndarray, radius: float) -> np.ndarray:
    """(n, size, size) bool: a disc of ``radius`` pixels around each ``(x, y)`` of ``centres``."""
    ys, xs = np.mgrid[0:size, 0:size]
    c = np.asarray(centres, np.float64)
    return (xs[None] - c[:, 0, None, None]) ** 2 + (ys[None] - c[:, 1, None, None]) ** 2 <= radius ** 2


def masking_agreement(vlm, gradcam: GradCAM, images: np.ndarray, present: np.ndarray, phrases: Sequence[str],
                      radius, batch_size: int = 256) -> dict:
    """Per phrase, the share of (image, phrase) where hiding the phrase's own Grad-CAM point lowers
    its score most (module docstring). ``present`` (n, k) bool: which of ``phrases`` each image
    holds (visible); only images with two or more are used. ``radius``: the hiding disc's, in
    pixels, one for all or one per phrase (about each object's own size). Returns
    ``{"agreement": {phrase: share}, "cases": {phrase: n}, "min": the lowest share}``."""
    images, present = np.asarray(images), np.asarray(present, bool)
    rows = np.flatnonzero(present.sum(axis=1) >= 2)
    k, size = len(phrases), images.shape[1]
    radius = np.broadcast_to(np.asarray(radius, np.float64), (k,))
    agree, cases = np.zeros(k), np.zeros(k)
    if len(rows):
        xy = gradcam(images[rows], list(phrases)).xy  # (m, k, 2); NaN where not found
        with torch.no_grad():
            probes = vlm.encode_texts([phrase_probe(p) for p in phrases])
        masked, index = [], []  # index: (row of rows, the phrase whose point is hidden)
        for i, r in enumerate(rows):
            fill = np.median(images[r].reshape(-1, 3), axis=0).astype(np.uint8)
            for j in np.flatnonzero(present[r]):
                if np.isnan(xy[i, j]).any():
                    continue
                img = images[r].copy()
                img[disc_mask(size, xy[i, j][None], radius[j])[0]] = fill
                masked.append(img)
                index.append((i, j))
        scores = np.full((len(rows), k, k), np.nan)  # [image, hidden phrase, scored phrase]
        with torch.no_grad():
            for lo in range(0, len(masked), batch_size):
                s = (vlm.encode_images(np.stack(masked[lo:lo + batch_size])) @ probes.T).cpu().numpy()
                for (i, j), row in zip(index[lo:lo + batch_size], s):
                    scores[i, j] = row
        for i, r in enumerate(rows):
            held = np.flatnonzero(present[r])
            for p in held:
                col = scores[i, held, p]
                if np.isnan(col).all():
                    continue
                cases[p] += 1
                agree[p] += held[np.nanargmin(col)] == p
    share = {p: (float(agree[j] / cases[j]) if cases[j] else None) for j, p in enumerate(phrases)}
    known = [v for v in share.values() if v is not None]
    return {"agreement": share, "cases": {p: int(c) for p, c in zip(phrases, cases)},
            "min": min(known) if known else None}


__all__ = ["disc_mask", "masking_agreement"]
