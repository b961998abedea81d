"""How the labeler's 3-D on top of reads an own scene: Grad-CAM points triangulated on the tilted
and left cameras against the true positions, per ordered pair of objects.

For every pair (a, b) in the labelled held-out data (``zsrm own-scene``'s ``eval-data``), over the
frames where the oracle says "a on top of b" (true positions, evaluation only) and over the
others where a and b are both present: the triangulated points' horizontal distance and height
difference (percentiles, metres), and how often the labeler's rule says it. Prints a table,
writes JSON.

    python probes/solid_on_top.py --data runs/benchmarks/libero/chain/eval-data --out results/side/benchmarks/solid_on_top.json
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def pair_stats(points: np.ndarray, truth: np.ndarray, holds: np.ndarray, both: np.ndarray, a: int, b: int) -> dict:
    """Percentiles of the triangulated horizontal distance and height difference of a over b,
    where the oracle says a on top of b and where it does not (both present), and the rule's rate."""
    horizontal = np.linalg.norm(points[:, a, :2] - points[:, b, :2], axis=-1)
    dz = points[:, a, 2] - points[:, b, 2]
    out = {}
    for name, rows in (("holds", truth & both), ("not", ~truth & both)):
        finite = rows & np.isfinite(dz)
        q = (lambda v: [round(float(x), 4) for x in np.percentile(v[finite], (10, 50, 90))] if finite.any() else None)
        out[name] = {"frames": int(rows.sum()), "horizontal_p10_50_90": q(horizontal), "dz_p10_50_90": q(dz),
                     "labeler_says": round(float(holds[rows].mean()), 3) if rows.any() else None}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="a labelled own-scene dataset with pixel rays")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    from zsrm.common.files import write_json
    from zsrm.data.dataset import ExplorationData
    from zsrm.evaluation.grounding_quality import load_labels
    from zsrm.grounding.annotate import LabelConfig, gradcam_objects, labelers, world_thresholds
    from zsrm.grounding.labeler import relation_tuples, world_table

    data = ExplorationData(args.data)
    manifest, grad = load_labels(data)
    cfg = LabelConfig(**manifest["config"])
    labeler = labelers(data, cfg, relations=("on_top_of",))[data.scenes[0]]
    if labeler.rays is None:
        raise SystemExit(f"{args.data} has no pixel rays (collected before 2026-12-07, or no table_height)")
    arrays = data.object_arrays(data.load(["positions", "present"]))
    pixels = gradcam_objects(data, grad)
    points = labeler.points(pixels)
    said = labeler.table(pixels, arrays["present"])
    truth = world_table(arrays["positions"], arrays["present"], data.objects, world_thresholds(data, cfg),
                        relations=("on_top_of",), solid=True)
    rows = {}
    for t, (a, b) in enumerate(relation_tuples("on_top_of", data.objects)):
        both = arrays["present"][:, a] & arrays["present"][:, b]
        key = f"{data.objects[a]} on top of {data.objects[b]}"
        rows[key] = pair_stats(points, truth.holds["on_top_of"][:, t], said.holds["on_top_of"][:, t], both, a, b)
        h, n = rows[key]["holds"], rows[key]["not"]
        print(f"{key:40s} holds {h['frames']:4d} (says {h['labeler_says']}) h {h['horizontal_p10_50_90']} "
              f"dz {h['dz_p10_50_90']} | not {n['frames']:4d} (says {n['labeler_says']})")
    write_json(args.out, {"data": args.data, "pairs": rows, "thresholds": world_thresholds(data, cfg).__dict__,
                          "meta": {"command": "python probes/solid_on_top.py " + " ".join(sys.argv[1:]),
                                   "truth": "the scene's oracle on true positions, 3-D reading (evaluation only)"}},
               indent=1)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
