"""The full zero-shot reward (ZSRM, paper 2.2): the binarised reward of the fine-tuned model.

The goal text and its negatives (:mod:`zsrm.tasks.negatives`: the other relations
over the same objects and the swapped object order) are scored against the frame of the
camera the goal's relation is read on; the reward is 1 when the goal text wins the argmax,
else 0 (no threshold to tune). The raw score, the cosine of the frame and the goal text,
stays available (``output="raw"``), and so does the margin of the goal over its best
negative (``output="margin"``, > 0 exactly when the binarised reward is 1).

Any :class:`~zsrm.vlm.base.VisionLanguageModel` can score: the fine-tuned VLM, the student
network (:mod:`zsrm.fullmodel.student`), or the base VLM itself (the base reward with the
same binarisation, for comparison). Text embeddings are computed once per goal.

>>> import numpy as np
>>> from zsrm.testing import ColourVLM
>>> reward = ZSRMReward(ColourVLM())
>>> frames = np.zeros((3, 32, 32, 3), np.uint8)
>>> reward({"front": frames}, "a yellow block on top of a red block").shape
(3,)
>>> reward.goal_camera("a yellow block on top of a red block")  # the camera "on top of" is read on
'front'
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch

from zsrm.rewards.interface import RewardModel, check_goal, check_images
from zsrm.tasks.catalogue import as_task
from zsrm.tasks.negatives import candidate_texts
from zsrm.tasks.relations import RELATIONS
from zsrm.tasks.scene_goals import parse_scene_goal
from zsrm.vlm.text_cache import TextEmbeddingCache

OUTPUTS = ("binary", "raw", "margin")


def decide(sims: np.ndarray) -> dict[str, np.ndarray]:
    """The binarised reward's rule, in one place: from cosines (N, 1 + negatives) of frames with
    the goal text (column 0) and its negatives, ``binary`` is 1 where the goal text wins the
    argmax (ties go to the goal, as np.argmax takes the first column), ``raw`` the goal's cosine
    and ``margin`` the goal's cosine minus the best negative's (> 0 exactly where ``binary`` is 1,
    but for ties).

    >>> decide(np.array([[0.9, 0.2], [0.1, 0.5]]))["binary"]
    array([1., 0.], dtype=float32)
    """
    sims = np.asarray(sims)
    return {"binary": (sims.argmax(axis=1) == 0).astype(np.float32), "raw": sims[:, 0].astype(np.float32),
            "margin": (sims[:, 0] - sims[:, 1:].max(axis=1)).astype(np.float32)}


def _check_output(output: str) -> str:
    if output not in OUTPUTS:
        raise ValueError(f"unknown output {output!r}; choose one of {', '.join(OUTPUTS)}")
    return output


class ZSRMReward(RewardModel):
    """Binarised (or raw) reward of a contrastively trained model for a spatial goal sentence.

    model:      a VisionLanguageModel (fine-tuned VLM, student, or base VLM).
    output:     ``"binary"`` (1 if the goal text beats every negative), ``"raw"`` (cosine of
                the frame and the goal text) or ``"margin"`` (goal cosine minus the best
                negative's).
    camera:     the camera to read; None (default) reads the one the goal's relation needs.
    batch_size: frames per forward pass.
    objects:    an own scene's noun phrases (its adapter's ``objects``): goals name them
                (:func:`~zsrm.tasks.scene_goals.parse_scene_goal`); None: zsrm's objects.
    """

    name = "zsrm"

    def __init__(self, model, output: str = "binary", camera: str | None = None, batch_size: int = 256,
                 cache_texts: bool = True, name: str | None = None, objects: Sequence[str] | None = None):
        self.output = _check_output(output)
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.model = model.eval()
        self.fixed_camera = self.camera = camera
        self.batch_size = int(batch_size)
        if name is not None:
            self.name = name
        elif output != "binary":
            self.name = f"zsrm_{output}"
        self.text_cache = TextEmbeddingCache(lambda texts: model.encode_texts(texts, normalize=True),
                                             enabled=cache_texts)
        self._candidates: dict[str, list[str]] = {}
        self.objects = tuple(objects) if objects else None

    @classmethod
    def from_folder(cls, folder: str | Path, **kwargs) -> "ZSRMReward":
        """A model folder written by ``zsrm finetune`` (the VLM, or the student with ``--student``)."""
        from zsrm.fullmodel import load_reward_backbone

        return cls(load_reward_backbone(folder), **kwargs)

    # --- goal --------------------------------------------------------------------------
    def candidates(self, goal: str) -> list[str]:
        """The goal's canonical text first, then its negatives (GoalError for non-spatial goals)."""
        goal = check_goal(goal)
        if goal not in self._candidates:
            self._candidates[goal] = candidate_texts(self.read_goal(goal))
        return self._candidates[goal]

    def read_goal(self, goal: str):
        """The goal's Task, or with ``objects`` its SceneGoal over them (GoalError, one line)."""
        return parse_scene_goal(goal, self.objects) if self.objects else as_task(goal)

    def goal_camera(self, goal: str) -> str:
        return self.fixed_camera or RELATIONS[self.read_goal(check_goal(goal)).relation].camera

    def prepare(self, goal: str) -> None:
        """Embed the goal and its negatives once, and pick the camera the goal needs."""
        self.text_cache(self.candidates(goal))
        self.camera = self.goal_camera(goal)

    # --- scoring -----------------------------------------------------------------------
    @torch.no_grad()
    def similarities(self, images: np.ndarray, goal: str) -> np.ndarray:
        """Cosines (N, 1 + negatives) of frames with the goal text (column 0) and its negatives."""
        images = check_images(images)
        texts = self.text_cache(self.candidates(goal)).float()
        out = []
        for i in range(0, len(images), self.batch_size):
            emb = self.model.encode_images(images[i:i + self.batch_size], normalize=True).float()
            out.append(emb @ texts.to(emb.device).T)
        return torch.cat(out).cpu().numpy()

    def outputs(self, images: np.ndarray, goal: str) -> dict[str, np.ndarray]:
        """Every output (see :func:`decide`) of frames of the goal's camera, from one forward."""
        return decide(self.similarities(images, goal))

    def score(self, images: np.ndarray, goal: str, output: str | None = None) -> np.ndarray:
        """Rewards (N,) of frames of the goal's camera, as ``output`` (default: this model's)."""
        return self.outputs(images, goal)[_check_output(output or self.output)]

    def compute(self, observations: Mapping[str, np.ndarray] | None, goal: str,
                infos: Sequence[dict] | None) -> np.ndarray:
        camera = self.goal_camera(goal)
        if not observations or camera not in observations:
            have = ", ".join(observations or ()) or "none"
            raise ValueError(f"the zsrm reward for {goal!r} reads camera {camera!r}, but the observations "
                             f"have: {have}; make the env with cameras=({camera!r}, ...)")
        return self.score(check_images(observations[camera], f"observations[{camera!r}]"), goal)

    def __repr__(self) -> str:
        backend = getattr(self.model, "backend", type(self.model).__name__)
        return f"ZSRMReward(model={backend!r}, output={self.output!r}, camera={self.camera!r})"
