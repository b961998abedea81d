"""The zsrm reward kept honest by the labeler while a policy trains on it.

A policy finds frames the reward model was never taught: on "a yellow block in between a red
block and a green block" a policy trained on the shipped student learnt to hold the block high in
one place, which the student paid for in 0.95 of decisions and the oracle in 0.44
(``probes/reward_hacking.py``). The labeler that made the student's training data (Grad-CAM +
Table 1, :class:`zsrm.grounding.goal_check.GoalLabeler`) reads those frames right (0.994 agreement
with the oracle there), but is too slow for every step. So, every ``update_every`` frames the
policy reaches, a sample of them is labelled by it and the reward model takes a few steps on
them: a frame the policy keeps reaching that only looks like the goal stops paying. This is the
paper's own training signal (no state, no goal images), asked about the frames the policy sees.

>>> import numpy as np
>>> from zsrm.testing import ColourVLM
>>> labeler = lambda frames: frames[:, 0, 0, 0] > 127  # "the goal holds" where the corner is bright
>>> frames = np.zeros((4, 32, 32, 3), np.uint8); frames[2:] = 255
>>> reward = CorrectedZSRMReward(ColourVLM(), labeler, update_every=4, label_frames=4, steps=1, min_each=2)
>>> reward({"front": frames}, "a yellow block on top of a red block").shape
(4,)
>>> reward.updates, reward.labelled
(1, 4)
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import torch

from zsrm.rewards.binarised import ZSRMReward
from zsrm.rewards.interface import check_images
from zsrm.rewards.vice import FrameBank


class CorrectedZSRMReward(ZSRMReward):
    """:class:`~zsrm.rewards.binarised.ZSRMReward` whose model keeps learning from the policy's frames.

    labeler:      frames (N, H, W, 3) of the goal's camera -> (N,) bool, does the goal hold; with
                  ``label_cameras``, also given those cameras' frames of the same steps by name.
    update_every: frames between updates; each labels ``label_frames`` of the frames seen since the
                  last one (drawn at random) and takes ``steps`` Adam steps on batches of half
                  labelled goal frames, half others, from the latest ``memory`` of each.
    labelled:     (frames, verdicts) the labeler gave before training (exploration renders): kept in
                  the banks for good, so that the first update need not wait for the policy to
                  reach the goal (a policy held by a fooled reward may never reach it).
    Updates wait until ``min_each`` of each kind have been labelled. ``on_update(model)`` runs after each update (the
    run keeps the latest model, so a resumed run starts from it). Only the image side learns: the
    goal's text embeddings stay those cached at the start. The loss is the goal's probability
    among its negatives (the binarised reward's candidates): up on goal frames, down on the others.
    """

    name = "zsrm"

    def __init__(self, model, labeler: Callable[[np.ndarray], np.ndarray], update_every: int,
                 label_frames: int = 128, steps: int = 50, memory: int = 4096, batch_size: int = 64,
                 lr: float = 1e-4, min_each: int = 16, seed: int = 0, on_update=None,
                 label_cameras: tuple[str, ...] = (), labelled: tuple[np.ndarray, np.ndarray] | None = None,
                 **kwargs):
        super().__init__(model, **kwargs)
        if min(update_every, label_frames, steps, memory, batch_size) < 1:
            raise ValueError(f"update_every, label_frames, steps, memory and batch_size must be >= 1, got "
                             f"{update_every}, {label_frames}, {steps}, {memory}, {batch_size}")
        self.labeler, self.update_every, self.label_frames = labeler, int(update_every), int(label_frames)
        self.steps, self.memory, self.batch_size, self.min_each = int(steps), int(memory), int(batch_size), int(min_each)
        self.rng = np.random.default_rng(seed)
        self.label_cameras = tuple(label_cameras)  # cameras the labeler reads beside the goal's
        self.banks: dict[bool, FrameBank] = {}
        if labelled is not None:
            frames, holds = np.asarray(labelled[0]), np.asarray(labelled[1], dtype=bool)
            self.banks = {kind: FrameBank(frames[holds == kind], self.memory) for kind in (True, False)
                          if (holds == kind).any()}
        self.recent: list[dict[str, np.ndarray]] = []
        self.seen = self.updates = self.labelled = self.labelled_goal = 0
        self.opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=lr)
        self.on_update = on_update

    def compute(self, observations, goal, infos) -> np.ndarray:
        reward = super().compute(observations, goal, infos)
        camera = self.goal_camera(goal)
        frames = check_images(observations[camera])
        self.recent.append({camera: np.array(frames), **{c: np.array(observations[c]) for c in self.label_cameras}})
        self.seen += len(frames)
        if self.seen >= self.update_every:
            self.seen = 0
            seen = {key: np.concatenate([step[key] for step in self.recent]) for key in self.recent[0]}
            self.learn(seen.pop(camera), goal, seen)
            self.recent = []
        return reward

    def learn(self, frames: np.ndarray, goal: str, others: dict[str, np.ndarray] | None = None) -> None:
        """Label a sample of ``frames`` (and ``others``, other cameras' frames of the same steps, for
        the labeler) and, once goal and other frames have both been seen, train."""
        pick = np.sort(self.rng.choice(len(frames), size=min(self.label_frames, len(frames)), replace=False))
        sample = frames[pick]
        holds = np.asarray(self.labeler(sample, **{c: v[pick] for c, v in (others or {}).items()}), dtype=bool)
        self.labelled += len(sample)
        self.labelled_goal += int(holds.sum())
        for kind in (True, False):
            if (holds == kind).any():
                if kind not in self.banks:
                    self.banks[kind] = FrameBank(sample[:0], self.memory)
                self.banks[kind].add(sample[holds == kind])
        if len(self.banks) < 2 or min(len(b) for b in self.banks.values()) < self.min_each:
            return
        self.train_steps(goal)
        self.updates += 1
        if self.on_update is not None:
            self.on_update(self.model)

    def train_steps(self, goal: str) -> None:
        texts = self.text_cache(self.candidates(goal)).float().detach()
        scale = float(getattr(self.model, "logit_scale", torch.tensor(np.log(1 / 0.07))).detach().exp())
        half = self.batch_size // 2
        target = torch.cat([torch.ones(half), torch.zeros(self.batch_size - half)])
        self.model.train()
        for _ in range(self.steps):
            pos, neg = self.banks[True], self.banks[False]
            batch = np.concatenate([pos[self.rng.integers(len(pos), size=half)],
                                    neg[self.rng.integers(len(neg), size=self.batch_size - half)]])
            emb = self.model.encode_images(batch, normalize=True).float()
            log_p = torch.log_softmax(scale * emb @ texts.to(emb.device).T, dim=1)[:, 0].cpu()
            # -log p(goal) on goal frames, -log(1 - p(goal)) on the others
            loss = -(target * log_p + (1 - target) * torch.log1p(-log_p.exp().clamp(max=1 - 1e-6))).mean()
            self.opt.zero_grad()
            loss.backward()
            self.opt.step()
        self.model.eval()
