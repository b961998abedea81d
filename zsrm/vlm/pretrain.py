"""``zsrm pretrain-vlm``: contrastive pretraining of the scene VLM on captioned renders.

The offline stand-in for CLIP's internet pretraining: renders of random scenes with all four
colours, captioned with which objects they show (never where), and the multi-positive
contrastive loss (identical captions in a batch are positives, not negatives).

The renders are data, made by a data stage (:mod:`zsrm.data.renders`, cached in
``WORKDIR/renders``) and handed to :func:`pretrain`: the VLM knows no simulator.

With ``pendulum_scenes`` N > 0, N renders of the double pendulum at random poses
(:mod:`zsrm.data.pendulum_renders`, cached in ``WORKDIR/pendulum-renders``) join the batches,
captioned with the pole's pose in words ("an inverted pendulum standing upright", "a pendulum
tilting to the left", "a fallen pendulum", :mod:`zsrm.tasks.pendulum`): what CLIP learned from
web captions and the pendulum's base reward (Figure 4) needs. Such a VLM is another model: it
goes to a folder named with ``out``, never over the shipped one. With N = 0 nothing changes
(the same batches, the same identity as the shipped VLM's).

With ``box_scenes`` N > 0, renders of N tabletop scenes with the open box
(:mod:`zsrm.data.box_renders`, cached in ``WORKDIR/box-renders``; a third of them start with a
block in the box) join the batches, captioned with the visible blocks and, where it shows, "a
box". The presence renders have no box, so the shipped VLM never learnt the word and its
Grad-CAM cannot find the box that "inside of" is read against. ``init`` starts from a saved
scene VLM (e.g. the shipped one) instead of random weights, and ``freeze_trunk`` keeps that
VLM's image trunk, up to and including the Grad-CAM layer, bit-identical (no gradient, no
weight decay): RL policies read the trunk's feature map, so they see the same features while
the head and the text projection learn the box. These too are other models, for another ``out``.

With ``scene`` (a user's own scene, :class:`zsrm.envs.SceneAdapter`), the renders are that
scene's (:mod:`zsrm.data.own_renders`, cached in ``WORKDIR/own-renders``) and the captions name
its objects by the adapter's phrases ("a red mug and a blue plate"): the scene VLM learns the
new objects' names. Which objects a render shows is read from the simulator (the adapter's
privileged accessor), the one step of the pipeline that reads it; with real CLIP weights it is
not needed. Another model again, for another ``out``.

Resumable: the model, optimizer and step are checkpointed in ``WORKDIR/checkpoint/``;
running the same command again continues where a killed run stopped. Every step's batch, captions and flips come from
``np.random.default_rng([seed, step])``, so a resumed run matches an uninterrupted one.
"""
from __future__ import annotations

import csv
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import nn

from zsrm.common.checkpoints import adamw, load_optimizer, read_checkpoint_state, save_checkpoint, warmup_cosine
from zsrm.common.files import atomic_path
from zsrm.common.registry import read_config
from zsrm.tasks.catalogue import SCENE_SHAPES
from zsrm.tasks.language import COLOURS
from zsrm.tasks.pendulum import POSES, all_pendulum_captions, mirrored, pendulum_caption
from zsrm.vlm.losses import multi_positive_contrastive_loss
from zsrm.vlm.presence import (all_box_captions, all_phrases_captions, all_presence_captions, box_visible,
                                phrases_caption, presence_caption, visible_colours, visible_names)
from zsrm.vlm.scene import SCENE_PRESETS, SHIPPED_SCENE_DIR, SceneConfig, SceneFolder, SceneVLM, create_scene_vlm

SHAPES = list(SCENE_SHAPES.values())  # a render's "shape" index -> the shape its captions name


@dataclass
class PretrainConfig:
    """Pretrain the offline scene VLM on captioned renders (resumable).

    Render random tabletop and pushing scenes (all four colours, all cameras), caption each
    image with which objects it shows (never where) and train the scene VLM contrastively.
    Re-running the same command resumes from WORKDIR/checkpoint.
    """

    out: str = str(SHIPPED_SCENE_DIR)  # folder for the final model (default: the shipped zsrm/vlm/weights/scene)
    workdir: str = "runs/pretrain-vlm"  # render cache, checkpoints and log
    arch: Literal["default", "tiny"] = "default"  # architecture preset (SCENE_PRESETS)
    scenes: int = 4000  # scenes to render, x3 cameras
    shard_size: int = 250  # scenes per cached render shard
    image_size: int = 64  # render side in pixels
    steps: int = 1200  # optimizer steps
    batch_size: int = 128  # images per step
    lr: float = 2e-3  # peak learning rate
    weight_decay: float = 0.05  # AdamW weight decay of weight matrices
    warmup_steps: int = 100  # linear warmup steps before the cosine decay
    seed: int = 0  # seed of the renders, the initial weights and every batch
    checkpoint_every: int = 250  # steps between checkpoints
    threads: int = 0  # torch threads (0: torch's default)
    pendulum_scenes: int = 0  # pendulum renders with pose captions (upright, leaning, fallen) to mix in; needs --out
    box_scenes: int = 0  # tabletop scenes with the open box (captioned "a box" where it shows) to mix in; needs --out
    init: str = ""  # start from this scene VLM folder (e.g. zsrm/vlm/weights/scene), not random weights; needs --out
    freeze_trunk: bool = False  # --init's image trunk (to the Grad-CAM layer) stays bit-identical; the rest learns
    scene: str = ""  # your own scene (module:Class or a registered id): learn its objects' names from its renders, not zsrm's; needs --out
    zoom: float = 0.0  # with --scene: share of each batch shown as zoomed views (a window of a render, captioned with what the window shows: presence, never where)

    # Settings that define the run: a checkpoint made with others cannot be resumed.
    IDENTITY = ("arch", "scenes", "shard_size", "image_size", "steps", "batch_size", "lr", "weight_decay",
                "warmup_steps", "seed")
    # Settings added after the shipped VLM was trained: part of the identity only when changed,
    # so that its checkpoints and config still match.
    ADDED = {"pendulum_scenes": 0, "box_scenes": 0, "init": "", "freeze_trunk": False, "scene": "", "zoom": 0.0}

    def identity(self) -> dict:
        d = {k: getattr(self, k) for k in self.IDENTITY}
        d.update({k: getattr(self, k) for k, default in self.ADDED.items() if getattr(self, k) != default})
        return d


def check_config(cfg: PretrainConfig) -> None:
    """Refuse what cannot be a run: a negative render count, another VLM than the shipped one
    written over it, a frozen trunk with no --init, an --init that is not a scene VLM of
    ``arch`` at ``image_size``."""
    for name in ("pendulum_scenes", "box_scenes"):
        if getattr(cfg, name) < 0:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got {getattr(cfg, name)}")
    if not 0.0 <= cfg.zoom <= 1.0:
        raise ValueError(f"--zoom is a share of each batch, in [0, 1], got {cfg.zoom}")
    if cfg.zoom and not cfg.scene:
        raise ValueError("--zoom is for your own scene's renders (--scene)")
    if cfg.scene and (cfg.pendulum_scenes or cfg.box_scenes):
        raise ValueError("--scene learns your own scene's objects; --pendulum-scenes and --box-scenes are zsrm's scenes")
    if cfg.freeze_trunk and not cfg.init:
        raise ValueError("--freeze-trunk keeps the trunk of the VLM named by --init "
                         "(e.g. --init zsrm/vlm/weights/scene); a frozen random trunk would learn nothing")
    # Each setting that makes another VLM than the shipped one, and an --out to suggest for it.
    other_vlm = {"--pendulum-scenes": (cfg.pendulum_scenes, "runs/vlm-pendulum"),
                 "--box-scenes": (cfg.box_scenes, "runs/vlm-box"), "--init": (cfg.init, "runs/vlm-box"),
                 "--freeze-trunk": (cfg.freeze_trunk, "runs/vlm-box"), "--scene": (cfg.scene, "runs/vlm-own-scene")}
    for flag, (value, example) in other_vlm.items():
        if value and Path(cfg.out).resolve() == SHIPPED_SCENE_DIR.resolve():
            raise ValueError(f"{flag} trains another VLM than the shipped one: name its folder with --out "
                             f"(e.g. --out {example})")
    if cfg.init:
        _check_init(cfg)


def _check_init(cfg: PretrainConfig) -> None:
    """--init names a saved scene VLM made with ``arch`` and ``image_size`` (its config.json only)."""
    try:
        have = read_config(cfg.init, kind=SceneVLM.backend, schema=SceneFolder).config
    except (FileNotFoundError, ValueError) as err:
        raise ValueError(f"--init: {err}") from None
    want = SceneConfig(**{**SCENE_PRESETS[cfg.arch], "image_size": cfg.image_size})
    diff = [f"{k}: {getattr(have, k)} there, {getattr(want, k)} here" for k in SceneConfig.__dataclass_fields__
            if getattr(have, k) != getattr(want, k)]
    if diff:
        raise ValueError(f"--init {cfg.init} is a scene VLM of another architecture than --arch {cfg.arch} "
                         f"--image-size {cfg.image_size} ({'; '.join(diff)})")


# --- training ----------------------------------------------------------------------------------
def _initial_model(cfg: PretrainConfig) -> SceneVLM:
    """The model a new run starts from: the scene VLM ``init``, or random weights of ``arch``."""
    if cfg.init:
        model = SceneVLM.from_folder(cfg.init)
        model.meta = {}  # the run's provenance replaces the init's
        return model
    return create_scene_vlm(cfg.arch, seed=cfg.seed, image_size=cfg.image_size)


def _optimizer(model: SceneVLM, cfg: PretrainConfig) -> torch.optim.Optimizer:
    """AdamW over what the run trains; with ``freeze_trunk`` the image trunk is left out (no
    gradient, no weight decay), so it stays bit-identical."""
    if cfg.freeze_trunk:
        for p in model.visual.trunk_parameters():
            p.requires_grad_(False)
    return adamw(model, cfg.lr, cfg.weight_decay)


def learning_rate(step: int, cfg: PretrainConfig) -> float:
    """Linear warmup, then cosine decay to zero."""
    return warmup_cosine(step, cfg.lr, cfg.warmup_steps, cfg.steps)


def make_batch(data: dict, train_rows: np.ndarray, step: int, cfg: PretrainConfig, pendulum: dict | None = None,
               box: dict | None = None, objects: tuple[str, ...] | None = None):
    """Images (uint8 NHWC) and captions of one step, a pure function of (seed, step).

    ``objects``: the phrases of a user's own scene, in the order of ``data["visible"]``'s columns
    (the renders are that scene's; its captions name them).

    ``pendulum``: pendulum renders (:func:`zsrm.data.pendulum_renders.render_pendulum_scenes`);
    ``box``: box renders (:func:`zsrm.data.box_renders.render_box_scenes`), every row with
    something to name. Either or both are drawn into the batch with ``data``'s rows, uniformly
    over all rows."""
    rng = np.random.default_rng([cfg.seed, 1, step])
    if pendulum is not None or box is not None:
        return _mixed_batch(data, train_rows, rng, cfg, pendulum, box)
    rows = train_rows[rng.choice(len(train_rows), min(cfg.batch_size, len(train_rows)), replace=False)]
    if objects is not None and cfg.zoom > 0:
        images, captions = _zoomed_batch(data, rows, rng, cfg, objects)
    else:
        images = data["images"][rows]
        if objects is not None:
            captions = [phrases_caption(visible_names(data["visible"][r], objects, cfg.image_size), rng) for r in rows]
        else:
            captions = [presence_caption(visible_colours(data["visible"][r], cfg.image_size), SHAPES[data["shape"][r]],
                                         rng) for r in rows]
    # Mirror half the images: presence does not depend on left and right, captions never say where.
    flip = rng.random(len(rows)) < 0.5
    images = np.where(flip[:, None, None, None], images[:, :, ::-1], images)
    return np.ascontiguousarray(images), captions


ZOOM_SIDES = (0.35, 0.7)  # a zoomed view's side, as a share of the render's


def zoomed_view(image: np.ndarray, mask: np.ndarray, rng: np.random.Generator, threshold: int):
    """A window of ``image`` (side drawn from ``ZOOM_SIDES``) scaled back to its size, and which
    objects it shows (``mask``: each pixel's object, 1-based, 0 for none): those with at least
    ``threshold`` pixels in the window. None when an object is cut to fewer (it would be seen
    and not named) or nothing is shown, after a few draws."""
    size = image.shape[0]
    for _ in range(8):
        side = int(round(size * rng.uniform(*ZOOM_SIDES)))
        y, x = (int(v) for v in rng.integers(0, size - side + 1, 2))
        counts = np.bincount(mask[y:y + side, x:x + side].ravel(), minlength=mask.max() + 1)[1:]
        shown = counts >= threshold
        if shown.any() and not ((counts > 0) & ~shown).any():
            idx = (np.arange(size) * side // size)
            return image[y + idx[:, None], x + idx[None, :]], np.flatnonzero(shown)
    return None


def _zoomed_batch(data: dict, rows: np.ndarray, rng: np.random.Generator, cfg: PretrainConfig, objects):
    """An own scene's batch with a ``cfg.zoom`` share of zoomed views: the same presence captions,
    of a window of the render (a narrower camera), never saying where in it."""
    from zsrm.vlm.presence import min_visible_pixels

    if "masks" not in data:
        raise ValueError("zoomed views need the renders' object masks: render them with masks (zsrm pretrain-vlm "
                         "--scene --zoom renders them; use another --workdir for renders made without)")
    images, captions = [], []
    for r in rows:
        view = zoomed_view(data["images"][r], data["masks"][r], rng, min_visible_pixels(cfg.image_size)) \
            if rng.random() < cfg.zoom else None
        if view is None:
            images.append(data["images"][r])
            captions.append(phrases_caption(visible_names(data["visible"][r], objects, cfg.image_size), rng))
        else:
            images.append(view[0])
            captions.append(phrases_caption([objects[j] for j in view[1]], rng))
    return np.stack(images), captions


def _mixed_batch(data: dict, train_rows: np.ndarray, rng: np.random.Generator, cfg: PretrainConfig,
                 pendulum: dict | None = None, box: dict | None = None):
    """A batch drawn from the presence rows, the pendulum renders and the box renders together
    (numbered in that order, so a run without box renders draws as before); half the images
    mirrored, a mirrored pendulum's lean captioned as the other side."""
    n_pendulum = 0 if pendulum is None else len(pendulum["images"])
    n_box = 0 if box is None else len(box["images"])
    total = len(train_rows) + n_pendulum + n_box
    picks = rng.choice(total, min(cfg.batch_size, total), replace=False)
    flips = rng.random(len(picks)) < 0.5
    images, captions = [], []
    for k, flip in zip(picks, flips):
        if k < len(train_rows):
            r = train_rows[k]
            image = data["images"][r]
            captions.append(presence_caption(visible_colours(data["visible"][r], cfg.image_size),
                                             SHAPES[data["shape"][r]], rng))
        elif k < len(train_rows) + n_pendulum:
            j = k - len(train_rows)
            image, pose = pendulum["images"][j], POSES[pendulum["pose"][j]]
            captions.append(pendulum_caption(mirrored(pose) if flip else pose, rng))
        else:  # captions never say where, so a mirrored box scene keeps its caption
            j = k - len(train_rows) - n_pendulum
            image = box["images"][j]
            captions.append(presence_caption(visible_colours(box["visible"][j], cfg.image_size),
                                             SCENE_SHAPES["tabletop"], rng,
                                             box=box_visible(box["box_visible"][j], cfg.image_size)))
        images.append(image[:, ::-1] if flip else image)
    return np.ascontiguousarray(np.stack(images)), captions


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


def _provenance(cfg: PretrainConfig, train_images: int, log: list[dict], pendulum: dict | None,
                box: dict | None = None, objects: tuple[str, ...] | None = None) -> dict:
    """What the saved model's config.json says about its training (the pendulum's, the box's,
    ``init`` and ``freeze_trunk`` only if used)."""
    meta = {
        "trained_by": "zsrm pretrain-vlm",
        "config": cfg.identity(),
        "train_images": int(train_images),
        "train_scenes": cfg.scenes,
        "colours": list(COLOURS),
        "final_loss": log[-1]["loss"] if log else None,
        "train_seconds": log[-1]["seconds"] if log else None,
    }
    if pendulum is not None:
        meta.update({"pendulum_images": int(len(pendulum["images"])), "pendulum_poses": list(POSES)})
    if box is not None:
        meta["box_images"] = int(len(box["images"]))
    if cfg.init:
        meta["init"] = cfg.init
    if cfg.freeze_trunk:
        meta["freeze_trunk"] = True
    if objects is not None:  # what it learnt to name (from the simulator's object list), in place of the colours
        meta.pop("colours")
        meta.update({"scene": cfg.scene, "objects": list(objects)})
    return meta


def _check_renders(cfg: PretrainConfig, data: dict, pendulum: dict | None,
                   box: dict | None, objects: tuple[str, ...] | None = None) -> tuple[dict | None, dict | None]:
    """The pendulum and box renders a run of ``cfg`` trains on (the first ``pendulum_scenes``
    and ``box_scenes`` scenes; of the box's, the images with something to name), checked."""
    check_config(cfg)
    if bool(cfg.scene) != (objects is not None):
        raise ValueError(f"scene is {cfg.scene!r} but the objects of its renders were {'not ' if objects is None else ''}given")
    for name, scenes, renders in (("pendulum", cfg.pendulum_scenes, pendulum), ("box", cfg.box_scenes, box)):
        if bool(scenes) != (renders is not None):
            raise ValueError(f"{name}_scenes is {scenes} but {name} renders were "
                             f"{'not ' if renders is None else ''}given")
        if renders is not None and renders["images"].shape[1:3] != data["images"].shape[1:3]:
            raise ValueError(f"{name} renders are {renders['images'].shape[1]} px, the scenes "
                             f"{data['images'].shape[1]} px")
    if pendulum is not None:
        pendulum = {k: v[:cfg.pendulum_scenes] for k, v in pendulum.items()}
    if box is not None:
        named = [bool(visible_colours(v, cfg.image_size)) or box_visible(b, cfg.image_size)
                 for v, b in zip(box["visible"], box["box_visible"])]
        keep = (box["scene_index"] < cfg.box_scenes) & np.array(named, bool)
        box = {k: v[keep] for k, v in box.items()}
    return pendulum, box


def _captions_to_encode(pendulum, box, objects) -> list[str]:
    """Every caption a run can draw, encoded once up front (none for too many own objects)."""
    if objects is not None:
        return all_phrases_captions(objects)
    return ([c for s in SHAPES for c in all_presence_captions(s)] + (all_pendulum_captions() if pendulum is not None else [])
            + (all_box_captions() if box is not None else []))


def pretrain(cfg: PretrainConfig, data: dict, progress: bool = True, pendulum: dict | None = None,
             box: dict | None = None, objects: tuple[str, ...] | None = None) -> SceneVLM:
    """Train (or resume training) a scene VLM on renders ``data`` (see
    :func:`zsrm.data.renders.render_presence_scenes`) and save it to ``cfg.out``; with
    ``cfg.pendulum_scenes``, also on the pendulum renders ``pendulum`` (see
    :func:`zsrm.data.pendulum_renders.render_pendulum_scenes`); with ``cfg.box_scenes``, also
    on the box renders ``box`` (see :func:`zsrm.data.box_renders.render_box_scenes`); with
    ``cfg.scene``, ``data`` are that scene's renders (:mod:`zsrm.data.own_renders`), ``objects`` its phrases."""
    from tqdm import tqdm

    pendulum, box = _check_renders(cfg, data, pendulum, box, objects)
    extra = {name: renders for name, renders in (("pendulum", pendulum), ("box", box), ("objects", objects))
             if renders is not None}
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    work, ckpt = Path(cfg.workdir), Path(cfg.workdir) / "checkpoint"
    work.mkdir(parents=True, exist_ok=True)
    # Images in which nothing is visible (all objects hidden or fallen) have no true caption.
    names = COLOURS if objects is None else objects
    train_rows = np.array([r for r in range(len(data["images"])) if visible_names(data["visible"][r], names, cfg.image_size)])

    if ckpt.exists() and (ckpt / "state.json").exists():
        model, opt, start, log = _load_checkpoint(ckpt, cfg)
        print(f"resuming from {ckpt} at step {start}/{cfg.steps}")
    else:
        model = _initial_model(cfg)
        opt, start, log = _optimizer(model, cfg), 0, []
    model.train()
    # Encode every possible caption once: the frozen sentence encoder then never runs again.
    texts = _captions_to_encode(pendulum, box, objects)
    if texts:
        model.sentence_features(texts)

    t0, elapsed_before = time.time(), (log[-1]["seconds"] if log else 0.0)
    bar = tqdm(total=cfg.steps, initial=start, desc="pretrain scene VLM", unit="step", disable=not progress)
    for step in range(start, cfg.steps):
        for group in opt.param_groups:
            group["lr"] = learning_rate(step, cfg)
        images, captions = make_batch(data, train_rows, step, cfg, **extra)
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
    model.meta = _provenance(cfg, len(train_rows), log, pendulum, box, objects)
    model.save(cfg.out)
    with atomic_path(work / "log.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["step", "loss", "seconds"])
        writer.writeheader()
        writer.writerows(log)
    return model


__all__ = ["PretrainConfig", "pretrain", "make_batch", "learning_rate", "check_config"]
