"""zsrm's mirror methods for distillation, not the paper's.

The tabletop and its front camera are symmetric about x = 0 (``tests/test_scene_physics.py``), so a
frame flipped left to right, with its action's x negated, is a frame and action of the mirror task:
"left of" and "right of" swap, a stacking goal is its own mirror (the relations table's ``mirror``).

* ``zsrm distill --mirror``: each frame of a batch, with probability 1/2, is mirrored
  (:func:`mirror_batch`), so every task also teaches its mirror task.
* ``zsrm distill --mirror-teachers``: each task is taught by the better of its own task policy and
  its mirror task's, as the zsrm reward judges them (:func:`teacher_return`: their training return
  under the zsrm reward at the end of training; no oracle reward is read). A task taught by its
  mirror's policy distils that policy's rollouts mirrored (:func:`taught_by`), and DAgger labels
  its frames with that policy's action on the flipped frame, x negated
  (:class:`zsrm.policy.dagger.MirroredTeacher`).
"""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

RETURN_EVALUATIONS = 3  # a task policy's training return: the mean over its last three evaluations


def mirror_actions(actions):
    """Actions with their x (the first component, in the camera's plane) negated: a copy."""
    actions = actions.clone() if isinstance(actions, torch.Tensor) else np.array(actions, copy=True)
    actions[:, 0] = -actions[:, 0]
    return actions


def mirror_batch(images: torch.Tensor, actions: torch.Tensor, codes: torch.Tensor, mirrors: torch.Tensor,
                 generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Half the frames (at random) mirrored left to right: flipped, their action's x negated,
    their goal its mirror goal's (``mirrors[code]``)."""
    flip = torch.rand(len(codes), generator=generator) < 0.5
    images, actions = images.clone(), actions.clone()
    images[flip] = images[flip].flip(-1)
    actions[flip] = mirror_actions(actions[flip])
    return images, actions, torch.where(flip, mirrors[codes], codes)


def trial_summary(policy: str | Path) -> Path:
    """The trial summary of a task policy folder: ``summary.json`` beside it in a sweep's run
    folder, or, for a kept policy (``<results>/task_policies/<trial>/policy``), the kept
    ``<results>/trials/<trial>.json``."""
    policy = Path(policy)
    for path in (policy.parent / "summary.json", policy.parent.parent.parent / "trials" / f"{policy.parent.name}.json"):
        if path.is_file():
            return path
    raise FileNotFoundError(f"no trial summary for the task policy {policy} (neither {policy.parent / 'summary.json'} "
                            "nor a kept trials/<trial>.json): --mirror-teachers compares the task policies' "
                            "training returns; keep the sweep's summaries (zsrm multitask-policies does)")


def teacher_return(policy: str | Path) -> float:
    """A task policy's training return under the zsrm reward (``train_reward``), mean over its last
    three evaluations: how the reward it was trained with judges it, no oracle reward read."""
    path = trial_summary(policy)
    curve = json.loads(path.read_text()).get("curve") or []
    returns = [point["train_reward"] for point in curve if "train_reward" in point][-RETURN_EVALUATIONS:]
    if not returns:
        raise ValueError(f"{path} records no training return (train_reward); rerun its trial")
    return float(np.mean(returns))


def teaching_tasks(mirrors: list[int], policies: list[str | Path]) -> list[int]:
    """For each task, the task whose policy teaches it: its own, or its mirror task's
    (``mirrors[i]``, as :meth:`~zsrm.policy.training.CloningData.mirror_codes` gives them) when that
    policy's training return is higher."""
    returns = [teacher_return(p) for p in policies]
    return [j if returns[j] > returns[i] else i for i, j in enumerate(mirrors)]


def taught_by(data, teaching: list[int]):
    """:class:`~zsrm.policy.training.CloningData` whose task i, where ``teaching[i] != i``, holds
    the frames of task ``teaching[i]`` mirrored (flipped, x negated) in place of its own."""
    keep = torch.tensor([teaching[int(c)] == int(c) for c in range(len(teaching))])[data.codes]
    images, actions, codes = [data.images[keep]], [data.actions[keep]], [data.codes[keep]]
    for i, j in enumerate(teaching):
        if j != i:
            rows = data.codes == j
            images.append(data.images[rows].flip(-1))
            actions.append(mirror_actions(data.actions[rows]))
            codes.append(torch.full((int(rows.sum()),), i, dtype=data.codes.dtype))
    return replace(data, images=torch.cat(images), actions=torch.cat(actions), codes=torch.cat(codes),
                   teaching=tuple(teaching))
