"""The base reward of the paper (section 2.1): the VLM's image-text dot product.

``r_t = E_I(I_t) . E_L(g)``, with three modes:

* ``"dot"``: the raw dot product of the unnormalised embeddings (the paper's formula);
* ``"cosine"``: the dot product of the L2-normalised embeddings;
* ``"projection"``: goal-baseline regularisation of VLM-RMs (Rocamonde et al. 2023,
  Definition 1), see :func:`projection_reward`;
* ``"binary"``: 1 when the goal sentence's cosine beats every one of ``negatives`` (sentences
  for what the frame could show instead), else 0: the binarisation of the full reward
  (:func:`zsrm.rewards.binarised.decide`) on the base VLM's scores. The pendulum's base reward
  (Figure 4) is this, with the other poses as negatives (:data:`zsrm.tasks.pendulum.NEGATIVES`):
  never negative, so that an episode the env ends early earns less.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import torch
from torch.nn import functional as F

from zsrm.rewards.interface import RewardModel, check_goal, check_images
from zsrm.vlm.text_cache import TextEmbeddingCache

MODES = ("dot", "cosine", "projection", "binary")


def projection_reward(x: torch.Tensor, goal: torch.Tensor, baseline: torch.Tensor, alpha: float) -> torch.Tensor:
    """Goal-baseline regularised reward of VLM-RMs (Rocamonde et al. 2023, Definition 1).

    ``r = 1 - 0.5 * ||(alpha * P + (1 - alpha) * I) (x - g)||^2``

    with ``x``, ``g``, ``b`` the L2-normalised image, goal and baseline embeddings (normalised
    here) and ``P = d d^T / ||d||^2`` the orthogonal projection onto ``d = g - b``. VLM-RMs
    write it as ``1 - 0.5 ||alpha proj_L(x) + (1 - alpha) x - g||^2`` with ``proj_L`` the
    projection onto the line L through b and g; as g lies on L, ``proj_L(x) = g + P (x - g)``
    and the two forms are equal. ``alpha = 0`` gives ``1 - 0.5 ||x - g||^2 = x . g`` (cosine);
    ``alpha = 1`` keeps only the component of ``x - g`` along the baseline-to-goal direction,
    removing the parts of the embedding that the baseline prompt says are irrelevant.

    >>> g, b = torch.tensor([1.0, 0.0, 0.0]), torch.tensor([0.0, 1.0, 0.0])
    >>> x = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    >>> projection_reward(x, g, b, alpha=1.0)  # x off the g-b direction loses only that part
    tensor([1.0000, 0.7500])
    """
    if not 0.0 <= float(alpha) <= 1.0:
        raise ValueError(f"alpha must be in [0, 1], got {alpha}")
    x = F.normalize(torch.as_tensor(x, dtype=torch.float32), dim=-1)
    g = F.normalize(torch.as_tensor(goal, dtype=torch.float32).reshape(-1), dim=-1)
    b = F.normalize(torch.as_tensor(baseline, dtype=torch.float32).reshape(-1), dim=-1)
    d = g - b
    dd = torch.dot(d, d)
    if dd < 1e-12:
        raise ValueError("the goal and the baseline have the same embedding; choose a different baseline")
    diff = x - g
    # (alpha P + (1 - alpha) I) diff, without forming the D x D matrix.
    m = alpha * (diff @ d / dd)[..., None] * d + (1.0 - alpha) * diff
    return 1.0 - 0.5 * (m * m).sum(dim=-1)


class BaseReward(RewardModel):
    """``r = E_I(image) . E_L(goal)`` from any :class:`~zsrm.vlm.base.VisionLanguageModel`.

    Images are encoded in batches of ``batch_size`` (one forward for all envs of a step); goal
    and baseline embeddings come from a text cache (``cache_texts=False`` re-encodes them at
    every call, the simple way). ``mode`` is ``"dot"``, ``"cosine"``, ``"projection"`` (needs
    ``baseline``, a sentence describing the scene without the goal, and ``alpha`` in [0, 1]) or
    ``"binary"`` (needs ``negatives``, sentences the goal must beat).

    >>> import gymnasium as gym, zsrm.envs
    >>> from zsrm.vlm import load_vlm
    >>> reward = BaseReward(load_vlm("scene"), camera="front", mode="cosine")
    >>> env = gym.make("zsrm/Pushing-v0", task="a yellow puck close to a blue puck")
    >>> obs, info = env.reset(seed=0)
    >>> frames = {"front": obs["front"][None]}  # a batch of one env
    >>> r_yellow = reward(frames, "a yellow puck and a blue puck")
    >>> r_red = reward(frames, "a red block and a green block")
    >>> bool(r_yellow[0] > r_red[0])  # the scene VLM knows which objects are present
    True
    """

    name = "base"

    def __init__(self, vlm, camera: str = "front", mode: str = "dot", baseline: str | None = None,
                 alpha: float = 0.5, batch_size: int = 64, cache_texts: bool = True,
                 negatives: Sequence[str] | None = None):
        if mode not in MODES:
            raise ValueError(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}")
        if mode == "binary":
            if isinstance(negatives, str) or not negatives:
                raise ValueError("mode 'binary' needs negatives: sentences the goal must beat "
                                 "(e.g. 'a fallen pendulum')")
            negatives = tuple(check_goal(n) for n in negatives)
        elif negatives is not None:
            raise ValueError(f"negatives are used only by mode 'binary', not {mode!r}")
        self.negatives = negatives
        if mode == "projection":
            if baseline is None:
                raise ValueError("mode 'projection' needs a baseline sentence (e.g. 'two pucks on a table')")
            baseline = check_goal(baseline)
            if not 0.0 <= float(alpha) <= 1.0:
                raise ValueError(f"alpha must be in [0, 1], got {alpha}")
        elif baseline is not None:
            raise ValueError(f"a baseline is used only by mode 'projection', not {mode!r}")
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.vlm = vlm
        self.camera = camera
        self.mode = mode
        self.baseline = baseline
        self.alpha = float(alpha)
        self.batch_size = int(batch_size)
        # Unnormalised embeddings: "dot" needs them, the other modes normalise.
        self.text_cache = TextEmbeddingCache(lambda texts: vlm.encode_texts(texts, normalize=False),
                                             enabled=cache_texts)

    def texts(self, goal: str) -> list[str]:
        """The sentences scored: the goal, then the baseline or the negatives."""
        goal = check_goal(goal)
        return [goal, *([self.baseline] if self.baseline is not None else []), *(self.negatives or ())]

    def prepare(self, goal: str) -> None:
        self.text_cache(self.texts(goal))

    @torch.no_grad()
    def image_embeddings(self, images: np.ndarray) -> torch.Tensor:
        """``(N, D)`` unnormalised image embeddings, ``batch_size`` images per forward."""
        images = check_images(images)
        chunks = [self.vlm.encode_images(images[i:i + self.batch_size], normalize=False)
                  for i in range(0, len(images), self.batch_size)]
        return torch.cat(chunks)

    @torch.no_grad()
    def score(self, images: np.ndarray, goal: str) -> np.ndarray:
        """Rewards ``(N,)`` of frames ``(N, H, W, 3) uint8`` for a goal sentence."""
        img = self.image_embeddings(images).float()
        texts = self.text_cache(self.texts(goal)).to(img.device).float()
        if self.mode == "dot":
            r = img @ texts[0]
        elif self.mode == "cosine":
            r = F.normalize(img, dim=-1) @ F.normalize(texts[0], dim=-1)
        elif self.mode == "binary":
            from zsrm.rewards.binarised import decide

            sims = F.normalize(img, dim=-1) @ F.normalize(texts, dim=-1).T
            return decide(sims.cpu().numpy())["binary"]
        else:
            r = projection_reward(img, texts[0], texts[1], self.alpha)
        return r.cpu().numpy().astype(np.float32)

    def compute(self, observations: Mapping[str, np.ndarray] | None, goal: str,
                infos: Sequence[dict] | None) -> np.ndarray:
        return self.score(self.images(observations), goal)

    def __repr__(self) -> str:
        extra = f", baseline={self.baseline!r}, alpha={self.alpha}" if self.mode == "projection" else ""
        extra += f", negatives={list(self.negatives)!r}" if self.negatives else ""
        return f"BaseReward(vlm={getattr(self.vlm, 'backend', type(self.vlm).__name__)!r}, camera={self.camera!r}, mode={self.mode!r}{extra})"
