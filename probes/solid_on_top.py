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

# Camera sets compared (the labeler's first): on_top_of F1 against the oracle over every pair and frame.
CAMERA_SETS = (("tilted", "left"), ("front", "left", "tilted"), ("front", "left"), ("front", "tilted"))


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
    from zsrm.envs.cameras import triangulate_rays
    from zsrm.evaluation.metrics import binary_metrics
    from zsrm.grounding.labeler import pixel_planes, relation_tuples, world_table

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
    rows, sets = {}, {}
    th = world_thresholds(data, cfg)
    for cams in CAMERA_SETS:  # which cameras the points are triangulated from
        pts = triangulate_rays([labeler.rays[c] for c in cams], [pixels[c] for c in cams])
        tab = world_table(pts, arrays["present"], data.objects, th, relations=("on_top_of",), solid=True)
        m = binary_metrics(tab.holds["on_top_of"].ravel(), truth.holds["on_top_of"].ravel())
        sets["+".join(cams)] = {k: round(float(m[k]), 4) for k in ("f1", "precision", "recall")}
        print("+".join(cams), sets["+".join(cams)])
    flat = labelers(data, LabelConfig(**{**manifest["config"], "on_top": "front"}), relations=("on_top_of",))
    tab = flat[data.scenes[0]].table(pixels, arrays["present"])
    m = binary_metrics(tab.holds["on_top_of"].ravel(), truth.holds["on_top_of"].ravel())
    sets["front (Table 1)"] = {k: round(float(m[k]), 4) for k in ("f1", "precision", "recall")}
    print("front (Table 1)", sets["front (Table 1)"])
    # hybrid: over the footprint on the tilted camera's table plane (metres), higher on the front camera (no gap)
    planes = pixel_planes(pixels, labeler.table_homography)
    tup = relation_tuples("on_top_of", data.objects)
    flat_xy, front = planes["tilted"], planes["front"]
    near = np.linalg.norm(flat_xy[:, tup[:, 0]] - flat_xy[:, tup[:, 1]], axis=-1) < th.eps_x
    rise = front[:, tup[:, 0], 1] - front[:, tup[:, 1], 1]
    hyb = near & (rise > 0) & (rise < labeler.thresholds["front"].eps_y) & arrays["present"][:, tup].all(-1)
    m = binary_metrics(hyb.ravel(), truth.holds["on_top_of"].ravel())
    sets["hybrid"] = {k: round(float(m[k]), 4) for k in ("f1", "precision", "recall")}
    print("hybrid", sets["hybrid"])
    for t, (a, b) in enumerate(relation_tuples("on_top_of", data.objects)):
        both = arrays["present"][:, a] & arrays["present"][:, b]
        key = f"{data.objects[a]} on top of {data.objects[b]}"
        rows[key] = pair_stats(points, truth.holds["on_top_of"][:, t], said.holds["on_top_of"][:, t], both, a, b)
        h, n = rows[key]["holds"], rows[key]["not"]
        print(f"{key:40s} holds {h['frames']:4d} (says {h['labeler_says']}) h {h['horizontal_p10_50_90']} "
              f"dz {h['dz_p10_50_90']} | not {n['frames']:4d} (says {n['labeler_says']})")
    write_json(args.out, {"data": args.data, "camera_sets": sets, "pairs": rows, "thresholds": world_thresholds(data, cfg).__dict__,
                          "meta": {"command": "python probes/solid_on_top.py " + " ".join(sys.argv[1:]),
                                   "truth": "the scene's oracle on true positions, 3-D reading (evaluation only)"}},
               indent=1)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
