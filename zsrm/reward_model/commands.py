"""Subcommands of the full reward model: ``zsrm finetune`` and ``zsrm eval-reward``.

Heavy imports (torch, the models, MuJoCo) happen inside the commands, so ``zsrm --help`` stays fast.
"""
from __future__ import annotations

import json
import platform
import sys
from pathlib import Path


def _cmd_finetune(args):
    from zsrm.reward_model.training import config_from_args, finetune

    cfg = config_from_args(args)
    if not Path(cfg.data).is_dir():
        raise FileNotFoundError(f"no dataset folder {cfg.data}: run zsrm collect and zsrm label first")
    finetune(cfg, fresh=args.fresh, progress=not args.quiet)
    print(f"saved the {'student' if cfg.student else 'fine-tuned VLM'} to {cfg.out} "
          f"(validation in {Path(cfg.out) / 'training.json'})")


def _cmd_eval_reward(args):
    import numpy as np

    from zsrm.reward_model.evaluate import EVAL_TASKS, evaluate_rewards, rollout_frames, write_curves
    from zsrm.reward_model.student import load_reward_backbone
    from zsrm.rewards.base import BaseReward
    from zsrm.rewards.zsrm import ZSRMReward

    tasks = args.tasks or list(EVAL_TASKS)
    names = {"zsrm": args.zsrm}
    for item in args.compare or []:
        key, sep, folder = item.partition("=")
        if not sep or not key or not folder or key in ("zsrm", "base", "meta"):
            raise ValueError(f"--compare takes NAME=FOLDER with a new NAME, got {item!r}")
        names[key] = folder
    for folder in names.values():
        if not Path(folder).is_dir():
            raise FileNotFoundError(f"no model folder {folder}: train it with zsrm finetune")
    models = {key: ZSRMReward(load_reward_backbone(folder), name=key) for key, folder in names.items()}
    base_vlm = load_reward_backbone(args.base)
    models["base"] = ZSRMReward(base_vlm, name="base_binary")
    names["base"] = args.base

    frames = {t: rollout_frames(t, args.scripted_episodes, args.random_episodes, args.seed, args.every,
                                progress=not args.quiet) for t in tasks}

    def base_raw(f):
        return BaseReward(base_vlm, camera=f.camera, mode=args.base_mode).score(f.images, f.goal)

    results = evaluate_rewards(models, frames, raw_scores={"base": base_raw})
    results["meta"] = {
        "command": "zsrm " + " ".join(sys.argv[1:]),
        "models": names,
        "training": {k: _training_summary(v) for k, v in names.items() if k != "base"},
        "frames": {t: {"n": len(f), "positives": int(f.success.sum()), "camera": f.camera, "goal": f.goal,
                       "scripted": int((f.source == "scripted").sum()), "random": int((f.source == "random").sum())}
                   for t, f in frames.items()},
        "episodes": {"scripted": args.scripted_episodes, "random": args.random_episodes,
                     "seeds": f"{args.seed}-{args.seed + args.scripted_episodes + args.random_episodes - 1}",
                     "every": args.every},
        "label": "info['is_success'] of the task's scene (the oracle, true state)",
        "binary": "1 when the goal text beats every negative (other relations over the same objects, swapped "
                  "order) on the camera the relation is read on; the base reward is binarised by the same rule",
        "auroc": f"of the raw score: zsrm cosine(frame, goal); base: BaseReward mode {args.base_mode!r}",
        "f1_best_threshold": "F1 of the raw score at its best threshold on these labels (privileged upper bound)",
        "machine": platform.platform(),
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1, default=float) + "\n")

    if args.curves:
        for t in tasks:
            curve_models = {k: m for k, m in models.items() if k != "base"}
            curve_models["zsrm_raw"] = ZSRMReward(models["zsrm"].model, output="raw")
            # The base reward as the paper plots it (Figure 5: the raw score), and binarised.
            curve_models["base"] = BaseReward(base_vlm, camera=frames[t].camera, mode=args.base_mode)
            curve_models["base_binary"] = models["base"]
            csv_path, png_path, _ = write_curves(t, curve_models, args.curves, steps=args.curve_steps,
                                                 seed=args.seed + 999)
            print(f"wrote {csv_path} and {png_path}")

    width = max(14, *(len(k) + 8 for k in models))
    header = f"{'task':<12}" + "".join(f"{k + ' F1':>{width}}" for k in models)
    print(header + "".join(f"{k + ' AUROC':>{width}}" for k in models))
    for t in tasks:
        row = f"{t:<12}" + "".join(f"{results[k][t]['f1']:>{width}.3f}" for k in models)
        row += "".join(f"{results[k][t]['auroc']:>{width}.3f}" for k in models)
        print(row)
    print(f"wrote {out}")
    return 0 if np.isfinite([results[k][t]["f1"] for k in models for t in tasks]).all() else 1


def _training_summary(folder: str) -> dict | None:
    """What ``zsrm finetune`` recorded about a model: its settings and held-out accuracy."""
    path = Path(folder) / "training.json"
    if not path.is_file():
        return None
    d = json.loads(path.read_text())
    val = d.get("validation", {})
    return {"config": d.get("config"), "train_pairs": d.get("train_pairs"), "train_seconds": d.get("train_seconds"),
            "val_pairs_scored": val.get("pairs"),
            "val_argmax_accuracy_vs_gradcam_labels": val.get("argmax_accuracy")}


def add_command(sub):
    p = sub.add_parser("finetune", help="train the full reward model on labelled pairs (CLIP-style), or the student")
    p.add_argument("--data", default="data/zsrm/explore",
                   help="dataset folder of zsrm collect + zsrm label, or of benchmarks/reward_data.py (the default)")
    p.add_argument("--labels", default="labels", help="labels folder inside the dataset (Grad-CAM captions)")
    p.add_argument("--vlm", default="scene",
                   help="VLM to start from (scene, open_clip:RN50, a folder); with --student, the VLM whose "
                        "text tower embeds the goal texts")
    p.add_argument("--student", action="store_true", help="train the small student network from scratch")
    p.add_argument("--student-arch", dest="student_arch", choices=("default", "tiny"))
    p.add_argument("--spatial-grid", dest="spatial_grid", type=int,
                   help="grid of the position-aware read-out added to the VLM's image head (default 4; 0: none)")
    p.add_argument("--text-adapter", dest="text_adapter", type=int,
                   help="hidden units of the whitened-text read-out added to the VLM's text tower (default 256; 0: none)")
    p.add_argument("--out", help="model folder (default runs/zsrm/vlm, or runs/zsrm/student with --student)")
    p.add_argument("--workdir", help="checkpoint and log folder (default OUT.work)")
    p.add_argument("--steps", type=int)
    p.add_argument("--batch-size", dest="batch_size", type=int)
    p.add_argument("--lr", type=float, help="peak learning rate (default 1e-3)")
    p.add_argument("--weight-decay", dest="weight_decay", type=float)
    p.add_argument("--warmup-steps", dest="warmup_steps", type=int)
    p.add_argument("--hard-negative-weight", dest="hard_negative_weight", type=float,
                   help="weight of the caption-vs-negative-texts loss (default 1; 0 for the plain contrastive loss)")
    p.add_argument("--balance", type=float, help="1 draws each relation equally often, 0 pairs uniformly")
    p.add_argument("--shift", type=int, help="random translation in pixels (default 2)")
    p.add_argument("--val-fraction", dest="val_fraction", type=float, help="episodes held out (default 0.1)")
    p.add_argument("--seed", type=int)
    p.add_argument("--checkpoint-every", dest="checkpoint_every", type=int)
    p.add_argument("--eval-every", dest="eval_every", type=int)
    p.add_argument("--threads", type=int, help="torch threads (default: torch's)")
    p.add_argument("--fresh", action="store_true", help="drop the checkpoint and start over")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_finetune_defaults)

    p = sub.add_parser("eval-reward", help="zsrm vs base reward against the oracle on held-out frames; curves")
    p.add_argument("--zsrm", default="runs/zsrm/student",
                   help="the full reward model reported as 'zsrm': a student or fine-tuned VLM folder")
    p.add_argument("--compare", nargs="+", metavar="NAME=FOLDER",
                   help="more models to report beside it, e.g. finetuned_vlm=runs/zsrm/vlm")
    p.add_argument("--base", default="scene", help="the base VLM (spec)")
    p.add_argument("--base-mode", dest="base_mode", default="dot", choices=("dot", "cosine"),
                   help="the base reward's raw score (default dot, paper 2.1)")
    p.add_argument("--tasks", nargs="+", help="catalogue tasks (default stack place_left place_right push_close)")
    p.add_argument("--scripted-episodes", dest="scripted_episodes", type=int, default=10)
    p.add_argument("--random-episodes", dest="random_episodes", type=int, default=10)
    p.add_argument("--every", type=int, default=2, help="keep every this many steps' frame (default 2)")
    p.add_argument("--seed", type=int, default=10_000, help="first episode seed (default 10000)")
    p.add_argument("--out", default="results/reward_eval.json")
    p.add_argument("--curves", default="results/reward_curves", help="folder for curve CSV/PNG ('' to skip)")
    p.add_argument("--curve-steps", dest="curve_steps", type=int, default=80)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_eval_reward)


def _finetune_defaults(args):
    if args.out is None:
        args.out = "runs/zsrm/student" if args.student else "runs/zsrm/vlm"
    return _cmd_finetune(args)
