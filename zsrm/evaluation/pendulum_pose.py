"""``zsrm eval-pose``: does a VLM know the pendulum's pose in words? (the test behind Figure 4)

The pendulum's base reward is 1 when "an inverted pendulum standing upright" beats the other
poses' sentences (:data:`zsrm.tasks.pendulum.NEGATIVES`). Before a policy is trained on it, this
checks the rule itself on held-out renders of known pose (:mod:`zsrm.data.pendulum_renders`,
another seed than the pretraining's): each frame's pose is the argmax over the four poses'
canonical sentences. Reported: accuracy overall and per pose, the confusion matrix, and the
precision, recall and F1 of "upright" (exactly the base reward's decision).

>>> from zsrm.testing import ColourVLM
>>> result = pose_eval(ColourVLM(), n_images=4, image_size=32, progress=False)
>>> sorted(k for k in result if k.startswith("accuracy."))
['accuracy.fallen', 'accuracy.leaning_left', 'accuracy.leaning_right', 'accuracy.upright']
"""
from __future__ import annotations

import platform

import numpy as np

from zsrm.tasks.pendulum import CAPTIONS, POSES

DEFAULT_SEED = 1  # zsrm pretrain-vlm renders the pendulum with its --seed, 0 by default


def pose_texts() -> list[str]:
    """The canonical sentence of each pose, in :data:`POSES` order (the goal is upright's)."""
    return [CAPTIONS[p][0] for p in POSES]


def pose_eval(vlm, n_images: int = 400, seed: int = DEFAULT_SEED, image_size: int = 64, progress: bool = True) -> dict:
    """Pose accuracy of ``vlm`` on ``n_images`` renders of seed ``seed`` (see the module docstring)."""
    import torch
    from tqdm import tqdm

    from zsrm.data.pendulum_renders import render_pendulum_scenes

    if n_images < 1:
        raise ValueError(f"n_images must be >= 1, got {n_images}")
    with tqdm(total=n_images, desc="render pendulum poses", unit="image", disable=not progress) as bar:
        data = render_pendulum_scenes(range(n_images), seed=seed, size=image_size, progress=bar.update)
    with torch.no_grad():
        sims = vlm.similarity(data["images"], pose_texts()).float().cpu().numpy()
    truth, pred = data["pose"].astype(int), sims.argmax(axis=1)
    confusion = np.zeros((len(POSES), len(POSES)), int)
    np.add.at(confusion, (truth, pred), 1)
    result: dict = {"accuracy": float((pred == truth).mean())}
    for k, pose in enumerate(POSES):
        result[f"accuracy.{pose}"] = float((pred[truth == k] == k).mean()) if (truth == k).any() else None
    up = POSES.index("upright")
    tp, said, true = int(((pred == up) & (truth == up)).sum()), int((pred == up).sum()), int((truth == up).sum())
    precision = tp / said if said else None
    recall = tp / true if true else None
    result["upright.precision"], result["upright.recall"] = precision, recall
    result["upright.f1"] = 2 * precision * recall / (precision + recall) if precision and recall else 0.0
    result["meta"] = {
        "n_images": int(n_images), "seed": int(seed), "image_size": int(image_size), "poses": list(POSES),
        "texts": pose_texts(), "confusion_rows_true_cols_predicted": confusion.tolist(),
        "rule": "predicted pose: argmax of the cosine to each pose's canonical sentence; 'upright' is "
                "the pendulum base reward's decision (the goal beats the other poses' sentences)",
        "truth": "pose class of the rendered tip's true position (zsrm.tasks.pendulum.pose_class)",
        "vlm": getattr(vlm, "meta", {}),
        "machine": platform.platform(),
    }
    return result
