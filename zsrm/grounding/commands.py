"""CLI of the grounding stage: ``zsrm collect``, ``zsrm label``, ``zsrm eval-grounding``.

Each one resumes where a killed run stopped (finished shards are kept; the manifest refuses
to mix options).

    zsrm collect --out data/grounding --images 1000
    zsrm label data/grounding --vlm scene
    zsrm eval-grounding data/grounding --out results/grounding.json --figure results/figure3.png
"""
from __future__ import annotations

import json
from pathlib import Path


def _csv(text: str) -> tuple[str, ...]:
    return tuple(s.strip() for s in text.split(",") if s.strip())


def flatten(report: dict, keep: tuple[str, ...] = ("meta", "notes", "relations")) -> dict:
    """Nested report -> flat dotted keys (``median_px_error.front``); ``keep`` stay nested.

    >>> flatten({"f1": {"left_of": 0.9}, "meta": {"images": 4}})
    {'f1.left_of': 0.9, 'meta': {'images': 4}}
    """
    out: dict = {}

    def walk(prefix: str, value):
        if isinstance(value, dict) and prefix not in keep:
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        else:
            out[prefix] = value

    walk("", report)
    return out


def cmd_collect(args) -> int:
    from zsrm.data.collect import CollectConfig, collect

    cfg = CollectConfig(images=args.images, shard_size=args.shard_size, seed=args.seed, scenes=_csv(args.scenes),
                        cameras=_csv(args.cameras), image_size=args.image_size, min_objects=args.min_objects,
                        max_objects=args.max_objects, exclude=_csv(args.exclude), episode_steps=args.episode_steps,
                        record_every=args.record_every, p_stack=args.p_stack, p_side=args.p_side)
    data = collect(cfg, args.out, progress=not args.quiet)
    print(f"{len(data)} images x {len(cfg.cameras)} cameras in {args.out} ({len(data.shards)} shards)")
    return 0


def cmd_label(args) -> int:
    from zsrm.grounding.annotate import LabelConfig, label_dataset

    if not Path(args.data).is_dir():
        raise FileNotFoundError(f"no dataset folder {args.data}: run zsrm collect first")
    cfg = LabelConfig(vlm=args.vlm, target=args.target, locate=args.locate, cell_centres=args.cell_centres, template=args.template,
                      batch_size=args.batch_size)
    folder = label_dataset(args.data, cfg, out=args.labels, progress=not args.quiet)
    print(f"labels (Grad-CAM captions; true-coordinate captions under {folder}/oracle, for evaluation only) "
          f"in {folder}")
    return 0


def cmd_eval_grounding(args) -> int:
    from zsrm.data.shards import read_manifest
    from zsrm.grounding.evaluate import evaluate_grounding, figure3, write_tables
    from zsrm.data.dataset import ExplorationData

    if not Path(args.data).is_dir():
        raise FileNotFoundError(f"no dataset folder {args.data}: run zsrm collect and zsrm label first")
    report = evaluate_grounding(args.data, labels=args.labels)
    report["meta"]["command"] = "zsrm eval-grounding " + " ".join(
        [args.data, "--labels", str(args.labels), "--out", str(args.out)]
        + (["--figure", str(args.figure)] if args.figure else []))
    flat = flatten(report)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(flat, indent=2) + "\n")
    if args.csv:
        write_tables(report, args.csv)
    if args.figure:
        from zsrm.vlm import load_vlm

        data = ExplorationData(args.data)
        vlm = load_vlm(read_manifest(data.labels_folder(args.labels))["config"]["vlm"])
        figure3(args.data, vlm, args.figure, labels=args.labels, index=args.index)
    for cam in report["median_px_error"]:
        print(f"{cam:7s} median error {report['median_px_error'][cam]:.2f} px "
              f"(block {report['block_width_px'][cam]:.1f} px), p90 {report['p90_px_error'][cam]:.2f} px")
    for rel, f1 in report["f1"].items():
        print(f"{rel:12s} F1 {'n/a' if f1 is None else f'{f1:.3f}'}  (support {report['support'][rel]})")
    for note in report["notes"]:
        print("note:", note)
    print(f"wrote {out}" + (f" and {args.figure}" if args.figure else ""))
    return 0


def add_command(subparsers) -> None:
    from zsrm.data.collect import CollectConfig

    d = CollectConfig()
    p = subparsers.add_parser("collect", help="random exploration images of every camera, in resumable shards")
    p.add_argument("--out", required=True, help="dataset folder (resumes if it holds a manifest)")
    p.add_argument("--images", type=int, default=d.images)
    p.add_argument("--shard-size", type=int, default=d.shard_size)
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--scenes", default=",".join(d.scenes), help="comma list: tabletop,pushing")
    p.add_argument("--cameras", default=",".join(d.cameras))
    p.add_argument("--image-size", type=int, default=d.image_size)
    p.add_argument("--min-objects", type=int, default=d.min_objects)
    p.add_argument("--max-objects", type=int, default=d.max_objects)
    p.add_argument("--exclude", default="", help="colours never placed, comma list")
    p.add_argument("--episode-steps", type=int, default=d.episode_steps)
    p.add_argument("--record-every", type=int, default=d.record_every)
    p.add_argument("--p-stack", type=float, default=d.p_stack, help="chance a block starts stacked on another")
    p.add_argument("--p-side", type=float, default=d.p_side, help="chance an object starts beside another")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_collect)

    from zsrm.data.dataset import LABELS
    from zsrm.grounding.annotate import LabelConfig

    lc = LabelConfig()
    p = subparsers.add_parser("label", help="Grad-CAM captions of a collected dataset (+ true ones, for evaluation)")
    p.add_argument("data", help="folder written by zsrm collect")
    p.add_argument("--labels", default=LABELS, help="labels folder (relative to DATA unless absolute)")
    p.add_argument("--vlm", default=lc.vlm, help="scene | a saved VLM folder | open_clip:MODEL[:TAG]")
    p.add_argument("--target", default=lc.target)
    p.add_argument("--locate", default=lc.locate)
    p.add_argument("--cell-centres", default=lc.cell_centres, choices=("grid", "receptive_field"),
                   help="pixel position of each Grad-CAM cell: its geometric centre, or the centroid of its "
                        "measured input gradient (which global pooling pulls toward the image centre)")
    p.add_argument("--template", default=lc.template)
    p.add_argument("--batch-size", type=int, default=lc.batch_size)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_label)

    p = subparsers.add_parser("eval-grounding", help="localisation error, caption P/R/F1, Figure 3")
    p.add_argument("data", help="a collected and labelled dataset folder")
    p.add_argument("--labels", default=LABELS)
    p.add_argument("--out", default="results/grounding.json")
    p.add_argument("--figure", default=None, help="Figure 3 style PNG to write")
    p.add_argument("--index", type=int, default=None, help="image of the figure (default: first with red+yellow)")
    p.add_argument("--csv", default=None, help="also write PREFIX_cameras.csv and PREFIX_relations.csv")
    p.set_defaults(func=cmd_eval_grounding)
