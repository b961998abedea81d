"""The interface every reward in zsrm implements (base, zsrm, vice, curiosity, oracle).

A reward model scores a *batch* of observations for one goal sentence::

    rewards = model(observations, goal, infos)   # -> np.ndarray (N,) float32

``observations`` is what a vectorised env returns for Dict image observations: a dict
``camera -> (N, H, W, 3) uint8``. ``model.camera`` names the camera the model reads (None for
models that read only ``infos``, like the oracle). ``infos`` is the list of the N envs' info
dicts; only privileged rewards (oracle, evaluation) may read it.

Models that embed the goal text keep the embedding in a
:class:`~zsrm.vlm.text_cache.TextEmbeddingCache`, so the text tower runs once per goal, not once
per step.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Mapping, Sequence

import numpy as np
import torch


def check_goal(goal) -> str:
    """The goal sentence, stripped; ValueError for anything but a non-empty string."""
    if not isinstance(goal, str) or not goal.strip():
        raise ValueError(f"the goal must be a non-empty sentence, got {goal!r}")
    return goal.strip()


def check_images(images, name: str = "images") -> np.ndarray:
    """A batch of RGB frames as ``(N, H, W, 3) uint8``; ValueError naming the problem otherwise."""
    if isinstance(images, torch.Tensor) or not isinstance(images, np.ndarray):
        raise ValueError(f"{name} must be a numpy array (N, H, W, 3) of uint8, got {type(images).__name__}")
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (N, H, W, 3), got {images.shape}")
    if images.dtype != np.uint8:
        raise ValueError(f"{name} must be uint8 RGB, got dtype {images.dtype}")
    if images.shape[0] == 0:
        raise ValueError(f"{name} is an empty batch")
    return images


def batch_size_of(observations: Mapping[str, np.ndarray] | None, infos: Sequence[dict] | None) -> int:
    """N, from the observation arrays or else from the infos; ValueError if they disagree."""
    sizes = {len(v) for v in (observations or {}).values()}
    if infos is not None:
        sizes.add(len(infos))
    if not sizes:
        raise ValueError("give observations (camera -> (N, H, W, 3) uint8) or infos")
    if len(sizes) != 1:
        raise ValueError(f"observations and infos must hold the same number of envs, got sizes {sorted(sizes)}")
    return sizes.pop()


class RewardModel(ABC):
    """A reward from observations and a goal sentence, for a batch of envs at once.

    Subclasses set ``camera`` (or None) and ``name`` and implement :meth:`compute`;
    :meth:`__call__` checks the inputs and the output shape. :meth:`prepare` lets wrappers
    warm per-goal state (the goal's text embedding) before the first step.
    """

    camera: str | None = None
    name: str = "reward"

    def __call__(self, observations: Mapping[str, np.ndarray] | None, goal: str,
                 infos: Sequence[dict] | None = None) -> np.ndarray:
        goal = check_goal(goal)
        if observations is not None and not isinstance(observations, Mapping):
            raise ValueError("observations must be a dict camera -> (N, H, W, 3) uint8 array")
        n = batch_size_of(observations, infos)
        rewards = np.asarray(self.compute(observations, goal, infos), dtype=np.float32)
        if rewards.shape != (n,):
            raise RuntimeError(f"{type(self).__name__}.compute returned shape {rewards.shape}, expected ({n},)")
        return rewards

    @abstractmethod
    def compute(self, observations: Mapping[str, np.ndarray] | None, goal: str,
                infos: Sequence[dict] | None) -> np.ndarray:
        """Rewards (N,) for a checked, stripped goal."""

    def prepare(self, goal: str) -> None:
        """Compute what depends on the goal only (e.g. its text embedding) ahead of the first step."""
        check_goal(goal)

    def images(self, observations: Mapping[str, np.ndarray] | None) -> np.ndarray:
        """This model's camera's frames, checked: ``(N, H, W, 3) uint8``."""
        if not observations or self.camera not in observations:
            have = ", ".join(observations or ()) or "none"
            raise ValueError(f"{self.name} reward reads camera {self.camera!r}, but the observations have: {have}")
        return check_images(observations[self.camera], f"observations[{self.camera!r}]")

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, camera={self.camera!r})"
