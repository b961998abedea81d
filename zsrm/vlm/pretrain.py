"""``zsrm pretrain-vlm``: contrastive pretraining of the scene VLM on captioned renders.

The offline stand-in for CLIP's internet pretraining: renders of random scenes with all four
colours, captioned with which objects they show (never where), and the multi-positive
contrastive loss (identical captions in a batch are positives, not negatives).

Resumable: renders are cached in shards (``WORKDIR/renders/shard-*.npz``) and the model,
optimizer and step are checkpointed in ``WORKDIR/checkpoint/``; running the same command
again continues where a killed run stopped. Every step's batch, captions and flips come from
``np.random.default_rng([seed, step])``, so a resumed run matches an uninterrupted one.
"""
from __future__ import annotations

import csv
import json
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from zsrm.tasks.language import COLOURS
from zsrm.vlm.factory import SHIPPED_SCENE_DIR
from zsrm.vlm.losses import multi_positive_contrastive_loss
from zsrm.vlm.optim import adamw, load_optimizer, read_checkpoint_state, save_checkpoint, warmup_cosine
from zsrm.vlm.presence import SCENES, SHAPES, all_presence_captions, presence_caption, render_presence_scenes, \
    visible_colours
from zsrm.vlm.scene import SceneVLM, create_scene_vlm


@dataclass
class PretrainConfig:
    out: str = str(SHIPPED_SCENE_DIR)  # where the final model is saved
    workdir: str = "runs/pretrain-vlm"  # render cache, checkpoint and log
    arch: str = "default"  # a key of SCENE_PRESETS
    scenes: int = 4000  # x 3 cameras = training images
    shard_size: int = 250  # scenes per cached render shard
    image_size: int = 64
    steps: int = 1200
    batch_size: int = 128
    lr: float = 2e-3
    weight_decay: float = 0.05
    warmup_steps: int = 100
    seed: int = 0
    checkpoint_every: int = 250
    threads: int = 0  # torch threads; 0 keeps torch's default

    # Settings that define the run: a checkpoint made with others cannot be resumed.
    IDENTITY = ("arch", "scenes", "shard_size", "image_size", "steps", "batch_size", "lr", "weight_decay",
                "warmup_steps", "seed")

    def identity(self) -> dict:
        return {k: getattr(self, k) for k in self.IDENTITY}


# --- data --------------------------------------------------------------------------------------
def load_renders(cfg: PretrainConfig, progress: bool = True) -> dict:
    """The training renders, rendered once and cached shard by shard (a killed run keeps its shards)."""
    from tqdm import tqdm

    folder = Path(cfg.workdir) / "renders"
    folder.mkdir(parents=True, exist_ok=True)
    manifest = folder / "manifest.json"
    spec = {"seed": cfg.seed, "shard_size": cfg.shard_size, "image_size": cfg.image_size, "stream": "train"}
    if manifest.exists() and json.loads(manifest.read_text()) != spec:
        raise ValueError(f"{folder} holds renders made with other settings ({manifest.read_text().strip()}); "
                         "use another --workdir or --fresh")
    manifest.write_text(json.dumps(spec) + "\n")
    shards = []
    n_shards = math.ceil(cfg.scenes / cfg.shard_size)
    with tqdm(total=n_shards * cfg.shard_size, desc="render scenes", unit="scene", disable=not progress) as bar:
        for s in range(n_shards):
            hi = min(cfg.scenes, (s + 1) * cfg.shard_size)
            path = folder / f"shard-{s:04d}.npz"
            if path.exists():
                with np.load(path) as z:
                    data = {k: z[k] for k in z.files}
                shards.append(_take_scenes(data, hi))
                bar.update(cfg.shard_size)
                continue
            # Always render whole shards so that a shard means the same scenes in every run.
            data = render_presence_scenes(range(s * cfg.shard_size, (s + 1) * cfg.shard_size), seed=cfg.seed,
                                          size=cfg.image_size, progress=bar.update)
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, **data)
            tmp.replace(path)
            shards.append(_take_scenes(data, hi))
    return {k: np.concatenate([sh[k] for sh in shards]) for k in shards[0]}


def _take_scenes(data: dict, end: int) -> dict:
    keep = data["scene_index"] < end
    return {k: v[keep] for k, v in data.items()}


# --- training ----------------------------------------------------------------------------------
def _optimizer(model: SceneVLM, cfg: PretrainConfig) -> torch.optim.Optimizer:
    return adamw(model, cfg.lr, cfg.weight_decay)


def learning_rate(step: int, cfg: PretrainConfig) -> float:
    """Linear warmup, then cosine decay to zero."""
    return warmup_cosine(step, cfg.lr, cfg.warmup_steps, cfg.steps)


def make_batch(data: dict, train_rows: np.ndarray, step: int, cfg: PretrainConfig):
    """Images (uint8 NHWC) and captions of one step, a pure function of (seed, step)."""
    rng = np.random.default_rng([cfg.seed, 1, step])
    rows = train_rows[rng.choice(len(train_rows), min(cfg.batch_size, len(train_rows)), replace=False)]
    captions = [presence_caption(visible_colours(data["visible"][r], cfg.image_size), SHAPES[SCENES[data["shape"][r]]],
                                 rng) for r in rows]
    images = data["images"][rows]
    # Mirror half the images: presence does not depend on left and right, captions never say where.
    flip = rng.random(len(rows)) < 0.5
    images = np.where(flip[:, None, None, None], images[:, :, ::-1], images)
    return np.ascontiguousarray(images), captions


def contrastive_step_loss(model: SceneVLM, images: np.ndarray, captions: list[str]) -> torch.Tensor:
    image_emb = nn.functional.normalize(model.image_head(model.image_trunk(model.preprocess(images))), dim=-1)
    text_emb = nn.functional.normalize(model.encode_text_tokens(captions), dim=-1)
    scale = model.logit_scale.exp().clamp(max=100.0)
    return multi_positive_contrastive_loss(image_emb, text_emb, captions, scale)


def _save_checkpoint(folder: Path, model: SceneVLM, opt: torch.optim.Optimizer, step: int, cfg: PretrainConfig,
                     log: list[dict]):
    save_checkpoint(folder, model.save, opt, {"step": step, "config": cfg.identity(), "log": log})


def _load_checkpoint(folder: Path, cfg: PretrainConfig):
    state = read_checkpoint_state(folder, cfg.identity())
    model = SceneVLM.from_folder(folder)
    opt = _optimizer(model, cfg)
    load_optimizer(folder, opt)
    return model, opt, state["step"], state["log"]


def pretrain(cfg: PretrainConfig, fresh: bool = False, progress: bool = True) -> SceneVLM:
    """Train (or resume training) a scene VLM and save it to ``cfg.out``."""
    from tqdm import tqdm

    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    work = Path(cfg.workdir)
    ckpt = work / "checkpoint"
    if fresh:
        shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True, exist_ok=True)
    data = load_renders(cfg, progress)
    # Images in which nothing is visible (all objects hidden or fallen) have no true caption.
    train_rows = np.array([r for r in range(len(data["images"])) if visible_colours(data["visible"][r], cfg.image_size)])

    if ckpt.exists() and (ckpt / "state.json").exists():
        model, opt, start, log = _load_checkpoint(ckpt, cfg)
        print(f"resuming from {ckpt} at step {start}/{cfg.steps}")
    else:
        model = create_scene_vlm(cfg.arch, seed=cfg.seed, image_size=cfg.image_size)
        opt, start, log = _optimizer(model, cfg), 0, []
    model.train()
    # Encode every possible caption once: the frozen sentence encoder then never runs again.
    model.sentence_features([c for s in SHAPES.values() for c in all_presence_captions(s)])

    t0, elapsed_before = time.time(), (log[-1]["seconds"] if log else 0.0)
    bar = tqdm(total=cfg.steps, initial=start, desc="pretrain scene VLM", unit="step", disable=not progress)
    for step in range(start, cfg.steps):
        for group in opt.param_groups:
            group["lr"] = learning_rate(step, cfg)
        images, captions = make_batch(data, train_rows, step, cfg)
        loss = contrastive_step_loss(model, images, captions)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        bar.update(1)
        bar.set_postfix(loss=f"{loss.item():.3f}", temp=f"{model.logit_scale.exp().item():.1f}")
        if (step + 1) % 25 == 0 or step + 1 == cfg.steps:
            log.append({"step": step + 1, "loss": round(loss.item(), 5),
                        "seconds": round(elapsed_before + time.time() - t0, 1)})
        if (step + 1) % cfg.checkpoint_every == 0 or step + 1 == cfg.steps:
            _save_checkpoint(ckpt, model, opt, step + 1, cfg, log)
    bar.close()

    model.eval()
    model.meta = {
        "trained_by": "zsrm pretrain-vlm",
        "config": cfg.identity(),
        "train_images": int(len(train_rows)),
        "train_scenes": cfg.scenes,
        "colours": list(COLOURS),
        "final_loss": log[-1]["loss"] if log else None,
        "train_seconds": log[-1]["seconds"] if log else None,
    }
    model.save(cfg.out)
    with open(work / "log.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["step", "loss", "seconds"])
        writer.writeheader()
        writer.writerows(log)
    return model


def config_from_args(args) -> PretrainConfig:
    fields = PretrainConfig.__dataclass_fields__
    return PretrainConfig(**{k: getattr(args, k) for k in fields if getattr(args, k, None) is not None})


__all__ = ["PretrainConfig", "pretrain", "load_renders", "make_batch", "learning_rate"]
