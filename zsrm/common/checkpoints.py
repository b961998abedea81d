"""What the two contrastive training loops share (``zsrm pretrain-vlm`` and ``zsrm finetune``):
AdamW with decay on weight matrices only, linear warmup then cosine decay, and checkpoints
that a killed run resumes from.

A checkpoint is a folder: the model's weights (written by the caller), the optimiser's state
(its tensors in ``optimizer.safetensors``, the rest in ``optimizer.json``: nothing is pickled) and
``state.json`` (step, the settings that define the run, the log). It is written beside the
old one and swapped in, so a kill mid-write leaves the previous checkpoint intact.
"""
from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import Callable

import torch
from torch import nn

from zsrm.common.files import ZsrmFileError, output_error, read_json, write_json
from zsrm.common.registry import load_tensors, parse_fields, save_tensors

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
    """Write a checkpoint: ``save_weights(tmp_folder)``, the optimiser and ``state`` (JSON). A
    failed write (full disk) leaves the previous checkpoint and raises one ZsrmFileError."""
    tmp = folder.with_name(folder.name + ".tmp")
    try:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        save_weights(tmp)
        save_optimizer(opt, tmp)
        write_json(tmp / "state.json", state, indent=None)
        old = folder.with_name(folder.name + ".old")
        if folder.exists():
            folder.rename(old)
        tmp.rename(folder)
        shutil.rmtree(old, ignore_errors=True)
    except OSError as err:
        shutil.rmtree(tmp, ignore_errors=True)
        raise output_error(folder, err) from None
    except ZsrmFileError as err:  # a failed write inside the new checkpoint: name the checkpoint
        shutil.rmtree(tmp, ignore_errors=True)
        raise ZsrmFileError(str(err).replace(str(tmp), str(folder))) from None


def read_checkpoint_state(folder: Path, identity: dict, fields: dict | None = None) -> dict:
    """The checkpoint's ``state.json``, checked: ``config`` (an object) and ``fields`` (``key ->
    type``; default: ``step`` and ``log``). A ValueError naming each difference when it was made
    with other settings than ``identity`` (its ``"config"``)."""
    path = Path(folder) / "state.json"
    schema = {"config": dict, **(fields or {"step": int, "log": list})}
    state = vars(parse_fields(schema, read_json(path, "a checkpoint's state"), str(path)))
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
    write_json(Path(folder) / OPTIMIZER_JSON, {"param_groups": state_dict["param_groups"], "state": other},
               indent=None)


def read_optimizer(folder: Path, opt: torch.optim.Optimizer) -> dict:
    """The state dict :func:`save_optimizer` wrote (or, from checkpoints written before it, the
    tensors-only ``optimizer.pt``, read with ``weights_only=True``), checked against ``opt``:
    its groups, parameter counts and tensor shapes. Anything else is one ZsrmFileError."""
    folder = Path(folder)
    if not (folder / OPTIMIZER_JSON).exists() and (folder / "optimizer.pt").exists():
        path = folder / "optimizer.pt"
        try:
            state_dict = torch.load(path, weights_only=True)
        except Exception as err:  # weights_only refuses anything but tensors and plain containers
            raise ZsrmFileError(f"{path} is not plain tensors, so it was not read (nothing in it ran): "
                                f"{str(err).strip().splitlines()[0][:200] if str(err).strip() else type(err).__name__}; "
                                "pass --fresh to start over") from None
        return _check_optimizer_state(path, state_dict, opt)
    path = folder / OPTIMIZER_JSON
    saved = parse_fields({"param_groups": list, "state": dict}, read_json(path, "an optimiser's state"), str(path))
    state: dict[int, dict] = {}
    for key, value in {**load_tensors(folder / OPTIMIZER_TENSORS), **saved.state}.items():
        pid, _, name = key.partition(".")
        if not pid.isdigit() or not name:
            raise ZsrmFileError(f"{folder}: optimiser state key {key!r} is not PARAMETER.NAME")
        state.setdefault(int(pid), {})[name] = value
    if not all(isinstance(g, dict) and isinstance(g.get("params"), list) for g in saved.param_groups):
        raise ZsrmFileError(f"{path}: every param group must be an object with a 'params' list")
    groups = [{k: tuple(v) if k == "betas" else v for k, v in group.items()} for group in saved.param_groups]
    return _check_optimizer_state(path, {"state": state, "param_groups": groups}, opt)


def _check_optimizer_state(path: Path, state_dict, opt: torch.optim.Optimizer) -> dict:
    if not isinstance(state_dict, dict) or not {"state", "param_groups"} <= set(state_dict):
        raise ZsrmFileError(f"{path} is not an optimiser state (an object with 'state' and 'param_groups')")
    ours, theirs = opt.param_groups, state_dict["param_groups"]
    if len(ours) != len(theirs) or any(len(a["params"]) != len(b.get("params", ())) for a, b in zip(ours, theirs)):
        raise ZsrmFileError(f"{path} is the optimiser of another model: "
                            f"{[len(g.get('params', ())) for g in theirs]} parameters per group there, "
                            f"{[len(g['params']) for g in ours]} here")
    params = {pid: p for a, b in zip(ours, theirs) for pid, p in zip(b["params"], a["params"])}
    for pid, entry in state_dict["state"].items():
        for name, value in (entry.items() if isinstance(entry, dict) else ()):
            if pid not in params or (torch.is_tensor(value) and value.ndim and value.shape != params[pid].shape):
                raise ZsrmFileError(f"{path}: the optimiser state {pid}.{name} does not fit the model's parameters")
    return state_dict


def check_optimizer(folder: Path, opt: torch.optim.Optimizer) -> None:
    """Fail now, with one line, if the optimiser state in ``folder`` cannot restore ``opt``."""
    read_optimizer(folder, opt)


def load_optimizer(folder: Path, opt: torch.optim.Optimizer) -> None:
    """Restore what :func:`save_optimizer` wrote, checked first (:func:`read_optimizer`)."""
    state_dict = read_optimizer(folder, opt)
    try:
        opt.load_state_dict(state_dict)
    except (ValueError, KeyError, TypeError) as err:
        raise ZsrmFileError(f"{folder}: the optimiser state does not restore: {err}") from None
