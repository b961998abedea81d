"""What the two contrastive training loops share (``zsrm pretrain-vlm`` and ``zsrm finetune``):
AdamW with decay on weight matrices only, linear warmup then cosine decay, and checkpoints
that a killed run resumes from.

A checkpoint is a folder: the model's weights (written by the caller), the optimiser's state
(its tensors in ``optimizer.safetensors``, the rest in ``optimizer.json``: nothing is pickled) and
``state.json`` (step, the settings that define the run, the log). It is written beside the
old one and swapped in, so a kill mid-write leaves the previous checkpoint intact.
"""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path
from typing import Callable

import torch
from torch import nn

from zsrm.vlm.registry import load_tensors, save_tensors

OPTIMIZER_TENSORS, OPTIMIZER_JSON = "optimizer.safetensors", "optimizer.json"


def adamw(model: nn.Module, lr: float, weight_decay: float) -> torch.optim.AdamW:
    """AdamW over the trainable parameters; biases, norms and scales (ndim < 2) get no decay."""
    params = [p for p in model.parameters() if p.requires_grad]
    return torch.optim.AdamW([{"params": [p for p in params if p.ndim >= 2], "weight_decay": weight_decay},
                              {"params": [p for p in params if p.ndim < 2], "weight_decay": 0.0}], lr=lr)


def warmup_cosine(step: int, lr: float, warmup_steps: int, steps: int) -> float:
    """Linear warmup to ``lr``, then cosine decay to zero at ``steps``."""
    if step < warmup_steps:
        return lr * (step + 1) / warmup_steps
    progress = (step - warmup_steps) / max(1, steps - warmup_steps)
    return 0.5 * lr * (1 + math.cos(math.pi * min(1.0, progress)))


def save_checkpoint(folder: Path, save_weights: Callable[[Path], None], opt: torch.optim.Optimizer, state: dict):
    """Write a checkpoint: ``save_weights(tmp_folder)``, the optimiser and ``state`` (JSON)."""
    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    save_weights(tmp)
    save_optimizer(opt, tmp)
    (tmp / "state.json").write_text(json.dumps(state) + "\n")
    old = folder.with_name(folder.name + ".old")
    if folder.exists():
        folder.rename(old)
    tmp.rename(folder)
    shutil.rmtree(old, ignore_errors=True)


def read_checkpoint_state(folder: Path, identity: dict) -> dict:
    """The checkpoint's ``state.json``; a ValueError naming each difference when it was made
    with other settings than ``identity`` (its ``"config"``)."""
    state = json.loads((folder / "state.json").read_text())
    if state["config"] != identity:
        diff = {k: (state["config"].get(k), v) for k, v in identity.items() if state["config"].get(k) != v}
        raise ValueError(f"the checkpoint in {folder} was made with other settings "
                         f"({'; '.join(f'{k}: {a} there, {b} now' for k, (a, b) in diff.items())}); "
                         "pass --fresh to start over or use another --workdir")
    return state


def save_optimizer(opt: torch.optim.Optimizer, folder: Path) -> None:
    """The optimiser's state: per-parameter tensors as safetensors, the rest (hyperparameters,
    parameter ids, non-tensor state) as JSON."""
    state_dict = opt.state_dict()
    tensors, other = {}, {}
    for pid, state in state_dict["state"].items():
        for key, value in state.items():
            (tensors if torch.is_tensor(value) else other)[f"{pid}.{key}"] = value
    save_tensors(tensors, Path(folder) / OPTIMIZER_TENSORS)
    (Path(folder) / OPTIMIZER_JSON).write_text(json.dumps({"param_groups": state_dict["param_groups"],
                                                           "state": other}) + "\n")


def load_optimizer(folder: Path, opt: torch.optim.Optimizer) -> None:
    """Restore what :func:`save_optimizer` wrote (or, from checkpoints written before it, the
    tensors-only ``optimizer.pt``, read with ``weights_only=True``)."""
    folder = Path(folder)
    if not (folder / OPTIMIZER_JSON).exists() and (folder / "optimizer.pt").exists():
        opt.load_state_dict(torch.load(folder / "optimizer.pt", weights_only=True))
        return
    saved = json.loads((folder / OPTIMIZER_JSON).read_text())
    state: dict[int, dict] = {}
    for key, value in {**load_tensors(folder / OPTIMIZER_TENSORS), **saved["state"]}.items():
        pid, name = key.split(".", 1)
        state.setdefault(int(pid), {})[name] = value
    groups = [{k: tuple(v) if k == "betas" else v for k, v in group.items()} for group in saved["param_groups"]]
    opt.load_state_dict({"state": state, "param_groups": groups})
