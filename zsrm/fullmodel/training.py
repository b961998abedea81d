"""``zsrm finetune``: train the full reward model on the labelled pairs, CLIP-style (paper 2.2).

Two models train with the same loop:

* the fine-tuned VLM (default): starts from a VLM (``scene``, ``open_clip:RN50``, a folder)
  and trains both towers, with two zero-initialised adapters for where things are and who is
  where in the sentence (:mod:`zsrm.fullmodel.adapted`);
* the student (``student=True``): a small CNN from scratch whose text side is the VLM's
  frozen text embeddings through an MLP (:mod:`zsrm.fullmodel.student`).

The loss is the multi-positive contrastive loss of :mod:`zsrm.vlm.losses` (identical captions
in a batch are positives of each other, not negatives) plus, with weight
``hard_negative_weight``, the loss of the reward's own decision: each image's caption against
its task's negative texts (:mod:`zsrm.tasks.negatives`), leaving out negatives that the
labeler also found true for that image.

Resumable: the weights, optimizer and step are checkpointed in ``WORKDIR/checkpoint``; running
the same command again continues where a killed run stopped. Each step's batch is a function
of (seed, step) only, so a resumed run draws the same batches as an uninterrupted one.
"""
from __future__ import annotations

import csv
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Sequence

import numpy as np
import torch
from torch import nn

from zsrm.common.checkpoints import adamw, load_optimizer, read_checkpoint_state, save_checkpoint, warmup_cosine
from zsrm.common.files import atomic_path, write_json
from zsrm.common.registry import load_weights, save_weights
from zsrm.data.dataset import LABELS
from zsrm.fullmodel.adapted import AdaptedVLM
from zsrm.fullmodel.pairs import CaptionedImages, caption_relation
from zsrm.fullmodel.student import StudentConfig, StudentRewardNet
from zsrm.tasks.negatives import caption_candidates
from zsrm.vlm.base import VisionLanguageModel
from zsrm.vlm.factory import DEFAULT_VLM, load_vlm
from zsrm.vlm.losses import multi_positive_contrastive_loss

CHECKPOINT_WEIGHTS = "weights.safetensors"
STUDENT_PRESETS = {
    "default": {},
    "tiny": {"widths": (8, 8, 16, 16), "embed_dim": 16, "text_hidden": 32},
}


@dataclass
class FinetuneConfig:
    """Train the full reward model on labelled pairs (CLIP-style), or the student."""

    data: str = "data/zsrm/explore"  # dataset folder of zsrm reward-data (the default), or of zsrm collect + zsrm label
    labels: str = LABELS  # labels folder inside the dataset (only its Grad-CAM captions are read)
    out: str = ""  # model folder (default runs/zsrm/vlm, or runs/zsrm/student with --student)
    workdir: str = ""  # checkpoint and log folder (default OUT.work)
    vlm: str = DEFAULT_VLM  # VLM to start from (scene, open_clip:RN50, a folder); for the student, the one whose text tower it reads
    student: bool = False  # train the small student network from scratch
    student_arch: Literal["default", "tiny"] = "default"  # the student's architecture (STUDENT_PRESETS)
    spatial_grid: int = 4  # grid of the position-aware read-out added to the VLM's image head (0: none)
    text_adapter: int = 256  # hidden units of the whitened-text read-out added to the VLM's text tower (0: none)
    steps: int = 1500  # optimizer steps
    batch_size: int = 128  # pairs per step
    lr: float = 1e-3  # peak learning rate
    weight_decay: float = 0.05  # AdamW weight decay of weight matrices
    warmup_steps: int = 100  # linear warmup steps before the cosine decay
    hard_negative_weight: float = 1.0  # weight of the caption-vs-negative-texts loss (0: the plain contrastive loss)
    balance: float = 1.0  # 1 draws each relation equally often, 0 pairs uniformly
    shift: int = 2  # random translation of the images by up to this many pixels
    val_fraction: float = 0.1  # share of the exploration episodes held out for validation
    seed: int = 0  # seed of the split, the initial weights and every batch
    checkpoint_every: int = 100  # steps between checkpoints
    eval_every: int = 500  # steps between validations
    val_pairs: int = 2000  # validation pairs scored at each validation
    threads: int = 0  # torch threads (0: torch's default)

    # Settings that define the run: a checkpoint made with others cannot be resumed.
    IDENTITY = ("data", "labels", "vlm", "student", "student_arch", "spatial_grid", "text_adapter", "steps", "batch_size", "lr", "weight_decay",
                "warmup_steps", "hard_negative_weight", "balance", "shift", "val_fraction", "seed")

    def __post_init__(self):
        for name in ("steps", "batch_size", "checkpoint_every", "eval_every", "val_pairs"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.batch_size < 2:
            raise ValueError("batch_size must be >= 2: a contrastive batch needs negatives")
        if self.student and self.student_arch not in STUDENT_PRESETS:
            raise ValueError(f"unknown student architecture {self.student_arch!r}; known: {', '.join(STUDENT_PRESETS)}")
        if self.spatial_grid < 0 or self.text_adapter < 0:
            raise ValueError(f"spatial_grid and text_adapter must be >= 0, got {self.spatial_grid}, {self.text_adapter}")
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr}")
        if self.weight_decay < 0 or self.hard_negative_weight < 0 or self.shift < 0:
            raise ValueError("weight_decay, hard_negative_weight and shift must be >= 0")
        if not self.out:
            self.out = "runs/zsrm/student" if self.student else "runs/zsrm/vlm"
        if not self.workdir:
            self.workdir = str(Path(self.out).with_name(Path(self.out).name + ".work"))

    def identity(self) -> dict:
        return {k: getattr(self, k) for k in self.IDENTITY}


# --- model -------------------------------------------------------------------------------------
def initial_model(cfg: FinetuneConfig) -> VisionLanguageModel:
    """The model before training: the VLM with zero-initialised image and text adapters (see
    :mod:`zsrm.fullmodel.adapted`), or a fresh student on the VLM's text tower."""
    torch.manual_seed(cfg.seed)
    vlm = load_vlm(cfg.vlm)
    if cfg.student:
        return StudentRewardNet(StudentConfig(**STUDENT_PRESETS[cfg.student_arch]), vlm, cfg.vlm)
    if (cfg.spatial_grid or cfg.text_adapter) and not isinstance(vlm, (AdaptedVLM, StudentRewardNet)):
        # The text adapter reads a frozen copy of the VLM as it was: load it a second time.
        reference = load_vlm(cfg.vlm) if cfg.text_adapter else None
        return AdaptedVLM(vlm, cfg.spatial_grid, cfg.text_adapter, reference=reference, reference_spec=cfg.vlm)
    return vlm


def _optimizer(model: nn.Module, cfg: FinetuneConfig) -> torch.optim.Optimizer:
    return adamw(model, cfg.lr, cfg.weight_decay)


def learning_rate(step: int, cfg: FinetuneConfig) -> float:
    """Linear warmup, then cosine decay to zero."""
    return warmup_cosine(step, cfg.lr, cfg.warmup_steps, cfg.steps)


# --- loss --------------------------------------------------------------------------------------
def shift_images(images: np.ndarray, shift: int, rng: np.random.Generator) -> np.ndarray:
    """Translate each image by up to ``shift`` pixels (edges repeated). Relations between objects
    do not change under a small common translation; no flips, as they would swap left and right."""
    if shift <= 0:
        return images
    n, h, w, _ = images.shape
    padded = np.pad(images, ((0, 0), (shift, shift), (shift, shift), (0, 0)), mode="edge")
    dy, dx = rng.integers(0, 2 * shift + 1, (2, n))
    return np.stack([padded[i, dy[i]:dy[i] + h, dx[i]:dx[i] + w] for i in range(n)])


def reward_logits(image_emb: torch.Tensor, text_emb: torch.Tensor, captions: Sequence[str],
                  vocab_index: dict[str, int], holds: Sequence[set[str]] | None = None,
                  scale: torch.Tensor | float = 1.0):
    """Scaled similarities of each image to its caption and the caption's negatives, the rest
    of the vocabulary masked to -inf. Returns (logits (B, U), the caption's column (B,)).

    A negative that is also one of the image's own captions (``holds``) is masked: it is true
    there, not a negative.
    """
    allowed = torch.zeros(len(captions), text_emb.shape[0], dtype=torch.bool, device=image_emb.device)
    target = torch.empty(len(captions), dtype=torch.long, device=image_emb.device)
    for i, cap in enumerate(captions):
        true_here = holds[i] if holds is not None else set()
        allowed[i, [vocab_index[t] for t in caption_candidates(cap) if t == cap or t not in true_here]] = True
        target[i] = vocab_index[cap]
    # Mask after scaling: -inf times a learnable scale would give NaN gradients.
    logits = (scale * (image_emb @ text_emb.T)).masked_fill(~allowed, float("-inf"))
    return logits, target


def batch_loss(model: VisionLanguageModel, images: np.ndarray, captions: list[str],
               holds: Sequence[set[str]] | None, hard_negative_weight: float) -> tuple[torch.Tensor, dict]:
    """Contrastive loss of one batch of pairs; returns (loss, its parts as floats)."""
    image_emb = model.encode_images(images, normalize=True)
    needed = dict.fromkeys(captions)
    if hard_negative_weight > 0:
        for cap in list(needed):
            needed.update(dict.fromkeys(caption_candidates(cap)))
    vocab = list(needed)
    index = {t: i for i, t in enumerate(vocab)}
    text_emb = model.encode_texts(vocab, normalize=True)
    scale = model.logit_scale.exp().clamp(max=100.0)
    clip = multi_positive_contrastive_loss(image_emb, text_emb[[index[c] for c in captions]], captions, scale)
    parts = {"clip": clip.item()}
    loss = clip
    if hard_negative_weight > 0:
        logits, target = reward_logits(image_emb, text_emb, captions, index, holds, scale)
        hard = nn.functional.cross_entropy(logits, target)
        parts["hard"] = hard.item()
        loss = loss + hard_negative_weight * hard
    return loss, parts


@torch.no_grad()
def evaluate_pairs(model: VisionLanguageModel, data: CaptionedImages, max_pairs: int = 2000,
                   batch_size: int = 128, seed: int = 0) -> dict:
    """On (up to ``max_pairs``) pairs: the contrastive loss, and how often each caption beats
    its negatives (the binarised reward's rule) against the labels, overall and per relation."""
    if data.n_pairs == 0:
        return {}
    was_training = model.training
    model.eval()
    rng = np.random.default_rng([seed, 3])
    idx = np.sort(rng.choice(data.n_pairs, min(max_pairs, data.n_pairs), replace=False))
    loss_sum, loss_n, correct, relations = 0.0, 0, [], []
    for start in range(0, len(idx), batch_size):
        part = idx[start:start + batch_size]
        images, captions = data.pair_images(part), data.pair_texts(part)
        holds = [data.holds(i) for i in part]
        if len(part) > 1:
            loss, _ = batch_loss(model, images, captions, None, 0.0)
            loss_sum, loss_n = loss_sum + float(loss) * len(part), loss_n + len(part)
        image_emb = model.encode_images(images, normalize=True)
        vocab = list(dict.fromkeys(t for c in captions for t in caption_candidates(c)))
        index = {t: i for i, t in enumerate(vocab)}
        logits, target = reward_logits(image_emb, model.encode_texts(vocab, normalize=True), captions, index, holds)
        correct += (logits.argmax(dim=1) == target).tolist()
        relations += [caption_relation(c) for c in captions]
    model.train(was_training)
    correct_a, relations_a = np.array(correct), np.array(relations)
    return {
        "pairs": int(len(idx)),
        "loss": loss_sum / loss_n if loss_n else float("nan"),
        "argmax_accuracy": float(correct_a.mean()),
        "argmax_accuracy_by_relation": {r: float(correct_a[relations_a == r].mean())
                                        for r in sorted(set(relations))},
    }


# --- checkpoints -------------------------------------------------------------------------------
def _save_checkpoint(folder: Path, model: nn.Module, opt: torch.optim.Optimizer, step: int, cfg: FinetuneConfig,
                     log: list[dict]):
    save_checkpoint(folder, lambda tmp: save_weights(model, tmp, CHECKPOINT_WEIGHTS), opt,
                    {"step": step, "config": cfg.identity(), "log": log})


def _load_checkpoint(folder: Path, model: nn.Module, opt: torch.optim.Optimizer, cfg: FinetuneConfig):
    state = read_checkpoint_state(folder, cfg.identity())
    load_weights(model, folder, CHECKPOINT_WEIGHTS)
    load_optimizer(folder, opt)
    return state["step"], state["log"]


# --- training ----------------------------------------------------------------------------------
def finetune(cfg: FinetuneConfig, data: CaptionedImages | None = None, model: VisionLanguageModel | None = None,
             fresh: bool = False, progress: bool = True) -> VisionLanguageModel:
    """Train (or resume training) the reward model of ``cfg`` and save it to ``cfg.out``.

    ``data``: in-memory pairs (default: read ``cfg.data``); ``model``: the initial model
    (default: :func:`initial_model`). A resumed run must be given the same initial model, as
    the checkpoint holds its trained weights, not how to build it.
    """
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    work = Path(cfg.workdir)
    if fresh:
        shutil.rmtree(work, ignore_errors=True)
    if data is None:
        data = CaptionedImages.from_dataset(cfg.data, cfg.labels)
    train, val = data.split(cfg.val_fraction, cfg.seed)
    if train.n_pairs == 0:
        raise ValueError("no training pairs: the labels hold no caption for the cameras of the data")
    model = model if model is not None else initial_model(cfg)
    model.train()
    opt = _optimizer(model, cfg)
    start, log = 0, []
    fit = getattr(model, "fit_text_statistics", None)
    if callable(fit):  # statistics of the training captions and their negatives (restored on resume)
        fit(train.vocabulary())
    if (work / "checkpoint" / "state.json").exists():
        start, log = _load_checkpoint(work / "checkpoint", model, opt, cfg)
        if progress:
            print(f"resuming from {work / 'checkpoint'} at step {start}/{cfg.steps}")
    work.mkdir(parents=True, exist_ok=True)
    _train_steps(cfg, model, opt, train, val, start, log, progress)
    _save_trained(cfg, model, train, val, log)
    return model


def _train_steps(cfg: FinetuneConfig, model, opt, train: CaptionedImages, val: CaptionedImages, start: int,
                 log: list[dict], progress: bool) -> None:
    """Steps ``start`` to ``cfg.steps``: a batch of (seed, step), a log entry every 25 steps,
    validation every ``eval_every``, a checkpoint every ``checkpoint_every``."""
    from tqdm import tqdm

    weights = train.sampling_weights(cfg.balance)
    elapsed_before, t0 = (log[-1]["seconds"] if log else 0.0), time.time()
    bar = tqdm(total=cfg.steps, initial=start, desc="train student" if cfg.student else "fine-tune VLM",
               unit="step", disable=not progress)
    for step in range(start, cfg.steps):
        for group in opt.param_groups:
            group["lr"] = learning_rate(step, cfg)
        rng = np.random.default_rng([cfg.seed, 11, step])
        idx = rng.choice(train.n_pairs, cfg.batch_size, p=weights)
        images = shift_images(train.pair_images(idx), cfg.shift, rng)
        loss, parts = batch_loss(model, images, train.pair_texts(idx), [train.holds(i) for i in idx],
                                 cfg.hard_negative_weight)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        bar.update(1)
        bar.set_postfix(loss=f"{loss.item():.3f}", temp=f"{model.logit_scale.exp().item():.1f}")
        seconds = round(elapsed_before + time.time() - t0, 1)
        entry = None
        if (step + 1) % 25 == 0 or step + 1 == cfg.steps:
            entry = {"step": step + 1, "loss": round(loss.item(), 5), **{k: round(v, 5) for k, v in parts.items()},
                     "seconds": seconds}
        if val.n_pairs and ((step + 1) % cfg.eval_every == 0 or step + 1 == cfg.steps):
            res = evaluate_pairs(model, val, cfg.val_pairs, cfg.batch_size, cfg.seed)
            entry = entry or {"step": step + 1, "seconds": seconds}
            entry.update(val_loss=round(res["loss"], 5), val_argmax_accuracy=round(res["argmax_accuracy"], 4))
            bar.write(f"step {step + 1}: validation loss {res['loss']:.3f}, "
                      f"caption beats its negatives on {100 * res['argmax_accuracy']:.1f}% of held-out pairs")
        if entry:
            log.append(entry)
        if (step + 1) % cfg.checkpoint_every == 0 or step + 1 == cfg.steps:
            _save_checkpoint(Path(cfg.workdir) / "checkpoint", model, opt, step + 1, cfg, log)
    bar.close()


def _save_trained(cfg: FinetuneConfig, model, train: CaptionedImages, val: CaptionedImages, log: list[dict]) -> None:
    """The final validation, the model in ``cfg.out`` with its training summary, the log as CSV."""
    model.eval()
    final_val = evaluate_pairs(model, val, cfg.val_pairs, cfg.batch_size, cfg.seed) if val.n_pairs else {}
    summary = {
        "trained_by": "zsrm finetune" + (" --student" if cfg.student else ""),
        "config": cfg.identity(),
        "train_images": len(train), "train_pairs": train.n_pairs,
        "val_images": len(val), "val_pairs": val.n_pairs,
        "train_relation_counts": train.relation_counts(),
        "validation": final_val,
        "train_seconds": log[-1]["seconds"] if log else None,
    }
    if isinstance(getattr(model, "meta", None), dict):
        model.meta = {**model.meta, "zsrm_finetune": summary}
    out = Path(cfg.out)
    model.save(out)
    write_json(out / "training.json", summary, indent=1)
    keys = list(dict.fromkeys(k for row in log for k in row))
    with atomic_path(Path(cfg.workdir) / "log.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(log)


__all__ = ["FinetuneConfig", "finetune", "batch_loss", "evaluate_pairs", "initial_model", "learning_rate",
           "shift_images", "STUDENT_PRESETS"]
