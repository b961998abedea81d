"""Does the masking check pick the stand-in VLMs that localise? Seeds x zoomed views on an own scene.

For each pretraining seed, with and without zoomed views, the stand-in VLM of ``zsrm own-scene``'s
settings is pretrained (or reused), checked as the chain checks it (presence AUROC, masking
agreement: no position read), and then measured as only evaluation may: it labels held-out data
of the scene, whose true pixels give each object's median Grad-CAM error, and whose oracle gives
the labeler's F1. Writes one JSON row per (zoom, seed).

    python probes/vlm_seed_probe.py --scene examples.slate_scene.adapter:SlateScene \\
        --seeds 0 1 2 --zooms 0 0.5 --out results/side/scenes/slate_vlm_seeds.json

The table of docs/own-scene.md from such files, each with its chain's summary (the objects'
half widths):

    python probes/vlm_seed_probe.py --table results/side/scenes/slate_vlm_seeds.json \
        results/scenes/slate_scene.json results/side/scenes/own_scene_vlm_seeds.json \
        results/scenes/own_scene.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

RELATIONS = ("left_of", "in_front_of", "in_between", "close_to")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--table", nargs="+", metavar="FILE", help="print the markdown table of pairs of "
                        "(this probe's file, its scene's chain summary) and stop")
    parser.add_argument("--scene")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--zooms", type=float, nargs="+", default=[0.0, 0.5])
    parser.add_argument("--work", default="runs/vlm-probe")
    parser.add_argument("--eval-images", type=int, default=1000)
    parser.add_argument("--out")
    args = parser.parse_args(argv)
    if args.table:
        print(table(args.table[0::2], args.table[1::2]))
        return 0
    if not (args.scene and args.out):
        parser.error("give --scene and --out (or --table)")
    import torch

    from zsrm.cli import main as zsrm
    from zsrm.common.files import read_json, write_json
    from zsrm.pipeline.own_scene import CHECK_IMAGES, check_vlm

    torch.set_num_threads(1)
    work = Path(args.work) / args.scene.split(":")[-1]
    held_out = work / "eval-data"
    if not (held_out / "manifest.json").is_file():
        zsrm(["collect", "--scene", args.scene, "--out", str(held_out), "--images", str(args.eval_images),
              "--shard-size", "250", "--seed", "1", "--quiet"])
    rows = []
    for zoom in args.zooms:
        for seed in args.seeds:
            folder = work / f"zoom{zoom:g}" / f"vlm-seed{seed}"
            if not (folder / "config.json").is_file():  # the settings zsrm own-scene pretrains with
                zsrm(["pretrain-vlm", "--scene", args.scene, "--out", str(folder), "--workdir",
                      str(folder.parent / f"pretrain-seed{seed}"), "--arch", "tiny", "--scenes", "800", "--shard-size",
                      "100", "--steps", "2000", "--batch-size", "64", "--checkpoint-every", "500", "--warmup-steps",
                      "50", "--threads", "1", "--seed", str(seed), "--zoom", str(zoom), "--quiet"])
            check_file = folder / "check.json"
            if not check_file.is_file():
                write_json(check_file, check_vlm(folder, args.scene, n_images=CHECK_IMAGES), indent=1)
            check = read_json(check_file)
            labels, report = f"labels-zoom{zoom:g}-seed{seed}", folder / "grounding.json"
            if not report.is_file():
                zsrm(["label", str(held_out), "--vlm", str(folder), "--labels", labels, "--quiet"])
                zsrm(["eval-grounding", str(held_out), "--labels", labels, "--out", str(report)])
            g = read_json(report)
            prefix = "median_px_error_by_colour."
            errors = {k[len(prefix):]: v for k, v in g.items() if k.startswith(prefix)}
            rows.append({"zoom": zoom, "seed": seed, "masking_min": check["masking"]["min"],
                         "masking": check["masking"]["agreement"], "presence_auroc": check["presence_auroc"],
                         "median_error_px": errors, "worst_median_error_px": max(errors.values()),
                         "labeler_f1": {r: g.get(f"f1_vs_world.{r}") for r in RELATIONS}})
            print(json.dumps({k: rows[-1][k] for k in ("zoom", "seed", "masking_min", "worst_median_error_px",
                                                       "labeler_f1")}))
    write_json(args.out, {"scene": args.scene, "rows": rows, "meta": {
        "command": "python probes/vlm_seed_probe.py " + " ".join(sys.argv[1:]),
        "held_out": f"zsrm collect --scene {args.scene} --seed 1 --images {args.eval_images}",
        "masking": "the chain's check (zsrm.grounding.selfcheck): reads renders and which objects each holds",
        "median_error_px": "evaluation only: against the true pixels of the held-out data, role.object"}}, indent=1)
    print(f"wrote {args.out}")
    return 0


def table(probes, chains) -> str:
    """Markdown rows: per VLM its masking floor, its worst object as a share of half its width,
    whether every object is within half its width, and the labeler's F1."""
    from zsrm.common.files import read_json

    lines = ["| scene | zoom | seed | lowest masking agreement | worst: error / half width (px) | all within | "
             "labeler left of / in front of / in between |", "|---|---|---|---|---|---|---|"]
    for probe, chain in zip(probes, chains):
        rows, loc = read_json(probe)["rows"], read_json(chain)["localisation"]
        half = {f"{role}.{obj}": cell["half_width_px"] for obj, cells in loc.items() for role, cell in cells.items()}
        for r in rows:
            share = {k: r["median_error_px"][k] / half[k] for k in half}
            worst = max(share, key=share.get)
            role, obj = worst.split(".", 1)
            error = r["median_error_px"][worst]
            where = (f"never located ({obj}, {role})" if error == float("inf") else
                     f"{error:.1f} / {half[worst]:.1f} ({obj}, {role})")
            f1 = " / ".join(f"{r['labeler_f1'][k]:.2f}" for k in ("left_of", "in_front_of", "in_between"))
            lines.append(f"| {Path(chain).stem} | {r['zoom']:g} | {r['seed']} | {r['masking_min']:.2f} | {where} | "
                         f"{'yes' if max(share.values()) <= 1 else 'no'} | {f1} |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
