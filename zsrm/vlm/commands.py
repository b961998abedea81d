"""Subcommands of the VLM stage: ``zsrm pretrain-vlm`` and ``zsrm eval-vlm``."""
from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path


def _cmd_pretrain(args):
    from zsrm.vlm.pretrain import config_from_args, pretrain

    cfg = config_from_args(args)
    if args.resume and args.fresh:
        raise ValueError("--resume and --fresh contradict each other")
    if args.resume and not (Path(cfg.workdir) / "checkpoint" / "state.json").exists():
        raise FileNotFoundError(f"--resume: no checkpoint in {cfg.workdir}/checkpoint")
    for name in ("scenes", "steps", "batch_size", "shard_size", "checkpoint_every"):
        if getattr(cfg, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be at least 1")
    pretrain(cfg, fresh=args.fresh, progress=not args.quiet)
    print(f"wrote {cfg.out} (model.safetensors, config.json); log in {cfg.workdir}/log.csv")


def _cmd_eval(args):
    from zsrm.vlm.evaluate import presence_eval, write_presence_results
    from zsrm.vlm.factory import load_vlm

    if args.images < 10:
        raise ValueError("--images must be at least 10")
    vlm = load_vlm(args.vlm)
    result, arrays = presence_eval(vlm, n_images=args.images, seed=args.seed, progress=not args.quiet)
    command = ["zsrm", "eval-vlm", "--vlm", args.vlm, "--images", str(args.images), "--seed", str(args.seed)]
    result["meta"]["command"] = shlex.join(command + (["--out", str(args.out)] if args.out else []))
    print(json.dumps({k: v for k, v in result.items() if k.startswith("auroc.")}, indent=2))
    if args.out:
        json_path, png_path = write_presence_results(result, arrays, args.out)
        print(f"wrote {json_path} and {png_path}")
    failing = [k for k, v in result.items() if k.startswith("auroc.") and not v >= args.min_auroc]
    if failing:
        print(f"below {args.min_auroc}: {', '.join(failing)}", file=sys.stderr)
        return 1


def add_command(sub):
    from zsrm.vlm.pretrain import PretrainConfig

    d = PretrainConfig()
    p = sub.add_parser("pretrain-vlm", help="pretrain the offline scene VLM on captioned renders (resumable)",
                       description="Render random tabletop and pushing scenes (all four colours, all cameras), "
                       "caption each image with which objects it shows (never where) and train the scene VLM "
                       "contrastively. Re-running the same command resumes from WORKDIR/checkpoint.")
    p.add_argument("--out", default=d.out, help="folder for the final model (default: the shipped zsrm/vlm/weights/scene)")
    p.add_argument("--workdir", default=d.workdir, help=f"render cache, checkpoints and log (default {d.workdir})")
    p.add_argument("--arch", default=d.arch, help="architecture preset: default or tiny")
    p.add_argument("--scenes", type=int, default=d.scenes, help=f"scenes to render, x3 cameras (default {d.scenes})")
    p.add_argument("--shard-size", type=int, default=d.shard_size, help="scenes per cached render shard")
    p.add_argument("--steps", type=int, default=d.steps, help=f"optimizer steps (default {d.steps})")
    p.add_argument("--batch-size", type=int, default=d.batch_size)
    p.add_argument("--lr", type=float, default=d.lr)
    p.add_argument("--warmup-steps", type=int, default=d.warmup_steps)
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--checkpoint-every", type=int, default=d.checkpoint_every, help="steps between checkpoints")
    p.add_argument("--threads", type=int, default=d.threads, help="torch threads (0: torch's default)")
    p.add_argument("--fresh", action="store_true", help="delete WORKDIR (renders and checkpoint) and start over")
    p.add_argument("--resume", action="store_true",
                   help="resume from WORKDIR/checkpoint (the default whenever a checkpoint exists)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_pretrain)

    p = sub.add_parser("eval-vlm", help="zero-shot presence AUROC of each colour on held-out renders",
                       description="Score 'a C block' / 'a C puck' against the other colours' probes on held-out "
                       "renders and report AUROC per colour against true visibility.")
    p.add_argument("--vlm", default="scene", help="VLM spec: scene, a saved folder, open_clip:MODEL[:TAG|:FILE|:none]")
    p.add_argument("--images", type=int, default=500, help="held-out images (default 500)")
    p.add_argument("--seed", type=int, default=0, help="seed of the held-out (eval) stream")
    p.add_argument("--out", help="JSON path, e.g. results/vlm_presence.json (a PNG is written beside it)")
    p.add_argument("--min-auroc", type=float, default=0.95, help="exit 1 if any colour falls below this")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_eval)
