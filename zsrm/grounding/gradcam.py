"""Grad-CAM phrase grounding: where in the image is "red block"? (paper 2.2, Figure 3)

Grad-CAM (Selvaraju et al., 2017) weighs the channels of the VLM's last convolutional ReLU
by the spatially averaged gradient of a phrase's score and keeps the positive part. The
phrase's score is the cosine between the image embedding and the phrase's text embedding;
the ``"contrast"`` target subtracts the mean score of other phrases (e.g. the other
colours), which sharpens the map onto what makes this object differ from the others.

Speed: the gradient of the score is needed only from the Grad-CAM layer onward, so the
image trunk runs once per image (without autograd) and every phrase's gradient comes
through the image head alone, all phrases in one batched backward pass
(:meth:`GradCAM.heatmaps`). :meth:`GradCAM.reference_heatmaps` is the plain way, one full
forward and backward pass per phrase, kept to test against and to benchmark.

>>> import numpy as np
>>> from zsrm.grounding.gradcam import GradCAM
>>> from zsrm.testing import ColourVLM
>>> image = np.zeros((32, 32, 3), np.uint8); image[4:10, 20:26] = (220, 30, 30)
>>> result = GradCAM(ColourVLM(), locate="argmax")(image[None], ["red block", "blue block"])
>>> result.xy[0, 0].round(), bool(result.found[0, 1])
(array([22.,  6.]), False)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
from torch import nn

from zsrm.vlm.base import image_batch
from zsrm.vlm.text_cache import TextEmbeddingCache

TARGETS = ("contrast", "score")
LOCATE = ("argmax", "peak_centroid", "fine")
# locate="fine": the share of the fine map's peak a cell needs to join the object's blob. Fine
# LayerCAM maps are sharp and uneven over an object (edges respond most), so a low cut keeps the
# whole object; on a development split 0.1 beat 0.05, 0.2, 0.3 and 0.5.
FINE_FRACTION = 0.1
CELL_CENTRES = ("grid", "receptive_field")


@dataclass
class GradCAMResult:
    """Grad-CAM of P phrases on N images.

    maps:   (N, P, h, w) heat maps on the Grad-CAM layer's grid (non-negative).
    xy:     (N, P, 2) the object's pixel coordinates (x right, row down) in the input
            images' pixel frame; NaN where the phrase was not found.
    peak:   (N, P) the heat map's maximum (0: no positive evidence anywhere).
    score:  (N, P) the target's value: the VLM's evidence that the phrase is in the image.
    found:  (N, P) False where the map is empty or ``score`` is below the presence threshold.
    """

    phrases: tuple[str, ...]
    maps: np.ndarray
    xy: np.ndarray
    peak: np.ndarray
    score: np.ndarray
    found: np.ndarray


def _as_batch(images) -> list[np.ndarray]:
    """Checked uint8 (H, W, 3) arrays, from any image batch the VLM interface accepts."""
    return image_batch(images)


def _image_size(images: list[np.ndarray]) -> tuple[int, int]:
    """(height, width) of the raw images, the frame the coordinates are given in."""
    sizes = {im.shape[:2] for im in images}
    if len(sizes) != 1:
        raise ValueError(f"images of one call must share a size, got {sorted(sizes)}")
    return sizes.pop()


class GradCAM:
    """Grad-CAM of noun phrases on a :class:`~zsrm.vlm.base.VisionLanguageModel`.

    target:        ``"contrast"`` (phrase score minus the mean score of ``contrast``
                   phrases; by default the other phrases of the call) or ``"score"``.
    locate:        ``"argmax"`` (the paper: the centre of the heat map's highest cell),
                   ``"peak_centroid"`` (the heat-weighted centroid of the connected cells
                   above half the peak around the argmax: sub-cell precision) or ``"fine"``
                   (:meth:`fine_locate`: the peak centroid of LayerCAM at the VLM's finer
                   ``fine_layer``, averaged over mirrored and shifted views; the heat maps,
                   peaks and scores stay Grad-CAM's).
    cell_centres:  where each Grad-CAM cell sits in the image: ``"grid"`` (the cell's
                   geometric centre) or ``"receptive_field"`` (the centroid of the cell's
                   gradient with respect to the input pixels, measured once on the first
                   images seen; it removes the down-right shift of strided padded convs).
    presence_threshold: ``found`` needs ``score`` above it; None: only a non-empty map.
                   The default, ``"auto"``, is 0 for the contrast target (the phrase must
                   beat the mean of the others) and None for the raw score, whose scale
                   depends on the model.
    """

    def __init__(self, vlm, target: str = "contrast", contrast: Sequence[str] | None = None,
                 locate: str = "peak_centroid", cell_centres: str = "receptive_field",
                 presence_threshold: float | str | None = "auto", batch_size: int = 32, template: str = "{}"):
        for what, value, known in (("Grad-CAM target", target, TARGETS), ("locate method", locate, LOCATE),
                                    ("cell_centres", cell_centres, CELL_CENTRES)):
            if value not in known:
                raise ValueError(f"unknown {what} {value!r}; choose one of {', '.join(known)}")
        if batch_size < 1:
            raise ValueError(f"batch_size must be positive, got {batch_size}")
        self.vlm = vlm.eval()
        self.target = target
        self.contrast = tuple(contrast) if contrast is not None else None
        self.locate = locate
        self.cell_centres = cell_centres
        if presence_threshold == "auto":
            presence_threshold = 0.0 if target == "contrast" else None
        self.presence_threshold = presence_threshold
        self.batch_size = batch_size
        self.template = template
        self._text_cache = TextEmbeddingCache(
            lambda phrases: self.vlm.encode_texts([self.template.format(p) for p in phrases]).float())
        self._centres: dict[tuple, np.ndarray] = {}
        # The finer layer "fine" reads (None: the Grad-CAM layer itself, through the head).
        self.fine_layer = getattr(vlm, "fine_layer", None)

    # --- targets ---------------------------------------------------------------------------
    def _texts(self, phrases: Sequence[str]) -> torch.Tensor:
        return self._text_cache(phrases)

    def target_vectors(self, phrases: Sequence[str]) -> torch.Tensor:
        """(P, D): each phrase's target is the dot product of this vector with the normalised
        image embedding (the cosine, minus the mean cosine of the contrast phrases)."""
        phrases = list(phrases)
        if not phrases or any(not isinstance(p, str) or not p.strip() for p in phrases):
            raise ValueError("phrases must be a non-empty list of non-empty strings")
        text = self._texts(phrases)
        if self.target == "score":
            return text
        pool = list(self.contrast) if self.contrast is not None else phrases
        pool_emb = self._texts(pool)
        rows = []
        for p, t in zip(phrases, text):
            others = [i for i, q in enumerate(pool) if q != p]
            rows.append(t - pool_emb[others].mean(0) if others else t)
        return torch.stack(rows)

    # --- heat maps -------------------------------------------------------------------------
    def _pixels(self, images) -> torch.Tensor:
        return self.vlm.preprocess(images).float()

    def heatmaps(self, images, phrases: Sequence[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """Fast Grad-CAM: ``(maps (N, P, h, w), scores (N, P))``. The trunk runs once per image
        without autograd; all phrases' gradients come through the head in one backward pass."""
        images = _as_batch(images)
        weights = self.target_vectors(phrases)
        maps, scores = [], []
        for start in range(0, len(images), self.batch_size):
            pixels = self._pixels(images[start:start + self.batch_size])
            with torch.no_grad():
                feats = self.vlm.image_trunk(pixels).float()
            m, s = head_gradcam(self.vlm.image_head, feats, weights)
            maps.append(m)
            scores.append(s)
        return torch.cat(maps), torch.cat(scores)

    def reference_heatmaps(self, images, phrases: Sequence[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """Plain Grad-CAM, the way it is usually written: for each phrase, a full forward
        pass with autograd and a full backward pass (parameters included), the layer's
        activations and gradient caught on the way. Same result as :meth:`heatmaps`."""
        images = _as_batch(images)
        weights = self.target_vectors(phrases)
        pixels = self._pixels(images)
        maps, scores = [], []
        for w in weights:
            self.vlm.zero_grad(set_to_none=True)
            with torch.enable_grad():
                feats = self.vlm.image_trunk(pixels)
                feats.retain_grad()
                emb = nn.functional.normalize(self.vlm.image_head(feats).float(), dim=-1)
                target = emb @ w
                target.sum().backward()
            alpha = feats.grad.mean(dim=(-2, -1), keepdim=True)
            maps.append(torch.relu((alpha * feats).sum(dim=1)).detach())
            scores.append(target.detach())
        self.vlm.zero_grad(set_to_none=True)
        return torch.stack(maps, dim=1), torch.stack(scores, dim=1)

    # --- the finer layer ---------------------------------------------------------------------
    def _fine_gradients(self, pixels: torch.Tensor, weights: torch.Tensor):
        """(activations (N, C, h, w), each phrase's target gradient (N, P, C, h, w)) at the fine
        layer: the layers before it run once per image, the rest once per phrase."""
        n, p = len(pixels), len(weights)
        caught = {}

        def repeat(module, inputs, output):  # one copy per phrase: each copy's gradient is that phrase's
            caught["a"] = output.detach()
            caught["rep"] = caught["a"].repeat_interleave(p, dim=0).requires_grad_(True)
            return caught["rep"]

        handle = self.vlm.get_submodule(self.fine_layer).register_forward_hook(repeat) if self.fine_layer else None
        try:
            with torch.enable_grad():
                if handle:
                    emb = self.vlm.image_head(self.vlm.image_trunk(pixels))
                else:
                    with torch.no_grad():
                        feats = self.vlm.image_trunk(pixels)
                    emb = self.vlm.image_head(repeat(None, None, feats))
                emb = nn.functional.normalize(emb.float(), dim=-1)
                target = (emb.view(n, p, -1) * weights[None]).sum(-1)
                (grads,) = torch.autograd.grad(target.sum(), caught["rep"])
        finally:
            if handle:
                handle.remove()
        return caught["a"].float(), grads.float().view(n, p, *caught["a"].shape[1:])

    def fine_heatmaps(self, images, phrases: Sequence[str]) -> torch.Tensor:
        """LayerCAM (Jiang et al., 2021) at the VLM's ``fine_layer``: (N, P, h, w). Each cell's
        activations are weighted by their own positive gradient, not by the map-wide mean as in
        Grad-CAM, which is what keeps an early, finer layer's map on the object."""
        images = _as_batch(images)
        weights = self.target_vectors(phrases)
        maps = []
        for start in range(0, len(images), self.batch_size):
            feats, grads = self._fine_gradients(self._pixels(images[start:start + self.batch_size]), weights)
            maps.append((torch.relu(grads) * torch.relu(feats[:, None])).sum(dim=2))
        return torch.cat(maps)

    def fine_locate(self, images, phrases: Sequence[str]) -> np.ndarray:
        """(N, P, 2) object coordinates from :meth:`fine_heatmaps`: the centroid of each map's
        peak blob, averaged over four views of every image: as it is and mirrored, each also
        shifted by half a fine cell down and right (a peak centroid's error depends on where the
        object falls on the cell grid and on the side its padded, strided convs favour; the
        views average both out)."""
        images = np.stack(_as_batch(images))
        height, width = images.shape[1:3]
        views, shift = [], 0
        for step in range(2):
            moved = np.pad(images, ((0, 0), (shift, 0), (shift, 0), (0, 0)), mode="edge")[:, :height, :width]
            for mirror in (False, True):
                view = np.ascontiguousarray(moved[:, :, ::-1] if mirror else moved)
                maps = self.fine_heatmaps(view, phrases).cpu().numpy()
                xy = locate(maps, self.centres(view, maps.shape[-2:], fine=True), "peak_centroid", FINE_FRACTION)
                if mirror:
                    xy[..., 0] = width - 1 - xy[..., 0]
                views.append(xy - shift)
            shift = max(1, round(width / maps.shape[-1] / 2))
        views = np.stack(views)
        ok = np.isfinite(views)
        with np.errstate(invalid="ignore"):  # no view found the object: NaN
            return np.where(ok, views, 0).sum(0) / ok.sum(0)

    # --- where the cells are ---------------------------------------------------------------
    def centres(self, images, grid: tuple[int, int], fine: bool = False) -> np.ndarray:
        """(h, w, 2) pixel coordinates (x, row) of each cell of the Grad-CAM layer (or of the
        fine layer) in the images' frame; receptive-field centres are measured on the first
        images seen at each size, unless :meth:`calibrate` set them."""
        size = _image_size(images)
        key = (fine, tuple(grid), size)
        if key not in self._centres:
            if self.cell_centres == "grid":
                self._centres[key] = grid_centres(grid, size)
            else:
                layer = self.fine_layer if fine else None
                self._centres[key] = receptive_field_centres(self.vlm, self._pixels(images[:8]), size, layer)
        return self._centres[key]

    def calibrate(self, images, fine: bool = False) -> np.ndarray:
        """Measure (or, for ``"grid"``, compute) the cell centres of the Grad-CAM layer (or the
        fine layer) for images of this size now, from these images, and return them: (h, w, 2)."""
        images = _as_batch(images)
        with torch.no_grad():
            grid = tuple(_activations(self.vlm, self._pixels(images[:1]), self.fine_layer if fine else None).shape[-2:])
        self._centres.pop((fine, grid, _image_size(images)), None)
        return self.centres(images, grid, fine)

    def set_centres(self, centres: np.ndarray, size: tuple[int, int], fine: bool = False) -> None:
        """Use these (h, w, 2) cell centres for images of ``size`` (height, width)."""
        centres = np.asarray(centres, dtype=np.float64)
        self._centres[(fine, centres.shape[:2], tuple(size))] = centres

    def __call__(self, images, phrases: Sequence[str]) -> GradCAMResult:
        images = _as_batch(images)
        if len(images) == 0:
            raise ValueError("no images given")
        maps, scores = self.heatmaps(images, phrases)
        maps, scores = maps.cpu().numpy(), scores.cpu().numpy()
        if self.locate == "fine":
            xy = self.fine_locate(images, phrases)
        else:
            xy = locate(maps, self.centres(images, maps.shape[-2:]), self.locate)
        peak = maps.max(axis=(-2, -1))
        found = peak > 0
        if self.presence_threshold is not None:
            found &= scores > self.presence_threshold
        xy[~found] = np.nan
        return GradCAMResult(tuple(phrases), maps, xy, peak, scores, found)


def head_gradcam(head, feats: torch.Tensor, weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Grad-CAM through the image ``head`` alone: ``(maps (N, P, h, w), targets (N, P))`` for
    Grad-CAM-layer activations ``feats`` (N, C, h, w) and target vectors ``weights`` (P, D),
    or (N, P, D) when each image has its own phrases (the grounded policy's goals)."""
    n = feats.shape[0]
    weights = weights if weights.dim() == 3 else weights[None]
    p = weights.shape[1]
    # One copy of the activations per phrase: each copy's gradient is that phrase's.
    rep = feats.detach().repeat_interleave(p, dim=0).requires_grad_(True)
    with torch.enable_grad():
        emb = nn.functional.normalize(head(rep).float(), dim=-1)
        target = (emb.view(n, p, -1) * weights).sum(-1)
        (grads,) = torch.autograd.grad(target.sum(), rep)
    grads = grads.view(n, p, *feats.shape[1:])
    alpha = grads.mean(dim=(-2, -1), keepdim=True)
    maps = torch.relu((alpha * feats.detach()[:, None]).sum(dim=2))
    return maps.detach(), target.detach()


def grid_centres(grid: tuple[int, int], size: tuple[int, int]) -> np.ndarray:
    """Geometric cell centres of an ``h x w`` grid over an image of ``size`` (height, width)."""
    (h, w), (height, width) = grid, size
    cols = (np.arange(w) + 0.5) * width / w - 0.5
    rows = (np.arange(h) + 0.5) * height / h - 0.5
    return np.stack(np.meshgrid(cols, rows), axis=-1)


def _activations(vlm, pixels: torch.Tensor, layer: str | None = None) -> torch.Tensor:
    """The output of the VLM's module ``layer`` on ``pixels`` (None: the Grad-CAM layer's)."""
    if layer is None:
        return vlm.image_trunk(pixels)
    caught = {}
    handle = vlm.get_submodule(layer).register_forward_hook(lambda module, i, out: caught.setdefault("a", out))
    try:
        vlm.image_trunk(pixels)
    finally:
        handle.remove()
    return caught["a"]


def receptive_field_centres(vlm, pixels: torch.Tensor, size: tuple[int, int], layer: str | None = None) -> np.ndarray:
    """(h, w, 2) centre of each Grad-CAM cell's (or module ``layer``'s cells') effective
    receptive field, in the frame of images of ``size``: the peak of the input-gradient
    magnitude (summed over ``pixels``), refined by its centroid within one cell stride of the peak. The centroid over the whole
    image would be pulled toward the image centre by the long, faint tails that global
    context gives every cell (measured: 4 px on 4 px cells); the peak is where the cell looks."""
    x = pixels.detach().clone().requires_grad_(True)
    with torch.enable_grad():
        feats = _activations(vlm, x, layer)
        h, w = feats.shape[-2:]
        height, width = x.shape[-2:]
        reach = max(1, round(max(height / h, width / w)))  # one cell stride, in input pixels
        out = np.zeros((h, w, 2))
        for i in range(h):
            for j in range(w):
                (g,) = torch.autograd.grad(feats[:, :, i, j].sum(), x, retain_graph=True)
                mass = g.abs().sum(dim=(0, 1)).double().numpy()
                if not mass.max() > 0:  # a dead cell: fall back to its grid centre
                    out[i, j] = ((j + 0.5) * width / w - 0.5, (i + 0.5) * height / h - 0.5)
                    continue
                r, c = np.unravel_index(int(mass.argmax()), mass.shape)
                r0, r1, c0, c1 = max(r - reach, 0), min(r + reach + 1, height), max(c - reach, 0), min(c + reach + 1, width)
                win = mass[r0:r1, c0:c1]
                rows, cols = np.mgrid[r0:r1, c0:c1]
                out[i, j] = ((win * cols).sum() / win.sum(), (win * rows).sum() / win.sum())
    # From the model's input resolution to the raw images' (preprocessing resizes).
    out[..., 0] = (out[..., 0] + 0.5) * size[1] / width - 0.5
    out[..., 1] = (out[..., 1] + 0.5) * size[0] / height - 0.5
    return out


def locate(maps: np.ndarray, centres: np.ndarray, method: str = "peak_centroid", fraction: float = 0.5) -> np.ndarray:
    """Object coordinates (..., 2) from heat maps (..., h, w) and cell centres (h, w, 2); the
    peak centroid weighs the connected cells above ``fraction`` of the peak around it."""
    from scipy import ndimage

    lead, (h, w) = maps.shape[:-2], maps.shape[-2:]
    flat = maps.reshape(-1, h, w)
    out = np.full((flat.shape[0], 2), np.nan)
    for k, m in enumerate(flat):
        peak = m.max()
        if not peak > 0:
            continue
        i, j = np.unravel_index(np.argmax(m), m.shape)
        if method == "argmax":
            out[k] = centres[i, j]
            continue
        # The blob around the peak only: other objects' blobs must not pull the centroid.
        labels, _ = ndimage.label(m >= fraction * peak)
        mass = np.where(labels == labels[i, j], m, 0.0)
        out[k] = (mass[..., None] * centres).sum(axis=(0, 1)) / mass.sum()
    return out.reshape(*lead, 2)
