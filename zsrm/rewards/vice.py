"""VICE as the paper uses it (privileged baseline, section 3.2 b): a binary goal classifier
trained on true goal images (positives) and other frames (negatives); reward 1 when it says
the frame shows the goal, else 0.

It is privileged: its training frames are labelled by the oracle (true state). The frames
themselves come from a higher layer (:mod:`zsrm.rl.vice` rolls out scripted and random
policies); this module only fits and applies the classifier.

>>> import numpy as np
>>> frames = np.zeros((8, 32, 32, 3), np.uint8); frames[4:, :, :16] = 255  # goal: left half white
>>> labels = np.array([0, 0, 0, 0, 1, 1, 1, 1], bool)
>>> clf = fit_goal_classifier(frames, labels, image_size=32, steps=60, seed=0)
>>> VICEReward(clf, camera="front")({"front": frames}, "a white left half").tolist()
[0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch
from torch import nn

from zsrm.common.registry import WEIGHTS_FILE, build_model, load_weights, read_config, save_folder
from zsrm.rewards.interface import RewardModel, check_images

KIND = "zsrm-vice"


@dataclass
class GoalClassifierConfig:
    image_size: int = 64
    widths: tuple[int, int, int] = (16, 32, 32)


class GoalClassifier(nn.Module):
    """A small CNN: frames (N, H, W, 3) uint8 -> goal logits (N,)."""

    def __init__(self, config: GoalClassifierConfig | None = None):
        super().__init__()
        self.config = config or GoalClassifierConfig()
        layers, cin = [], 3
        for cout in self.config.widths:
            layers += [nn.Conv2d(cin, cout, 3, stride=2, padding=1), nn.ReLU()]
            cin = cout
        side = self.config.image_size // 2 ** len(self.config.widths)
        self.net = nn.Sequential(*layers, nn.Flatten(), nn.Linear(cin * side * side, 64), nn.ReLU(), nn.Linear(64, 1))

    def forward(self, images) -> torch.Tensor:
        x = torch.as_tensor(np.ascontiguousarray(images)).permute(0, 3, 1, 2).float() / 255.0
        if x.shape[-1] != self.config.image_size:
            x = nn.functional.interpolate(x, size=self.config.image_size, mode="bilinear", align_corners=False)
        return self.net(x).squeeze(-1)

    def save(self, folder: str | Path, meta: dict | None = None) -> None:
        save_folder(folder, {"kind": KIND, "config": asdict(self.config), "meta": meta or {}}, {WEIGHTS_FILE: self})

    @classmethod
    def from_folder(cls, folder: str | Path) -> "GoalClassifier":
        """A classifier saved by :meth:`save`: config and weights checked before it is built."""
        config = read_config(folder, kind=KIND, schema={"kind": str, "config": GoalClassifierConfig, "meta": dict})
        model = build_model(folder, lambda: cls(config.config))
        load_weights(model, folder)
        return model.eval()


def fit_goal_classifier(images: np.ndarray, labels: np.ndarray, image_size: int = 64, steps: int = 600,
                        batch_size: int = 128, lr: float = 1e-3, seed: int = 0) -> GoalClassifier:
    """Fit a classifier on frames and their oracle labels; batches are half positives, half
    negatives (goal frames are rare in random play)."""
    images, labels = check_images(images), np.asarray(labels, bool)
    if len(images) != len(labels):
        raise ValueError(f"{len(images)} frames but {len(labels)} labels")
    if not labels.any() or labels.all():
        raise ValueError(f"need goal and non-goal frames, got {int(labels.sum())} goal and {int((~labels).sum())} "
                         "other frames")
    torch.manual_seed(seed)
    model = GoalClassifier(GoalClassifierConfig(image_size=image_size))
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    return train_steps(model, opt, images[labels], images[~labels], steps, batch_size, np.random.default_rng(seed))


def train_steps(model: GoalClassifier, opt, positives: np.ndarray, negatives: np.ndarray, steps: int,
                batch_size: int, rng: np.random.Generator) -> GoalClassifier:
    """``steps`` Adam steps on batches of half positives, half negatives; the model left in eval mode."""
    target = torch.cat([torch.ones(batch_size // 2), torch.zeros(batch_size - batch_size // 2)])
    model.train()
    for _ in range(steps):
        batch = np.concatenate([positives[rng.integers(len(positives), size=batch_size // 2)],
                                negatives[rng.integers(len(negatives), size=batch_size - batch_size // 2)]])
        loss = nn.functional.binary_cross_entropy_with_logits(model(batch), target)
        opt.zero_grad()
        loss.backward()
        opt.step()
    return model.eval()


class VICEReward(RewardModel):
    """1 when the goal classifier says the frame shows the goal (probability above 0.5)."""

    name = "vice"

    def __init__(self, classifier: GoalClassifier, camera: str):
        self.classifier, self.camera = classifier.eval(), camera

    @torch.no_grad()
    def compute(self, observations: Mapping[str, np.ndarray] | None, goal: str,
                infos: Sequence[dict] | None) -> np.ndarray:
        return (self.classifier(self.images(observations)) > 0).float().numpy()


class FrameBank:
    """Fixed frames, then a ring of the latest ``memory`` frames added after them (one array, so
    that a batch draws from both with one index)."""

    def __init__(self, fixed: np.ndarray, memory: int):
        self.fixed, self.memory, self.stored = len(fixed), int(memory), 0
        self.frames = np.concatenate([fixed, np.zeros((self.memory, *fixed.shape[1:]), np.uint8)])

    def add(self, frames: np.ndarray) -> None:
        self.frames[self.fixed + (self.stored + np.arange(len(frames))) % self.memory] = frames
        self.stored += len(frames)

    def __len__(self) -> int:
        return self.fixed + min(self.stored, self.memory)

    def __getitem__(self, index):
        return self.frames[:len(self)][index]


class OnlineVICEReward(VICEReward):
    """VICE as Fu et al. (2018) train it: the classifier keeps learning while the policy trains.

    The frames it scores are the policy's. Every ``update_every`` of them it takes ``steps`` Adam
    steps on batches of half true goal frames (``positives``, oracle-labelled) and half negatives:
    the non-goal frames it was fitted on and the policy's latest ``memory`` frames. A frame the
    policy keeps reaching that only looks like the goal then stops paying. With ``oracle_labels``
    the policy's frames are labelled by the oracle (``info["is_success"]``) as the fitted-on frames
    are, VICE-RAQ (Singh et al., 2019) with every frame queried: its goal frames join the positives,
    so a policy that reaches the goal is not taught that the goal does not pay. ``on_update(classifier)``
    runs after each update (the run keeps the latest classifier, so a resumed run starts from it;
    the policy's frames and the optimiser's moments start afresh)."""

    def __init__(self, classifier: GoalClassifier, camera: str, positives: np.ndarray, negatives: np.ndarray,
                 update_every: int, steps: int = 50, memory: int = 2048, batch_size: int = 128, lr: float = 1e-3,
                 seed: int = 0, oracle_labels: bool = False, on_update=None):
        super().__init__(classifier, camera)
        if update_every < 1 or steps < 1 or memory < 1:
            raise ValueError(f"update_every, steps and memory must be >= 1, got {update_every}, {steps}, {memory}")
        self.positives = FrameBank(check_images(positives), memory)
        self.negatives = FrameBank(check_images(negatives), memory)
        self.update_every, self.steps, self.batch_size = int(update_every), int(steps), int(batch_size)
        self.oracle_labels = bool(oracle_labels)
        self.seen = self.updates = 0
        self.rng = np.random.default_rng(seed)
        self.opt = torch.optim.Adam(classifier.parameters(), lr=lr)
        self.on_update = on_update

    def compute(self, observations, goal, infos) -> np.ndarray:
        reward = super().compute(observations, goal, infos)
        frames = self.images(observations)
        if self.oracle_labels:
            if infos is None:
                raise ValueError("oracle_labels needs the env's infos (their is_success) for the policy's frames")
            goal_reached = np.array([bool(info["is_success"]) for info in infos])
            self.positives.add(frames[goal_reached])
            self.negatives.add(frames[~goal_reached])
        else:
            self.negatives.add(frames)
        self.seen += len(frames)
        if self.seen >= self.update_every:
            self.seen -= self.update_every
            train_steps(self.classifier, self.opt, self.positives, self.negatives, self.steps, self.batch_size,
                        self.rng)
            self.updates += 1
            if self.on_update is not None:
                self.on_update(self.classifier)
        return reward
